"""Closed triangulated surfaces from CAD files: reading, the closed-manifold check, and the mass
properties of the solid they bound.

A surface is read with meshio (STL ASCII or binary, OBJ, gmsh ``.msh``, and the other formats
meshio knows; gmsh for a ``.msh`` meshio cannot read), its triangles are scaled and checked to
bound a solid: every edge is shared by exactly two triangles that run along it in opposite
directions (a closed, consistently oriented 2-manifold). The orientation is then made outward:
the signed volume enclosed (divergence theorem) must be positive, else every triangle is
flipped.

Mass properties (:func:`mass_properties`) come from the same theorem, the solid split into the
tetrahedra (0, a, b, c) of the origin and each triangle: volume V = Σ det(a, b, c)/6, first
moment Σ V_t (a + b + c)/4 and second moment ∫ x xᵀ dV = Σ V_t/20 (a aᵀ + b bᵀ + c cᵀ + s sᵀ),
s = a + b + c (the closed form of a tetrahedron's covariance with a vertex at the origin;
Eberly, "Polyhedral mass properties", 2002). They are exact for the polyhedron; a surface
tessellating a curved solid carries the tessellation's error (tests/geometry/test_surface.py).
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np


class SurfaceError(ValueError):
    """A surface file that cannot be read or does not bound a solid (the message says why)."""


@dataclass(frozen=True)
class ClosedSurface:
    """A closed, outward-oriented triangle surface [m]: ``vertices`` (nv, 3), ``triangles``
    (nt, 3) vertex indices, counter-clockwise seen from outside."""

    vertices: np.ndarray
    triangles: np.ndarray

    @property
    def corners(self) -> np.ndarray:
        """(nt, 3, 3) the triangles' corner coordinates [m]."""
        return self.vertices[self.triangles]

    @property
    def area(self) -> float:
        """Surface area [m²]."""
        c = self.corners
        return float(0.5 * np.linalg.norm(np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0]), axis=1).sum())


@dataclass(frozen=True)
class MassProperties:
    """Of the solid of uniform density: ``volume`` [m³], ``mass`` [kg], ``centre`` of mass [m]
    and ``inertia`` (3, 3) [kg m²] about the centre of mass, in the surface's frame."""

    volume: float
    mass: float
    centre: np.ndarray
    inertia: np.ndarray


def closed_surface(vertices, triangles) -> ClosedSurface:
    """The surface of ``triangles`` (nt, 3) on ``vertices`` (nv, 3) [m], merged at coincident
    vertices, checked closed and consistently oriented, and oriented outward; SurfaceError
    otherwise."""
    v = np.asarray(vertices, np.float64).reshape(-1, 3)
    t = np.asarray(triangles, np.int64).reshape(-1, 3)
    if len(t) == 0:
        raise SurfaceError("has no triangles")
    if not np.all(np.isfinite(v)):
        raise SurfaceError("has vertices that are not finite numbers")
    v, t = _merged_vertices(v, t)
    c = v[t]
    degenerate = np.linalg.norm(np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0]), axis=1) == 0
    if degenerate.any():
        raise SurfaceError(f"has {int(degenerate.sum())} triangles of zero area")
    _check_closed(t)
    surface = ClosedSurface(v, t)
    if signed_volume(surface) < 0:
        surface = ClosedSurface(v, t[:, ::-1].copy())
    return surface


