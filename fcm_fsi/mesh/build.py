"""The fixed background mesh: structured simplices or gmsh boxes with refine zones."""
from __future__ import annotations

from pathlib import Path

import numpy as np
from mpi4py import MPI

from dolfinx import mesh as dmesh

from ..config.loader import ConfigError
from ..config.mesh import MeshConfig
from ..io.logging import get_logger

log = get_logger("mesh")


def build_mesh(cfg: MeshConfig, comm: MPI.Comm, case_dir: Path | None = None) -> dmesh.Mesh:
    """Create the background mesh described by ``cfg`` (collective on ``comm``)."""
    if cfg.kind == "rectangle":
        if cfg.dim != 2:
            raise ConfigError("key 'mesh.kind' = 'rectangle' needs 2 entries in mesh.lower/upper")
        diag = {"right": dmesh.DiagonalType.right, "left": dmesh.DiagonalType.left,
                "crossed": dmesh.DiagonalType.crossed}[cfg.diagonal]
        msh = dmesh.create_rectangle(comm, [np.array(cfg.lower), np.array(cfg.upper)], list(cfg.cells),
                                     dmesh.CellType.triangle, dmesh.GhostMode.shared_facet, diagonal=diag)
    elif cfg.kind == "box":
        if cfg.dim != 3:
            raise ConfigError("key 'mesh.kind' = 'box' needs 3 entries in mesh.lower/upper")
        msh = dmesh.create_box(comm, [np.array(cfg.lower), np.array(cfg.upper)], list(cfg.cells),
                               dmesh.CellType.tetrahedron, dmesh.GhostMode.shared_facet)
    elif cfg.kind in ("gmsh_box", "gmsh_disk"):
        msh = gmsh_box(cfg, comm)
    else:
        msh = gmsh_file(cfg, comm, case_dir)
    ncells = msh.topology.index_map(msh.topology.dim).size_global
    log.info("mesh %s: %d cells, %d vertices, h_min = %.4g m", cfg.kind, ncells,
             msh.topology.index_map(0).size_global, min_cell_size(msh))
    return msh


def cell_sizes(msh: dmesh.Mesh) -> np.ndarray:
    """Largest vertex distance of every local (owned + ghost) cell [m]."""
    x = msh.geometry.x
    nv = msh.topology.dim + 1
    cells = msh.geometry.dofmap.array.reshape(-1, nv)
    h = np.zeros(cells.shape[0])
    for i in range(nv):
        for j in range(i + 1, nv):
            h = np.maximum(h, np.linalg.norm(x[cells[:, i]] - x[cells[:, j]], axis=1))
    return h


def min_cell_size(msh: dmesh.Mesh) -> float:
    """Global smallest cell size h_min [m] (collective)."""
    h = cell_sizes(msh)
    local = h.min() if h.size else np.inf
    return float(msh.comm.allreduce(local, op=MPI.MIN))


def gmsh_box(cfg: MeshConfig, comm: MPI.Comm) -> dmesh.Mesh:
    """Unstructured rectangle/box/disk from gmsh with box-shaped refine zones (built on rank 0)."""
    import gmsh
    from dolfinx.io import gmshio

    dim = cfg.dim
    if comm.rank == 0:
        gmsh.initialize()
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("box")
        lo, hi = np.array(cfg.lower), np.array(cfg.upper)
        if cfg.kind == "gmsh_disk":
            c = 0.5 * (lo + hi)
            tag = gmsh.model.occ.addDisk(c[0], c[1], 0.0, cfg.radius, cfg.radius)
        elif dim == 2:
            tag = gmsh.model.occ.addRectangle(lo[0], lo[1], 0.0, *(hi - lo))
        else:
            tag = gmsh.model.occ.addBox(*lo, *(hi - lo))
        gmsh.model.occ.synchronize()
        gmsh.model.addPhysicalGroup(dim, [tag], 1)
        fields = []
        for zone in cfg.refine:
            f = gmsh.model.mesh.field.add("Box")
            zl = list(zone.lower) + [0.0] * (3 - len(zone.lower))
            zu = list(zone.upper) + [0.0] * (3 - len(zone.upper))
            gmsh.model.mesh.field.setNumber(f, "VIn", zone.size)
            gmsh.model.mesh.field.setNumber(f, "VOut", cfg.size)
            for ax, a, b in zip("XYZ", zl, zu):
                gmsh.model.mesh.field.setNumber(f, f"{ax}Min", a)
                gmsh.model.mesh.field.setNumber(f, f"{ax}Max", b)
            fields.append(f)
        if fields:
            fmin = gmsh.model.mesh.field.add("Min")
            gmsh.model.mesh.field.setNumbers(fmin, "FieldsList", fields)
            gmsh.model.mesh.field.setAsBackgroundMesh(fmin)
            gmsh.option.setNumber("Mesh.MeshSizeExtendFromBoundary", 0)
            gmsh.option.setNumber("Mesh.MeshSizeFromPoints", 0)
            gmsh.option.setNumber("Mesh.MeshSizeFromCurvature", 0)
        gmsh.option.setNumber("Mesh.MeshSizeMax", cfg.size)
        gmsh.model.mesh.generate(dim)
    msh, _, _ = gmshio.model_to_mesh(gmsh.model, comm, 0, gdim=dim)
    if comm.rank == 0:
        gmsh.finalize()
    return msh


def gmsh_file(cfg: MeshConfig, comm: MPI.Comm, case_dir: Path | None) -> dmesh.Mesh:
    """Read a gmsh .msh file (path relative to the case file)."""
    from dolfinx.io import gmshio

    path = Path(cfg.file)
    if not path.is_absolute() and case_dir is not None:
        path = case_dir / path
    if not path.is_file():
        raise ConfigError(f"key 'mesh.file' = {cfg.file!r}: file not found ({path})")
    msh, _, _ = gmshio.read_from_msh(str(path), comm, 0, gdim=cfg.dim)
    return msh
