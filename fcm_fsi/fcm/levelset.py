"""Signed distance (level set) of the structure on mesh nodes (SPEC §1, issue #5 item 1).

The structure is a union of primitives (fcm/shapes.py) — spheres, boxes, finite capped
cylinders and closed triangle surfaces from CAD files (kind MESH: their exact signed distance
sampled on a grid at set-up, interpolated trilinearly here, :func:`_grid_distance`) — each
either static (world frame) or carried by a rigid DEM body. Its level set is

    φ(x) = min_i d_i(x),   clipped to [−cutoff, +cutoff],

with d_i the exact signed distance to primitive i, **positive outside the structure (in
the fluid), negative inside**. Only a band |φ| < cutoff around the surface is needed by
the finite-cover cut, so points farther than ``cutoff`` from every primitive get exactly
+cutoff and points deeper than ``cutoff`` get exactly −cutoff.

2D meshes pass points with z = 0 and 3D primitives: a disc is a z-cylinder, a rectangle a
box. Their extent along z must be at least 2·cutoff, so that the depth below the end caps
never undercuts the in-plane depth within the band.

Poses: body ``b`` has centre of mass ``body_pos[b]`` and unit quaternion ``body_quat[b]``
= (w, x, y, z), body → world, ``x_w = body_pos + R(q) x_b`` — the convention of
``fcm_fsi/dem/state.py`` (the kernel rotates with :func:`fcm_fsi.geometry.rotate`, the
reference with :func:`fcm_fsi.geometry.quat_to_matrix_np`). A primitive's frame sits at
``offset`` in its body frame, rotated by ``rot`` (shape frame → body frame).

Search: every call (i) moves the primitives to the world, O(shapes); (ii) lists each
primitive in the cells of a uniform grid that the box around its *reach sphere* (bounding
radius + cutoff) overlaps — cell edge = median reach, so a typical primitive sits in ≤ 27 cells and
the grid is capped at O(shapes) cells; (iii) each point reads the one cell it lies in and
evaluates only the listed primitives whose reach sphere contains it. Any primitive that
can bring φ below +cutoff is in that list, and a point inside a primitive is always inside
its reach, so the sign is exact everywhere. Cost O(points + shapes) for bounded primitive
sizes; points are processed in parallel, each independently, so results do not depend on
the thread count.

measured (numba 0.56, 2 cores shared with other jobs, load ≈ 2.5, warm): 1e6 random points
in a 1 m cube against 1000 boxes of edge 2–6 cm on 1000 randomly posed bodies, cutoff 3 cm
(half the points in the band): 0.09–0.12 s per ``evaluate`` on 1 thread, 0.17–0.18 s on
2 threads (the second core was busy); 6.6 candidates per point, 27 cells per box.
"""
from __future__ import annotations

import numba
import numpy as np

from ..geometry import rotate
from .shapes import (  # noqa: F401  # noqa: F401 (BOX … grid_margin: re-exported)
    BOX,
    CYLINDER,
    KIND_NAMES,
    MESH,
    NO_SHAPE,
    SPHERE,
    STATIC,
    WALL,
    Shapes,
    bounding_radius,
    grid_margin,
)

#: |n·a| [-] from which a box axis a facing a plane of normal n takes the whole narrowing of
#: :func:`narrowed_at_walls` (below it the share falls as (|n·a|/NARROW_TILT)²: 0.12 at 5°)
NARROW_TILT = 0.25

# --------------------------------------------------------------------------- kernels

