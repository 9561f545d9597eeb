"""`mesh.structure_band`: cells graded from a size at the blocks' faces (the tsunami's `paper`
level). The face distance against the level set's NumPy reference, the size law in closed
form, a gmsh mesh that follows it, the case checks, `python -m fcm_fsi mesh`, and a coupled
run on such a mesh."""
from __future__ import annotations

import re
import subprocess
import sys

import numpy as np
import pytest
from mpi4py import MPI

from fcm_fsi.config.case import case_from_dict, load_case
from fcm_fsi.config.loader import ConfigError, build
from fcm_fsi.config.mesh import MeshConfig
from fcm_fsi.fcm.levelset import FaceDistance, Shapes
from fcm_fsi.fcm.levelset_reference import signed_distance_reference
from fcm_fsi.geometry import quat_to_matrix_np
from fcm_fsi.mesh.build import build_mesh, cell_size_function, cell_sizes
from tests.conftest import ROOT, mpi_env, run_cli
from tests.fcm.test_levelset import random_poses, random_shapes


def test_face_distance_is_the_reference_level_sets_magnitude():
    """Outside the shapes the distance to their union, inside one its depth: |φ| of the
    brute-force reference (all points × all primitives, no cutoff) for moving rotated
    spheres, boxes and cylinders."""
    rng = np.random.default_rng(7)
    shapes = random_shapes(rng, 40, nbodies=6)
    pos, quat = random_poses(rng, 6)
    Rb = quat_to_matrix_np(quat)
    b = shapes.body
    centres = np.where((b >= 0)[:, None], pos[b] + np.einsum("sij,sj->si", Rb[b], shapes.offset), shapes.offset)
    x = np.concatenate([rng.uniform(-0.1, 1.1, (400, 3)), centres + rng.uniform(-0.01, 0.01, centres.shape)])
    phi, _ = signed_distance_reference(x, shapes, pos, quat, cutoff=1.0e9)
    faces = FaceDistance(shapes, pos, quat)
    d = np.array([faces(*p) for p in x])
    assert (phi < 0).sum() > 0                    # some points inside a shape
    np.testing.assert_allclose(d, np.abs(phi), rtol=0, atol=1e-14)


def test_face_distance_of_one_box_in_closed_form():
    """A 2 × 1 × 1 m box at the origin: 1.5 m from x = 2.5 on its axis, √2 from a point
    one metre beyond an edge in two directions, 0.3 m deep at x = 0.7."""
    faces = FaceDistance(Shapes.box((0.0, 0.0, 0.0), (2.0, 1.0, 1.0)), np.zeros((0, 3)), np.zeros((0, 4)))
    assert faces(2.5, 0.0, 0.0) == pytest.approx(1.5, abs=1e-15)
    assert faces(2.0, 1.5, 0.0) == pytest.approx(np.sqrt(2.0), abs=1e-15)
    assert faces(0.7, 0.0, 0.0) == pytest.approx(0.3, abs=1e-15)


def band_config(**mesh) -> MeshConfig:
    data = {"kind": "gmsh_box", "lower": [0.0, 0.0, 0.0], "upper": [2.0, 1.0, 1.0], "size": 0.2,
            "structure_band": {"size": 0.04, "grading": 0.5}}
    data.update(mesh)
    return build(MeshConfig, data, prefix="mesh")


