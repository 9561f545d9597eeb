"""fluid/column_pressure.py: the local static pressure, p at the top of the vertical plus the
weight of the fluid below it, against closed forms."""
from __future__ import annotations

import numpy as np
import pytest
from dolfinx import fem, mesh
from mpi4py import MPI

from fcm_fsi.fluid.column_pressure import ColumnPressure, column_integral, vertical_frame

G = 9.81
RHO_L, RHO_A = 998.2, 1.2
TOP, INTERFACE, RAMP = 0.2, 0.1, 0.02     # [m]: the mesh's cells are 0.02 m high, ρ ramps over one


def _mesh(dim: int):
    if dim == 2:
        return mesh.create_rectangle(MPI.COMM_WORLD, [[0.0, 0.0], [0.3, TOP]], [15, 10])
    return mesh.create_box(MPI.COMM_WORLD, [[0.0, 0.0, 0.0], [0.3, 0.2, TOP]], [15, 10, 10])


def _weight_above(z: np.ndarray) -> np.ndarray:
    """∫ from z to the top of the P1 interpolant of water below INTERFACE and air above (its
    ramp between INTERFACE and INTERFACE + RAMP) × g [Pa], for z outside the ramp."""
    air = RHO_A * G * (TOP - np.maximum(z, INTERFACE + RAMP))
    ramp = 0.5 * (RHO_L + RHO_A) * G * RAMP * (z < INTERFACE + RAMP)
    water = RHO_L * G * np.maximum(INTERFACE - z, 0.0)
    return air + ramp + water


@pytest.mark.parametrize("dim", [2, 3])
def test_layered_water_and_air_give_the_weight_of_the_column(dim):
    """Water below, air above, an ambient pressure that varies across the top: the column
    pressure is the top's plus the weight of the P1 density below it, to round-off, at points
    off the grid of columns and levels."""
    msh = _mesh(dim)
    up = dim - 1
    V = fem.FunctionSpace(msh, ("Lagrange", 1))
    rho = fem.Function(V)
    rho.interpolate(lambda x: np.where(x[up] <= INTERFACE + 1e-9, RHO_L, RHO_A))
    p = fem.Function(V)                        # only its values at the top matter
    p.interpolate(lambda x: 50.0 + 30.0 * x[0] + (x[up] - TOP) * 1e3)
    gravity = np.zeros(dim)
    gravity[up] = -G
    column = ColumnPressure(msh, gravity, 0.02)
    rng = np.random.default_rng(7)
    pts = np.zeros((80, 3))
    pts[:, 0] = rng.uniform(0.0, 0.3, 80)
    if dim == 3:
        pts[:, 1] = rng.uniform(0.0, 0.2, 80)
    z = np.concatenate([rng.uniform(0.0, INTERFACE, 40), rng.uniform(INTERFACE + RAMP, TOP, 40)])
    pts[:, up] = z
    values = column.values(pts, p, rho)
    expected = 50.0 + 30.0 * pts[:, 0] + _weight_above(z)
    # between levels the weight is interpolated linearly: exact where ρ is constant; the top's
    # pressure is read 1e-9 m inside the mesh (≤ ρ_l g × 1e-9 m = 1e-5 Pa)
    np.testing.assert_allclose(values, expected, rtol=0, atol=1e-4)
    np.testing.assert_allclose(column.values(pts, p, RHO_L), 50.0 + 30.0 * pts[:, 0] + RHO_L * G * (TOP - z),
                               rtol=0, atol=1e-4)


def test_points_asked_again_keep_their_columns_and_get_the_values_of_a_fresh_call():
    """A coupled step asks for the static pressure at the same points once per implicit pass:
    their columns and stencils are kept (for two sets of points), and the values are those of a
    ColumnPressure that builds them anew, to the bit, for new pressures and densities."""
    msh = _mesh(3)
    V = fem.FunctionSpace(msh, ("Lagrange", 1))
    rho, p = fem.Function(V), fem.Function(V)
    column, fresh = ColumnPressure(msh, [0.0, 0.0, -G], 0.02), ColumnPressure(msh, [0.0, 0.0, -G], 0.02)
    rng = np.random.default_rng(3)
    a, b = (rng.uniform([0.0, 0.0, 0.0], [0.3, 0.2, TOP], (40 + 10 * MPI.COMM_WORLD.rank, 3)) for _ in range(2))
    for k, pts in enumerate([a, b, a, b, a]):
        rho.interpolate(lambda x, k=k: np.where(x[2] <= INTERFACE + 0.01 * k, RHO_L, RHO_A))
        p.interpolate(lambda x, k=k: 50.0 * k + 30.0 * x[0])
        got = column.values(pts, p, rho, with_density=True)
        fresh._geometry = []
        want = fresh.values(pts, p, rho, with_density=True)
        for g, w in zip(got, want):
            np.testing.assert_array_equal(g, w)
    assert len(column._geometry) == 2


def test_the_column_integral_is_the_trapezoidal_rule_from_the_first_level_in_the_mesh():
    """NumPy reference: levels above the mesh add nothing; a level below the mesh's edge keeps
    the density of the last one in it."""
    rho = np.array([[5.0, 1.0, 2.0, 4.0, 9.0]])
    found = np.array([[False, True, True, True, False]])
    w = column_integral(rho, found, 2.0, 0.5)
    np.testing.assert_allclose(w, [[0.0, 0.0, 1.5, 4.5, 8.5]])


def test_the_vertical_frame_is_orthonormal_for_any_gravity():
    for g in ([0.0, 0.0, -9.81], [1.0, -2.0, -9.0], [-9.81, 0.0, 0.0]):
        up, across = vertical_frame(np.array(g), 3)
        frame = np.vstack([across, up])
        np.testing.assert_allclose(frame @ frame.T, np.eye(3), atol=1e-14)
        np.testing.assert_allclose(up, -np.array(g) / np.linalg.norm(g))
    up, across = vertical_frame(np.array([0.0, -9.81]), 2)
    np.testing.assert_allclose(up, [0.0, 1.0, 0.0])
    np.testing.assert_allclose(across @ up, [0.0])
