"""Meshes for the Navier–Stokes benchmarks, with named boundaries.

- :func:`rectangle` / :func:`box`: structured dolfinx simplices, boundaries named by axis,
  ``xmin xmax ymin ymax (zmin zmax)``.
- :func:`channel_2d`: Schäfer–Turek 2D channel [0, 2.2] × [0, 0.41] with a cylinder of
  diameter 0.1 at (0.2, 0.2); :func:`channel_3d`: the 3D-1Z channel [0, 2.5] × [0, 0.41]²
  with a z-aligned cylinder at (0.5, 0.2). Boundaries ``inlet outlet walls cylinder``.
  Built by gmsh on rank 0, cached as .msh under ``meshes/cache/`` and distributed with
  ``dolfinx.io.gmshio.model_to_mesh``.
- :func:`channel_unfitted`: the same channels (2D or 3D) WITHOUT the cylinder hole, graded
  to ``h_cyl`` around where the cylinder will be cut out by its level set (finite cover).
"""
from __future__ import annotations

import hashlib
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from dolfinx import mesh as dmesh

from ..config.mesh import box_boundary_names

CACHE = Path(__file__).resolve().parents[2] / "meshes" / "cache"
CHANNEL_NAMES = {"inlet": 1, "outlet": 2, "walls": 3, "cylinder": 4}


@dataclass
class TaggedMesh:
    """A mesh with facet tags and the name → tag map of its boundaries."""

    mesh: dmesh.Mesh
    facet_tags: dmesh.MeshTags
    names: dict[str, int]


def tag_box_boundaries(msh, lower, upper) -> TaggedMesh:
    """Tag the axis-aligned planes of a rectangle/box mesh, named by axis
    (:func:`~fcm_fsi.config.mesh.box_boundary_names`): tags 1, 2, … = xmin, xmax, ymin, ymax, zmin, zmax."""
    names = box_boundary_names(len(lower))
    fdim = msh.topology.dim - 1
    facets, values = [], []
    for tag, (axis, coord) in enumerate(((a, c) for a in range(len(lower)) for c in (lower[a], upper[a])), 1):
        f = dmesh.locate_entities_boundary(msh, fdim, lambda x, a=axis, c=coord: np.isclose(x[a], c))
        facets.append(f)
        values.append(np.full(len(f), tag, dtype=np.int32))
    facets = np.concatenate(facets)
    values = np.concatenate(values)
    # a facet on an edge/corner belongs to one plane only (each facet lies in exactly one plane)
    order = np.argsort(facets, kind="stable")
    facets, values = facets[order], values[order]
    facets, first = np.unique(facets, return_index=True)
    tags = dmesh.meshtags(msh, fdim, facets, values[first])
    return TaggedMesh(msh, tags, {n: i for i, n in enumerate(names, 1)})


def rectangle(comm, lower=(0.0, 0.0), upper=(1.0, 1.0), n=(32, 32), diagonal: str = "right") -> TaggedMesh:
    """Structured triangles with boundaries xmin, xmax, ymin, ymax."""
    diag = {"right": dmesh.DiagonalType.right, "left": dmesh.DiagonalType.left,
            "crossed": dmesh.DiagonalType.crossed}[diagonal]
    msh = dmesh.create_rectangle(comm, [np.array(lower), np.array(upper)], list(n),
                                 dmesh.CellType.triangle, diagonal=diag)
    return tag_box_boundaries(msh, lower, upper)


def box(comm, lower=(0.0, 0.0, 0.0), upper=(1.0, 1.0, 1.0), n=(8, 8, 8)) -> TaggedMesh:
    """Structured tetrahedra with boundaries xmin, xmax, ymin, ymax, zmin, zmax."""
    msh = dmesh.create_box(comm, [np.array(lower), np.array(upper)], list(n), dmesh.CellType.tetrahedron)
    return tag_box_boundaries(msh, lower, upper)