def test_cell_size_law():
    """h = min(mesh.size, band.size + grading · d, refine zones): 0.04 m at a face, 0.04 +
    0.5 × 0.1 at 0.1 m, mesh.size beyond (0.2 − 0.04)/0.5 = 0.32 m, a zone's size inside it."""
    cfg = band_config(refine=[{"lower": [1.8, 0.0, 0.0], "upper": [2.0, 1.0, 1.0], "size": 0.1}])
    size_at = cell_size_function(cfg, lambda x, y, z: abs(x - 0.5))
    assert size_at(0.5, 0.5, 0.5) == pytest.approx(0.04)
    assert size_at(0.6, 0.5, 0.5) == pytest.approx(0.09)
    assert size_at(0.4, 0.5, 0.5) == pytest.approx(0.09)
    assert size_at(1.5, 0.5, 0.5) == pytest.approx(0.2)
    assert size_at(1.9, 0.5, 0.5) == pytest.approx(0.1)
    assert cell_size_function(band_config(structure_band=None), None) is None
    with pytest.raises(ConfigError, match="structure_band"):
        cell_size_function(cfg, None)


def test_gmsh_mesh_follows_the_band():
    """A 0.4 × 0.2 × 0.2 m block in a 2 × 1 × 1 m box, band 0.04 m, grading 0.5, 0.2 m
    elsewhere. gmsh's size is an edge length and a tetrahedron's longest edge is ≈ 1.6 × it,
    so: cells at the faces have longest edges under 2.5 × 0.04 m (0.2-m cells, were the band
    ignored, are 5 × that), cells far from the block over 0.2 m, and the count is a fraction
    of a 0.04-m box around the block and its band."""
    block = FaceDistance(Shapes.box((1.0, 0.5, 0.5), (0.4, 0.2, 0.2)), np.zeros((0, 3)), np.zeros((0, 4)))
    comm = MPI.COMM_WORLD
    msh = build_mesh(band_config(), comm, face_distance=block)
    x = msh.geometry.x
    cells = msh.geometry.dofmap.array.reshape(-1, 4)
    h = cell_sizes(msh)
    d = np.array([block(*p) for p in x[cells].mean(axis=1)])
    assert np.median(h[d < 0.02]) < 2.5 * 0.04
    assert np.median(h[d > 0.5]) > 0.2
    ncells = msh.topology.index_map(3).size_global
    box_zone = build_mesh(band_config(structure_band=None, refine=[
        {"lower": [0.6, 0.1, 0.1], "upper": [1.4, 0.9, 0.9], "size": 0.04}]), comm)
    assert ncells < 0.5 * box_zone.topology.index_map(3).size_global


GOOD = {"name": "band", "run": {"t_end": 0.02, "dt": 0.01},
        "mesh": {"kind": "gmsh_box", "lower": [0, 0, 0], "upper": [2, 1, 1], "size": 0.2,
                 "structure_band": {"size": 0.05}},
        "fluid": {"density": 1000.0, "viscosity": 1.0e-3, "gravity": [0, 0, -9.81]},
        "dem": {"dt": 1.0e-4, "gravity": [0, 0, -9.81],
                "materials": [{"name": "m", "stiffness": 1.0e4, "restitution": 0.5, "friction_angle": 30.0,
                               "density": 2000.0}],
                "blocks": [{"shape": "sphere", "material": "m", "position": [1, 0.5, 0.5], "radius": 0.1}]}}


def test_band_settings_are_checked():
    """A band needs a gmsh mesh, a size under mesh.size, a grading in (0, 1] and blocks to
    grade from; each refusal names the key."""
    case = case_from_dict(GOOD)
    assert case.mesh.structure_band.size == 0.05 and case.mesh.structure_band.grading == 0.3
    bad = [({"kind": "box", "cells": [4, 2, 2]}, "mesh.structure_band.*gmsh_box"),
           ({"structure_band": {"size": 0.2}}, "structure_band.size.*0.2.*mesh.size"),
           ({"structure_band": {"size": 0.05, "grading": 1.5}}, "structure_band.grading.*1.5"),
           ({"structure_band": {"size": 0.05, "grading": 0.0}}, "structure_band.grading")]
    for change, message in bad:
        data = {**GOOD, "mesh": {**GOOD["mesh"], **change}}
        with pytest.raises(ConfigError, match=message):
            case_from_dict(data)
    fluid_only = {k: v for k, v in GOOD.items() if k != "dem"}
    with pytest.raises(ConfigError, match="mesh.structure_band.*coupled"):
        case_from_dict(fluid_only)


