"""Bonds: every point q within the horizon δ_p of each point p (the family H_p of eq 2), found in
O(N) by binning the points into cells of edge max δ, and the pre-notch filter that removes the
bonds crossing a notch. NumPy twins: ``reference.py``."""
from __future__ import annotations

import numba
import numpy as np

from ..geometry import sort_by_cell


@numba.njit(cache=True)
def _cells(x, lo, edge, dims):
    """Cell of every point and the points sorted by cell (counting sort): (start[c], order)."""
    n = x.shape[0]
    cell = np.empty(n, np.int64)
    for i in range(n):
        c = 0
        for a in range(2, -1, -1):
            k = int((x[i, a] - lo[a]) / edge)
            k = min(max(k, 0), dims[a] - 1)
            c = c * dims[a] + k
        cell[i] = c
    return sort_by_cell(cell, dims[0] * dims[1] * dims[2])


@numba.njit(cache=True)
def _visit(x, horizon, lo, edge, dims, start, order, p, out, base):
    """Neighbours of point p in the 27 (3D; 9 in 2D) cells around its own: counted, and written to
    ``out[base:]`` when ``out`` has room. Returns the count."""
    k = np.empty(3, np.int64)
    for a in range(3):
        k[a] = min(max(int((x[p, a] - lo[a]) / edge), 0), dims[a] - 1)
    r2 = horizon[p] * horizon[p] * (1.0 + 1e-12)
    m = 0
    for dz in range(-1, 2):
        cz = k[2] + dz
        if cz < 0 or cz >= dims[2]:
            continue
        for dy in range(-1, 2):
            cy = k[1] + dy
            if cy < 0 or cy >= dims[1]:
                continue
            for dx in range(-1, 2):
                cx = k[0] + dx
                if cx < 0 or cx >= dims[0]:
                    continue
                c = (cz * dims[1] + cy) * dims[0] + cx
                for s in range(start[c], start[c + 1]):
                    q = order[s]
                    if q == p:
                        continue
                    d2 = 0.0
                    for a in range(3):
                        d2 += (x[q, a] - x[p, a]) ** 2
                    if d2 <= r2:
                        if out.shape[0] > 0:
                            out[base + m] = q
                        m += 1
    return m


@numba.njit(parallel=True, cache=True)
def bond_lists(x, horizon):
    """CSR bond lists: ``offsets`` (N+1) and ``nbr``: the points q ≠ p with |x_q − x_p| ≤ δ_p, for
    points ``x`` (N, 3) [m] and horizons ``horizon`` (N,) [m]; within a point in cell order."""
    n = x.shape[0]
    edge = horizon.max()
    lo = np.empty(3)
    dims = np.empty(3, np.int64)
    for a in range(3):
        lo[a] = x[:, a].min()
        dims[a] = max(int((x[:, a].max() - lo[a]) / edge) + 1, 1)
    start, order = _cells(x, lo, edge, dims)
    counts = np.empty(n, np.int64)
    none = np.empty(0, np.int64)
    for p in numba.prange(n):
        counts[p] = _visit(x, horizon, lo, edge, dims, start, order, p, none, 0)
    offsets = np.zeros(n + 1, np.int64)
    for p in range(n):
        offsets[p + 1] = offsets[p] + counts[p]
    nbr = np.empty(offsets[n], np.int64)
    for p in numba.prange(n):
        _visit(x, horizon, lo, edge, dims, start, order, p, nbr, offsets[p])
    return offsets, nbr


@numba.njit(cache=True)
def _orient(ax, ay, bx, by, cx, cy):
    return (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)


@numba.njit(cache=True)
def _crosses_segment(p, q, a, b):
    """The closed segments p–q and a–b (2D) meet."""
    d1 = _orient(a[0], a[1], b[0], b[1], p[0], p[1])
    d2 = _orient(a[0], a[1], b[0], b[1], q[0], q[1])
    d3 = _orient(p[0], p[1], q[0], q[1], a[0], a[1])
    d4 = _orient(p[0], p[1], q[0], q[1], b[0], b[1])
    return d1 * d2 <= 0.0 and d3 * d4 <= 0.0 and not (d1 == 0.0 and d2 == 0.0)


