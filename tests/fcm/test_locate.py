"""The kept point locations (fcm/locate.py) against a fresh search at every call."""
import numpy as np
import pytest
from dolfinx import fem, geometry, mesh
from mpi4py import MPI
from scipy.spatial import cKDTree

from fcm_fsi.fcm.locate import (
    NearPairs,
    P1Values,
    PointLocator,
    close_active_pairs,
    close_active_pairs_reference,
    first_component_at,
)


def searched(msh, points):
    """(point, cell) of dolfinx's search, owned cells only, as sorted pairs."""
    tree = geometry.BoundingBoxTree(msh, msh.topology.dim)
    found = geometry.compute_colliding_cells(msh, geometry.compute_collisions(tree, points), points)
    point = np.repeat(np.arange(len(points)), np.diff(found.offsets))
    cell = found.array
    owned = cell < msh.topology.index_map(msh.topology.dim).size_local
    return sorted(zip(point[owned].tolist(), cell[owned].tolist()))


@pytest.mark.parametrize("dim", [2, 3])
def test_kept_cells_are_the_search_s_cells_as_points_move(dim):
    """Points strictly inside cells, on mesh vertices and faces (several cells), and outside
    the mesh, moved a little at every call (some across cell faces): the same (point, cell)
    pairs as dolfinx's search, while most points are not searched again."""
    comm = MPI.COMM_WORLD
    if dim == 2:
        msh = mesh.create_unit_square(comm, 8, 8)
    else:
        msh = mesh.create_unit_cube(comm, 5, 5, 5)
    rng = np.random.default_rng(3)
    inner = np.zeros((400, 3))
    inner[:, :dim] = rng.uniform(0.02, 0.98, (400, dim))
    on_mesh = np.zeros((20, 3))
    on_mesh[:, :dim] = rng.integers(1, 5, (20, dim)) / (8 if dim == 2 else 5)    # mesh vertices
    outside = np.zeros((5, 3))
    outside[:, :dim] = 1.5
    points = np.concatenate([inner, on_mesh, outside])
    slots = np.arange(len(points))
    locator = PointLocator(msh, len(points))
    searched_counts = []
    for step in range(4):
        moved = points.copy()
        if step:
            moved[:400, :dim] += rng.normal(scale=1e-3 * step, size=(400, dim))
        point, cell = locator.locate(slots, moved)
        assert sorted(zip(point.tolist(), cell.tolist())) == searched(msh, moved)
        searched_counts.append(locator.searched)
    assert searched_counts[0] == len(points)
    assert max(searched_counts[1:]) < 0.2 * len(points)       # the vertices, the outside, the movers
    assert min(searched_counts[1:]) >= 25


def test_near_pairs_equal_a_fresh_search_as_bodies_move():
    """Points of 12 bodies side by side, some bodies moved at each call (slowly: pairs kept; fast:
    searched again): the pairs of different bodies closer than the radius among the active points
    equal a fresh KD-tree search, bodies at rest are not searched again, and a moved body's
    points are searched among the bodies within its reach only."""
    rng = np.random.default_rng(7)
    body = np.repeat(np.arange(12), 150)
    corner = 0.28 * np.stack(np.unravel_index(np.arange(12), (4, 3, 1)), axis=1)   # boxes that overlap a little
    x = corner[body] + rng.uniform(0.0, 0.3, (len(body), 3))
    near = NearPairs(body, radius=0.08, margin=0.04)
    for step in range(6):
        if step:
            shift = np.zeros((12, 3))
            shift[step % 12] = rng.normal(scale=0.004, size=3)          # within margin/2: kept
            shift[(step + 5) % 12] = rng.normal(scale=0.05, size=3)     # beyond: searched again
            x = x + shift[body]
        active = rng.uniform(size=len(body)) < 0.8
        i, j, d2 = near.pairs(x, active)
        idx = np.flatnonzero(active)
        ref = cKDTree(x[idx]).query_pairs(0.08, output_type="ndarray")
        a, b = idx[ref[:, 0]], idx[ref[:, 1]]
        other = body[a] != body[b]
        expect = sorted(zip(np.minimum(a, b)[other].tolist(), np.maximum(a, b)[other].tolist()))
        assert len(expect) > 100 and sorted(zip(i.tolist(), j.tolist())) == expect
        np.testing.assert_allclose(d2, np.sum((x[i] - x[j]) ** 2, axis=1))
        if step:
            assert near.searched_bodies <= 2
            assert near.searched_points < len(x)        # only the bodies the moved ones can reach


def test_close_active_pairs_kernel_equals_its_numpy_twin():
    """The Numba filter of candidate pairs gives the NumPy twin's pairs and squared distances to
    the bit (5,000 random points, 40,000 candidates, a third inactive)."""
    rng = np.random.default_rng(3)
    x = rng.uniform(-1.0, 1.0, (5000, 3))
    i, j = rng.integers(0, 5000, 40000), rng.integers(0, 5000, 40000)
    active = rng.uniform(size=5000) > 0.33
    got = close_active_pairs(x, i, j, active, 0.5)
    want = close_active_pairs_reference(x, i, j, active, 0.5)
    assert 1000 < len(want[0]) < 20000
    for a, b in zip(got, want):
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("dim", [2, 3])
def test_p1_values_equal_dolfinx_eval(dim):
    """P1 functions (a random field, and x + 2y − z exactly) at random points in their located
    cells equal ``Function.eval`` to round-off; a P2 function takes the eval fallback."""
    comm = MPI.COMM_WORLD
    msh = mesh.create_unit_square(comm, 7, 5) if dim == 2 else mesh.create_unit_cube(comm, 4, 3, 5)
    rng = np.random.default_rng(11)
    V = fem.FunctionSpace(msh, ("Lagrange", 1))
    noise, linear = fem.Function(V), fem.Function(V)
    noise.x.array[:] = rng.normal(size=noise.x.array.size)
    noise.x.scatter_forward()
    linear.interpolate(lambda x: x[0] + 2 * x[1] - x[2])
    quad = fem.Function(fem.FunctionSpace(msh, ("Lagrange", 2)))
    quad.interpolate(lambda x: x[0] ** 2 + x[1])
    points = np.zeros((300, 3))
    points[:, :dim] = rng.uniform(0.0, 1.0, (300, dim))
    locator = PointLocator(msh, len(points))
    point, cell = locator.locate(np.arange(len(points)), points)
    values = P1Values.of(msh)
    assert values is locator.p1
    got = values.values((noise, linear, quad), points[point], cell)
    for row, fn in zip(got, (noise, linear, quad)):
        np.testing.assert_allclose(row, first_component_at(fn, points[point], cell), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(got[1], points[point] @ np.array([1.0, 2.0, -1.0]), rtol=1e-12, atol=1e-12)