def run_mesh_tool(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "fcm_fsi", "mesh", *args], cwd=ROOT, env=mpi_env(),
                          capture_output=True, text=True, timeout=300)


def test_mesh_tool_counts_the_tsunami_band_mesh(tmp_path):
    """`python -m fcm_fsi mesh` on the tsunami's paper level coarsened 40 × (0.4 m at the
    faces, 1.2 m elsewhere): counts and sizes printed, the .msh written and readable, and the
    case file's paper level is the band of 0.01 m it describes."""
    paper = load_case(ROOT / "cases" / "tsunami_building.yaml", ["resolution=paper"])
    assert paper.mesh.structure_band.size == 0.01 and not paper.mesh.refine
    out = tmp_path / "band.msh"
    res = run_mesh_tool("cases/tsunami_building.yaml", "--set", "resolution=paper", "--set", "mesh.size=1.2",
                        "--set", "mesh.structure_band.size=0.4", "--write", str(out))
    assert res.returncode == 0, res.stderr[-2000:]
    n = int(re.search(r"(\d+) tetrahedra", res.stdout).group(1))
    hmin, hmax = map(float, re.search(r"min ([\d.]+), median [\d.]+, max ([\d.]+)", res.stdout).groups())
    assert 5_000 < n < 60_000             # 18,973 when written; the 0.4 m box zone of `coarse`: 30,223
    assert 0.2 < hmin < 0.4 * 2.5 and hmax > 1.2
    import meshio
    assert len(meshio.read(out).cells_dict["tetra"]) == n
    bad = run_mesh_tool("cases/tsunami_building.yaml", "--set", "mesh.kind=box", "--set", "mesh.cells=[30, 10, 12]")
    assert bad.returncode == 2 and "mesh.kind" in bad.stderr and "Traceback" not in bad.stderr


def first_step(out) -> dict:
    import csv
    with open(out / "series.csv") as f:
        return {k.split(" [")[0]: v for k, v in next(csv.DictReader(f)).items()}


def test_coupled_run_on_a_band_mesh_and_on_its_file(tmp_path):
    """impact_box_3d with a 0.2 m band at its fixed box (0.5 m elsewhere) runs on 2 ranks and
    its log reports the band's smallest cells. The same mesh written by `python -m
    fcm_fsi mesh --write` and read back as `mesh.kind: gmsh_file` (the cluster route for the
    paper level) gives the same first step (dolfinx 0.5.2's read_from_msh once failed on
    every gmsh_file run)."""
    band = ["--set", "mesh.structure_band={size: 0.2, grading: 0.5}"]
    common = ["--set", "run.t_end=0.02", "--set", "output.xdmf=false"]
    res = run_cli(["cases/impact_box_3d.yaml", "--output", str(tmp_path / "band"), *band, *common], np_=2)
    assert res.returncode == 0, res.stderr[-3000:]
    log = res.stdout + res.stderr
    h_min = float(re.search(r"mesh gmsh_box: \d+ cells, \d+ vertices, h_min = ([\d.e-]+) m", log).group(1))
    assert 0.1 < h_min < 0.5 * 0.5
    msh = tmp_path / "band.msh"
    made = run_mesh_tool("cases/impact_box_3d.yaml", *band, "--write", str(msh))
    assert made.returncode == 0, made.stderr[-2000:]
    res = run_cli(["cases/impact_box_3d.yaml", "--output", str(tmp_path / "file"), "--set", "mesh.kind=gmsh_file",
                   "--set", f"mesh.file={msh}", *common], np_=2)
    assert res.returncode == 0, res.stderr[-3000:]
    assert f"h_min = {h_min:.4g} m" in res.stdout + res.stderr
    a, b = first_step(tmp_path / "band"), first_step(tmp_path / "file")
    for key in ("force_x", "force_z", "kinetic_energy", "liquid_volume_error"):
        assert float(a[key]) == pytest.approx(float(b[key]), rel=1e-9, abs=1e-12), key