@numba.njit(cache=True)
def _world_frames(body, offset, rot, body_pos, body_quat):
    """World centre (ns, 3) [m] and shape → world rotation (ns, 3, 3) of every primitive."""
    ns = body.shape[0]
    centre = offset.copy()
    R = rot.copy()
    for s in range(ns):
        b = body[s]
        if b == STATIC:
            continue
        q0, q1, q2, q3 = body_quat[b, 0], body_quat[b, 1], body_quat[b, 2], body_quat[b, 3]
        rx, ry, rz = rotate(q0, q1, q2, q3, offset[s, 0], offset[s, 1], offset[s, 2])
        centre[s, 0] = body_pos[b, 0] + rx
        centre[s, 1] = body_pos[b, 1] + ry
        centre[s, 2] = body_pos[b, 2] + rz
        for c in range(3):
            R[s, 0, c], R[s, 1, c], R[s, 2, c] = rotate(q0, q1, q2, q3, rot[s, 0, c], rot[s, 1, c], rot[s, 2, c])
    return centre, R


@numba.njit(cache=True)
def _grid(centre, reach, cell, max_cells):
    """Grid over the reach boxes of all primitives: lower corner, cells per axis, cell edge [m].
    The edge grows until the grid has at most ``max_cells`` cells."""
    lo = np.empty(3)
    span = np.empty(3)
    for d in range(3):
        lo[d] = (centre[:, d] - reach).min()
        span[d] = (centre[:, d] + reach).max() - lo[d]
    dims = np.empty(3, np.int64)
    while True:
        ncell = 1.0
        for d in range(3):
            ncell *= np.floor(span[d] / cell) + 1.0
        if ncell <= max_cells:
            break
        cell *= max(1.26, 0.99 * (ncell / max_cells) ** (1.0 / 3.0))
    for d in range(3):
        dims[d] = int(span[d] / cell) + 1
    return lo, dims, cell


@numba.njit(cache=True)
def _cell_range(c, r, lo, cell, n):
    """Cells [first, last] along one axis touched by the interval [c − r, c + r]."""
    first = max(int(np.floor((c - r - lo) / cell)), 0)
    last = min(int(np.floor((c + r - lo) / cell)), n - 1)
    return first, last


@numba.njit(cache=True)
def _bin_shapes(centre, reach, lo, dims, cell):
    """CSR lists cell → primitives whose reach box touches the cell, in primitive order."""
    ns = centre.shape[0]
    ncell = dims[0] * dims[1] * dims[2]
    start = np.zeros(ncell + 1, np.int64)
    for sweep in range(2):          # counting sort: sweep 0 counts the listings per cell, sweep 1 files them
        fill = start[:-1].copy()
        items = np.empty(start[ncell] if sweep == 1 else 0, np.int64)
        for s in range(ns):
            x0, x1 = _cell_range(centre[s, 0], reach[s], lo[0], cell, dims[0])
            y0, y1 = _cell_range(centre[s, 1], reach[s], lo[1], cell, dims[1])
            z0, z1 = _cell_range(centre[s, 2], reach[s], lo[2], cell, dims[2])
            for ix in range(x0, x1 + 1):
                for iy in range(y0, y1 + 1):
                    for iz in range(z0, z1 + 1):
                        c = (ix * dims[1] + iy) * dims[2] + iz
                        if sweep == 0:
                            start[c + 1] += 1
                        else:
                            items[fill[c]] = s
                            fill[c] += 1
        if sweep == 0:
            for c in range(ncell):
                start[c + 1] += start[c]
    return start, items


@numba.njit(cache=True, inline="always")
def _local_distance(kind, hx, hy, hz, px, py, pz):
    """Exact signed distance [m] of the shape-frame point p to a centred primitive."""
    if kind == SPHERE:
        return np.sqrt(px * px + py * py + pz * pz) - hx
    if kind == BOX:
        qx, qy, qz = abs(px) - hx, abs(py) - hy, abs(pz) - hz
        ox, oy, oz = max(qx, 0.0), max(qy, 0.0), max(qz, 0.0)
        return np.sqrt(ox * ox + oy * oy + oz * oz) + min(max(qx, max(qy, qz)), 0.0)
    qr, qz = np.sqrt(px * px + py * py) - hx, abs(pz) - hy          # cylinder: radial, axial
    orr, oz = max(qr, 0.0), max(qz, 0.0)
    return np.sqrt(orr * orr + oz * oz) + min(max(qr, qz), 0.0)


