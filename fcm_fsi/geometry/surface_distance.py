"""Signed distance to a closed triangle surface, exact at points and sampled on a regular grid.

At a point p the distance is the least distance to the triangles (closest point on a triangle,
Ericson, Real-Time Collision Detection §5.1.5) and the sign is the winding number's
w(p) = Σ Ω_t(p) / 4π, Ω_t the signed solid angle of triangle t seen from p (Van Oosterom and
Strackee, IEEE Trans. Biomed. Eng. 30 (1983) 125): w = 1 inside a closed outward surface, 0
outside, so p is inside where w > ½ — robust to the surface's creases and corners, where a
nearest-face normal is ambiguous. Negative inside, positive outside (the level set's sign).

:func:`signed_distance` is the Numba kernel (all triangles per point, points in parallel;
O(points × triangles), a set-up cost), :func:`signed_distance_reference` its NumPy twin.
:func:`distance_grid` samples it on the nodes of a regular grid over the surface's bounding box
plus a margin, the table the structure level set interpolates (fcm/levelset.py, kind MESH).
"""
from __future__ import annotations

from dataclasses import dataclass

import numba as nb
import numpy as np

from .surface import ClosedSurface


@nb.njit(cache=True)
def closest_point_triangle(px, py, pz, a, b, c):
    """Closest point of triangle (a, b, c) to p (Ericson, Real-Time Collision Detection §5.1.5)."""
    abx, aby, abz = b[0] - a[0], b[1] - a[1], b[2] - a[2]
    acx, acy, acz = c[0] - a[0], c[1] - a[1], c[2] - a[2]
    apx, apy, apz = px - a[0], py - a[1], pz - a[2]
    d1 = abx * apx + aby * apy + abz * apz
    d2 = acx * apx + acy * apy + acz * apz
    if d1 <= 0.0 and d2 <= 0.0:
        return a[0], a[1], a[2]
    bpx, bpy, bpz = px - b[0], py - b[1], pz - b[2]
    d3 = abx * bpx + aby * bpy + abz * bpz
    d4 = acx * bpx + acy * bpy + acz * bpz
    if d3 >= 0.0 and d4 <= d3:
        return b[0], b[1], b[2]
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        v = d1 / (d1 - d3)
        return a[0] + v * abx, a[1] + v * aby, a[2] + v * abz
    cpx, cpy, cpz = px - c[0], py - c[1], pz - c[2]
    d5 = abx * cpx + aby * cpy + abz * cpz
    d6 = acx * cpx + acy * cpy + acz * cpz
    if d6 >= 0.0 and d5 <= d6:
        return c[0], c[1], c[2]
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        w = d2 / (d2 - d6)
        return a[0] + w * acx, a[1] + w * acy, a[2] + w * acz
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        return b[0] + w * (c[0] - b[0]), b[1] + w * (c[1] - b[1]), b[2] + w * (c[2] - b[2])
    den = 1.0 / (va + vb + vc)
    v = vb * den
    w = vc * den
    return a[0] + abx * v + acx * w, a[1] + aby * v + acy * w, a[2] + abz * v + acz * w


@nb.njit(cache=True, inline="always")
def _solid_angle(px, py, pz, a, b, c):
    """Signed solid angle [sr] of triangle (a, b, c) seen from p: 2 atan2(det, den) with
    det = a'·(b' × c'), den = |a'||b'||c'| + (a'·b')|c'| + (b'·c')|a'| + (c'·a')|b'|, x' = x − p."""
    ax, ay, az = a[0] - px, a[1] - py, a[2] - pz
    bx, by, bz = b[0] - px, b[1] - py, b[2] - pz
    cx, cy, cz = c[0] - px, c[1] - py, c[2] - pz
    la = np.sqrt(ax * ax + ay * ay + az * az)
    lb = np.sqrt(bx * bx + by * by + bz * bz)
    lc = np.sqrt(cx * cx + cy * cy + cz * cz)
    det = ax * (by * cz - bz * cy) + ay * (bz * cx - bx * cz) + az * (bx * cy - by * cx)
    den = la * lb * lc + (ax * bx + ay * by + az * bz) * lc + (bx * cx + by * cy + bz * cz) * la \
        + (cx * ax + cy * ay + cz * az) * lb
    return 2.0 * np.arctan2(det, den)


@nb.njit(cache=True, parallel=True)
def signed_distance(points, corners):
    """Signed distance [m] of ``points`` (n, 3) [m] to the closed outward surface of triangles
    ``corners`` (nt, 3, 3) [m]: least distance to a triangle, negative where the winding number
    exceeds ½ (module docstring)."""
    out = np.empty(points.shape[0])
    for i in nb.prange(points.shape[0]):
        px, py, pz = points[i, 0], points[i, 1], points[i, 2]
        best = np.inf
        winding = 0.0
        for t in range(corners.shape[0]):
            cx, cy, cz = closest_point_triangle(px, py, pz, corners[t, 0], corners[t, 1], corners[t, 2])
            best = min(best, (px - cx) ** 2 + (py - cy) ** 2 + (pz - cz) ** 2)
            winding += _solid_angle(px, py, pz, corners[t, 0], corners[t, 1], corners[t, 2])
        d = np.sqrt(best)
        out[i] = -d if winding > 2.0 * np.pi else d
    return out