def test_unreadable_mesh_files_are_bad_input(tmp_path):
    """A .msh gmsh cannot read, or one without a physical group of cells, ends on both ranks
    with exit 2 and a message naming mesh.file, not a traceback or a hang."""
    import gmsh
    garbage = tmp_path / "garbage.msh"
    garbage.write_text("not a mesh\n")
    bare = tmp_path / "bare.msh"
    gmsh.initialize()
    gmsh.option.setNumber("General.Terminal", 0)
    gmsh.model.occ.addBox(0, -2, 0, 12, 4, 6)
    gmsh.model.occ.synchronize()
    gmsh.option.setNumber("Mesh.MeshSizeMax", 2.0)
    gmsh.model.mesh.generate(3)
    gmsh.option.setNumber("Mesh.SaveAll", 1)
    gmsh.write(str(bare))
    gmsh.finalize()
    for path, message in ((garbage, "cannot read"), (bare, "no physical group")):
        res = run_cli(["cases/impact_box_3d.yaml", "--output", str(tmp_path / "out"), "--set", "mesh.kind=gmsh_file",
                       "--set", f"mesh.file={path}", "--set", "run.t_end=0.02"], np_=2, timeout=120)
        assert res.returncode == 2, res.stderr[-2000:]
        assert "mesh.file" in res.stderr and message in res.stderr and "Traceback" not in res.stderr


def test_graded_refine_zone_grows_its_cells_away_from_the_zone():
    """A refine zone with ``grading``: the gmsh cells below it grow about linearly with the
    distance, size + grading · d, instead of jumping from 0.0025 to 0.04 at its edge (the jump
    that made the sloshing tank's 0.0025 band unstable); the size law agrees."""
    def mesh(grading):
        zone = {"lower": [0.0, 0.96], "upper": [1.0, 1.04], "size": 0.005, **({"grading": grading} if grading else {})}
        cfg = build(MeshConfig, {"kind": "gmsh_box", "lower": [0.0, 0.0], "upper": [1.0, 1.4], "size": 0.04,
                                 "refine": [zone]}, "mesh")
        msh = build_mesh(cfg, MPI.COMM_WORLD)
        cells = msh.geometry.dofmap.array.reshape(-1, 3)
        y = msh.geometry.x[cells, 1].mean(axis=1)
        return cfg, y, cell_sizes(msh)
    cfg, y, h = mesh(0.5)
    for d in (0.02, 0.04):                       # cells centred d below the zone
        near = np.abs(y - (0.96 - d)) < 0.004
        expected = 0.005 + 0.5 * d
        assert np.median(h[near]) == pytest.approx(expected, rel=0.35), (d, np.median(h[near]))
    _, y0, h0 = mesh(None)
    graded_below, plain_below = np.median(h[np.abs(y - 0.95) < 0.005]), np.median(h0[np.abs(y0 - 0.95) < 0.005])
    assert plain_below > 2 * graded_below, (plain_below, graded_below)   # ungraded: ≈ the coarse size already
    law = cell_size_function(build(MeshConfig, {**{k: getattr(cfg, k) for k in ("kind", "lower", "upper", "size")},
                                                "refine": [{"lower": [0.0, 0.96], "upper": [1.0, 1.04], "size": 0.005,
                                                            "grading": 0.5}],
                                                "structure_band": {"size": 0.03, "grading": 0.5}}, "mesh"),
                             lambda x, y, z: 10.0)
    assert law(0.5, 1.0, 0.0) == pytest.approx(0.005)
    assert law(0.5, 0.92, 0.0) == pytest.approx(0.025)
    assert law(0.5, 0.5, 0.0) == pytest.approx(0.04)