@numba.njit(cache=True, inline="always")
def _grid_distance(values, start, nx, ny, nz, hx, hy, hz, px, py, pz):
    """A mesh's signed distance [m] at the shape-frame point p: trilinear interpolation of its
    grid (nodes nx × ny × nz over the box |p_k| ≤ h_k, values from ``start``) at p clamped to
    the box, plus the distance from p to the box. Every boundary node lies at least the grid's
    margin outside the surface, so outside the box the value is ≥ that margin (the level set
    is then clipped to +cutoff), and it is continuous across the box's faces."""
    cx, cy, cz = min(max(px, -hx), hx), min(max(py, -hy), hy), min(max(pz, -hz), hz)
    outside = np.sqrt((px - cx) ** 2 + (py - cy) ** 2 + (pz - cz) ** 2)
    tx, ty, tz = (cx + hx) / (2.0 * hx) * (nx - 1), (cy + hy) / (2.0 * hy) * (ny - 1), (cz + hz) / (2.0 * hz) * (nz - 1)
    i, j, k = min(int(tx), nx - 2), min(int(ty), ny - 2), min(int(tz), nz - 2)
    fx, fy, fz = tx - i, ty - j, tz - k
    value = 0.0
    for a in range(2):
        wa = fx if a else 1.0 - fx
        for b in range(2):
            wb = fy if b else 1.0 - fy
            base = start + ((i + a) * ny + (j + b)) * nz + k
            value += wa * wb * ((1.0 - fz) * values[base] + fz * values[base + 1])
    return value + outside


@numba.njit(cache=True, inline="always")
def _primitive_distance(kind, half, grid, values, R, s, dx, dy, dz):
    """Signed distance [m] to primitive ``s`` of the point at (dx, dy, dz) from its world
    centre: the shape-frame point Rᵀ (x − c), then :func:`_local_distance` or, for a mesh,
    :func:`_grid_distance`."""
    px = R[s, 0, 0] * dx + R[s, 1, 0] * dy + R[s, 2, 0] * dz
    py = R[s, 0, 1] * dx + R[s, 1, 1] * dy + R[s, 2, 1] * dz
    pz = R[s, 0, 2] * dx + R[s, 1, 2] * dy + R[s, 2, 2] * dz
    if kind[s] == MESH:
        return _grid_distance(values, grid[s, 0], grid[s, 1], grid[s, 2], grid[s, 3],
                              half[s, 0], half[s, 1], half[s, 2], px, py, pz)
    return _local_distance(kind[s], half[s, 0], half[s, 1], half[s, 2], px, py, pz)


@numba.njit(cache=True, inline="always")
def _point_cell(x, lo, dims, cell):
    """Flat index of the grid cell holding point x, −1 outside the grid."""
    c = 0
    for d in range(3):
        t = (x[d] - lo[d]) / cell
        if not (0.0 <= t < dims[d]):
            return -1
        c = c * dims[d] + int(t)
    return c


