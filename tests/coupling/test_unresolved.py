"""Unresolved blocks as point particles (coupling/unresolved.py): the projected area of a box,
the particle load against closed forms, and a level set that leaves a body out."""
from __future__ import annotations

import numpy as np
import pytest

from fcm_fsi.coupling.unresolved import particle_force, projected_area
from fcm_fsi.fcm.levelset import Shapes, StructureLevelSet
from fcm_fsi.geometry import quat_to_matrix_np


def test_projected_area_of_a_box_face_on_edge_on_and_along_its_diagonal():
    half = np.array([[0.5, 0.5, 0.5]])
    eye = np.eye(3)[None]
    assert projected_area(half, eye, np.array([[0.0, 0.0, 1.0]]))[0] == pytest.approx(1.0)
    edge = np.array([[1.0, 1.0, 0.0]]) / np.sqrt(2.0)
    assert projected_area(half, eye, edge)[0] == pytest.approx(np.sqrt(2.0))
    diagonal = np.ones((1, 3)) / np.sqrt(3.0)               # a unit cube's shadow: a hexagon of area √3
    assert projected_area(half, eye, diagonal)[0] == pytest.approx(np.sqrt(3.0))
    # a 1 × 0.2 × 0.8 plate turned by a random rotation, seen along its turned thin axis: 1 × 0.8
    rng = np.random.default_rng(3)
    q = rng.normal(size=4)
    R = quat_to_matrix_np(q / np.linalg.norm(q))
    plate = np.array([[0.5, 0.1, 0.4]])
    assert projected_area(plate, R[None], R[:, 1][None])[0] == pytest.approx(0.8)


def test_particle_force_is_buoyancy_at_rest_and_quadratic_drag_against_the_flow():
    half = np.array([[0.5, 0.1, 0.4], [np.nan, np.nan, np.nan]])
    axes = np.tile(np.eye(3), (2, 1, 1))
    volume = np.array([0.16, 0.16])
    g = np.array([0.0, 0.0, -9.81])
    rest = particle_force(np.zeros((2, 3)), np.array([998.2, 1.204]), np.zeros((2, 3)), volume, half, axes, 1.05, g)
    np.testing.assert_allclose(rest, [[0, 0, 998.2 * 0.16 * 9.81], [0, 0, 1.204 * 0.16 * 9.81]], rtol=1e-14)
    u = np.array([[0.0, 3.0, 0.0], [0.0, 3.0, 0.0]])            # a 3 m/s current along y
    v = np.array([[0.0, 1.0, 0.0], [0.0, 1.0, 0.0]])            # the blocks moving at 1 m/s with it
    f = particle_force(u, np.full(2, 1000.0), v, volume, half, axes, 1.05, np.zeros(3))
    face = 4 * 0.5 * 0.4                                          # the 1 × 0.8 face across y
    sphere = np.pi * (3 * 0.16 / (4 * np.pi)) ** (2 / 3)
    np.testing.assert_allclose(f[:, 1], 0.5 * 1000.0 * 1.05 * np.array([face, sphere]) * 2.0 ** 2, rtol=1e-14)
    assert np.all(f[:, [0, 2]] == 0.0)


def test_a_body_left_out_of_the_level_set_is_fluid_and_the_others_stay():
    shapes = Shapes.concat([Shapes.box((0, 0, 0), (0.2, 0.2, 0.2), body=0), Shapes.box((0, 0, 0), (0.2, 0.2, 0.2), body=1)])
    pos = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    quat = np.tile([1.0, 0.0, 0.0, 0.0], (2, 1))
    x = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    ls = StructureLevelSet(shapes, 2, 0.3)
    assert np.allclose(ls.evaluate(x, pos, quat)[0], -0.1)
    ls.unseen[0] = True
    phi, owner = ls.evaluate(x, pos, quat)
    assert phi[0] == 0.3 and owner[0] == -2 and phi[1] == pytest.approx(-0.1) and owner[1] == 1
