"""The static walls of a case (``dem.walls``), read once: what the blocks touch (the DEM's
wall contact) and what the fluid's level set sees as walls (the gap fill,
``coupling.gap_fill``).

A ``plane`` wall is one half-space, a ``box`` its six inner faces (five with ``open_top``),
in the order x−, x+, y−, y+, z−, z+; a ``mesh`` wall is a set of triangles. Every plane and
every mesh carries its material and the time it disappears (``remove_at``, a gate; ∞ for a
permanent wall).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..config.dem import DEMConfig
from .contact import Materials
from .wall_contact import WallContact


@dataclass(frozen=True)
class Walls:
    """The planes and triangle meshes of ``dem.walls`` (SI units).

    planes        (np, 4)    unit normal into the domain n and offset n·x on the plane [m]
    points        (np, 3)    the plane's point as given (a box: the corner of the face) [m]
    normals       (np, 3)    the plane's normal as given (a box: ± the axis), not normalised
    plane_mat     (np,)      material index of each plane
    permanent     (np,)      False for the planes of a wall with ``remove_at``
    tris          (nt, 3, 3) triangle vertices [m]
    tri_mesh      (nt,)      mesh index of each triangle
    mesh_mat      (nm,)      material index of each mesh
    until         (np + nm,) time each plane, then each mesh, disappears [s] (∞: never)
    """

    planes: np.ndarray
    points: np.ndarray
    normals: np.ndarray
    plane_mat: np.ndarray
    permanent: np.ndarray
    tris: np.ndarray
    tri_mesh: np.ndarray
    mesh_mat: np.ndarray
    until: np.ndarray

    @property
    def empty(self) -> bool:
        return len(self.planes) == 0 and len(self.tris) == 0

    def gap_planes(self, gdim: int) -> np.ndarray:
        """Planes (k, 6) = point [m], normal into the domain, of the permanent plane and box
        walls, for the level set's gap fill. Gates and triangle meshes are left out; for a 2D
        fluid (points at z = 0) so are planes whose normal has a z component (they bound the
        blocks' depth, not the fluid)."""
        planes = np.concatenate([self.points, self.normals], axis=1)[self.permanent].reshape(-1, 6)
        if gdim == 2:
            planes = planes[np.abs(planes[:, 5]) == 0.0]
        return planes


def walls_of(cfg: DEMConfig) -> Walls:
    """The :class:`Walls` of ``cfg.walls``."""
    planes, points, normals, pmat, perm, tris, tmesh, mmat, puntil, muntil = ([] for _ in range(10))
    for w in cfg.walls:
        mi = cfg.material_index(w.material)
        until = math.inf if w.remove_at is None else w.remove_at
        n_pl = len(planes)
        if w.kind == "plane":
            n = np.asarray(w.normal, np.float64)
            n /= np.linalg.norm(n)
            planes.append([*n, float(n @ np.asarray(w.point))])
            points.append(w.point)
            normals.append(w.normal)
        elif w.kind == "box":
            lo, hi = np.asarray(w.lo), np.asarray(w.hi)
            for d in range(3):
                if d == 2 and w.open_top:
                    faces = [(lo, 1.0)]
                else:
                    faces = [(lo, 1.0), (hi, -1.0)]
                for corner, sgn in faces:
                    n = np.zeros(3)
                    n[d] = sgn
                    planes.append([*n, sgn * corner[d]])
                    points.append(corner)
                    normals.append(n)
        else:
            V = np.asarray(w.vertices, np.float64)
            for t in w.triangles:
                tris.append(V[list(t)])
                tmesh.append(len(mmat))
            mmat.append(mi)
            muntil.append(until)
        n_new = len(planes) - n_pl
        pmat.extend([mi] * n_new)
        perm.extend([w.remove_at is None] * n_new)
        puntil.extend([until] * n_new)
    return Walls(planes=np.reshape(np.asarray(planes, np.float64), (-1, 4)),
                 points=np.reshape(np.asarray(points, np.float64), (-1, 3)),
                 normals=np.reshape(np.asarray(normals, np.float64), (-1, 3)),
                 plane_mat=np.asarray(pmat, np.int64), permanent=np.asarray(perm, bool),
                 tris=np.reshape(np.asarray(tris, np.float64), (-1, 3, 3)), tri_mesh=np.asarray(tmesh, np.int64),
                 mesh_mat=np.asarray(mmat, np.int64), until=np.asarray(puntil + muntil, np.float64))


def gap_walls(cfg: DEMConfig, gdim: int) -> np.ndarray:
    """The gap fill's planes (k, 6) of ``cfg.walls`` (:meth:`Walls.gap_planes`)."""
    return walls_of(cfg).gap_planes(gdim)


def wall_contact(walls: Walls, materials: Materials, ns: int, clip: bool) -> WallContact | None:
    """The spring–dashpot–slider contact of ``ns`` spheres with ``walls`` (None without walls)."""
    if walls.empty:
        return None
    return WallContact(materials, walls.planes, walls.plane_mat, walls.tris, walls.tri_mesh, walls.mesh_mat, ns, clip,
                       until=walls.until)
