"""Structure level set: Numba kernel vs brute-force NumPy reference, closed-form distances to
spheres, rotated boxes and cylinders, DEM pose convention, clipping, owners, and O(N) search."""
from __future__ import annotations

import numpy as np
import pytest

from fcm_fsi.coupling.dem_side import rigid_body_velocity
from fcm_fsi.dem.bodies import axis_angle_quat
from fcm_fsi.dem.state import DEMState
from fcm_fsi.fcm.levelset import NO_SHAPE, WALL, Shapes, StructureLevelSet
from fcm_fsi.fcm.levelset_reference import signed_distance_reference
from fcm_fsi.geometry import quat_to_matrix_np


def random_rotation(rng) -> np.ndarray:
    q = rng.normal(size=4)
    return quat_to_matrix_np(q / np.linalg.norm(q))


def random_shapes(rng, n, nbodies, box=1.0, size=(0.02, 0.08)) -> Shapes:
    """n primitives of random kind, size, offset and orientation, ~1/4 of them static."""
    parts = []
    for _ in range(n):
        kind = rng.integers(3)
        body = int(rng.integers(-1, nbodies)) if nbodies else -1
        centre = rng.uniform(0, box, 3) if body < 0 else rng.uniform(-0.05, 0.05, 3)
        lo, hi = size
        if kind == 0:
            parts.append(Shapes.sphere(centre, rng.uniform(lo, hi) / 2, body=body))
        elif kind == 1:
            parts.append(Shapes.box(centre, rng.uniform(lo, hi, 3), random_rotation(rng), body=body))
        else:
            r, length = rng.uniform(lo, hi) / 2, rng.uniform(lo, hi)
            parts.append(Shapes.cylinder(centre, r, length, rng.normal(size=3), body))
    return Shapes.concat(parts)


def random_poses(rng, nbodies, box=1.0):
    q = rng.normal(size=(nbodies, 4))
    return rng.uniform(0, box, (nbodies, 3)), q / np.linalg.norm(q, axis=1)[:, None]


def evaluate(shapes, points, nbodies=0, pos=None, quat=None, cutoff=10.0):
    pos = np.zeros((nbodies, 3)) if pos is None else pos
    quat = np.tile([1.0, 0, 0, 0], (nbodies, 1)) if quat is None else quat
    return StructureLevelSet(shapes, nbodies, cutoff).evaluate(np.atleast_2d(points), pos, quat)


@pytest.mark.parametrize("cutoff", [0.02, 0.1, 2.0])
def test_kernel_matches_reference(cutoff):
    rng = np.random.default_rng(3)
    shapes = random_shapes(rng, 60, nbodies=20)
    pos, quat = random_poses(rng, 20)
    x = rng.uniform(-0.1, 1.1, (4000, 3))
    x[:1000] = pos[rng.integers(20, size=1000)] + rng.normal(scale=0.03, size=(1000, 3))  # inside and near bodies
    ls = StructureLevelSet(shapes, 20, cutoff)
    phi, owner = ls.evaluate(x, pos, quat)
    phi_ref, owner_ref = signed_distance_reference(x, shapes, pos, quat, cutoff)
    np.testing.assert_allclose(phi, phi_ref, rtol=0, atol=1e-12)
    assert (phi < 0).sum() > 50 and (np.abs(phi) < cutoff).sum() > 500   # the test sees insides and the band
    np.testing.assert_array_equal(owner, owner_ref)


