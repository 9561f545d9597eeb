"""The fixed background mesh: structured simplices, or gmsh boxes with refine zones and a band
graded away from the structure's faces."""
from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
from dolfinx import mesh as dmesh
from mpi4py import MPI

from ..config.loader import ConfigError
from ..config.mesh import MeshConfig
from ..io.logging import get_logger

log = get_logger("mesh")


def build_mesh(cfg: MeshConfig, comm: MPI.Comm, case_dir: Path | None = None,
               face_distance: Callable[[float, float, float], float] | None = None) -> dmesh.Mesh:
    """Create the background mesh described by ``cfg`` (collective on ``comm``).
    ``face_distance(x, y, z)`` [m]: distance to the structure's faces, for ``mesh.structure_band``."""
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
        msh = gmsh_box(cfg, comm, face_distance)
    else:
        msh = gmsh_file(cfg, comm, case_dir)
    ncells = msh.topology.index_map(msh.topology.dim).size_global
    log.info("mesh %s: %d cells, %d vertices, h_min = %.4g m", cfg.kind, ncells,
             msh.topology.index_map(0).size_global, min_cell_size(msh))
    return msh


def cell_sizes(msh: dmesh.Mesh) -> np.ndarray:
    """Largest vertex distance of every local (owned + ghost) cell [m]."""
    return longest_edges(msh.geometry.x, msh.geometry.dofmap.array.reshape(-1, msh.topology.dim + 1))


