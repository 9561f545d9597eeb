"""Bonded structures from CAD files (dem.blocks[].fill: bonded_grid): a box read from a file and cut
on a grid that divides it is the bonded box structure of those cells (mass, inertia, bonds exact);
a sphere's pieces add up to the polyhedron's mass and inertia within the cut faces' lattice; the
cross-section test, the union distance and the clipping against their references; the fluid sees
the union of the pieces as the surface; a bonded cube stands on the floor without a bond breaking."""
from __future__ import annotations

import numpy as np
import pytest

from fcm_fsi.config.dem import DEMConfig
from fcm_fsi.config.loader import ConfigError, build
from fcm_fsi.coupling.dem_side import fluid_thickness, shapes_of_blocks
from fcm_fsi.dem.builder import assemble
from fcm_fsi.dem.grid_fill import clip_to_box, in_section, union_distance
from fcm_fsi.dem.model import build_state, build_system, grid_fill_of
from fcm_fsi.fcm.levelset import StructureLevelSet
from fcm_fsi.geometry.surface import mass_properties, read_surface
from fcm_fsi.geometry.surface_distance import signed_distance_reference
from tests.geometry.surfaces import box_surface, sphere_surface, write_surface

RHO = 2000.0


def dem_config(blocks, **over) -> DEMConfig:
    return build(DEMConfig, {"dt": 1e-5, "gravity": [0.0, 0.0, -9.81],
                             "materials": [{"name": "c", "stiffness": 1e6, "restitution": 0.5,
                                            "friction_angle": 30.0, "density": RHO}],
                             "blocks": blocks, "cohesive": {"sigma_c": 1e5, "delta_f": 1e-3}, **over},
                 source="t.yaml", prefix="dem")


def grid_block(file, **over):
    return {"shape": "mesh", "material": "c", "file": file, "radius": 0.045, "position": [0.0, 0.0, 0.0],
            "fill": "bonded_grid", "grid_size": 0.2, "sdf_spacing": 0.02, "sdf_margin": 0.1, **over}


@pytest.fixture(scope="module")
def cube_file(tmp_path_factory):
    """A 1 × 0.6 × 0.4 m box, file origin at its corner."""
    return str(write_surface(tmp_path_factory.mktemp("grid") / "box.stl", *box_surface((0, 0, 0), (1.0, 0.6, 0.4))))


@pytest.fixture(scope="module")
def sphere_file(tmp_path_factory):
    """gmsh's sphere of radius 0.5 m (3,200 triangles)."""
    return str(write_surface(tmp_path_factory.mktemp("grid") / "sphere.stl", *sphere_surface(0.5, 0.05)))


def test_a_box_cut_on_its_grid_is_the_bonded_box_structure(cube_file):
    """5 × 3 × 2 cells of 0.2 m: 30 pieces of 2000 · 0.008 = 16 kg with a cube's inertia
    m·2g²/12, centred in their cells, bonded on the same 59 faces of 0.04 m² as the builder's
    structure of those boxes; exact to round-off (no cut face is partial)."""
    cfg = dem_config([grid_block(cube_file)])
    fill = grid_fill_of(cfg, 0)
    lo = np.stack(np.meshgrid(*(np.arange(n) * 0.2 for n in (5, 3, 2)), indexing="ij"), -1).reshape(-1, 3)
    boxes = assemble(lo, lo + 0.2, density=RHO, sphere_radius=0.045)
    assert len(fill.pieces) == 30
    for p in fill.pieces:
        assert p.properties.mass == pytest.approx(16.0, rel=1e-12)
        np.testing.assert_allclose(np.sort(p.template.inertia), np.full(3, 16.0 * 2 * 0.04 / 12), rtol=1e-10)
        np.testing.assert_allclose(p.properties.centre, 0.2 * (p.cells[0] + 0.5), atol=1e-12)
    assert len(fill.bonds) == len(boxes.faces) == 59
    np.testing.assert_allclose([b.areas.sum() for b in fill.bonds], 0.04, rtol=1e-12)
    state = build_state(cfg)
    assert state.nb == 30
    assert state.mass.sum() == pytest.approx(480.0, rel=1e-12)


