"""Exact cut-simplex measures: Numba kernel vs an independent NumPy route, and exact geometry."""
from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI

from fcm_fsi.fcm.cut import cut_measures, cut_measures_reference


@pytest.mark.parametrize("nv, gdim", [(3, 2), (4, 3)])
def test_kernel_matches_reference(nv, gdim):
    rng = np.random.default_rng(1)
    x = rng.random((500, nv, gdim))
    s = rng.standard_normal((500, nv))
    a, b = cut_measures(x, s)
    c, d = cut_measures_reference(x, s)
    np.testing.assert_allclose(a, c, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(b, d, rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize("nv, gdim", [(3, 2), (4, 3)])
def test_parts_add_up(nv, gdim):
    rng = np.random.default_rng(2)
    x = rng.random((300, nv, gdim))
    s = rng.standard_normal((300, nv))
    pos, surf_p = cut_measures(x, s)
    neg, surf_n = cut_measures(x, -s)
    full, _ = cut_measures(x, np.abs(s) + 1.0)
    np.testing.assert_allclose(pos + neg, full, rtol=1e-12)
    np.testing.assert_allclose(surf_p, surf_n, rtol=1e-12)


def test_plane_cut_of_unit_cube_mesh_is_exact():
    """A linear level set is represented exactly by P1: volume below the plane and its area are exact."""
    from dolfinx import fem, mesh

    from fcm_fsi.fluid.phase_field import p1_cell_geometry
    msh = mesh.create_unit_cube(MPI.COMM_WORLD, 6, 5, 4)
    V = fem.FunctionSpace(msh, ("Lagrange", 1))
    geom = p1_cell_geometry(V)
    n = np.array([0.3, 0.2, 1.0])
    c = 0.6   # plane n·x = c; inside: n·x ≤ c
    vals = c - geom.coords @ n
    vol, area = cut_measures(geom.coords, vals)
    vol, area = msh.comm.allreduce(vol.sum()), msh.comm.allreduce(area.sum())
    # exact: the plane z = (c − 0.3x − 0.2y) stays within (0, 1) over the unit square
    exact_vol = c - 0.3 / 2 - 0.2 / 2
    exact_area = np.linalg.norm(n) / n[2]
    assert abs(vol - exact_vol) < 1e-12
    assert abs(area - exact_area) < 1e-12


@pytest.mark.parametrize("nv, gdim", [(3, 2), (3, 3), (4, 3)])
def test_whole_cell_measure_is_the_simplex_formula_to_the_bit(nv, gdim):
    """The allocation-free simplex measures give the array formula's value bit for bit (edge
    vectors, then the cross product or the determinant), so the cut measures of uncut cells did
    not change with them."""
    from fcm_fsi.fcm.cut import _tet_volume, _tri_area
    x = np.random.default_rng(3).normal(size=(200, nv, gdim))
    for c in x:
        u, v = c[1] - c[0], c[2] - c[0]
        if nv == 4:
            w = c[3] - c[0]
            exact = abs(u[0] * (v[1] * w[2] - v[2] * w[1]) - u[1] * (v[0] * w[2] - v[2] * w[0])
                        + u[2] * (v[0] * w[1] - v[1] * w[0])) / 6.0
            assert _tet_volume(c[0], c[1], c[2], c[3]) == exact
        elif gdim == 2:
            assert _tri_area(c[0], c[1], c[2]) == 0.5 * abs(u[0] * v[1] - u[1] * v[0])
        else:
            cross = (u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0])
            assert _tri_area(c[0], c[1], c[2]) == 0.5 * np.sqrt(sum(q * q for q in cross))