@numba.njit(cache=True, parallel=True)
def _evaluate(x, kind, body, half, grid, values, radius, centre, R, cutoff, lo, dims, cell, start, items,
              planes, gap, phi, owner, fill_other, fill_weight, second, margin):
    """Clipped union distance φ and owner body at every point; returns the number of
    (point, primitive) candidates read from the bins (the search cost). ``second`` and
    ``margin`` get the nearest other owner (bodies and static shapes, not the walls) and how
    much farther it is, d₂ − d₁ ≥ 0 (``cutoff`` where there is none).

    With ``gap`` > 0 the fluid between two different owners (bodies, the static shapes, or
    the walls ``planes`` (np, 6) = point, unit normal into the fluid) is filled where the two
    nearest are less than ``gap`` apart: φ = min(φ, (d₁ + d₂ − gap)/2), d₁ ≤ d₂ the
    distances to the nearest two owners (all walls count as one, so tank corners are not
    filled); the fill belongs to the nearer non-wall owner (its load goes there).

    Where the fill attains φ (inside it and in the fluid next to it) its wall velocity mixes
    the nearest three owners' (a wall's is 0), ū = Σ_k w_k ū_k (:func:`_fill_weights`):
    ``fill_other`` (n, 2) gets the two owners besides ``owner`` (WALL for the walls; column
    0 the other of the nearest two) and ``fill_weight`` (n, 2) their weights w, the owner
    keeping 1 − Σ w. So ū is continuous in space — each surface's own velocity on it (a
    floor's 0 under a block), the owner's where the fill ends, the mean where two are equally
    near, also where a block lands beside a fixed stopper on the floor (three owners) — and
    hence in time as gaps open and close. A fill velocity that jumps from one owner's to
    another's as a node changes side gave pressure impulses on the block of block_overturn
    (docs/design-notes.md)."""
    tests = 0
    for i in numba.prange(x.shape[0]):
        best = cutoff
        arg = -1
        d1, o1 = cutoff, NO_SHAPE           # the nearest three distinct owners (gap fill)
        d2, o2 = cutoff, NO_SHAPE
        d3, o3 = cutoff, NO_SHAPE
        c = _point_cell(x[i], lo, dims, cell)
        if c >= 0:
            for k in range(start[c], start[c + 1]):
                s = items[k]
                dx = x[i, 0] - centre[s, 0]
                dy = x[i, 1] - centre[s, 1]
                dz = x[i, 2] - centre[s, 2]
                reach = radius[s] + cutoff
                if dx * dx + dy * dy + dz * dz >= reach * reach:
                    continue
                d = _primitive_distance(kind, half, grid, values, R, s, dx, dy, dz)
                if d < best:
                    best = d
                    arg = s
                d1, o1, d2, o2, d3, o3 = _three_nearest(d, body[s], d1, o1, d2, o2, d3, o3)
            tests += start[c + 1] - start[c]
        phi[i] = max(best, -cutoff)
        owner[i] = NO_SHAPE if arg < 0 else body[arg]
        second[i] = o2
        margin[i] = d2 - d1 if o2 != NO_SHAPE else cutoff
        if gap > 0.0 and arg >= 0:
            for w in range(planes.shape[0]):
                d = ((x[i, 0] - planes[w, 0]) * planes[w, 3] + (x[i, 1] - planes[w, 1]) * planes[w, 4]
                     + (x[i, 2] - planes[w, 2]) * planes[w, 5])
                d1, o1, d2, o2, d3, o3 = _three_nearest(d, WALL, d1, o1, d2, o2, d3, o3)
            fill = 0.5 * (d1 + d2 - gap)
            if o2 != NO_SHAPE and fill < phi[i]:
                phi[i] = max(fill, -cutoff)
                w1, w2, w3 = _fill_weights(d1, d2, d3 if o3 != NO_SHAPE else cutoff + gap, gap)
                if o1 == WALL:
                    owner[i] = o2
                    fill_other[i, 0], fill_weight[i, 0] = WALL, w1
                else:
                    owner[i] = o1
                    fill_other[i, 0], fill_weight[i, 0] = o2, w2
                fill_other[i, 1], fill_weight[i, 1] = o3, w3
    return tests


@numba.njit(cache=True, inline="always")
def _fill_weights(d1, d2, d3, gap):
    """Weights (w₁, w₂, w₃), Σ = 1, of the nearest three owners' velocities in the gap fill at
    distances d₁ ≤ d₂ ≤ d₃ [m]: w_k ∝ t_k/d_k, the inverse distance (a squeezed layer's
    linear profile between two surfaces) times the taper t_k = max(0, 1 − (d_k − d₁)/gap),
    which ends an owner's share where the fill ends (d_k − d₁ = gap); on or inside the
    nearest surface (d₁ ≤ 0) its own velocity."""
    if d1 <= 0.0:
        return 1.0, 0.0, 0.0
    p1 = 1.0 / d1
    p2 = max(1.0 - (d2 - d1) / gap, 0.0) / d2
    p3 = max(1.0 - (d3 - d1) / gap, 0.0) / d3
    total = p1 + p2 + p3
    return p1 / total, p2 / total, p3 / total