def signed_distance_reference(points: np.ndarray, corners: np.ndarray) -> np.ndarray:
    """NumPy twin of :func:`signed_distance`: the distance to each triangle as the least of the
    distance to its plane (where the foot lies inside it) and to its three edges; the winding
    number from the same solid-angle formula. O(n × nt) memory."""
    p = np.asarray(points, np.float64)[:, None, None, :]                     # (n, 1, 1, 3)
    c = np.asarray(corners, np.float64)[None]                                # (1, nt, 3, 3)
    a, b, d = c[..., 0, :], c[..., 1, :], c[..., 2, :]
    normal = np.cross(b - a, d - a)
    normal = normal / np.linalg.norm(normal, axis=-1, keepdims=True)
    q = p[:, :, 0] - a                                                       # (n, nt, 3)
    height = np.einsum("ntk,ntk->nt", q, np.broadcast_to(normal, q.shape))
    foot = p[:, :, 0] - height[..., None] * normal
    inside = np.ones(height.shape, bool)
    for u, v in ((a, b), (b, d), (d, a)):
        inside &= np.einsum("ntk,ntk->nt", np.cross(v - u, foot - u), np.broadcast_to(normal, q.shape)) >= 0
    dist2 = np.where(inside, height ** 2, np.inf)
    for u, v in ((a, b), (b, d), (d, a)):
        e = v - u
        s = np.clip(np.einsum("ntk,ntk->nt", p[:, :, 0] - u, np.broadcast_to(e, q.shape))
                    / np.einsum("ntk,ntk->nt", e, e), 0.0, 1.0)
        dist2 = np.minimum(dist2, np.sum((p[:, :, 0] - u - s[..., None] * e) ** 2, axis=-1))
    x = c - p                                                                # (n, nt, 3, 3) corners − p
    length = np.linalg.norm(x, axis=-1)
    xa, xb, xc = x[..., 0, :], x[..., 1, :], x[..., 2, :]
    la, lb, lc = length[..., 0], length[..., 1], length[..., 2]
    det = np.einsum("ntk,ntk->nt", xa, np.cross(xb, xc))
    den = la * lb * lc + np.einsum("ntk,ntk->nt", xa, xb) * lc + np.einsum("ntk,ntk->nt", xb, xc) * la \
        + np.einsum("ntk,ntk->nt", xc, xa) * lb
    winding = (2.0 * np.arctan2(det, den)).sum(axis=1) / (4.0 * np.pi)
    d = np.sqrt(dist2.min(axis=1))
    return np.where(winding > 0.5, -d, d)


@dataclass(frozen=True)
class DistanceGrid:
    """The signed distance [m] sampled at the nodes of a regular grid: ``centre`` (3,) and
    ``half`` (3,) the grid box [m], ``dims`` (3,) nodes per axis, ``values`` (nx·ny·nz,) in
    C order (x slowest). Node (i, j, k) is at centre − half + (i, j, k) · 2 half / (dims − 1)."""

    centre: np.ndarray
    half: np.ndarray
    dims: np.ndarray
    values: np.ndarray

    @property
    def spacing(self) -> np.ndarray:
        """Node spacing per axis [m]."""
        return 2.0 * self.half / (self.dims - 1)

    def nodes(self) -> np.ndarray:
        """(nx·ny·nz, 3) node coordinates [m], in the order of ``values``."""
        axes = [np.linspace(c - h, c + h, n) for c, h, n in zip(self.centre, self.half, self.dims)]
        return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)


def distance_grid(surface: ClosedSurface, spacing: float, margin: float) -> DistanceGrid:
    """:func:`signed_distance` of ``surface`` on a grid of node spacing ≤ ``spacing`` [m] over
    its bounding box grown by ``margin`` [m] on every side (every node on the grid's boundary is
    then at least ``margin`` outside the surface)."""
    lo = surface.vertices.min(axis=0) - margin
    hi = surface.vertices.max(axis=0) + margin
    dims = np.ceil((hi - lo) / spacing).astype(np.int64) + 1
    grid = DistanceGrid(0.5 * (lo + hi), 0.5 * (hi - lo), dims, np.zeros(0))
    values = signed_distance(np.ascontiguousarray(grid.nodes()), np.ascontiguousarray(surface.corners))
    return DistanceGrid(grid.centre, grid.half, dims, values)