def test_sphere_pieces_add_up_to_the_polyhedron(sphere_file):
    """A sphere of radius 0.5 m on a 0.25 m grid: the pieces' mass and inertia about the common
    centre add up to the polyhedron's within 0.5 % (the cut faces' staircase of spacing
    min(r/2, g/8)); the bonds across the mid-plane x = 0 cover its cross-section π·0.5² within
    1.5 % (Gauss points kept inside, on a 4 × 4 split of the partial faces; the grid starts at
    the bounding box, x ≈ −0.5, so its third plane is x ≈ 0)."""
    cfg = dem_config([grid_block(sphere_file, radius=0.03, grid_size=0.25)])
    fill = grid_fill_of(cfg, 0)
    whole = mass_properties(read_surface(sphere_file), RHO)
    mass = sum(p.properties.mass for p in fill.pieces)
    inertia = np.zeros((3, 3))
    for p in fill.pieces:
        d = p.properties.centre - whole.centre
        inertia += p.properties.inertia + p.properties.mass * (d @ d * np.eye(3) - np.outer(d, d))
    assert mass == pytest.approx(whole.mass, rel=5e-3)
    np.testing.assert_allclose(np.diag(inertia), np.diag(whole.inertia), rtol=5e-3)
    plane = fill.origin[0] + 2 * fill.size
    assert abs(plane) < 1e-3
    mid = [b for b in fill.bonds if abs(b.normal[0]) == 1.0 and abs(b.points[0, 0] - plane) < 1e-9]
    assert sum(b.areas.sum() for b in mid) == pytest.approx(np.pi * 0.25, rel=1.5e-2)
    assert all(len(p.template.sph_radius) > 0 for p in fill.pieces)


def test_cross_section_test_matches_the_winding_number(sphere_file):
    """in_section on planes of the sphere equals the sign of the NumPy reference distance."""
    corners = read_surface(sphere_file).corners
    rng = np.random.default_rng(3)
    for k, plane in ((0, 0.1), (1, -0.37), (2, 0.0)):
        uv = rng.uniform(-0.55, 0.55, (300, 2))
        p = np.zeros((300, 3))
        p[:, k] = plane
        p[:, (k + 1) % 3], p[:, (k + 2) % 3] = uv[:, 0], uv[:, 1]
        ref = signed_distance_reference(p, corners) < 0
        np.testing.assert_array_equal(in_section(corners, k, plane, uv[:, 0], uv[:, 1]), ref)


def test_union_distance_of_an_l_shape():
    """Three unit cells in an L: outside, the least box distance; inside, the distance to the
    outer faces only (the shared faces are not surface)."""
    cells = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]])
    p = np.array([[1.0, 0.5, 0.5],      # on the face shared by cells 0 and 1: depth 0.5 (y, z faces)
                  [0.9, 0.9, 0.5],      # by the L's inner corner (1, 1): √2 · 0.1 to the notch's faces
                  [1.5, 1.5, 0.5],      # in the notch: 0.5 from both
                  [3.0, 0.5, 0.5]])     # 1 beyond the end
    np.testing.assert_allclose(union_distance(p, cells, np.zeros(3), 1.0), [-0.5, -0.1 * np.sqrt(2), 0.5, 1.0], atol=1e-12)


def test_clipped_triangles_cover_the_surface_once(sphere_file):
    """The triangles clipped to the cells of a grid (some planes through vertices) add up to the
    surface's area: every part of the surface in exactly one cell."""
    surface = read_surface(sphere_file)
    corners = surface.corners
    edges = np.linspace(-0.5, 0.5, 5)
    area = 0.0
    for x in zip(edges[:-1], edges[1:]):
        for y in zip(edges[:-1], edges[1:]):
            for z in zip(edges[:-1], edges[1:]):
                lo, hi = np.array([x[0], y[0], z[0]]), np.array([x[1], y[1], z[1]])
                t = clip_to_box(corners, lo, hi)
                area += 0.5 * np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1).sum()
    assert area == pytest.approx(surface.area, rel=1e-12)


