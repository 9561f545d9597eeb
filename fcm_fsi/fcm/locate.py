"""The owned mesh cells that contain moving points, kept between calls.

The hidden-surface closure (fcm/hidden.py) evaluates fields at the surface samples of every
block, and at points a little way out from them, at every fluid step. The blocks of a
standing structure hardly move, so almost every point stays in the cell that held it at the
last call. :class:`PointLocator` keeps, per point (a *slot*: the caller's stable index of
the point, e.g. its sample number), the one owned cell that held it strictly inside; at the
next call a point that is still strictly inside that cell (every barycentric coordinate
above :data:`INSIDE`) keeps it, and only the others are searched in the bounding-box tree
(dolfinx ``compute_colliding_cells``). A point strictly inside a cell lies in no other cell
(the cells do not overlap, and dolfinx's contact tolerance is far below :data:`INSIDE` × the
cell's height), so the result is the search's result; points on or near a face, edge or
vertex (several cells hold them) and points outside every cell are searched at every call.

:class:`P1Values` evaluates continuous piecewise-linear functions at located points from their
barycentric coordinates in the cell (a gather and a weighted sum, the same values as dolfinx's
``Function.eval`` to round-off, without its per-point pull-back).
"""
from __future__ import annotations

import weakref

import numba
import numpy as np
from dolfinx import geometry
from mpi4py import MPI
from scipy.spatial import cKDTree

#: a point whose barycentric coordinates in a cell all exceed this lies strictly inside it
INSIDE = 1e-6