def _merged_vertices(v: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Vertices that coincide to 1e-9 of the surface's size made one (STL repeats every vertex
    per triangle); the unused ones dropped."""
    size = float(np.ptp(v, axis=0).max()) or 1.0
    key = np.round(v / (1e-9 * size)).astype(np.int64)
    _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
    t = inverse.reshape(-1)[t]
    used, t = np.unique(t, return_inverse=True)
    return v[first[used]], t.reshape(-1, 3)


def _check_closed(t: np.ndarray) -> None:
    """Every directed edge once, and its reverse once: SurfaceError naming the open, the
    multiply shared and the inconsistently oriented edges."""
    directed = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    nv = int(t.max()) + 1
    code = directed[:, 0] * nv + directed[:, 1]
    codes, count = np.unique(code, return_counts=True)
    reverse = (codes % nv) * nv + codes // nv
    pos = np.searchsorted(codes, reverse).clip(max=len(codes) - 1)
    has_reverse = codes[pos] == reverse
    problems = []
    open_edges = int(np.count_nonzero(~has_reverse))
    if open_edges:
        problems.append(f"{open_edges} open edges (used by one triangle only)")
    doubled = int(np.count_nonzero(count > 1))
    if doubled:
        problems.append(f"{doubled} edges run the same way in two triangles (inconsistent orientation, "
                        "or more than two triangles at an edge)")
    if problems:
        raise SurfaceError("is not a closed, consistently oriented surface: " + "; ".join(problems))


def signed_volume(surface: ClosedSurface) -> float:
    """Σ det(a, b, c)/6 over the triangles [m³]: the enclosed volume, > 0 for outward triangles."""
    c = surface.corners
    return float(np.einsum("ti,ti->t", c[:, 0], np.cross(c[:, 1], c[:, 2])).sum() / 6.0)


def mass_properties(surface: ClosedSurface, density: float) -> MassProperties:
    """Volume, mass, centre of mass and inertia about it of the solid of ``density`` [kg/m³]
    bounded by ``surface`` (module docstring: tetrahedra from the origin)."""
    c = surface.corners
    a, b, d = c[:, 0], c[:, 1], c[:, 2]
    vt = np.einsum("ti,ti->t", a, np.cross(b, d)) / 6.0
    volume = vt.sum()
    s = a + b + d
    centre = (vt[:, None] * s).sum(axis=0) / (4.0 * volume)
    second = np.einsum("t,tij->ij", vt / 20.0, np.einsum("ti,tj->tij", a, a) + np.einsum("ti,tj->tij", b, b)
                       + np.einsum("ti,tj->tij", d, d) + np.einsum("ti,tj->tij", s, s))
    second -= volume * np.outer(centre, centre)                 # ∫ (x − c)(x − c)ᵀ dV
    inertia = density * (np.trace(second) * np.eye(3) - second)
    return MassProperties(float(volume), float(density * volume), centre, inertia)


# ------------------------------------------------------------------ reading files
def read_surface(path: str | Path, scale: float = 1.0) -> ClosedSurface:
    """The closed surface in ``path`` with its coordinates × ``scale`` [m]; SurfaceError for a
    missing or unreadable file, one without triangles, or one that does not bound a solid.
    Cached by (path, modification time, scale)."""
    path = Path(path)
    if not path.is_file():
        raise SurfaceError("file not found")
    return _read_cached(str(path.resolve()), path.stat().st_mtime_ns, float(scale))


@lru_cache(maxsize=16)
def _read_cached(path: str, mtime: int, scale: float) -> ClosedSurface:
    vertices, triangles = _read_triangles(Path(path))
    return closed_surface(scale * vertices, triangles)


def _read_triangles(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Vertices and triangles of a surface file (meshio; gmsh for a .msh meshio cannot read)."""
    import meshio
    try:
        mesh = meshio.read(str(path))
    except Exception as err:                      # meshio raises many kinds for a bad file
        if path.suffix.lower() != ".msh":
            raise SurfaceError(f"meshio cannot read it ({type(err).__name__}: {err})") from None
        return _read_with_gmsh(path)
    tri = [np.asarray(block.data) for block in mesh.cells if block.type == "triangle"]
    if not tri:
        raise SurfaceError(f"has no triangles (cell types: {', '.join(b.type for b in mesh.cells) or 'none'})")
    return np.asarray(mesh.points, np.float64)[:, :3], np.concatenate(tri)


def _read_with_gmsh(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """The 3-node triangles of a gmsh file, read with the gmsh API."""
    import gmsh
    started = gmsh.isInitialized()
    if not started:
        gmsh.initialize(["-v", "0"])
    try:
        gmsh.model.add("surface")
        try:
            gmsh.merge(str(path))
        except Exception as err:
            raise SurfaceError(f"gmsh cannot read it ({err})") from None
        tags, coords, _ = gmsh.model.mesh.getNodes()
        types, _, nodes = gmsh.model.mesh.getElements(2)
        tri = [n for ty, n in zip(types, nodes) if ty == 2]
        if not tri:
            raise SurfaceError("has no 3-node triangles")
        index = np.zeros(int(tags.max()) + 1, np.int64)
        index[tags.astype(np.int64)] = np.arange(len(tags))
        return np.asarray(coords).reshape(-1, 3), index[np.concatenate(tri).astype(np.int64)].reshape(-1, 3)
    finally:
        gmsh.model.remove()
        if not started:
            gmsh.finalize()