@numba.njit(cache=True, inline="always")
def _three_nearest(d, o, d1, o1, d2, o2, d3, o3):
    """Update the nearest three distinct owners (d₁, o₁) ≤ (d₂, o₂) ≤ (d₃, o₃) with candidate
    distance d of owner o (an owner's distance is the least of its candidates')."""
    if o == o1:
        d1 = min(d, d1)
    elif o == o2:
        d2 = min(d, d2)
    elif o == o3:
        d3 = min(d, d3)
    elif d < d3:
        d3, o3 = d, o
    if d3 < d2:
        d2, o2, d3, o3 = d3, o3, d2, o2
    if d2 < d1:
        d1, o1, d2, o2 = d2, o2, d1, o1
    return d1, o1, d2, o2, d3, o3


# --------------------------------------------------------------------------- interface

class StructureLevelSet:
    """Level set of a union of primitives, re-evaluated at every fluid step for new body poses.

    ``pair_tests`` and ``bin_entries`` hold the search cost of the last :meth:`evaluate`:
    (point, primitive) candidates read from the bins, and (primitive, cell) listings.
    """

    def __init__(self, shapes: Shapes, nbodies: int, cutoff: float, gap: float = 0.0, walls=None,
                 true_half: np.ndarray | None = None):
        """``gap`` [m] and ``walls`` (np, 6) (a point and the normal into the fluid per plane):
        fluid gaps narrower than ``gap`` between two bodies, or a body and a wall, count as
        solid (see :func:`_evaluate`); 0 ≤ gap < cutoff. ``true_half`` (nshape, 3) [m]: the
        blocks' own half extents where ``shapes`` widens boxes (``coupling.min_thickness``);
        each pose then narrows the widening where a block nears a wall
        (:func:`narrowed_at_walls`)."""
        if not cutoff > 0:
            raise ValueError(f"cutoff = {cutoff}: must be > 0 [m]")
        if not 0.0 <= gap < cutoff:
            raise ValueError(f"gap = {gap}: allowed 0 ≤ gap < cutoff = {cutoff} [m]")
        self.gap = float(gap)
        self.walls = _unit_planes(walls)
        if len(shapes) and shapes.body.max() >= nbodies:
            raise ValueError(f"Shapes.body refers to body {shapes.body.max()}, but nbodies = {nbodies}")
        short = np.flatnonzero(grid_margin(shapes) < cutoff)
        if short.size:
            raise ValueError(f"shape {short[0]} (a surface mesh): its distance grid reaches "
                             f"{grid_margin(shapes)[short[0]]:.4g} m beyond the surface, less than the cutoff "
                             f"{cutoff:.4g} m (grow the grid's margin)")
        self.shapes = shapes
        self.true_half = None
        if true_half is not None:
            true_half = np.asarray(true_half, np.float64).reshape(len(shapes), 3)
            if np.any(true_half > shapes.half) or np.any(true_half[shapes.kind != BOX] != shapes.half[shapes.kind != BOX]):
                raise ValueError("true_half: must not exceed the shapes' half extents, and equal them but for boxes")
            if np.any(true_half != shapes.half):
                self.true_half = true_half
        self.nbodies = int(nbodies)
        #: (nbodies,) bool: bodies the level set leaves out (``coupling.unresolved_cells``; set by the owner)
        self.unseen = np.zeros(self.nbodies, bool)
        self.cutoff = float(cutoff)
        self._radius = bounding_radius(shapes)
        self._reach = self._radius + self.cutoff
        self._cell = float(np.median(self._reach)) if len(shapes) else 1.0
        self._max_cells = 64 * len(shapes) + 4096
        self.pair_tests = 0
        self.bin_entries = 0
        self.fill_other, self.fill_weight = np.zeros((0, 2), np.int64), np.zeros((0, 2))
        self.second_owner, self.owner_margin = np.zeros(0, np.int64), np.zeros(0)

    def evaluate(self, x: np.ndarray, body_pos: np.ndarray, body_quat: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """φ and owner at the points ``x`` (n, 3) [m] (2D meshes pass z = 0).

        ``body_pos`` (nbodies, 3) [m] and unit ``body_quat`` (nbodies, 4) = (w, x, y, z),
        body → world. Returns φ (n,) [m], > 0 in the fluid, < 0 inside the structure, clipped
        to [−cutoff, cutoff], and owner (n,) int64: the body of the primitive attaining the
        minimum (−1 static), −2 where no primitive is closer than the cutoff. With a gap fill,
        ``self.fill_other`` (n, 2) and ``self.fill_weight`` (n, 2) give the fill's velocity blend
        afterwards (see :func:`_evaluate`; NO_SHAPE and 0 where there is no fill; WALL in
        column 0 marks the filled points between a body and a wall).
        ``self.second_owner`` (n,) and ``self.owner_margin`` (n,) [m] are the nearest other
        owner and how much farther its shapes are (for ``coupling.load_split: shared``).
        """
        x = np.ascontiguousarray(x, np.float64)
        body_pos = np.ascontiguousarray(body_pos, np.float64).reshape(self.nbodies, 3)
        body_quat = np.ascontiguousarray(body_quat, np.float64).reshape(self.nbodies, 4)
        if x.ndim != 2 or x.shape[1] != 3:
            raise ValueError(f"points x: shape {x.shape}, expected (n, 3)")
        phi = np.full(x.shape[0], self.cutoff)
        owner = np.full(x.shape[0], NO_SHAPE, np.int64)
        self.fill_other = np.full((x.shape[0], 2), NO_SHAPE, np.int64)
        self.fill_weight = np.zeros((x.shape[0], 2))
        self.second_owner = np.full(x.shape[0], NO_SHAPE, np.int64)
        self.owner_margin = np.full(x.shape[0], self.cutoff)
        self.pair_tests = self.bin_entries = 0
        if not len(self.shapes):
            return phi, owner
        s = self.shapes
        centre, R = _world_frames(s.body, s.offset, s.rot, body_pos, body_quat)
        half = s.half
        if self.true_half is not None and len(self.walls):
            half = narrowed_at_walls(s.half, self.true_half, centre, R, self.walls)
        kind, body, grid, radius, reach = s.kind, s.body, s.grid, self._radius, self._reach
        if self.unseen.any():
            keep = np.flatnonzero((s.body < 0) | ~self.unseen[np.maximum(s.body, 0)])
            if not keep.size:
                return phi, owner
            kind, body, grid, radius, reach = kind[keep], body[keep], grid[keep], radius[keep], reach[keep]
            half, centre, R = half[keep], centre[keep], R[keep]
        lo, dims, cell = _grid(centre, reach, self._cell, self._max_cells)
        start, items = _bin_shapes(centre, reach, lo, dims, cell)
        self.pair_tests = _evaluate(x, kind, body, half, grid, s.values, radius, centre, R, self.cutoff,
                                    lo, dims, cell, start, items, self.walls, self.gap, phi, owner,
                                    self.fill_other, self.fill_weight, self.second_owner, self.owner_margin)
        self.bin_entries = items.shape[0]
        return phi, owner


def narrowed_at_walls(half: np.ndarray, true_half: np.ndarray, centre: np.ndarray, R: np.ndarray,
                      planes: np.ndarray, tilt: float = NARROW_TILT) -> np.ndarray:
    """Box half extents (nshape, 3) [m] with each box's widening (``half`` − ``true_half``)
    narrowed where its true box nears a plane, so that the widened box keeps at least half the
    true box's distance D from it: a widened block's fluid shape must not meet a tank wall
    while the block itself is still off it (the fluid between them is squeezed out through a
    closing wedge at speeds without bound, and pushes the block through the wall).

    ``centre`` (nshape, 3) and ``R`` (nshape, 3, 3) are the boxes' world centres and axes
    (columns), ``planes`` (np, 6) a point and the unit normal into the fluid. For plane w
    the widening reaches Δ_w = Σ_k m_k |n_w·a_k| towards it (m = half − true_half, a_k the
    box axes); where Δ_w > D_w/2 the axes facing it are scaled by α_w = max(D_w, 0)/(2Δ_w),
    fully for |n_w·a_k| ≥ ``tilt``, by a share (|n_w·a_k|/tilt)² for axes nearly parallel to
    the plane (so a block standing or leaning on the floor keeps its widening across the
    floor's normal, and the narrowing is continuous in the pose; such an axis may leave
    ≤ 0.385 m_k·tilt of the widening past D_w/2). Each axis keeps the least factor over the
    planes."""
    boxes = np.flatnonzero(np.any(half > true_half, axis=1))
    if not boxes.size or not len(planes):
        return half
    m = (half - true_half)[boxes]                                            # (nb, 3)
    n, p = planes[:, 3:], planes[:, :3]                                      # (np, 3)
    proj = np.abs(np.einsum("wd,bdk->bwk", n, R[boxes]))                     # |n_w · a_k|, (nb, np, 3)
    distance = ((centre[boxes, None, :] - p[None]) * n[None]).sum(axis=2) - (proj * true_half[boxes, None, :]).sum(axis=2)
    reach = (proj * m[:, None, :]).sum(axis=2)                               # Δ_w
    with np.errstate(divide="ignore", invalid="ignore"):
        alpha = np.where(reach > 0.5 * distance, np.maximum(distance, 0.0) / (2.0 * reach), 1.0)
    factor = 1.0 - (1.0 - np.clip(alpha, 0.0, 1.0))[:, :, None] * np.minimum(proj / tilt, 1.0) ** 2
    out = half.copy()
    out[boxes] = true_half[boxes] + m * factor.min(axis=1)
    return out


class FaceDistance:
    """Distance [m] from a point to the nearest face of the primitives at fixed body poses:
    outside them the distance to their union, inside one its depth in that primitive (so the
    faces between touching primitives count too). Called point by point, e.g. by gmsh's mesh
    size callback (``mesh.structure_band``); O(primitives) per call."""

    def __init__(self, shapes: Shapes, body_pos: np.ndarray, body_quat: np.ndarray):
        nb = len(np.asarray(body_pos).reshape(-1, 3))
        self.kind, self.half, self.grid, self.values = shapes.kind, shapes.half, shapes.grid, shapes.values
        self.centre, self.R = _world_frames(shapes.body, shapes.offset, shapes.rot,
                                            np.ascontiguousarray(body_pos, np.float64).reshape(nb, 3),
                                            np.ascontiguousarray(body_quat, np.float64).reshape(nb, 4))

    def __call__(self, x: float, y: float, z: float) -> float:
        return _face_distance(float(x), float(y), float(z), self.kind, self.half, self.grid, self.values,
                              self.centre, self.R)


@numba.njit(cache=True)
def _face_distance(x, y, z, kind, half, grid, values, centre, R):
    """|min over primitives of the signed distance| at (x, y, z); inf without primitives."""
    best = np.inf
    for s in range(kind.shape[0]):
        best = min(best, _primitive_distance(kind, half, grid, values, R, s,
                                             x - centre[s, 0], y - centre[s, 1], z - centre[s, 2]))
    return abs(best)


def _unit_planes(walls) -> np.ndarray:
    """Planes (np, 6): point [m] and unit normal, from rows of point + any non-zero normal."""
    p = np.zeros((0, 6)) if walls is None else np.array(walls, np.float64).reshape(-1, 6)
    n = np.linalg.norm(p[:, 3:], axis=1)
    if np.any(n == 0):
        raise ValueError("walls: a plane normal is the zero vector")
    p[:, 3:] /= n[:, None]
    return np.ascontiguousarray(p)


# --------------------------------------------------------------------------- reference
