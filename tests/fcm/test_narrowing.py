"""A widened box block (``coupling.min_thickness``) near a tank wall: the widening is narrowed
so that the fluid shape keeps at least half the true box's distance to the wall
(fcm/levelset.narrowed_at_walls), and left alone away from walls and across a floor the
block stands on."""
from __future__ import annotations

import numpy as np
import pytest

from fcm_fsi.fcm.levelset import NARROW_TILT, Shapes, StructureLevelSet, narrowed_at_walls
from fcm_fsi.geometry import quat_to_matrix_np

TRUE = np.array([[0.1, 0.5, 0.4]])          # a 0.2 m wall block, 1.0 × 0.8 m
WIDE = np.array([[0.4, 0.5, 0.4]])          # widened to 0.8 m
SIDE_AND_FLOOR = np.array([[0.0, -5.0, 0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 0.0, 0.0, 1.0]])


def box_distance(centre, R, half, plane):
    """Distance [m] from a box (world centre, axes as columns, half extents) to a plane."""
    n = plane[3:]
    return float(n @ (centre - plane[:3]) - np.abs(n @ R) @ half)


def random_pose(rng):
    q = rng.normal(size=4)
    return quat_to_matrix_np(q / np.linalg.norm(q))


def test_far_from_walls_and_standing_on_the_floor_the_widening_stays():
    R = np.eye(3)[None]
    far = narrowed_at_walls(WIDE, TRUE, np.array([[15.0, 0.0, 3.0]]), R, SIDE_AND_FLOOR)
    standing = narrowed_at_walls(WIDE, TRUE, np.array([[15.0, 0.0, 0.4]]), R, SIDE_AND_FLOOR)   # on the floor
    assert np.array_equal(far, WIDE) and np.array_equal(standing, WIDE)


@pytest.mark.parametrize("seed", range(5))
def test_the_widened_box_keeps_half_the_true_distance_to_every_wall(seed):
    """Random orientations and distances: the widened box's distance to each wall is at least
    half the true box's, less the share left to axes nearly parallel to it (≤ 0.385 m tilt
    per axis), and never beyond the widened or below the true extents."""
    rng = np.random.default_rng(seed)
    m = WIDE - TRUE
    for _ in range(200):
        R = random_pose(rng)
        clear = np.abs(SIDE_AND_FLOOR[:, 3:] @ R) @ TRUE[0]            # centre height where D = 0
        centre = np.array([15.0, -5.0 + clear[0], clear[1]]) + np.array([0.0, 1.0, 1.0]) * rng.uniform(0, 1.0, 3)
        half = narrowed_at_walls(WIDE, TRUE, centre[None], R[None], SIDE_AND_FLOOR)
        assert np.all(half >= TRUE - 1e-15) and np.all(half <= WIDE + 1e-15)
        for plane in SIDE_AND_FLOOR:
            D = box_distance(centre, R, TRUE[0], plane)
            slack = 0.385 * NARROW_TILT * float(m[0] @ (np.abs(plane[3:] @ R) < NARROW_TILT))
            assert box_distance(centre, R, half[0], plane) >= 0.5 * D - slack - 1e-12


def test_a_block_flat_against_the_wall_is_its_true_box_there_and_the_narrowing_is_continuous():
    R = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])   # thin axis along y, facing the wall
    ys = -5.0 + 0.1 + np.linspace(0.0, 1.0, 401)                       # D from 0 to 1 m
    thin = np.array([narrowed_at_walls(WIDE, TRUE, np.array([[15.0, y, 3.0]]), R[None], SIDE_AND_FLOOR)[0, 0]
                     for y in ys])
    assert thin[0] == pytest.approx(TRUE[0, 0]) and thin[-1] == WIDE[0, 0]
    assert np.max(np.abs(np.diff(thin))) <= 0.5 * (ys[1] - ys[0]) + 1e-12          # Lipschitz ½ in D
    D = ys + 5.0 - 0.1
    assert np.all(ys + 5.0 - thin >= 0.5 * D - 1e-12)


def test_the_level_set_sees_the_fluid_gap_between_a_widened_block_and_the_wall():
    """A widened block 0.2 m off the side wall: without the narrowing its fluid shape reaches
    through the wall; with it the widened face stays 0.1 m off the wall (φ = 0.05 m halfway)."""
    shapes = Shapes.box((0.0, 0.0, 0.0), 2.0 * WIDE[0], rot=np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]),
                        body=0)
    true = Shapes.box((0.0, 0.0, 0.0), 2.0 * TRUE[0], rot=shapes.rot[0], body=0)
    pos, quat = np.array([[15.0, -5.0 + 0.1 + 0.2, 3.0]]), np.array([[1.0, 0.0, 0.0, 0.0]])
    gap_middle = np.array([[15.0, -4.95, 3.0]])
    widened = StructureLevelSet(shapes, 1, 0.5, walls=SIDE_AND_FLOOR).evaluate(gap_middle, pos, quat)[0]
    narrowed = StructureLevelSet(shapes, 1, 0.5, walls=SIDE_AND_FLOOR, true_half=true.half).evaluate(gap_middle, pos, quat)[0]
    assert widened[0] < 0 < narrowed[0] == pytest.approx(0.05)
