"""NumPy reference of the structure level set (fcm/levelset.py): the signed distance to the
blocks' primitives and the gap fill, point by point, for the kernel tests and for the
hidden-surface closure's small per-body evaluations."""
from __future__ import annotations

import numpy as np

from ..geometry import quat_to_matrix_np
from .levelset import BOX, MESH, NO_SHAPE, SPHERE, WALL, Shapes, _unit_planes


def _box_distance_reference(p: np.ndarray, half: np.ndarray) -> np.ndarray:
    """Signed distance to the box |p_k| ≤ half_k in any number of dimensions (last axis):
    the distance to the clamped closest point outside, minus the depth to the nearest face inside."""
    gap = np.linalg.norm(p - np.clip(p, -half, half), axis=-1)
    depth = np.min(half - np.abs(p), axis=-1)
    return np.where(gap > 0, gap, -depth)


def grid_distance_reference(p: np.ndarray, half: np.ndarray, grid: np.ndarray, values: np.ndarray) -> np.ndarray:
    """A mesh primitive's distance [m] at shape-frame points p (n, 3): trilinear interpolation
    of its grid at p clamped to the grid box, plus the distance from p to the box (as
    :func:`~fcm_fsi.fcm.levelset._grid_distance`)."""
    start, dims = grid[0], grid[1:]
    table = values[start:start + np.prod(dims)].reshape(dims)
    c = np.clip(p, -half, half)
    t = (c + half) / (2.0 * half) * (dims - 1)
    i = np.minimum(t.astype(np.int64), dims - 2)
    f = t - i
    value = np.zeros(len(p))
    for corner in np.ndindex(2, 2, 2):
        w = np.prod(np.where(np.array(corner), f, 1.0 - f), axis=1)
        value += w * table[i[:, 0] + corner[0], i[:, 1] + corner[1], i[:, 2] + corner[2]]
    return value + np.linalg.norm(p - c, axis=1)


def signed_distance_reference(x, shapes: Shapes, body_pos, body_quat, cutoff: float, gap: float = 0.0,
                              walls=None, fill=None):
    """Brute-force NumPy reference of :meth:`StructureLevelSet.evaluate` (all points × all
    primitives, and the gap fill from the per-owner minima; ``fill`` = (fill_other,
    fill_weight) arrays (n, 2) to receive the fill's velocity blend). Each primitive reduces to
    a box in its symmetry coordinates: a sphere is the interval |ρ₃| ≤ r in the distance ρ₃
    from its centre, a cylinder the rectangle |ρ| ≤ r, |z| ≤ h/2 in (radial distance, axial
    coordinate)."""
    x = np.asarray(x, np.float64)
    phi = np.full(len(x), float(cutoff))
    owner = np.full(len(x), NO_SHAPE, np.int64)
    if not len(shapes):
        return phi, owner
    Rb = quat_to_matrix_np(np.asarray(body_quat, np.float64).reshape(-1, 4))
    moving = shapes.body >= 0
    b = shapes.body[moving]
    centre, R = shapes.offset.copy(), shapes.rot.copy()
    body_pos = np.asarray(body_pos, np.float64).reshape(-1, 3)
    centre[moving] = body_pos[b] + np.einsum("sij,sj->si", Rb[b], centre[moving])
    R[moving] = Rb[b] @ R[moving]
    p = np.einsum("sji,nsj->nsi", R, x[:, None, :] - centre[None])       # (n, ns, 3) shape frame
    h = shapes.half
    d = np.select(
        [shapes.kind == SPHERE, shapes.kind == BOX],
        [_box_distance_reference(np.linalg.norm(p, axis=-1, keepdims=True), h[:, :1]),
         _box_distance_reference(p, h)],
        _box_distance_reference(np.stack([np.hypot(p[..., 0], p[..., 1]), p[..., 2]], axis=-1), h[:, :2]))
    for s in np.flatnonzero(shapes.kind == MESH):
        d[:, s] = grid_distance_reference(p[:, s], shapes.half[s], shapes.grid[s], shapes.values)
    arg = np.argmin(d, axis=1)
    dmin = d[np.arange(len(x)), arg]
    near = dmin < cutoff
    phi[near] = np.maximum(dmin[near], -cutoff)
    owner[near] = shapes.body[arg[near]]
    if gap > 0:
        if fill is None:
            fill = np.full((len(x), 2), NO_SHAPE, np.int64), np.zeros((len(x), 2))
        _gap_fill_reference(x, d, shapes.body, _unit_planes(walls), cutoff, gap, near, phi, owner, *fill)
    return phi, owner


def _gap_fill_reference(x, d, body, planes, cutoff, gap, near, phi, owner, fill_other, fill_weight):
    """φ = min(φ, (d₁ + d₂ − gap)/2) over the two nearest distinct owners (walls = one owner);
    the fill's velocity weights of the nearest three as :func:`_fill_weights`."""
    owners = np.unique(body)
    per_owner = np.stack([d[:, body == o].min(axis=1) for o in owners], axis=1)
    if len(planes):
        wall = np.einsum("npk,pk->np", x[:, None, :] - planes[None, :, :3], planes[:, 3:]).min(axis=1)
        per_owner = np.column_stack([per_owner, wall])
        owners = np.append(owners, WALL)
    if per_owner.shape[1] < 2:
        return
    absent = np.full((len(x), 1), cutoff)                  # a third owner that is not there
    per_owner = np.column_stack([np.minimum(per_owner, cutoff), absent])
    owners = np.append(owners, NO_SHAPE)
    order = np.argsort(per_owner, axis=1, kind="stable")[:, :3]
    dk = np.take_along_axis(per_owner, order, axis=1)       # (n, 3) nearest three, ascending
    ok = owners[order]
    ok[dk >= cutoff] = NO_SHAPE
    d1, d2 = dk[:, 0], dk[:, 1]
    fill = 0.5 * (d1 + d2 - gap)
    use = near & (d2 < cutoff) & (fill < phi)
    phi[use] = np.maximum(fill[use], -cutoff)
    dk[:, 2] = np.where(ok[:, 2] == NO_SHAPE, cutoff + gap, dk[:, 2])
    with np.errstate(divide="ignore", invalid="ignore"):
        p = np.maximum(1.0 - (dk - d1[:, None]) / gap, 0.0) / dk
        w = np.where(d1[:, None] > 0, p / p.sum(axis=1, keepdims=True), [1.0, 0.0, 0.0])
    wall_nearer = ok[:, 0] == WALL
    owner[use] = np.where(wall_nearer, ok[:, 1], ok[:, 0])[use]
    fill_other[use, 0] = np.where(wall_nearer, WALL, ok[:, 1])[use]
    fill_weight[use, 0] = np.where(wall_nearer, w[:, 0], w[:, 1])[use]
    fill_other[use, 1] = ok[use, 2]
    fill_weight[use, 1] = w[use, 2]
