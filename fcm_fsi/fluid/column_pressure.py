"""The local static pressure of the fluid: the pressure at the top of the vertical column
above a point plus the weight of the fluid in the column,

    P(x) = p(x_top) + ∫ ρ |g| ds   (s along −g, from x up to x_top),

x_top where the vertical through x leaves the mesh (the domain's top). In fluid at rest it
is the pressure; in a surge it is the shallow-water (hydrostatic) pressure under the local
depth; in air it is the ambient pressure whatever the water does elsewhere. The
hidden-surface closure (``coupling.hidden_pressure``) uses it as the pressure of the water
in the thin gaps under resting bodies.

Columns stand on a grid of spacing ``spacing`` across gravity (aligned with the mesh's
bounding box, so the domain's walls are grid lines), levels ``spacing``/2 apart along it,
counted down from the top. Only the columns around the requested points are built, each
down to the lowest requested point. The density is sampled at the levels and integrated by
the trapezoidal rule; a point's value is interpolated linearly between levels and
(bi)linearly between the columns around it (columns outside the mesh are left out and the
weights of the others renormalised). For a layered density (water at rest: ρ depends on the
height only, the interface flat) the interpolation in the columns' plane is exact.

The columns' points are located in the mesh once per set of columns (the mesh is fixed); the
values are gathered from the ranks' owned cells, so every rank gets the same columns.
"""
from __future__ import annotations

import numpy as np
from dolfinx import geometry
from mpi4py import MPI

from ..fcm.locate import P1Values


def vertical_frame(gravity: np.ndarray, dim: int) -> tuple[np.ndarray, np.ndarray]:
    """(up (3,), across (dim − 1, 3)): the unit vector against gravity and orthonormal
    vectors across it (2D: one, in the plane; 3D: two)."""
    g = np.zeros(3)
    g[:dim] = np.asarray(gravity, float)[:dim]
    norm = float(np.linalg.norm(g))
    if norm == 0.0:
        raise ValueError("the column pressure needs gravity")
    up = -g / norm
    if dim == 2:
        return up, np.array([[up[1], -up[0], 0.0]])
    seed = np.eye(3)[int(np.argmin(np.abs(up)))]
    e1 = np.cross(up, seed)
    e1 /= np.linalg.norm(e1)
    return up, np.array([e1, np.cross(up, e1)])


def column_integral(rho: np.ndarray, found: np.ndarray, g: float, ds: float) -> np.ndarray:
    """Weight of the fluid above each level [Pa] (ncol, nlev): ``rho`` (ncol, nlev) [kg/m³]
    at levels ``ds`` [m] apart counted down from the top, ``found`` where the level lies in
    the mesh; integrated by the trapezoidal rule from each column's first level in the mesh
    (0 there and above), ``g`` [m/s²] the magnitude of gravity. A level outside the mesh below
    that takes the density of the last level above it in the mesh (a point between the last
    level in the mesh and the floor gets the weight down to it)."""
    ncol, nlev = rho.shape
    last = np.where(found, np.arange(nlev)[None, :], -1)
    last = np.maximum.accumulate(last, axis=1)                    # the last level in the mesh so far
    started = last >= 0
    r = np.where(started, rho[np.arange(ncol)[:, None], np.maximum(last, 0)], 0.0)
    seg = 0.5 * (r[:, 1:] + r[:, :-1]) * ds * g
    seg = np.where(started[:, :-1], seg, 0.0)
    return np.concatenate([np.zeros((ncol, 1)), np.cumsum(seg, axis=1)], axis=1)


def column_neighbours(cols: np.ndarray) -> list[np.ndarray]:
    """For each grid axis and direction (−1, +1), the row in ``cols`` (ncol, k) of each column's
    neighbour, −1 where it is not among them."""
    k = cols.shape[1]
    lookup = {tuple(c): i for i, c in enumerate(cols.tolist())}
    neighbours = []
    for axis in range(k):
        for step in (-1, 1):
            shifted = cols.copy()
            shifted[:, axis] += step
            neighbours.append(np.array([lookup.get(tuple(c), -1) for c in shifted.tolist()], np.int64))
    return neighbours


