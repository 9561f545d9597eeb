"""The structure's primitives in body frames (the data of the level set, fcm/levelset.py):
spheres, boxes, finite capped cylinders, and closed triangulated surfaces carried as a
signed-distance grid (kind MESH, from a CAD file: fcm_fsi/geometry/surface*.py)."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

SPHERE, BOX, CYLINDER, MESH = 0, 1, 2, 3
KIND_NAMES = ("sphere", "box", "cylinder", "mesh")
NO_SHAPE = -2            # owner of points with no primitive within the cutoff
STATIC = -1              # body index of a static (world-frame) primitive
WALL = -3                # the walls, as one owner of the gap-fill search (only in fill_other)


@dataclass(frozen=True)
class Shapes:
    """Primitives in body frames. Arrays of length nshape (SI units).

    kind    int64           0 sphere, 1 box, 2 cylinder (finite, capped; axis = shape-frame z),
                            3 mesh (a closed triangle surface, as its signed-distance grid)
    body    int64           index of the body that carries the shape; −1 = static (world frame)
    offset  (nshape, 3)     shape centre in the body frame [m] (mesh: the grid box's centre)
    rot     (nshape, 3, 3)  shape frame → body frame rotation
    half    (nshape, 3)     box half extents; sphere (r, 0, 0); cylinder (r, half_length, 0);
                            mesh: the grid box's half extents [m]
    grid    (nshape, 4)     int64, mesh: first index in ``values`` and nodes per axis (nx, ny,
                            nz), node (i, j, k) at −half + (i, j, k)·2 half/(dims − 1) in the
                            shape frame; −1 for the other kinds
    values  (nv,)           the meshes' signed distances at their grid nodes [m], C order
    triangles               per shape: the mesh's triangle corners (nt, 3, 3) in the shape
                            frame [m] (its surface samples), None for the other kinds

    Build them with :meth:`sphere`, :meth:`box`, :meth:`cylinder`, :meth:`mesh` and join with
    :meth:`concat`; :meth:`take` selects some. A DEM box block of edge lengths (a, b, c),
    centred at its centre of mass in its principal frame, is ``Shapes.box((0, 0, 0), (a, b, c),
    body=i)``.
    """

    kind: np.ndarray
    body: np.ndarray
    offset: np.ndarray
    rot: np.ndarray
    half: np.ndarray
    grid: np.ndarray | None = None
    values: np.ndarray = field(default_factory=lambda: np.zeros(0))
    triangles: tuple = ()

    def __post_init__(self):
        n = len(self.kind)
        grid = np.full((n, 4), -1, np.int64) if self.grid is None else self.grid
        arrays = {"kind": (np.asarray(self.kind, np.int64), (n,)),
                  "body": (np.asarray(self.body, np.int64), (n,)),
                  "offset": (np.asarray(self.offset, np.float64).reshape(-1, 3), (n, 3)),
                  "rot": (np.asarray(self.rot, np.float64).reshape(-1, 3, 3), (n, 3, 3)),
                  "half": (np.asarray(self.half, np.float64).reshape(-1, 3), (n, 3)),
                  "grid": (np.asarray(grid, np.int64).reshape(-1, 4), (n, 4))}
        for name, (a, shape) in arrays.items():
            if a.shape != shape:
                raise ValueError(f"Shapes.{name}: shape {a.shape}, expected {shape}")
            object.__setattr__(self, name, np.ascontiguousarray(a))
        object.__setattr__(self, "values", np.ascontiguousarray(self.values, np.float64).reshape(-1))
        object.__setattr__(self, "triangles", tuple(self.triangles) if len(self.triangles) else (None,) * n)
        if len(self.triangles) != n:
            raise ValueError(f"Shapes.triangles: {len(self.triangles)} entries, expected {n}")
        _check_shapes(self)

    def __len__(self) -> int:
        return len(self.kind)

    @classmethod
    def sphere(cls, centre, r: float, body: int = STATIC) -> Shapes:
        """Sphere of radius ``r`` [m] centred at ``centre`` [m] (body frame, or world if static)."""
        return cls._one(SPHERE, body, centre, np.eye(3), (r, 0.0, 0.0))

    @classmethod
    def box(cls, centre, size, rot=None, body: int = STATIC) -> Shapes:
        """Box of edge lengths ``size`` = (a, b, c) [m] along the columns of ``rot``
        (shape → body frame, identity by default), centred at ``centre`` [m]."""
        return cls._one(BOX, body, centre, np.eye(3) if rot is None else rot, 0.5 * np.asarray(size, float))

    @classmethod
    def cylinder(cls, centre, r: float, length: float, axis=(0.0, 0.0, 1.0), body: int = STATIC) -> Shapes:
        """Capped cylinder of radius ``r`` and length ``length`` [m] along ``axis``, centred
        at ``centre`` [m]. In 2D (points at z = 0) the default axis gives a disc of radius r."""
        return cls._one(CYLINDER, body, centre, _frame_with_z_along(axis), (r, 0.5 * length, 0.0))

    @classmethod
    def mesh(cls, grid, corners, origin=(0.0, 0.0, 0.0), rot=None, body: int = STATIC) -> Shapes:
        """A closed triangle surface given by its signed-distance grid ``grid`` (a
        :class:`~fcm_fsi.geometry.surface_distance.DistanceGrid`) and triangle ``corners``
        (nt, 3, 3), both in the surface's own frame [m]; that frame's origin sits at ``origin``
        [m] rotated by ``rot`` (surface → body frame, identity by default)."""
        rot = np.eye(3) if rot is None else np.asarray(rot, np.float64)
        centre = np.asarray(origin, np.float64) + rot @ grid.centre
        return cls(np.array([MESH]), np.array([body]), centre.reshape(1, 3), rot.reshape(1, 3, 3),
                   np.reshape(grid.half, (1, 3)), np.concatenate([[0], grid.dims]).reshape(1, 4), grid.values,
                   (np.asarray(corners, np.float64) - grid.centre,))

    @classmethod
    def concat(cls, parts: list[Shapes]) -> Shapes:
        """All primitives of ``parts``, in order."""
        if not parts:
            return cls(np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 3)),
                       np.zeros((0, 3, 3)), np.zeros((0, 3)))
        grids, first = [], 0
        for p in parts:
            g = p.grid.copy()
            g[:, 0] = np.where(g[:, 0] >= 0, g[:, 0] + first, -1)
            grids.append(g)
            first += len(p.values)
        return cls(*(np.concatenate([getattr(p, f) for p in parts]) for f in ("kind", "body", "offset", "rot", "half")),
                   np.concatenate(grids), np.concatenate([p.values for p in parts]),
                   sum((p.triangles for p in parts), ()))

    def take(self, index) -> Shapes:
        """The primitives ``index`` (an index array), in that order (the grids' values kept whole)."""
        index = np.asarray(index, np.int64).reshape(-1)
        return Shapes(self.kind[index], self.body[index], self.offset[index], self.rot[index], self.half[index],
                      self.grid[index], self.values, tuple(self.triangles[i] for i in index))

    @classmethod
    def _one(cls, kind, body, centre, rot, half) -> Shapes:
        return cls(np.array([kind]), np.array([body]), np.reshape(centre, (1, 3)),
                   np.reshape(rot, (1, 3, 3)), np.reshape(half, (1, 3)))


def _check_shapes(s: Shapes) -> None:
    """Reject unknown kinds, body < −1, non-positive sizes, improper rotations and mesh grids
    that do not fit their values."""
    bad = np.flatnonzero((s.kind < SPHERE) | (s.kind > MESH))
    if bad.size:
        raise ValueError(f"Shapes.kind[{bad[0]}] = {s.kind[bad[0]]}: allowed 0 sphere, 1 box, 2 cylinder, 3 mesh")
    bad = np.flatnonzero(s.body < STATIC)
    if bad.size:
        raise ValueError(f"Shapes.body[{bad[0]}] = {s.body[bad[0]]}: allowed −1 (static) or a body index ≥ 0")
    used = np.array([[True, False, False], [True, True, True], [True, True, False], [True, True, True]])[s.kind]
    bad = np.flatnonzero(np.any(used & ~(s.half > 0), axis=1))
    if bad.size:
        raise ValueError(f"Shapes.half[{bad[0]}] = {s.half[bad[0]]}: sizes of kind {s.kind[bad[0]]} must be > 0")
    err = np.abs(np.einsum("sji,sjk->sik", s.rot, s.rot) - np.eye(3)).max(axis=(1, 2), initial=0.0)
    bad = np.flatnonzero((err > 1e-9) | (np.linalg.det(s.rot) < 0))
    if bad.size:
        raise ValueError(f"Shapes.rot[{bad[0]}] is not a proper rotation (RᵀR − I up to {err[bad[0]]:.2e})")
    mesh = s.kind == MESH
    g = s.grid
    fits = (g[:, 0] >= 0) & np.all(g[:, 1:] >= 2, axis=1) & (g[:, 0] + np.prod(g[:, 1:], axis=1) <= len(s.values))
    bad = np.flatnonzero(mesh & ~fits)
    if bad.size:
        raise ValueError(f"Shapes.grid[{bad[0]}] = {g[bad[0]]} does not fit the {len(s.values)} grid values "
                         "(first index ≥ 0, ≥ 2 nodes per axis)")


def _frame_with_z_along(axis) -> np.ndarray:
    """A rotation whose third column is the unit vector along ``axis``."""
    a = np.asarray(axis, np.float64)
    a = a / np.linalg.norm(a)
    helper = np.eye(3)[np.argmin(np.abs(a))]
    e1 = np.cross(helper, a)
    e1 /= np.linalg.norm(e1)
    return np.column_stack([e1, np.cross(a, e1), a])


def bounding_radius(shapes: Shapes) -> np.ndarray:
    """Radius [m] of the sphere about each primitive's centre that contains it (a mesh: its
    grid box)."""
    h = shapes.half
    return np.select([shapes.kind == SPHERE, (shapes.kind == BOX) | (shapes.kind == MESH)],
                     [h[:, 0], np.linalg.norm(h, axis=1)], np.hypot(h[:, 0], h[:, 1]))


def grid_margin(shapes: Shapes) -> np.ndarray:
    """Per primitive: the least signed distance [m] on its grid box's boundary nodes — how far
    beyond the surface a mesh's grid reaches (inf for the other kinds)."""
    out = np.full(len(shapes), np.inf)
    for s in np.flatnonzero(shapes.kind == MESH):
        start, nx, ny, nz = shapes.grid[s]
        v = shapes.values[start:start + nx * ny * nz].reshape(nx, ny, nz)
        out[s] = min(v[[0, -1]].min(), v[:, [0, -1]].min(), v[:, :, [0, -1]].min())
    return out