def _classify_and_mesh(gmsh, dim: int, length: float, height: float, center, radius: float,
                       h_cyl: float, h_far: float, axis: int | None = None,
                       band: tuple[float, float] | None = None) -> None:
    """Physical groups (fluid, inlet, outlet, walls, cylinder) and a size field graded with
    the distance from the cylinder surface (or, unfitted, from its axis: ``axis`` is the
    axis curve in 3D; in 2D the centre point is used).

    ``band = (d0, d1)``: instead, size h_cyl within d0 of the cylinder surface |ρ − r| (on
    both sides of it when the mesh is unfitted), growing linearly to h_far at d1 — a thin
    shell of fine cells where the wall pressure and shear live, at a fraction of the cells.
    """
    vols = gmsh.model.getEntities(dim)
    gmsh.model.addPhysicalGroup(dim, [v[1] for v in vols], 1)
    groups = {k: [] for k in CHANNEL_NAMES}
    for _, tag in gmsh.model.getBoundary(vols, oriented=False):
        com = np.array(gmsh.model.occ.getCenterOfMass(dim - 1, tag))
        if np.isclose(com[0], 0.0):
            groups["inlet"].append(tag)
        elif np.isclose(com[0], length):
            groups["outlet"].append(tag)
        elif np.linalg.norm(com[:2] - np.array(center[:2])) < 2 * radius:
            groups["cylinder"].append(tag)
        else:
            groups["walls"].append(tag)
    fitted = bool(groups["cylinder"])
    for name, tags in groups.items():
        if tags:
            gmsh.model.addPhysicalGroup(dim - 1, tags, CHANNEL_NAMES[name])
            gmsh.model.setPhysicalName(dim - 1, CHANNEL_NAMES[name], name)
    if band is not None:
        dist = gmsh.model.mesh.field.add("MathEval")
        gmsh.model.mesh.field.setString(
            dist, "F", f"Abs(Sqrt((x - {center[0]})^2 + (y - {center[1]})^2) - {radius})")
        d0, d1 = band
    else:
        dist = gmsh.model.mesh.field.add("Distance")
        d0 = 0.5 * radius if fitted else 1.5 * radius      # from the axis: the whole cut region is fine
        d1 = 0.5 * height + (3 * radius if fitted else d0 + 2 * radius)
        if fitted:
            gmsh.model.mesh.field.setNumbers(dist, "SurfacesList" if dim == 3 else "CurvesList",
                                             groups["cylinder"])
            if dim == 2:
                gmsh.model.mesh.field.setNumber(dist, "NumPointsPerCurve", 200)
        elif dim == 2:
            centre = gmsh.model.occ.addPoint(center[0], center[1], 0.0)
            gmsh.model.occ.synchronize()
            gmsh.model.mesh.field.setNumbers(dist, "PointsList", [centre])
        else:
            gmsh.model.mesh.field.setNumbers(dist, "CurvesList", [axis])
            gmsh.model.mesh.field.setNumber(dist, "NumPointsPerCurve", 100)
    thr = gmsh.model.mesh.field.add("Threshold")
    gmsh.model.mesh.field.setNumber(thr, "InField", dist)
    gmsh.model.mesh.field.setNumber(thr, "SizeMin", h_cyl)
    gmsh.model.mesh.field.setNumber(thr, "SizeMax", h_far)
    gmsh.model.mesh.field.setNumber(thr, "DistMin", d0)
    gmsh.model.mesh.field.setNumber(thr, "DistMax", d1)
    gmsh.model.mesh.field.setAsBackgroundMesh(thr)
    gmsh.option.setNumber("Mesh.MeshSizeExtendFromBoundary", 0)
    gmsh.option.setNumber("Mesh.MeshSizeFromPoints", 0)
    gmsh.option.setNumber("Mesh.MeshSizeFromCurvature", 0)
    gmsh.option.setNumber("Mesh.Algorithm", 6)
    gmsh.model.mesh.generate(dim)


def _build_or_load(comm, key: str, dim: int, builder) -> TaggedMesh:
    import gmsh
    from dolfinx.io import gmshio
    CACHE.mkdir(parents=True, exist_ok=True) if comm.rank == 0 else None
    path = CACHE / f"{key}.msh"
    if comm.rank == 0:
        if not getattr(gmsh, "_fcm_fsi_initialized", False):   # gmsh 4.8 has no isInitialized()
            gmsh.initialize()
            gmsh._fcm_fsi_initialized = True
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add(key)
        if path.exists():
            gmsh.open(str(path))
        else:
            builder(gmsh)
            tmp = path.with_suffix(f".{os.getpid()}.msh")
            gmsh.write(str(tmp))
            os.replace(tmp, path)
    msh, _, facet_tags = gmshio.model_to_mesh(gmsh.model if comm.rank == 0 else None, comm, 0, gdim=dim)
    if comm.rank == 0:
        gmsh.model.remove()
    return TaggedMesh(msh, facet_tags, dict(CHANNEL_NAMES))


