"""Blocks from CAD files (dem.blocks[].shape: mesh): mass properties from the polyhedron, the
skin of contact spheres, the file's origin at ``position``, the level set the fluid sees against
a box block's on a dolfinx mesh, and the errors that name the key."""
from __future__ import annotations

import numpy as np
import pytest

from fcm_fsi.config.dem import DEMConfig
from fcm_fsi.config.loader import ConfigError, build
from fcm_fsi.coupling.dem_side import fluid_thickness, shapes_of_blocks
from fcm_fsi.dem.bodies import axis_angle_quat
from fcm_fsi.dem.model import build_state
from fcm_fsi.fcm.levelset import StructureLevelSet
from fcm_fsi.geometry import quat_to_matrix_np
from fcm_fsi.geometry.surface_distance import signed_distance
from tests.geometry.surfaces import box_surface, write_surface

R = 0.045                  # (size − 2R)/2R not an integer on any axis: no tie in the lattice's count


def dem_config(blocks) -> DEMConfig:
    return build(DEMConfig, {"dt": 1e-5, "materials": [{"name": "c", "stiffness": 1e6, "restitution": 0.5,
                                                         "friction_angle": 30.0, "density": 2000.0}],
                             "blocks": blocks}, source="t.yaml", prefix="dem")


@pytest.fixture()
def cube_file(tmp_path):
    """A 1 × 0.6 × 0.4 m box whose file origin is its corner (binary STL)."""
    return str(write_surface(tmp_path / "box.stl", *box_surface((0, 0, 0), (1.0, 0.6, 0.4)), binary=True))


def mesh_block(file, **over):
    return {"shape": "mesh", "material": "c", "file": file, "radius": R, "position": [2.0, 1.0, 0.5],
            "sdf_spacing": 0.02, "sdf_margin": 0.2, **over}


def test_mesh_block_has_the_box_blocks_mass_inertia_and_face_spheres(cube_file):
    """The STL box and shape: box of the same size and centre: the same mass 2000·0.24 = 480 kg
    and principal inertia m/12 (b² + c², …), the same centre of mass (file origin + half the
    size), to the binary STL's float32 precision (~1e-7); every sphere of the box block is one of the mesh block's (its lattice
    reproduces the box's on the faces), and all the mesh block's spheres lie inside the solid,
    at depth r ≤ d < r + lattice spacing."""
    cfg = dem_config([mesh_block(cube_file),
                      {"shape": "box", "material": "c", "size": [1.0, 0.6, 0.4], "radius": R,
                       "position": [2.5, 1.3, 0.7]}])
    st = build_state(cfg)
    assert st.mass[0] == pytest.approx(480.0, rel=2e-7) and st.mass[1] == pytest.approx(480.0, rel=1e-13)
    np.testing.assert_allclose(np.sort(st.inertia[0]), np.sort(st.inertia[1]), rtol=5e-7)
    np.testing.assert_allclose(st.pos[0], st.pos[1], atol=1e-7)
    world = [st.sph_pos[st.sph_block == b] for b in (0, 1)]
    gap = np.linalg.norm(world[1][:, None] - world[0][None], axis=2).min(axis=1)
    assert gap.max() < 1e-6
    corners = box_surface((2.0, 1.0, 0.5), (3.0, 1.6, 0.9))
    depth = -signed_distance(world[0], np.asarray(corners[0])[corners[1]])
    assert depth.min() >= R - 1e-6 and depth.max() < R + 2 * R


def test_rotated_mesh_block_level_set_equals_the_box_block_on_a_dolfinx_mesh(cube_file):
    """The fluid's level set at the nodes of a dolfinx box mesh: the STL box and the box block,
    both turned 30° about (1, 1, 0), agree within 3h/8, h = sdf_spacing (the grid's trilinear
    error at the box's creases, tests/fcm/test_levelset_mesh.py)."""
    from dolfinx.mesh import create_box
    from mpi4py import MPI
    turn = {"axis": [1.0, 1.0, 0.0], "angle": 30.0}
    rot = quat_to_matrix_np(axis_angle_quat(turn["axis"], np.radians(30.0)))
    origin = np.array([2.5, 1.3, 0.7]) - rot @ [0.5, 0.3, 0.2]        # the file's origin turns about itself
    cfg = dem_config([mesh_block(cube_file, position=origin.tolist(), **turn),
                      {"shape": "box", "material": "c", "size": [1.0, 0.6, 0.4], "radius": R,
                       "position": [2.5, 1.3, 0.7], **turn}])
    st = build_state(cfg)
    shapes = shapes_of_blocks(cfg, st)
    mesh = create_box(MPI.COMM_SELF, [np.array([1.6, 0.6, 0.0]), np.array([3.4, 2.0, 1.4])], [36, 28, 28])
    x = mesh.geometry.x
    cutoff = 0.15
    phi = [StructureLevelSet(shapes.take([k]), 2, cutoff).evaluate(x, st.pos, st.quat)[0] for k in (0, 1)]
    err = np.abs(phi[0] - phi[1])
    assert err.max() <= 3 * 0.02 / 8
    assert np.count_nonzero(np.abs(phi[1]) < cutoff) > 5000
    assert fluid_thickness(cfg, st, 0.0, 3) == pytest.approx([0.4, 0.4], abs=0.02)


def test_position_places_the_files_origin(cube_file):
    st = build_state(dem_config([mesh_block(cube_file, position=[0.0, 0.0, 0.0])]))
    np.testing.assert_allclose(st.pos[0], [0.5, 0.3, 0.2], atol=1e-7)


@pytest.mark.parametrize("problem, message", [("missing", "file not found"), ("open", "6 open edges"),
                                              ("radius", "no contact sphere")])
def test_unusable_files_are_config_errors_naming_the_key(tmp_path, problem, message):
    v, t = box_surface((0, 0, 0), (0.2, 0.2, 0.2))
    file = str(tmp_path / "none.stl")
    if problem == "open":
        file = str(write_surface(tmp_path / "open.stl", v, t[2:]))
    elif problem == "radius":
        file = str(write_surface(tmp_path / "small.stl", v, t))
    cfg = dem_config([{"shape": "sphere", "material": "c", "radius": 0.1, "position": [5, 5, 5]},
                      mesh_block(file, radius=0.15)])
    with pytest.raises(ConfigError, match=rf"dem\.blocks\[1\]\.(file|radius)'.*{message}"):
        build_state(cfg)


def test_mesh_block_needs_a_3d_fluid(cube_file):
    import yaml

    from fcm_fsi.config.case import case_from_dict
    from tests.config.test_fuzz_cases import ROOT
    data = yaml.safe_load((ROOT / "cases" / "floating_box.yaml").read_text())
    data["dem"]["blocks"] = [mesh_block(cube_file, material="wood")]
    with pytest.raises(ConfigError, match=r"dem\.blocks\[0\]\.shape' = 'mesh' needs a 3D fluid"):
        case_from_dict(data)