def first_component_at(fn, points: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """The first component of dolfinx Function ``fn`` at ``points`` (n, 3) in their ``cells``
    (n,), as an (n,) array (``Function.eval`` returns a flat array for a single point)."""
    return np.reshape(fn.eval(points, np.asarray(cells, np.int32)), (len(cells), -1))[:, 0]


def _is_scalar_p1(space) -> bool:
    element = space.ufl_element()
    return (element.family() in ("Lagrange", "P", "CG") and element.degree() == 1
            and space.dofmap.index_map_bs == 1 and space.dofmap.bs == 1 and len(element.value_shape()) == 0)


class P1Values:
    """Values of P1 functions at points in known owned cells of a simplex ``mesh`` with affine
    cells: λ = J⁻¹ (x − x₀) once per call, then f(x) = Σ_k λ_k f(vertex k) per function (the
    P1 dofs of a cell follow its geometry's vertices, dolfinx's local numbering of both).
    Other elements fall back to ``Function.eval``. :meth:`of` shares one per mesh (the cells'
    inverse Jacobians are 9 numbers per cell)."""

    _shared: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()

    @classmethod
    def of(cls, mesh) -> P1Values:
        """The one instance for ``mesh``."""
        if mesh not in cls._shared:
            cls._shared[mesh] = cls(mesh)
        return cls._shared[mesh]

    def __init__(self, mesh) -> None:
        self.mesh = mesh
        self.dim = mesh.topology.dim
        imap = mesh.topology.index_map(self.dim)
        self.n_owned = imap.size_local
        x = mesh.geometry.x[:, : self.dim]
        ncells = imap.size_local + imap.num_ghosts
        # the first dim + 1 geometry nodes of a simplex are its vertices
        dofs = mesh.geometry.dofmap.array.reshape(ncells, -1)[: self.n_owned, : self.dim + 1]
        self.origin = x[dofs[:, 0]]                                        # (n_owned, dim)
        edges = np.stack([x[dofs[:, k]] - self.origin for k in range(1, self.dim + 1)], axis=2)
        self.inverse = np.linalg.inv(edges)                                # (n_owned, dim, dim)
        self._cell_dofs = {}              # id(space) → (weak reference to the space, (n_owned, dim + 1) or None)

    def barycentric(self, points: np.ndarray, cells: np.ndarray) -> np.ndarray:
        """(n, dim + 1) barycentric coordinates of ``points`` (n, 3) in the owned ``cells`` (n,),
        vertex 0 first."""
        lam = np.einsum("nij,nj->ni", self.inverse[cells], points[:, : self.dim] - self.origin[cells])
        return np.column_stack([1.0 - lam.sum(axis=1), lam])

    def _dofs(self, space) -> np.ndarray | None:
        """The owned cells' dofs of ``space`` if it is scalar P1, else None; kept per space (an id
        is checked against the space it was made for: a freed space's id may be reused)."""
        entry = self._cell_dofs.get(id(space))
        if entry is None or entry[0]() is not space:
            dofs = (space.dofmap.list.array.reshape(-1, self.dim + 1)[: self.n_owned]
                    if _is_scalar_p1(space) else None)
            entry = self._cell_dofs[id(space)] = (weakref.ref(space), dofs)
        return entry[1]

    def values(self, functions, points: np.ndarray, cells: np.ndarray) -> np.ndarray:
        """(len(functions), n): each function's first component at ``points`` (n, 3) in their
        owned ``cells`` (n,)."""
        cells = np.asarray(cells, np.int64)
        out = np.zeros((len(functions), len(cells)))
        if len(cells) == 0:
            return out
        lam = None
        for j, fn in enumerate(functions):
            dofs = self._dofs(fn.function_space)
            if dofs is None:
                out[j] = first_component_at(fn, points, cells)
                continue
            lam = self.barycentric(points, cells) if lam is None else lam
            out[j] = np.einsum("nk,nk->n", lam, fn.x.array[dofs[cells]])
        return out


class PointLocator:
    """Cells of ``mesh`` (simplices) holding points, for ``nslots`` point slots. Collective
    (:meth:`locate`): the ranks agree on which points are searched again."""

    def __init__(self, mesh, nslots: int) -> None:
        self.mesh, self.comm = mesh, mesh.comm
        self.dim = mesh.topology.dim
        self.tree = geometry.BoundingBoxTree(mesh, self.dim)
        imap = mesh.topology.index_map(self.dim)
        self.n_owned = imap.size_local
        self.p1 = P1Values.of(mesh)                                         # values at the located points
        self._cell = np.full(int(nslots), -1, np.int64)                    # owned cell held strictly, or −1
        self._kept = np.zeros(int(nslots), bool)                           # some rank holds it strictly
        self.searched = 0                                                  # points searched at the last call

    def strictly_inside(self, points: np.ndarray, cells: np.ndarray) -> np.ndarray:
        """Whether ``points`` (n, 3) lie strictly inside the owned ``cells`` (n,)."""
        if len(cells) == 0:
            return np.zeros(0, bool)
        return self.p1.barycentric(points, cells).min(axis=1) > INSIDE

    def locate(self, slots: np.ndarray, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(point, cell): every pair of a point of ``points`` (n, 3) and an owned cell of this
        rank containing it (as dolfinx's search would give them, filtered to owned cells);
        ``slots`` (n,) the points' slots."""
        slots = np.asarray(slots, np.int64)
        n = len(points)
        cached = self._kept[slots]
        mine = np.flatnonzero(self._cell[slots] >= 0)
        moved = np.zeros(n, np.int8)
        moved[mine[~self.strictly_inside(points[mine], self._cell[slots[mine]])]] = 1
        self.comm.Allreduce(MPI.IN_PLACE, moved, op=MPI.MAX)                # left its cell on its rank
        moved = moved.astype(bool)
        search = np.flatnonzero(~cached | moved)
        self.searched = int(search.size)
        keep = np.flatnonzero(cached & ~moved)
        keep = keep[self._cell[slots[keep]] >= 0]
        pts = np.ascontiguousarray(points[search], dtype=np.float64)
        cands = geometry.compute_collisions(self.tree, pts)
        found = geometry.compute_colliding_cells(self.mesh, cands, pts)
        point = search[np.repeat(np.arange(len(search)), np.diff(found.offsets))]
        cell = found.array.astype(np.int64)
        owned = cell < self.n_owned
        point, cell = point[owned], cell[owned]
        # the searched points strictly inside one of this rank's cells are kept from now on
        strict = self.strictly_inside(points[point], cell)
        s = slots[search]
        self._cell[s] = -1
        self._cell[slots[point[strict]]] = cell[strict]
        held = np.zeros(n, np.int8)
        held[point[strict]] = 1
        self.comm.Allreduce(MPI.IN_PLACE, held, op=MPI.MAX)
        held = held.astype(bool)
        self._kept[s] = held[search]
        return np.concatenate([keep, point]), np.concatenate([self._cell[slots[keep]], cell])


class NearPairs:
    """Pairs of points of different bodies closer than ``radius`` [m], kept between calls:
    the candidates within ``radius`` + ``margin`` are searched for a body only when one of its
    points has moved more than ``margin``/2 since they were searched (then no pair of points
    can have come closer than ``radius`` unnoticed), so a structure at rest is searched once.
    ``body`` (n,): each point's body."""

    def __init__(self, body: np.ndarray, radius: float, margin: float) -> None:
        self.body = np.asarray(body, np.int64)
        self.radius, self.margin = float(radius), float(margin)
        self._x = None                      # (n, 3) the points when their body's pairs were searched
        self._i = self._j = np.zeros(0, np.int64)
        self.searched_bodies = 0            # bodies searched again at the last call
        self.searched_points = 0            # points in the tree the moved bodies' points were searched in
        self._order = np.argsort(self.body, kind="stable")          # the points body by body
        ids, self._starts = np.unique(self.body[self._order], return_index=True)
        self._ids = ids

    def _boxes(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per body (0 … max id) the bounding box (lower, upper) of its points at ``x``; empty
        bodies get an inverted box."""
        nb = int(self.body.max(initial=-1)) + 1
        lo, hi = np.full((nb, 3), np.inf), np.full((nb, 3), -np.inf)
        if len(self._ids):
            xs = x[self._order]
            lo[self._ids] = np.minimum.reduceat(xs, self._starts, axis=0)
            hi[self._ids] = np.maximum.reduceat(xs, self._starts, axis=0)
        return lo, hi

    def _within_reach(self, x: np.ndarray, moved: np.ndarray) -> np.ndarray:
        """Indices of the points whose body's box comes within ``radius`` + ``margin`` of a
        ``moved`` body's box: every point a moved body's point can pair with."""
        lo, hi = self._boxes(x)
        reach = self.radius + self.margin
        mlo, mhi = lo[moved] - reach, hi[moved] + reach
        near = np.zeros(len(lo), bool)
        for a, b in zip(mlo, mhi):
            near |= np.all((lo <= b) & (hi >= a), axis=1)
        return np.flatnonzero(near[self.body])

    def pairs(self, x: np.ndarray, active: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(i, j, d²) with i < j, of the ``active`` points (n,) of different bodies closer than
        ``radius`` at ``x`` (n, 3)."""
        nb = int(self.body.max(initial=-1)) + 1
        if self._x is None:
            moved = np.ones(nb, bool)
        else:
            shift = np.einsum("ij,ij->i", x - self._x, x - self._x)
            moved = np.zeros(nb, bool)
            moved[self.body[shift > (0.5 * self.margin) ** 2]] = True
        self.searched_bodies = int(np.count_nonzero(moved))
        if moved.any():
            stale = moved[self.body[self._i]] | moved[self.body[self._j]]
            i, j = self._i[~stale], self._j[~stale]
            mine = np.flatnonzero(moved[self.body])
            reach = self._within_reach(x, moved) if self._x is not None else np.arange(len(x))
            self.searched_points = len(reach)
            hits = cKDTree(x[mine]).sparse_distance_matrix(cKDTree(x[reach]), self.radius + self.margin,
                                                           output_type="ndarray")
            ni, nj = mine[hits["i"]], reach[hits["j"]].astype(np.int64)
            cross = self.body[ni] != self.body[nj]
            a, b = np.minimum(ni[cross], nj[cross]), np.maximum(ni[cross], nj[cross])
            new = np.unique(a * len(x) + b)             # a pair of two moved bodies is found twice
            self._i = np.concatenate([i, new // len(x)])
            self._j = np.concatenate([j, new % len(x)])
            if self._x is None:
                self._x = x.copy()
            else:
                self._x[moved[self.body]] = x[moved[self.body]]
        return close_active_pairs(x, self._i, self._j, np.asarray(active, np.bool_), self.radius * self.radius)


@numba.njit(cache=True)
def close_active_pairs(x: np.ndarray, i: np.ndarray, j: np.ndarray, active: np.ndarray,
                       r2: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(i, j, d²) of the candidate pairs (``i``, ``j``) whose points (``x`` (n, 3)) are both
    ``active`` and at most √``r2`` [m] apart; d² = Σ_k (x_ik − x_jk)² in the order of k. NumPy
    twin: :func:`close_active_pairs_reference`."""
    keep = np.zeros(len(i), np.bool_)
    d2 = np.zeros(len(i))
    for k in range(len(i)):
        a, b = i[k], j[k]
        if active[a] and active[b]:
            s = 0.0
            for c in range(3):
                s += (x[a, c] - x[b, c]) ** 2
            d2[k] = s
            keep[k] = s <= r2
    at = np.flatnonzero(keep)
    return i[at], j[at], d2[at]


def close_active_pairs_reference(x: np.ndarray, i: np.ndarray, j: np.ndarray, active: np.ndarray,
                                 r2: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """NumPy twin of :func:`close_active_pairs`."""
    on = active[i] & active[j]
    i, j = i[on], j[on]
    d2 = np.sum((x[i] - x[j]) ** 2, axis=1)
    close = d2 <= r2
    return i[close], j[close], d2[close]