def edge_lengths(x: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """Lengths [m] (nc, nv(nv − 1)/2) of every simplex's edges: vertex coordinates x (n, 3),
    cells (nc, nv) indices."""
    nv = cells.shape[1]
    return np.stack([np.linalg.norm(x[cells[:, i]] - x[cells[:, j]], axis=1)
                     for i in range(nv) for j in range(i + 1, nv)], axis=1)


def longest_edges(x: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """Longest edge [m] of every simplex: vertex coordinates x (n, 3), cells (nc, nv) indices."""
    return edge_lengths(x, cells).max(axis=1, initial=0.0)


def cell_mean_edges(msh: dmesh.Mesh) -> np.ndarray:
    """Mean edge length of every local (owned + ghost) cell [m]: the cell's size, unlike its
    longest edge not doubled by a sliver's long edge."""
    return edge_lengths(msh.geometry.x, msh.geometry.dofmap.array.reshape(-1, msh.topology.dim + 1)).mean(axis=1)


def min_cell_size(msh: dmesh.Mesh) -> float:
    """Global smallest cell size h_min [m] (collective)."""
    h = cell_sizes(msh)
    local = h.min() if h.size else np.inf
    return float(msh.comm.allreduce(local, op=MPI.MIN))


def gmsh_box(cfg: MeshConfig, comm: MPI.Comm,
             face_distance: Callable[[float, float, float], float] | None = None) -> dmesh.Mesh:
    """Unstructured rectangle/box/disk from gmsh with refine zones and the structure band
    (generated on rank 0, distributed by dolfinx)."""
    return _from_rank0(comm, cfg.dim, lambda: generate_gmsh_box(cfg, face_distance))


def _from_rank0(comm: MPI.Comm, dim: int, make_model: Callable[[], None]) -> dmesh.Mesh:
    """The mesh of the gmsh model that ``make_model()`` builds on rank 0, distributed over
    ``comm``. An error on rank 0 stops every rank (no rank is left waiting)."""
    import gmsh
    from dolfinx.io import gmshio

    error = None
    if comm.rank == 0:
        gmsh.initialize()
        gmsh.option.setNumber("General.Terminal", 0)
        try:
            make_model()
        except Exception as err:      # noqa: BLE001 - every rank stops, not only rank 0
            error = err
    failed = comm.bcast(None if error is None else (isinstance(error, ConfigError), str(error)), root=0)
    if failed is not None:
        if comm.rank == 0:
            gmsh.finalize()
            raise error
        bad_input, message = failed
        raise ConfigError(message) if bad_input else RuntimeError(f"mesh generation failed on rank 0: {message}")
    msh, _, _ = gmshio.model_to_mesh(gmsh.model, comm, 0, gdim=dim)
    if comm.rank == 0:
        gmsh.finalize()
    return msh


def generate_gmsh_box(cfg: MeshConfig, face_distance: Callable[[float, float, float], float] | None = None) -> None:
    """Mesh the box/rectangle/disk of ``cfg`` in the current gmsh session (gmsh initialised;
    this process only). The cell size is ``mesh.size``, smaller in the refine zones, and with
    ``mesh.structure_band`` graded from the band's size at the faces ``face_distance``
    measures (distance [m] to the structure's faces at a point)."""
    import gmsh

    dim = cfg.dim
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
    size_at = cell_size_function(cfg, face_distance)
    failures: list[BaseException] = []
    if size_at is not None:
        def callback(dim_, tag_, x, y, z, *_):
            try:                 # an exception raised into gmsh's C callback would abort the process
                return size_at(x, y, z)
            except BaseException as err:      # noqa: BLE001 - re-raised after generate()
                failures.append(err)
                return cfg.size
        gmsh.model.mesh.setSizeCallback(callback)
    elif cfg.refine:
        gmsh.model.mesh.field.setAsBackgroundMesh(_refine_fields(cfg))
    if size_at is not None or cfg.refine:
        gmsh.option.setNumber("Mesh.MeshSizeExtendFromBoundary", 0)
        gmsh.option.setNumber("Mesh.MeshSizeFromPoints", 0)
        gmsh.option.setNumber("Mesh.MeshSizeFromCurvature", 0)
    gmsh.option.setNumber("Mesh.MeshSizeMax", cfg.size)
    gmsh.model.mesh.generate(dim)
    if failures:
        raise failures[0]


def _refine_fields(cfg: MeshConfig) -> int:
    """gmsh Box fields of the refine zones under one Min field; returns the Min field's tag."""
    import gmsh

    fields = []
    for zone in cfg.refine:
        f = gmsh.model.mesh.field.add("Box")
        zl = list(zone.lower) + [0.0] * (3 - len(zone.lower))
        zu = list(zone.upper) + [0.0] * (3 - len(zone.upper))
        gmsh.model.mesh.field.setNumber(f, "VIn", zone.size)
        gmsh.model.mesh.field.setNumber(f, "VOut", cfg.size)
        if zone.grading is not None:       # linear from VIn at the box to VOut this far out
            gmsh.model.mesh.field.setNumber(f, "Thickness", max(cfg.size - zone.size, 0.0) / zone.grading)
        for ax, a, b in zip("XYZ", zl, zu):
            gmsh.model.mesh.field.setNumber(f, f"{ax}Min", a)
            gmsh.model.mesh.field.setNumber(f, f"{ax}Max", b)
        fields.append(f)
    fmin = gmsh.model.mesh.field.add("Min")
    gmsh.model.mesh.field.setNumbers(fmin, "FieldsList", fields)
    return fmin


def cell_size_function(cfg: MeshConfig, face_distance: Callable[[float, float, float], float] | None
                       ) -> Callable[[float, float, float], float] | None:
    """The target cell size h(x) [m] of a mesh with ``mesh.structure_band`` (None without one):
    h = min(mesh.size, band.size + band.grading · d(x), the size of every refine zone at x),
    d = ``face_distance(x, y, z)`` [m] to the structure's faces; a refine zone's size is its
    ``size`` inside it and, with a ``grading``, size + grading · (distance to the zone) outside."""
    band = cfg.structure_band
    if band is None:
        return None
    if face_distance is None:
        raise ConfigError("key 'mesh.structure_band' needs the structure's blocks (a coupled case)")
    size, h0, g, dim = cfg.size, band.size, band.grading, cfg.dim
    zones = [(tuple(z.lower), tuple(z.upper), z.size, z.grading) for z in cfg.refine]

    def size_at(x: float, y: float, z: float) -> float:     # called by gmsh at every mesh point: plain floats
        h = min(size, h0 + g * face_distance(x, y, z))
        p = (x, y, z)[:dim]
        for zl, zu, zs, zg in zones:
            if zs >= h:
                continue
            outside = sum(max(a - c, c - b, 0.0) ** 2 for a, c, b in zip(zl, p, zu)) ** 0.5
            if outside == 0.0:
                h = zs
            elif zg is not None:
                h = min(h, zs + zg * outside)
        return h

    return size_at


def gmsh_file(cfg: MeshConfig, comm: MPI.Comm, case_dir: Path | None) -> dmesh.Mesh:
    """Read a gmsh .msh file (path relative to the case file) on rank 0 and distribute it.
    (dolfinx 0.5.2's ``gmshio.read_from_msh`` fails on every rank: it returns a name it never
    defines.)"""
    import gmsh

    path = Path(cfg.file)
    if not path.is_absolute() and case_dir is not None:
        path = case_dir / path
    if not path.is_file():
        raise ConfigError(f"key 'mesh.file' = {cfg.file!r}: file not found ({path})")

    def read() -> None:
        gmsh.model.add("file")
        try:
            gmsh.merge(str(path))
        except Exception as err:
            raise ConfigError(f"key 'mesh.file' = {cfg.file!r}: gmsh cannot read {path}: {err}") from None
        if not gmsh.model.getPhysicalGroups(cfg.dim):
            raise ConfigError(f"key 'mesh.file' = {cfg.file!r}: {path} has no physical group of dimension "
                              f"{cfg.dim} (dolfinx takes the cells of the physical groups: add one in gmsh)")

    return _from_rank0(comm, cfg.dim, read)


def mesh_extent(mesh) -> tuple[np.ndarray, np.ndarray]:
    """Lower and upper corners of the mesh's bounding box [m] (collective)."""
    x = mesh.geometry.x[:, : mesh.geometry.dim]
    lo, hi = x.min(axis=0, initial=np.inf), x.max(axis=0, initial=-np.inf)
    mesh.comm.Allreduce(MPI.IN_PLACE, lo, op=MPI.MIN)
    mesh.comm.Allreduce(MPI.IN_PLACE, hi, op=MPI.MAX)
    return lo, hi
