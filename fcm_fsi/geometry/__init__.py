"""Rotations by unit quaternions q = (w, x, y, z), body → world: ``x_w = R(q) x_b``; and points
sorted into the cells of a grid (:func:`sort_by_cell`), the O(N) neighbour searches' first step.

The convention of the DEM state (``fcm_fsi/dem/state.py``) and of the structure level set
(``fcm_fsi/fcm/levelset.py``); both packages import these helpers from here, so neither
depends on the other. :func:`rotate` is the Numba kernel, :func:`quat_to_matrix_np` its
plain-NumPy reference.
"""
from __future__ import annotations

import numba as nb
import numpy as np


@nb.njit(cache=True, inline="always")
def rotate(q0, q1, q2, q3, x, y, z):
    """R(q) (x, y, z) for a unit quaternion, returned as three floats."""
    tx = 2.0 * (q2 * z - q3 * y)
    ty = 2.0 * (q3 * x - q1 * z)
    tz = 2.0 * (q1 * y - q2 * x)
    return (x + q0 * tx + q2 * tz - q3 * ty,
            y + q0 * ty + q3 * tx - q1 * tz,
            z + q0 * tz + q1 * ty - q2 * tx)


@nb.njit(cache=True, inline="always")
def rotate_inv(q0, q1, q2, q3, x, y, z):
    """R(q)ᵀ (x, y, z)."""
    return rotate(q0, -q1, -q2, -q3, x, y, z)


def quat_to_matrix_np(q: np.ndarray) -> np.ndarray:
    """Rotation matrices of unit quaternions (w, x, y, z); (..., 4) → (..., 3, 3)."""
    w, x, y, z = (q[..., i] for i in range(4))
    R = np.empty(q.shape[:-1] + (3, 3))
    R[..., 0, 0] = 1 - 2 * (y * y + z * z)
    R[..., 0, 1] = 2 * (x * y - w * z)
    R[..., 0, 2] = 2 * (x * z + w * y)
    R[..., 1, 0] = 2 * (x * y + w * z)
    R[..., 1, 1] = 1 - 2 * (x * x + z * z)
    R[..., 1, 2] = 2 * (y * z - w * x)
    R[..., 2, 0] = 2 * (x * z - w * y)
    R[..., 2, 1] = 2 * (y * z + w * x)
    R[..., 2, 2] = 1 - 2 * (x * x + y * y)
    return R


@nb.njit(cache=True)
def sort_by_cell(cell, ncell):
    """Counting sort of points by their cell index ``cell`` (n,) in [0, ncell): (start, order)
    with the points of cell c at ``order[start[c]:start[c + 1]]``, in increasing point index.
    NumPy twin: :func:`sort_by_cell_np`."""
    n = cell.shape[0]
    start = np.zeros(ncell + 1, np.int64)
    for i in range(n):
        start[cell[i] + 1] += 1
    for c in range(ncell):
        start[c + 1] += start[c]
    fill = start[:-1].copy()
    order = np.empty(n, np.int64)
    for i in range(n):
        order[fill[cell[i]]] = i
        fill[cell[i]] += 1
    return start, order


def sort_by_cell_np(cell: np.ndarray, ncell: int) -> tuple[np.ndarray, np.ndarray]:
    """Plain-NumPy reference of :func:`sort_by_cell`."""
    start = np.concatenate([[0], np.cumsum(np.bincount(cell, minlength=ncell))]).astype(np.int64)
    return start, np.argsort(cell, kind="stable").astype(np.int64)
