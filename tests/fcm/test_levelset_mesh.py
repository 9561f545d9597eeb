"""The level set of a closed triangle surface (primitive kind MESH, a trilinear signed-distance
grid): Numba kernel against the NumPy twin, the grid of a cube against the box's exact
distance, the grid of gmsh's sphere against |x| − R, and the surface samples' identities."""
from __future__ import annotations

import numpy as np
import pytest

from fcm_fsi.fcm.levelset import FaceDistance, Shapes, StructureLevelSet, bounding_radius
from fcm_fsi.fcm.levelset_reference import signed_distance_reference
from fcm_fsi.fcm.surface_samples import surface_samples
from fcm_fsi.geometry import quat_to_matrix_np
from fcm_fsi.geometry.surface import closed_surface, mass_properties
from fcm_fsi.geometry.surface_distance import distance_grid
from tests.geometry.surfaces import box_surface, sphere_surface

CUTOFF = 0.15


def cube_mesh(spacing, body=0, margin=0.2):
    surface = closed_surface(*box_surface((-0.5, -0.5, -0.5), (0.5, 0.5, 0.5)))
    return surface, Shapes.mesh(distance_grid(surface, spacing, margin), surface.corners, body=body)


def test_kernel_matches_reference_with_meshes_among_other_primitives():
    rng = np.random.default_rng(5)
    surface, cube = cube_mesh(0.05)
    sphere = closed_surface(*sphere_surface(0.3, 0.15))
    q = rng.normal(size=4)
    rot = quat_to_matrix_np(q / np.linalg.norm(q))
    shapes = Shapes.concat([Shapes.box((0, 0, 0), (0.4, 0.2, 0.3), body=1), cube,
                            Shapes.mesh(distance_grid(sphere, 0.05, 0.2), sphere.corners, (0.1, 0.0, 0.2), rot, body=2),
                            Shapes.sphere((0.8, 0.8, 0.0), 0.2)])
    assert bounding_radius(shapes)[1] == pytest.approx(np.sqrt(3) * 0.7)
    pos = np.array([[0.2, -0.9, 0.0], [0.0, 0.0, 0.0], [1.1, 0.1, 0.0]])
    quat = rng.normal(size=(3, 4))
    quat /= np.linalg.norm(quat, axis=1)[:, None]
    x = rng.uniform(-1.5, 1.8, (20000, 3))
    ls = StructureLevelSet(shapes, 3, CUTOFF, gap=0.05, walls=[[0, 0, -0.6, 0, 0, 1]])
    phi, owner = ls.evaluate(x, pos, quat)
    fill = np.full((len(x), 2), -2), np.zeros((len(x), 2))
    ref, ref_owner = signed_distance_reference(x, shapes, pos, quat, CUTOFF, 0.05, [[0, 0, -0.6, 0, 0, 1]], fill)
    np.testing.assert_allclose(phi, ref, atol=1e-13)
    np.testing.assert_array_equal(owner, ref_owner)
    np.testing.assert_array_equal(ls.fill_other, fill[0])
    assert np.count_nonzero(np.abs(phi) < CUTOFF) > 1000 and np.any(owner == 2)
    plain, _ = signed_distance_reference(x, shapes, pos, quat, CUTOFF)         # without the gap fill
    face = FaceDistance(shapes, pos, quat)
    sample = np.flatnonzero((np.abs(plain) < CUTOFF) & (owner >= 1))[:40]
    np.testing.assert_allclose([face(*x[i]) for i in sample], np.abs(plain[sample]), atol=1e-13)


