"""Snapshots of a 3D run (``python -m fcm_fsi snapshots``): marching tetrahedra against closed-form
surfaces, and a render of a synthetic output folder in the dolfinx XDMF/HDF5 layout."""
from __future__ import annotations

import h5py
import numpy as np
from scipy.spatial import Delaunay

from fcm_fsi.cli import main
from fcm_fsi.tools.snapshots import isosurface, read_vtp


def cube_tets(n: int = 6, seed: int = 0):
    """Tetrahedra of the unit cube (Delaunay of a jittered grid, corners kept)."""
    g = np.linspace(0.0, 1.0, n + 1)
    x = np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 3)
    inner = np.all((x > 0) & (x < 1), axis=1)
    x[inner] += np.random.default_rng(seed).uniform(-0.2, 0.2, (inner.sum(), 3)) / n
    return x, Delaunay(x).simplices.astype(np.int64)


def area(tris: np.ndarray) -> float:
    return float(0.5 * np.linalg.norm(np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]), axis=1).sum())


def test_a_linear_field_gives_the_exact_plane():
    """φ = 0.3 x + z at level 0.5: the plane cuts the unit cube in a 1 × √(1 + 0.09) rectangle
    (z from 0.5 to 0.2 as x goes 0 → 1), reproduced exactly by the P1 field; every vertex on it."""
    x, tets = cube_tets()
    phi = 0.3 * x[:, 0] + x[:, 2]
    tris = isosurface(x, tets, phi, 0.5)
    assert abs(area(tris) - np.sqrt(1.09)) < 1e-12
    assert np.abs(0.3 * tris[..., 0] + tris[..., 2] - 0.5).max() < 1e-12


def test_a_sphere_converges_to_its_area():
    """|x − c| = 0.3: the piecewise-flat surface's area approaches 4π r² as the mesh refines."""
    errs = []
    for n in (8, 16):
        x, tets = cube_tets(n)
        tris = isosurface(x, tets, np.linalg.norm(x - 0.5, axis=1), 0.3)
        errs.append(abs(area(tris) - 4 * np.pi * 0.09) / (4 * np.pi * 0.09))
    assert errs[1] < errs[0] and errs[1] < 0.02


def test_render_writes_front_and_back_views(tmp_path):
    """A folder in the layout the runs write (fields.h5 of dolfinx's XDMFFile, blocks.pvd of
    the coupled model) gives one PNG per view at the nearest stored time; a 2D run is refused
    with a message, not a traceback."""
    from fcm_fsi.io.vtp import write_pvd
    x, tets = cube_tets()
    with h5py.File(tmp_path / "fields.h5", "w") as f:
        f["Mesh/mesh/geometry"] = x
        f["Mesh/mesh/topology"] = tets
        for t in (0.0, 0.5):
            f[f"Function/phi/{t:g}".replace(".", "_")] = (x[:, 2] < 0.3 + 0.2 * t).astype(float)[:, None]
    pts = np.array([[0.5, 0.5, 0.1], [0.5, 0.6, 0.1]])
    (tmp_path / "blocks_00000.vtp").write_text(_vtp(pts, np.array([0.0, 1.0])))
    write_pvd(tmp_path / "blocks.pvd", [(0.5, "blocks_00000.vtp")])
    assert read_vtp(tmp_path / "blocks_00000.vtp")["damage"].tolist() == [0.0, 1.0]
    assert main(["snapshots", str(tmp_path), "--times", "0.4"]) == 0
    assert (tmp_path / "snapshot_t0.4_front.png").stat().st_size > 10_000
    assert (tmp_path / "snapshot_t0.4_back.png").exists()
    assert main(["snapshots", str(tmp_path), "--times", "0.5", "--png-dir", str(tmp_path / "new" / "pngs")]) == 0   # created
    assert (tmp_path / "new" / "pngs" / "snapshot_t0.5_front.png").exists()
    with h5py.File(tmp_path / "fields.h5", "a") as f:
        del f["Mesh/mesh/topology"]
        f["Mesh/mesh/topology"] = tets[:, :3]
    assert main(["snapshots", str(tmp_path), "--times", "0.4"]) == 2


def _vtp(points, damage) -> str:
    """A minimal PolyData file of the coupled model's layout (points and a damage array)."""
    from fcm_fsi.io.vtp import _array
    return ('<?xml version="1.0"?><VTKFile type="PolyData"><PolyData><Piece><PointData>'
            + _array("damage", np.asarray(damage, np.float64), 1) + "</PointData><Points>"
            + _array("Points", np.asarray(points, np.float64), 3) + "</Points></Piece></PolyData></VTKFile>")