def channel_2d(comm, h_cyl: float = 0.005, h_far: float = 0.03) -> TaggedMesh:
    """Schäfer–Turek 2D-1/2D-2 geometry; cells of size h_cyl at the cylinder growing to h_far."""
    L, H, c, r = 2.2, 0.41, (0.2, 0.2), 0.05
    key = "st2d_" + hashlib.sha1(f"{L},{H},{c},{r},{h_cyl},{h_far},v1".encode()).hexdigest()[:10]

    def build(gmsh):
        rect = gmsh.model.occ.addRectangle(0, 0, 0, L, H)
        disk = gmsh.model.occ.addDisk(c[0], c[1], 0, r, r)
        gmsh.model.occ.cut([(2, rect)], [(2, disk)])
        gmsh.model.occ.synchronize()
        _classify_and_mesh(gmsh, 2, L, H, c, r, h_cyl, h_far)
    return _build_or_load(comm, key, 2, build)


def channel_3d(comm, h_cyl: float = 0.01, h_far: float = 0.05,
               band: tuple[float, float] | None = None) -> TaggedMesh:
    """Schäfer–Turek 3D-1Z geometry (square channel, z-aligned cylinder); ``band`` as in
    ``_classify_and_mesh``."""
    L, H, c, r = 2.5, 0.41, (0.5, 0.2), 0.05
    key = "st3d_" + hashlib.sha1(f"{L},{H},{c},{r},{h_cyl},{h_far},v1".encode()
                                 + (f",band{band}".encode() if band else b"")).hexdigest()[:10]

    def build(gmsh):
        bx = gmsh.model.occ.addBox(0, 0, 0, L, H, H)
        cyl = gmsh.model.occ.addCylinder(c[0], c[1], 0, 0, 0, H, r)
        gmsh.model.occ.cut([(3, bx)], [(3, cyl)])
        gmsh.model.occ.synchronize()
        _classify_and_mesh(gmsh, 3, L, H, c, r, h_cyl, h_far, band=band)
    return _build_or_load(comm, key, 3, build)


def channel_unfitted(comm, dim: int, h_cyl: float, h_far: float,
                     band: tuple[float, float] | None = None) -> TaggedMesh:
    """Schäfer–Turek channel (2D [0, 2.2] × [0, 0.41]; 3D [0, 2.5] × [0, 0.41]²) with no
    hole: cells of size h_cyl within 1.5 radii of the cylinder axis, growing to h_far (or,
    with ``band``, in a shell around the cylinder surface; the mesh stays unfitted).
    Boundaries ``inlet outlet walls``."""
    L = 2.2 if dim == 2 else 2.5
    H, r = 0.41, 0.05
    c = (0.2, 0.2) if dim == 2 else (0.5, 0.2)
    key = f"st{dim}d_unfitted_" + hashlib.sha1(f"{L},{H},{c},{r},{h_cyl},{h_far},v1".encode()
                                               + (f",band{band}".encode() if band else b"")).hexdigest()[:10]

    def build(gmsh):
        if dim == 2:
            gmsh.model.occ.addRectangle(0, 0, 0, L, H)
        else:
            gmsh.model.occ.addBox(0, 0, 0, L, H, H)
        gmsh.model.occ.synchronize()
        axis = gmsh.model.occ.addLine(gmsh.model.occ.addPoint(c[0], c[1], 0.0),
                                      gmsh.model.occ.addPoint(c[0], c[1], H if dim == 3 else 0.0)) \
            if dim == 3 else None
        gmsh.model.occ.synchronize()
        _classify_and_mesh(gmsh, dim, L, H, c, r, h_cyl, h_far, axis=axis, band=band)
    return _build_or_load(comm, key, dim, build)
