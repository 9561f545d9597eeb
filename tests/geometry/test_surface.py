"""Closed surfaces from CAD files: reading (STL ASCII and binary, OBJ, gmsh), the closed-manifold
check, the polyhedron's mass properties against closed forms, and the exact signed distance
(Numba kernel against its NumPy twin and the box's closed form)."""
from __future__ import annotations

import numpy as np
import pytest

from fcm_fsi.geometry.surface import SurfaceError, closed_surface, mass_properties, read_surface
from fcm_fsi.geometry.surface_distance import signed_distance, signed_distance_reference
from tests.geometry.surfaces import box_surface, sphere_surface, write_surface


def box_distance(p, lo, hi):
    """Exact signed distance to the box lo..hi."""
    outside = np.linalg.norm(p - np.clip(p, lo, hi), axis=1)
    depth = np.min(np.minimum(p - lo, hi - p), axis=1)
    return np.where(outside > 0, outside, -depth)


@pytest.mark.parametrize("name, kwargs", [("cube.stl", {"binary": False}), ("cube_bin.stl", {"binary": True}),
                                          ("cube.obj", {}), ("cube.msh", {"file_format": "gmsh"})])
def test_files_read_as_the_same_closed_cube(tmp_path, name, kwargs):
    v, t = box_surface((0.0, 0.0, 0.0), (1.0, 2.0, 3.0))
    surface = read_surface(write_surface(tmp_path / name, v, t, **kwargs), scale=0.5)
    assert len(surface.triangles) == 12 and len(surface.vertices) == 8
    assert np.allclose(surface.vertices.min(axis=0), 0) and np.allclose(surface.vertices.max(axis=0), [0.5, 1, 1.5])
    assert mass_properties(surface, 1.0).volume == pytest.approx(0.75, rel=1e-12)


def test_inward_triangles_are_turned_outward():
    v, t = box_surface()
    surface = closed_surface(v, t[:, ::-1])
    assert mass_properties(surface, 1.0).volume == pytest.approx(1.0, rel=1e-14)


def test_unit_cube_mass_properties_are_exact():
    """A 1 m cube of 2000 kg/m³ from 12 triangles: m = 2000 kg, centre (½, ½, ½) m,
    I = m/6 = 333.3 kg m² on the diagonal, 0 off it, to round-off."""
    props = mass_properties(closed_surface(*box_surface()), 2000.0)
    assert props.mass == pytest.approx(2000.0, rel=1e-14)
    np.testing.assert_allclose(props.centre, 0.5, rtol=1e-14)
    np.testing.assert_allclose(props.inertia, 2000.0 / 6.0 * np.eye(3), atol=1e-12 * 2000.0)


def test_shifted_box_inertia_about_its_centre():
    """A 1 × 2 × 3 m box away from the origin: the inertia about its centre of mass,
    m/12 (b² + c², a² + c², a² + b²) (parallel-axis shift of the origin's second moment)."""
    props = mass_properties(closed_surface(*box_surface((5.0, -4.0, 7.0), (6.0, -2.0, 10.0))), 1.0)
    np.testing.assert_allclose(props.centre, [5.5, -3.0, 8.5], rtol=1e-13)
    np.testing.assert_allclose(props.inertia, 6.0 / 12.0 * np.diag([13.0, 10.0, 5.0]), atol=1e-11)


def test_sphere_mass_properties_converge_at_second_order():
    """gmsh's sphere of radius R = 1 m: the polyhedron is inscribed (vertices on the sphere), so
    it lies between the spheres of radius R − δ and R, δ = R − √(R² − ρ²), ρ the largest
    triangle circumradius: 0 < 1 − V/V₀ ≤ 1 − (1 − δ/R)³ and 0 < 1 − I/I₀ ≤ 1 − (1 − δ/R)⁵
    (V₀ = 4/3 π R³, I₀ = 8/15 π R⁵ at unit density). Both errors fall ≥ 3× when the mesh
    size halves (second order: 4×)."""
    errors = []
    for size in (0.4, 0.2, 0.1):
        surface = closed_surface(*sphere_surface(1.0, size))
        props = mass_properties(surface, 1.0)
        c = surface.corners
        ab, ac = c[:, 1] - c[:, 0], c[:, 2] - c[:, 0]
        cross = np.linalg.norm(np.cross(ab, ac), axis=1)
        bc = np.linalg.norm(c[:, 2] - c[:, 1], axis=1)
        rho = (np.linalg.norm(ab, axis=1) * np.linalg.norm(ac, axis=1) * bc / (2 * cross)).max()
        shrink = np.sqrt(1.0 - rho ** 2)                               # (R − δ)/R
        dv = 1 - props.volume / (4 / 3 * np.pi)
        di = 1 - props.inertia.diagonal() / (8 / 15 * np.pi)
        assert 0 < dv <= 1 - shrink ** 3
        assert np.all((0 < di) & (di <= 1 - shrink ** 5))
        assert np.abs(props.centre).max() < 0.1 * dv
        errors.append((dv, di.max()))
    errors = np.array(errors)
    assert np.all(errors[:-1] / errors[1:] >= 3.0), errors


@pytest.mark.parametrize("damage, message", [("drop", "3 open edges"), ("flip", "3 edges run the same way")])
def test_open_or_inconsistent_surfaces_are_refused(damage, message):
    v, t = box_surface()
    t = t[1:] if damage == "drop" else np.vstack([t[:1, ::-1], t[1:]])
    with pytest.raises(SurfaceError, match=message):
        closed_surface(v, t)


def test_unreadable_and_missing_files_are_refused(tmp_path):
    with pytest.raises(SurfaceError, match="not found"):
        read_surface(tmp_path / "none.stl")
    (tmp_path / "bad.stl").write_bytes(b"solid x\n facet nonsense\n")
    with pytest.raises(SurfaceError, match="cannot read"):
        read_surface(tmp_path / "bad.stl")


def test_signed_distance_kernel_matches_twin_and_the_box():
    rng = np.random.default_rng(3)
    lo, hi = np.array([-0.3, 0.1, 0.0]), np.array([0.5, 0.4, 1.2])
    surface = closed_surface(*box_surface(lo, hi))
    p = rng.uniform(-1.0, 1.5, (400, 3))
    d = signed_distance(p, surface.corners)
    np.testing.assert_allclose(d, signed_distance_reference(p, surface.corners), atol=1e-14)
    np.testing.assert_allclose(d, box_distance(p, lo, hi), atol=1e-14)