@pytest.mark.parametrize("spacing", [0.1, 0.05])
def test_cube_grid_equals_the_box_within_the_interpolation_error(spacing):
    """The cube's distance is piecewise linear, with kinks where two or three faces are equally
    near; trilinear interpolation is exact away from them and off by at most 3h/8 in a cell
    that straddles them (min(x, y, z) at a cell's centre: 1/8 of h against h/2). Outside the
    grid box the level set is +cutoff (margin ≥ cutoff)."""
    _, cube = cube_mesh(spacing)
    x = np.random.default_rng(2).uniform(-1.2, 1.2, (40000, 3))
    ident = np.zeros((1, 3)), np.array([[1.0, 0.0, 0.0, 0.0]])
    mesh_phi, _ = StructureLevelSet(cube, 1, CUTOFF).evaluate(x, *ident)
    box_phi, _ = StructureLevelSet(Shapes.box((0, 0, 0), (1, 1, 1), body=0), 1, CUTOFF).evaluate(x, *ident)
    err = np.abs(mesh_phi - box_phi)
    assert err.max() <= 3 * spacing / 8
    assert np.all(mesh_phi[np.abs(x).max(axis=1) > 0.5 + 0.2] == CUTOFF)
    np.testing.assert_array_equal(np.sign(mesh_phi[np.abs(box_phi) > 3 * spacing / 8]),
                                  np.sign(box_phi[np.abs(box_phi) > 3 * spacing / 8]))


def test_sphere_grid_equals_the_sphere_within_tessellation_and_interpolation_error():
    """gmsh's sphere of R = 0.5 m (size 0.08 m) on a grid of h = 0.025 m: within the band,
    |φ − (|x| − R)| ≤ δ + h²·3/(8 (R − cutoff)) + h θ/4 — the inscribed polyhedron's sag δ, the
    trilinear error of the smooth distance (curvature ≤ 1/(R − cutoff)), and that at the
    polyhedron's creases (gradient jump ≤ the largest dihedral angle θ between neighbours)."""
    R, h = 0.5, 0.025
    surface = closed_surface(*sphere_surface(R, 0.08))
    shapes = Shapes.mesh(distance_grid(surface, h, CUTOFF), surface.corners, body=0)
    x = np.random.default_rng(4).uniform(-0.8, 0.8, (40000, 3))
    phi, _ = StructureLevelSet(shapes, 1, CUTOFF).evaluate(x, np.zeros((1, 3)), np.array([[1.0, 0, 0, 0]]))
    exact = np.clip(np.linalg.norm(x, axis=1) - R, -CUTOFF, CUTOFF)
    c = surface.corners
    normal = np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0])
    normal /= np.linalg.norm(normal, axis=1)[:, None]
    sag = R - np.abs(np.einsum("ti,ti->t", normal, c[:, 0])).min()        # deepest face plane
    theta = 2 * np.arccos(1 - sag / R)                                     # crease angle ≤ 2 × face tilt
    bound = sag + 3 * h * h / (8 * (R - CUTOFF)) + h * theta / 4
    err = np.abs(phi - exact)
    assert err.max() <= bound, (err.max(), sag, bound)


def test_mesh_samples_carry_the_surface_area_volume_and_zero_net_normal():
    """Surface samples of a triangle surface (each triangle cut into m² with edges ≤ spacing):
    Σ dA = the area, Σ n dA = 0 and Σ (x·n) dA / 3 = V (divergence theorem), exactly for the
    polyhedron, in any body frame."""
    surface = closed_surface(*sphere_surface(0.3, 0.1))
    shapes = Shapes.mesh(distance_grid(surface, 0.05, 0.2), surface.corners, (0.2, -0.1, 0.4),
                         quat_to_matrix_np(np.array([0.8, 0.2, -0.4, 0.4]) / np.linalg.norm([0.8, 0.2, -0.4, 0.4])))
    x, n, area = surface_samples(int(shapes.kind[0]), shapes.half[0], shapes.offset[0], shapes.rot[0], 0.02, 3,
                                 shapes.triangles[0])
    volume = mass_properties(surface, 1.0).volume
    assert area.sum() == pytest.approx(surface.area, rel=1e-12)
    assert np.abs((n * area[:, None]).sum(axis=0)).max() < 1e-13
    assert np.einsum("ij,ij->i", x, n) @ area / 3 == pytest.approx(volume, rel=1e-12)
    assert np.allclose(np.linalg.norm(n, axis=1), 1.0) and len(area) > 20 * len(surface.triangles)
    assert np.sqrt(4 * area.max() / np.sqrt(3)) <= 0.02 * 1.2      # an equilateral's edge from its area