def test_the_fluid_sees_the_union_of_the_pieces_as_the_solid(sphere_file):
    """The level set of all pieces against the whole sphere's (a clump block of the same file),
    h = sdf_spacing: outside the solid they agree to the grids' interpolation (3h/8). As between
    bonded boxes, the faces the pieces share are gaps of zero width that the coupling's gap fill
    closes (gap = h here, one cell by default): with it, every point inside is solid and every
    point more than gap/2 outside is fluid (the fill lowers φ by at most gap/2 where two
    pieces are nearly equally near)."""
    h, gap = 0.04, 0.04
    common = {"radius": 0.03, "sdf_spacing": h, "sdf_margin": 0.1, "position": [0.1, 0.0, 0.0]}
    grid_cfg = dem_config([grid_block(sphere_file, grid_size=0.25, **common)])
    whole_cfg = dem_config([{**grid_block(sphere_file, **common), "fill": "clump", "grid_size": None}])
    x = np.random.default_rng(5).uniform(-0.6, 0.7, (4000, 3))
    phi = {}
    for name, cfg, g in (("pieces", grid_cfg, 0.0), ("filled", grid_cfg, gap), ("whole", whole_cfg, 0.0)):
        st = build_state(cfg)
        phi[name] = StructureLevelSet(shapes_of_blocks(cfg, st), st.nb, 0.08, gap=g).evaluate(x, st.pos, st.quat)[0]
    tol = 3 * h / 8
    outside = phi["whole"] > 0
    assert np.abs(phi["pieces"][outside] - phi["whole"][outside]).max() <= tol
    assert np.all(phi["filled"][phi["whole"] < -tol] < 0)
    assert np.all(phi["filled"][phi["whole"] > gap / 2 + tol] > 0)
    assert np.count_nonzero(phi["whole"] < -tol) > 500


def test_bonded_pieces_hold_water_as_their_whole_solid(cube_file):
    """The thin-wall check (twice the deepest depth) sees the 0.2 m pieces of the 1 × 0.6 × 0.4 m
    box as the box: 0.4 m for each, not the piece's 0.2 m."""
    cfg = dem_config([grid_block(cube_file)])
    st = build_state(cfg)
    np.testing.assert_allclose(fluid_thickness(cfg, st, 0.0, 3), 0.4, atol=0.02)


def test_bonded_cube_stands_on_the_floor(cube_file):
    """The 30 bonded pieces of the box on a floor under gravity for 0.05 s: no bond breaks, and
    the pieces sit within the static overlap W/K of where they started."""
    cfg = dem_config([grid_block(cube_file, position=[0.0, 0.0, 0.0])],
                     walls=[{"kind": "plane", "material": "c", "point": [0, 0, 0], "normal": [0, 0, 1]}], dt=2e-5)
    system = build_system(cfg)
    start = system.state.pos.copy()
    for _ in range(2500):
        system.step()
    bonds = [i for i in system.interactions if type(i).__name__ == "CohesiveBonds"][0]
    assert not bonds.broken.any()
    assert np.abs(system.state.pos - start).max() < 5e-4


@pytest.mark.parametrize("block, message", [
    ({"shape": "box", "size": [1, 1, 1], "fill": "bonded_grid", "grid_size": 0.2}, "needs shape 'mesh'"),
    ({"fill": "bonded_grid", "grid_size": None}, "needs shape 'mesh' and a grid_size"),
    ({"fill": "clump"}, "grid_size' is used only with fill 'bonded_grid'"),
    ({"grid_size": 0.05}, r"grid_size' = 0.05 m is below 2·radius"),
])
def test_bad_bonded_grid_keys_are_refused(cube_file, block, message):
    with pytest.raises(ConfigError, match=message):
        dem_config([{**grid_block(cube_file), **block}])


def test_a_bonded_grid_needs_the_cohesive_law(cube_file):
    with pytest.raises(ConfigError, match=r"dem\.cohesive' is required"):
        build(DEMConfig, {"dt": 1e-5, "materials": [{"name": "c", "stiffness": 1e6, "restitution": 0.5,
                                                      "friction_angle": 30.0}], "blocks": [grid_block(cube_file)]},
              source="t.yaml", prefix="dem")