@pytest.mark.parametrize("gap", [0.01, 0.05])
def test_gap_fill_kernel_matches_reference(gap):
    """Gap fill between distinct owners (bodies, static shapes, walls as one owner): kernel = NumPy."""
    rng = np.random.default_rng(5)
    shapes = random_shapes(rng, 60, nbodies=20)
    pos, quat = random_poses(rng, 20)
    walls = np.array([[0, 0, 0, 0, 0, 1.0], [0, 0, 0, 1.0, 0, 0], [1.0, 0, 0, -2.0, 0, 0]])   # floor, two ends
    x = rng.uniform(0.0, 1.0, (4000, 3))
    x[:1000] = pos[rng.integers(20, size=1000)] + rng.normal(scale=0.03, size=(1000, 3))
    cutoff = 0.1
    ls = StructureLevelSet(shapes, 20, cutoff, gap=gap, walls=walls)
    phi, owner = ls.evaluate(x, pos, quat)
    fill = np.full((len(x), 2), NO_SHAPE, np.int64), np.zeros((len(x), 2))
    phi_ref, owner_ref = signed_distance_reference(x, shapes, pos, quat, cutoff, gap=gap, walls=walls, fill=fill)
    on_wall = fill[0][:, 0] == WALL
    plain, _ = signed_distance_reference(x, shapes, pos, quat, cutoff)
    np.testing.assert_allclose(phi, phi_ref, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(owner, owner_ref)
    no_fill_arrays, _ = signed_distance_reference(x, shapes, pos, quat, cutoff, gap=gap, walls=walls)
    np.testing.assert_array_equal(no_fill_arrays, phi_ref)       # the blend's arrays are optional
    np.testing.assert_array_equal(ls.fill_other, fill[0])
    np.testing.assert_allclose(ls.fill_weight, fill[1], rtol=0, atol=1e-12)
    blended = (ls.fill_weight > 0) & (ls.fill_weight < 1)
    assert blended[:, 0].sum() > 10 and (blended[:, 1].sum() > 10 or gap < 0.05)   # two (and three) owners mixed
    assert np.all(ls.fill_weight[ls.fill_other == NO_SHAPE] == 0) and np.all(ls.fill_weight.sum(axis=1) <= 1)
    assert 0 < on_wall.sum() < (phi < plain - 1e-12).sum()   # fills against walls and between bodies
    filled = (phi < 0) & (plain > 0)
    assert filled.sum() > 10                      # the test sees fill (19 and 250 points)
    assert np.all(phi <= plain + 1e-12) and np.all(owner[filled] >= -1)   # a union; fill never owned by a wall


def test_gap_fill_closes_a_sub_gap_layer_under_a_block():
    """A block 1 mm above the floor: the layer under it is solid with gap 5 mm, fluid without;
    the fill ends where block and floor are farther than the gap apart; tank corners stay fluid."""
    block = Shapes.box((0, 0, 0), (0.2, 0.1, 0.1), body=0)
    pos, quat = np.array([[0.5, 0.051, 0.0]]), np.array([[1.0, 0, 0, 0]])
    floor_and_end = np.array([[0, 0, 0, 0, 1.0, 0], [0, 0, 0, 1.0, 0, 0]])
    x = np.array([[0.5, 0.0005, 0.0],     # under the block, mid-gap
                  [0.5, 0.0, 0.0],        # on the floor under the block
                  [0.603, 0.0005, 0.0],   # 3 mm beyond the block's edge: d1 + d2 = 0.0005 + 0.0030...
                  [0.65, 0.0005, 0.0],    # 5 cm beyond the edge: fluid
                  [0.001, 0.001, 0.0]])   # tank corner, far from the block
    ls = StructureLevelSet(block, 1, 0.1, gap=0.005, walls=floor_and_end)
    phi, owner = ls.evaluate(x, pos, quat)
    d_block = np.hypot(0.003, 0.001 - 0.0005)
    np.testing.assert_allclose(phi[:3], [0.5 * (0.0005 + 0.0005 - 0.005), 0.5 * (0.001 - 0.005),
                                         0.5 * (0.0005 + d_block - 0.005)], atol=1e-15)
    assert np.all(owner[:3] == 0) and phi[3] > 0 and phi[4] > 0
    # the wall is the fill's other owner also at fluid points where the fill is the nearer surface
    np.testing.assert_array_equal(ls.fill_other[:, 0] == WALL, [True, True, True, True, False])
    plain, _ = StructureLevelSet(block, 1, 0.1).evaluate(x, pos, quat)
    assert np.all(plain[:3] > 0) and 0 < phi[3] < plain[3]


def test_gap_fill_velocity_is_continuous_and_each_surface_keeps_its_own():
    """The fill's wall velocity ū = (1 − w) ū_owner + w ū_other is continuous across the fill
    (its jumps between neighbouring samples shrink with their spacing), equals the floor's 0
    on the floor and the block's v on the block, and the block's v where the fill ends: a
    block 3 mm above the floor and 4 mm from a static stopper, gap 5 mm, moving at v."""
    from fcm_fsi.coupling.dem_side import blended_rigid_velocity
    shapes = Shapes.concat([Shapes.box((0, 0, 0), (0.2, 0.1, 0.1), body=0),
                            Shapes.box((0.654, 0.05, 0.0), (0.1, 0.1, 0.1))])        # static, 4 mm gap
    pos, quat = np.array([[0.5, 0.053, 0.0]]), np.array([[1.0, 0, 0, 0]])
    v, omega = np.array([[0.3, -0.2, 0.0]]), np.array([[0.0, 0.0, 2.0]])
    ls = StructureLevelSet(shapes, 1, 0.1, gap=0.005, walls=np.array([[0, 0, 0, 0, 1.0, 0]]))

    def ubar(x):
        phi, owner = ls.evaluate(x, pos, quat)
        return blended_rigid_velocity(pos, v, omega, x, owner, ls.fill_other, ls.fill_weight)

    def largest_jump(spacing):
        gx, gy = np.arange(0.45, 0.606, spacing), np.arange(0.0, 0.012, spacing)
        X, Y = np.meshgrid(gx, gy, indexing="ij")
        u = ubar(np.column_stack([X.ravel(), Y.ravel(), np.zeros(X.size)])).reshape(*X.shape, 3)
        return max(np.abs(np.diff(u, axis=0)).max(), np.abs(np.diff(u, axis=1)).max())

    coarse, fine = largest_jump(2e-4), largest_jump(5e-5)
    speed = np.linalg.norm(v) + 2.0 * 0.11
    assert fine < 0.1 * speed and fine < 0.35 * coarse        # a jump would not shrink with the spacing
    x = np.array([[0.5, 0.0, 0.0],        # on the floor under the block: the floor's 0
                  [0.5, 0.003, 0.0],      # on the block's underside: the block's velocity
                  [0.5, 0.0015, 0.0],     # mid-layer: the mean
                  [0.602, 0.03, 0.0],     # mid-gap to the stopper: the mean of v and 0
                  [0.59, 0.02, 0.0]])     # inside the block, 1 cm from its side: its own
    rigid = rigid_body_velocity(pos, v, omega, x, np.zeros(len(x), np.int64))
    np.testing.assert_allclose(ubar(x), [0 * rigid[0], rigid[1], 0.5 * rigid[2], 0.5 * rigid[3], rigid[4]],
                               atol=1e-12)


def test_sphere_distance():
    c, r = np.array([0.3, -0.2, 0.1]), 0.25
    u = np.array([2.0, -1.0, 2.0]) / 3.0
    d = np.array([-0.25, -0.1, 0.0, 0.05, 0.7])
    phi, _ = evaluate(Shapes.sphere(c, r), c + np.outer(r + d, u))
    np.testing.assert_allclose(phi, d, atol=1e-15)


def test_rotated_box_face_edge_corner_and_inside():
    R = quat_to_matrix_np(axis_angle_quat([1.0, 2.0, -0.5], 0.7))
    c, half = np.array([1.0, 2.0, -1.0]), np.array([0.3, 0.2, 0.1])
    local = np.array([[0.3 + 0.05, 0.1, -0.05],      # face +x, 0.05 out
                      [-0.3 - 0.03, 0.2 + 0.04, 0.0],  # edge (−x, +y)
                      [0.3 + 0.01, -0.2 - 0.02, 0.1 + 0.02],  # corner
                      [0.25, 0.0, 0.0],                # inside, nearest face +x at 0.05
                      [0.0, 0.05, 0.08]])              # inside, nearest face +z at 0.02
    expected = [0.05, 0.05, np.sqrt(0.01**2 + 0.02**2 + 0.02**2), -0.05, -0.02]
    phi, owner = evaluate(Shapes.box(c, 2 * half, R), c + local @ R.T)
    np.testing.assert_allclose(phi, expected, atol=1e-14)
    np.testing.assert_array_equal(owner, -1)


def test_cylinder_side_cap_rim_and_inside():
    axis = np.array([1.0, 1.0, 0.0]) / np.sqrt(2)
    perp = np.array([0.0, 0.0, 1.0])
    c, r, length = np.array([0.5, 0.0, 0.2]), 0.1, 0.6
    pts = [c + 0.15 * perp + 0.2 * axis,               # side: 0.05 out
           c + 0.05 * perp + 0.4 * axis,               # cap: 0.1 out
           c + 0.13 * perp - 0.34 * axis,              # rim: (0.03, 0.04) out
           c + 0.02 * perp + 0.0 * axis,               # inside, side at 0.08
           c + 0.0 * perp + 0.28 * axis]               # inside, cap at 0.02
    phi, _ = evaluate(Shapes.cylinder(c, r, length, axis), pts)
    np.testing.assert_allclose(phi, [0.05, 0.1, 0.05, -0.08, -0.02], atol=1e-14)


def test_cylinder_in_a_2d_mesh_is_a_disc():
    """Points at z = 0 and a z-cylinder of length 2·cutoff: φ is the clipped 2D disc distance."""
    rng = np.random.default_rng(5)
    x = np.column_stack([rng.uniform(-1, 1, (2000, 2)), np.zeros(2000)])
    phi, _ = evaluate(Shapes.cylinder((0.2, 0.1, 0.0), 0.3, 0.4), x, cutoff=0.2)
    disc = np.hypot(x[:, 0] - 0.2, x[:, 1] - 0.1) - 0.3
    np.testing.assert_allclose(phi, np.clip(disc, -0.2, 0.2), atol=1e-14)
    assert (disc < -0.2).sum() > 5     # points deeper than the cutoff are in the test


def test_body_rotated_90_degrees_about_z_turns_its_box():
    """A body at p rotated +90° about z carries its box (long edge 2 m along body x,
    offset 0.5 m along body x) to lie along world y, centred at p + (0, 0.5, 0)."""
    p = np.array([1.0, 2.0, 3.0])
    q = axis_angle_quat([0, 0, 1], np.pi / 2)[None]
    shapes = Shapes.box((0.5, 0, 0), (2.0, 0.4, 0.2), body=0)
    x = p + np.array([[0.0, 1.5 + 0.3, 0.0],     # beyond the far end along world y
                      [0.0, -0.5 - 0.1, 0.0],    # beyond the near end
                      [0.2 + 0.4, 0.5, 0.0],     # beside the long side, world x
                      [1.3, 0.0, 0.0]])          # where the unrotated box would have been
    phi, owner = evaluate(shapes, x, 1, p[None], q)
    np.testing.assert_allclose(phi, [0.3, 0.1, 0.4, 1.3 - 0.2], atol=1e-14)
    np.testing.assert_array_equal(owner, 0)


def test_pose_convention_is_the_dem_state_one():
    """A sphere attached to a DEM block at its sph_local has φ = −r at the DEM's sph_pos."""
    rng = np.random.default_rng(7)
    q = rng.normal(size=(3, 4))
    st = DEMState.from_blocks(rng.uniform(0, 1, (3, 3)), q, np.ones(3), np.ones((3, 3)), [0, 1, 2],
                              rng.uniform(-0.2, 0.2, (3, 3)), [0.05, 0.06, 0.07])
    shapes = Shapes.concat([Shapes.sphere(st.sph_local[s], st.sph_radius[s], body=st.sph_block[s])
                            for s in range(3)])
    phi, owner = evaluate(shapes, st.sph_pos, 3, st.pos, st.quat, cutoff=0.01)
    np.testing.assert_allclose(phi, -0.01)
    np.testing.assert_array_equal(owner, st.sph_block)
    phi, _ = evaluate(shapes, st.sph_pos + [0.08, 0, 0], 3, st.pos, st.quat, cutoff=1.0)
    np.testing.assert_allclose(phi, 0.08 - st.sph_radius, atol=1e-14)


def test_clipping_and_owner_ids():
    """Body 0 sphere, body 1 box, a static floor; far points get +cutoff and owner −2,
    deep points −cutoff and the owner of the deepest primitive."""
    cutoff = 0.05
    shapes = Shapes.concat([Shapes.sphere((0, 0, 0), 0.2, body=0),
                            Shapes.box((0, 0, 0), (0.4, 0.4, 0.4), body=1),
                            Shapes.box((0, 0, -1.0), (4.0, 4.0, 0.2))])
    pos = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    x = np.array([[0.0, 0.0, 0.0],      # deep in the sphere
                  [0.0, 0.0, 0.23],     # 0.03 above the sphere
                  [1.0, 0.0, 0.21],     # 0.01 above the box
                  [0.5, 0.0, 0.0],      # between them, 0.3 from both
                  [1.0, 0.0, -0.87],    # 0.03 above the floor
                  [1.0, 0.0, -1.0],     # in the floor, 0.1 deep
                  [5.0, 5.0, 5.0]])     # far from everything, outside the grid
    phi, owner = evaluate(shapes, x, 2, pos, np.tile([1.0, 0, 0, 0], (2, 1)), cutoff)
    np.testing.assert_allclose(phi, [-cutoff, 0.03, 0.01, cutoff, 0.03, -cutoff, cutoff], atol=1e-14)
    np.testing.assert_array_equal(owner, [0, 0, 1, -2, -1, -1, -2])
    assert np.all(np.abs(phi) <= cutoff)


def test_union_of_overlapping_shapes_is_the_minimum():
    shapes = Shapes.concat([Shapes.sphere((0, 0, 0), 0.3), Shapes.box((0.3, 0, 0), (0.4, 0.2, 0.2), body=0)])
    x = np.array([[0.55, 0.0, 0.0], [0.0, 0.0, 0.35], [0.3, 0.0, 0.0]])
    phi, owner = evaluate(shapes, x, 1)
    np.testing.assert_allclose(phi, [0.05, 0.05, -0.1], atol=1e-14)   # at x = 0.3: box depth 0.1, sphere 0
    np.testing.assert_array_equal(owner, [0, -1, 0])


def test_second_owner_and_margin_are_the_nearest_other_body_and_its_extra_distance():
    """Two overlapping boxes of bodies 0 and 1 (0: x ∈ [−0.2, 0.2], 1: x ∈ [0.1, 0.5], both
    |y|, |z| ≤ 0.1) and a static sphere far off: along y = z = 0 the second owner is the other
    box and the margin the difference of the two signed distances (brute force per box); a
    point with only one body within reach has no second owner (−2) and margin = cutoff."""
    boxes = [Shapes.box((0, 0, 0), (0.4, 0.2, 0.2), body=0), Shapes.box((0.3, 0, 0), (0.4, 0.2, 0.2), body=0)]
    shapes = Shapes.concat([boxes[0], Shapes.box((0.3, 0, 0), (0.4, 0.2, 0.2), body=1),
                            Shapes.sphere((5.0, 5.0, 5.0), 0.1)])
    x = np.column_stack([np.linspace(-0.3, 0.6, 37), np.zeros(37), np.zeros(37)])
    rest = (np.zeros((2, 3)), np.tile([1.0, 0, 0, 0], (2, 1)))
    ls = StructureLevelSet(shapes, 2, 1.0)
    phi, owner = ls.evaluate(x, *rest)
    d = np.column_stack([signed_distance_reference(x, b, rest[0][:1], rest[1][:1], 1.0)[0] for b in boxes])
    np.testing.assert_array_equal(owner, np.argmin(d, axis=1))
    np.testing.assert_array_equal(ls.second_owner, 1 - np.argmin(d, axis=1))
    np.testing.assert_allclose(ls.owner_margin, np.abs(d[:, 0] - d[:, 1]), atol=1e-14)
    near = StructureLevelSet(shapes, 2, 0.05)
    _, owner = near.evaluate(np.array([[-0.24, 0.0, 0.0]]), *rest)
    assert owner[0] == 0 and near.second_owner[0] == -2 and near.owner_margin[0] == 0.05


def test_no_shapes_and_invalid_input():
    phi, owner = evaluate(Shapes.concat([]), np.zeros((4, 3)), cutoff=0.1)
    np.testing.assert_array_equal(phi, 0.1)
    np.testing.assert_array_equal(owner, -2)
    with pytest.raises(ValueError, match="kind"):
        Shapes(np.array([4]), np.array([-1]), np.zeros((1, 3)), np.eye(3)[None], np.ones((1, 3)))
    with pytest.raises(ValueError, match="grid"):          # a mesh without its distance grid
        Shapes(np.array([3]), np.array([-1]), np.zeros((1, 3)), np.eye(3)[None], np.ones((1, 3)))
    with pytest.raises(ValueError, match="rot"):
        Shapes.box((0, 0, 0), (1, 1, 1), rot=np.diag([1.0, 1.0, -1.0]))
    with pytest.raises(ValueError, match="half"):
        Shapes.cylinder((0, 0, 0), 0.1, 0.0)
    with pytest.raises(ValueError, match="nbodies"):
        StructureLevelSet(Shapes.sphere((0, 0, 0), 1.0, body=2), 2, 0.1)


def test_result_does_not_depend_on_thread_count():
    import numba
    rng = np.random.default_rng(11)
    shapes = random_shapes(rng, 100, nbodies=30)
    pos, quat = random_poses(rng, 30)
    x = rng.uniform(0, 1, (20000, 3))
    ls = StructureLevelSet(shapes, 30, 0.05)
    one = ls.evaluate(x, pos, quat)
    numba.set_num_threads(min(2, numba.config.NUMBA_NUM_THREADS))
    two = ls.evaluate(x, pos, quat)
    np.testing.assert_array_equal(one[0], two[0])
    np.testing.assert_array_equal(one[1], two[1])


def search_cost(scale: int, rng) -> tuple[float, float]:
    """(candidates per point, bin listings per primitive) for 1000 scale³ primitives on as
    many bodies in a cube of edge scale [m], and 4000 scale³ points kept 0.15 m from its
    faces, where the primitives around a point have the bulk density at both scales."""
    n = 1000 * scale**3
    edge = 1.0 * scale
    shapes = random_shapes(rng, n, nbodies=n, box=edge)
    pos, quat = random_poses(rng, n, box=edge)
    x = rng.uniform(0.15, edge - 0.15, (4000 * scale**3, 3))
    ls = StructureLevelSet(shapes, n, cutoff=0.03)
    ls.evaluate(x, pos, quat)
    return ls.pair_tests / len(x), ls.bin_entries / n


def test_search_cost_is_linear():
    """8× more primitives and points at the same density: the work per point and per
    primitive stays put (counted in the kernel, not timed), far below brute force."""
    rng = np.random.default_rng(13)
    per_point_1, per_shape_1 = search_cost(1, rng)
    per_point_2, per_shape_2 = search_cost(2, rng)
    assert per_point_2 < 1.25 * per_point_1 and per_shape_2 < 1.25 * per_shape_1   # brute force: 8×
    assert per_point_2 < 8000 / 100      # brute force would read all 8000 primitives