def fill_across(cols: np.ndarray, values: np.ndarray, known: np.ndarray,
                max_sweeps: int = 1000, neighbours: list[np.ndarray] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """``values`` (ncol, nlev) at the columns of grid indices ``cols`` (ncol, k), the entries not
    ``known`` replaced, level by level, by the mean of the known values of the neighbouring
    columns (±1 along each grid axis), sweep after sweep until none is left that a known one
    reaches. Returns the values and which are now known. ``neighbours``: the columns'
    :func:`column_neighbours`, if known."""
    values, known = values.copy(), known.copy()
    if neighbours is None:
        neighbours = column_neighbours(cols)
    for _ in range(max_sweeps):
        todo = ~known
        if not todo.any():
            break
        total, count = np.zeros(values.shape), np.zeros(values.shape)
        for nb in neighbours:
            has = nb >= 0
            src = np.where(has[:, None], known[np.maximum(nb, 0)], False)
            total += np.where(src, values[np.maximum(nb, 0)], 0.0)
            count += src
        new = todo & (count > 0)
        if not new.any():
            break
        values[new] = total[new] / count[new]
        known = known | new
    return values, known


class _Columns:
    """What the points of a :meth:`ColumnPressure.values` call fix: each point's lower column
    corner ``cell``, fractions ``frac`` and ``level``; the columns ``cols`` around the points of all
    ranks, their levels ``nlev`` and level points (``pts``, with the owned cells holding them:
    ``point``, ``cells``); the columns' :func:`column_neighbours`; and the interpolation stencil
    of each point (per corner of its column cell: the column's row and the weight across)."""

    def __init__(self, key: bytes, cell, frac, level, cols, nlev, located, neighbours, corners) -> None:
        self.key, self.cell, self.frac, self.level, self.cols, self.nlev = key, cell, frac, level, cols, nlev
        self.pts, self.point, self.cells = located
        self.neighbours, self.corners = neighbours, corners


class ColumnPressure:
    """P of the module docstring on ``mesh`` for gravity ``gravity`` (dim,) [m/s²], columns
    ``spacing`` [m] apart."""

    def __init__(self, mesh, gravity: np.ndarray, spacing: float) -> None:
        self.mesh, self.comm, self.dim = mesh, mesh.comm, mesh.topology.dim
        self.g = float(np.linalg.norm(np.asarray(gravity, float)[: self.dim]))
        self.up, self.across = vertical_frame(gravity, self.dim)
        x = np.zeros((len(mesh.geometry.x), 3))
        x[:, : self.dim] = mesh.geometry.x[:, : self.dim]
        lo = (x @ self.across.T).min(axis=0, initial=np.inf)
        hi = np.append((x @ self.across.T).max(axis=0, initial=-np.inf), (x @ self.up).max(initial=-np.inf))
        self.comm.Allreduce(MPI.IN_PLACE, lo, op=MPI.MIN)
        self.comm.Allreduce(MPI.IN_PLACE, hi, op=MPI.MAX)
        self.lower, self.upper = lo, hi[:-1]                      # across gravity [m]
        self.top = float(hi[-1])                                  # [m] along up
        extent = self.upper - self.lower
        self.step = extent / np.maximum(np.ceil(extent / spacing), 1.0)   # [m] column spacing per axis
        self.ds = 0.5 * float(spacing)                            # [m] level spacing
        self.eps = 1e-9 * max(float(extent.max()), 1.0)
        self.tree = geometry.BoundingBoxTree(mesh, self.dim)
        self.n_owned = mesh.topology.index_map(self.dim).size_local
        self.p1 = P1Values.of(mesh)
        self._located = None                                      # (key, point, cell) of the last column set
        self._geometry = []                                       # the _Columns of the last calls' points

    def _columns(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Grid indices (n, k) of each point's lower column corner, its fractions (n, k) and
        its level (n,) (fractional, from the top)."""
        rel = (points @ self.across.T - self.lower) / self.step
        cell = np.clip(np.floor(rel), 0, np.round((self.upper - self.lower) / self.step) - 1).astype(np.int64)
        frac = np.clip(rel - cell, 0.0, 1.0)
        level = np.maximum((self.top - self.eps - points @ self.up) / self.ds, 0.0)
        return cell, frac, level

    def _needed(self, cell: np.ndarray, level: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The columns (m, k) around the points, on every rank, and the deepest level each needs."""
        k = cell.shape[1]
        corners = np.array(np.meshgrid(*[[0, 1]] * k, indexing="ij")).reshape(k, -1).T   # (2^k, k)
        idx = (cell[:, None, :] + corners[None, :, :]).reshape(-1, k)
        deep = np.repeat(np.ceil(level).astype(np.int64) + 1, len(corners))
        every = self.comm.allgather(np.column_stack([idx, deep]))
        both = np.concatenate(every) if every else np.zeros((0, k + 1), np.int64)
        if both.size == 0:
            return np.zeros((0, k), np.int64), np.zeros(0, np.int64)
        cols, inv = np.unique(both[:, :k], axis=0, return_inverse=True)
        deepest = np.zeros(len(cols), np.int64)
        np.maximum.at(deepest, inv.ravel(), both[:, k])
        return cols, deepest

    def _locate(self, cols: np.ndarray, nlev: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The level points of the columns (m × nlev, 3) and the owned cells that hold them
        (point index, local cell), reused while the columns stay the same."""
        key = (cols.tobytes(), nlev)
        if self._located is not None and self._located[0] == key:
            return self._located[1:]
        across = self.lower + cols * self.step
        across = np.clip(across, self.lower + self.eps, self.upper - self.eps)
        heights = self.top - self.eps - self.ds * np.arange(nlev)
        pts = (across @ self.across)[:, None, :] + heights[None, :, None] * self.up[None, None, :]
        pts = pts.reshape(-1, 3)
        cands = geometry.compute_collisions(self.tree, pts)
        found = geometry.compute_colliding_cells(self.mesh, cands, pts)
        point = np.repeat(np.arange(len(pts)), np.diff(found.offsets))
        cells = found.array
        owned = cells < self.n_owned
        point, cells = point[owned], cells[owned]
        point, first = np.unique(point, return_index=True)       # one owned cell per point
        cells = cells[first].astype(np.int32)
        self._located = (key, pts, point, cells)
        return pts, point, cells

    #: how many sets of points keep their columns (:meth:`_columns_of`): a hidden surface's probe
    #: points and the few nodes whose probe left the mesh
    KEPT_POINT_SETS = 2

    def _columns_of(self, points: np.ndarray) -> _Columns:
        """The columns and stencils of ``points`` (n, 3) (this rank's), kept for the last
        :data:`KEPT_POINT_SETS` sets of points: a coupled step asks for the same points once per
        implicit pass. Collective (the columns are every rank's)."""
        key = points.tobytes()
        at = next((i for i, g in enumerate(self._geometry) if g.key == key), -1)
        both = np.array([at, -at])
        self.comm.Allreduce(MPI.IN_PLACE, both, op=MPI.MAX)
        at = at if both[0] == -both[1] else -1                   # the same kept set on every rank
        if at >= 0:
            return self._geometry[at]
        cell, frac, level_of_point = self._columns(points)
        cols, deepest = self._needed(cell, level_of_point)
        nlev = max(int(deepest.max()) + 1, 2) if len(cols) else 0
        located = self._locate(cols, nlev) if len(cols) else (None, None, None)
        neighbours = column_neighbours(cols) if len(cols) else []
        corners = self._stencil(cols, cell, frac) if len(cols) else []
        g = _Columns(key, cell, frac, level_of_point, cols, nlev, located, neighbours, corners)
        self._geometry = ([g] + self._geometry)[: self.KEPT_POINT_SETS]
        return g

    def values(self, points: np.ndarray, pressure, density, level=None, with_density: bool = False):
        """P [Pa] at ``points`` (n, 3) (each rank its own; collective): ``pressure`` the
        fluid's P1 pressure, ``density`` a Function [kg/m³] or a number; ``level`` a level set
        of the solids (a Function, < 0 inside them) or None: the columns' points inside solids
        are left out of the interpolation across columns where a column in the fluid is
        there (next to a wall the columns through the wall carry the wall's contents, not the
        water's weight). ``with_density``: also the density [kg/m³] at the points, interpolated
        alike."""
        points = np.ascontiguousarray(np.asarray(points, float).reshape(-1, 3))
        g = self._columns_of(points)
        cols, nlev = g.cols, g.nlev
        if len(cols) == 0:
            return (np.zeros(len(points)), np.zeros(len(points))) if with_density else np.zeros(len(points))
        pts, point, cells = g.pts, g.point, g.cells
        functions = ((pressure,) if np.isscalar(density) else (pressure, density)) + (() if level is None else (level,))
        local = np.zeros((len(functions) + 1, len(pts)))
        local[:-1, point] = self.p1.values(functions, pts[point], cells)
        local[-1, point] = 1.0
        total = local
        self.comm.Allreduce(MPI.IN_PLACE, total, op=MPI.SUM)
        hits = total[-1]
        found = (hits > 0).reshape(len(cols), nlev)
        with np.errstate(invalid="ignore", divide="ignore"):
            avg = total[:-1] / np.maximum(hits, 1.0)
        p = avg[0].reshape(len(cols), nlev)
        rho = np.full_like(p, float(density)) if np.isscalar(density) else avg[1].reshape(len(cols), nlev)
        wet = found if level is None else found & (avg[-1].reshape(len(cols), nlev) >= 0)
        weight = column_integral(np.nan_to_num(rho), found, self.g, self.ds)
        first = np.argmax(found, axis=1)                          # the top of each column in the mesh
        valid = found.any(axis=1)
        rows = np.arange(len(cols))
        column = p[rows, first][:, None] + weight - weight[rows, first][:, None]   # P along each column
        if level is not None:
            # below a solid a column's weight counts the solid's contents: take those levels
            # from the columns beside it that reach them through fluid only
            clean = np.cumprod(~found | wet, axis=1).astype(bool) & found
            column, clean = fill_across(cols, column, clean, neighbours=g.neighbours)
            rho = np.where(clean | ~found, rho, np.nan)
            wet = wet & clean
        value = self._interpolate(g, valid, wet, column)
        if not with_density:
            return value
        return value, self._interpolate(g, valid, wet, rho)

    @staticmethod
    def _stencil(cols: np.ndarray, cell: np.ndarray, frac: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
        """Per corner of each point's column cell: the row in ``cols`` of that column and its
        (bi)linear weight across."""
        k = cell.shape[1]
        lookup = {tuple(c): i for i, c in enumerate(cols.tolist())}
        corners = np.array(np.meshgrid(*[[0, 1]] * k, indexing="ij")).reshape(k, -1).T
        out = []
        for corner in corners:
            idx = np.array([lookup[tuple(c)] for c in (cell + corner).tolist()], np.int64)
            w = np.prod(np.where(corner[None, :] == 1, frac, 1.0 - frac), axis=1)
            out.append((idx, w))
        return out

    def _interpolate(self, g: _Columns, valid, wet, column) -> np.ndarray:
        """Linear in the level, (bi)linear across the columns around each point (``g``); columns
        outside the mesh left out, and columns in a solid at the point's level where another
        is in the fluid (``wet`` per column and level)."""
        n, level = len(g.cell), g.level
        lev0 = np.minimum(np.floor(level).astype(np.int64), column.shape[1] - 2)
        t = np.clip(level - lev0, 0.0, 1.0)
        nearest = np.where(t < 0.5, lev0, lev0 + 1)
        stencil = []
        for idx, w in g.corners:
            v = (1 - t) * column[idx, lev0] + t * column[idx, lev0 + 1]
            ok = valid[idx] & np.isfinite(v)
            stencil.append((w, v, ok, ok & wet[idx, nearest]))
        any_wet = np.zeros(n, bool)
        for w, _, _, ok_wet in stencil:
            any_wet |= ok_wet & (w > 0)
        acc, wsum = np.zeros(n), np.zeros(n)
        for w, v, ok, ok_wet in stencil:
            use = np.where(any_wet, ok_wet, ok)
            acc += np.where(use, w * v, 0.0)
            wsum += np.where(use, w, 0.0)
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(wsum > 0, acc / np.maximum(wsum, 1e-300), np.nan)