@numba.njit(cache=True)
def _crosses_rectangle(p, q, c, e1, e2):
    """The segment p–q meets the rectangle c + a e1 + b e2, a, b in [0, 1] (3D)."""
    nx = e1[1] * e2[2] - e1[2] * e2[1]
    ny = e1[2] * e2[0] - e1[0] * e2[2]
    nz = e1[0] * e2[1] - e1[1] * e2[0]
    d1 = (p[0] - c[0]) * nx + (p[1] - c[1]) * ny + (p[2] - c[2]) * nz
    d2 = (q[0] - c[0]) * nx + (q[1] - c[1]) * ny + (q[2] - c[2]) * nz
    if d1 * d2 > 0.0 or d1 == d2:
        return False
    t = d1 / (d1 - d2)
    a = 0.0
    b = 0.0
    for k in range(3):
        r = p[k] + t * (q[k] - p[k]) - c[k]
        a += r * e1[k]
        b += r * e2[k]
    a /= e1[0] ** 2 + e1[1] ** 2 + e1[2] ** 2
    b /= e2[0] ** 2 + e2[1] ** 2 + e2[2] ** 2
    return 0.0 <= a <= 1.0 and 0.0 <= b <= 1.0


@numba.njit(parallel=True, cache=True)
def notch_keep(x, offsets, nbr, notches):
    """Mask of the bonds that cross none of ``notches`` (K, 3, 3): 2D segments (row 0 → row 1, z = 0,
    row 2 unused, flagged by a NaN) or 3D rectangles (corner, edge 1, edge 2)."""
    n = offsets.shape[0] - 1
    keep = np.ones(nbr.shape[0], np.bool_)
    for p in numba.prange(n):
        for b in range(offsets[p], offsets[p + 1]):
            q = nbr[b]
            for k in range(notches.shape[0]):
                if np.isnan(notches[k, 2, 0]):
                    hit = _crosses_segment(x[p], x[q], notches[k, 0], notches[k, 1])
                else:
                    hit = _crosses_rectangle(x[p], x[q], notches[k, 0], notches[k, 1], notches[k, 2])
                if hit:
                    keep[b] = False
                    break
    return keep


def notch_array(notches, dim: int) -> np.ndarray:
    """The case's notches (tuples of points) as the (K, 3, 3) array of :func:`notch_keep`."""
    out = np.zeros((len(notches), 3, 3))
    for k, pts in enumerate(notches):
        p = np.zeros((len(pts), 3))
        p[:, :dim] = np.asarray(pts, float)
        if dim == 2:
            out[k, 0], out[k, 1], out[k, 2, 0] = p[0], p[1], np.nan
        else:
            out[k] = [p[0], p[1] - p[0], p[2] - p[0]]
    return out


def transpose(offsets: np.ndarray, nbr: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The dual lists (the dual horizon H'_x of eq 2): for every point i the owned bonds b whose
    neighbour is i, as CSR (``dual_offsets``, ``dual_bond``), bond ids ascending."""
    n = len(offsets) - 1
    order = np.argsort(nbr, kind="stable")
    dual_offsets = np.zeros(n + 1, np.int64)
    np.cumsum(np.bincount(nbr, minlength=n), out=dual_offsets[1:])
    return dual_offsets, order.astype(np.int64)


def compress(offsets: np.ndarray, nbr: np.ndarray, keep: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The CSR lists without the bonds where ``keep`` is False."""
    owner = np.repeat(np.arange(len(offsets) - 1), np.diff(offsets))
    new = np.zeros_like(offsets)
    np.cumsum(np.bincount(owner[keep], minlength=len(offsets) - 1), out=new[1:])
    return new, nbr[keep]


def hole_keep(x: np.ndarray, offsets: np.ndarray, nbr: np.ndarray, centre, radius: float) -> np.ndarray:
    """Mask of the bonds whose segment stays outside the open disc |y − c| < R of a hole (2D):
    the distance from c to the closest point of the segment p–q is at least R. Vectorised NumPy
    (one pass at build time)."""
    owner = np.repeat(np.arange(len(offsets) - 1), np.diff(offsets))
    c = np.asarray(centre, float)
    p, d = x[owner, :2] - c, x[nbr, :2] - x[owner, :2]
    t = np.clip(-(p * d).sum(axis=1) / (d * d).sum(axis=1), 0.0, 1.0)
    closest = p + t[:, None] * d
    return np.hypot(closest[:, 0], closest[:, 1]) >= radius
