"""Material points of a regular lattice, and the boxes that select them."""
from __future__ import annotations

import numpy as np


def lattice_points(lower, upper, spacing: float) -> np.ndarray:
    """Points at the centres of the cells of edge ``spacing`` Δx [m] tiling the box
    [``lower``, ``upper``] (round(extent/Δx) cells per axis, at least one), as (N, 3) with z = 0
    in 2D; x fastest."""
    lower = np.asarray(lower, float)
    counts = [max(int(round((b - a) / spacing)), 1) for a, b in zip(lower, upper)]
    axes = [a + (np.arange(n) + 0.5) * spacing for a, n in zip(lower, counts)]
    grids = np.meshgrid(*axes, indexing="ij")
    pts = np.stack([g.ravel(order="F") for g in grids], axis=1)
    out = np.zeros((len(pts), 3))
    out[:, :len(counts)] = pts
    return out


def in_box(points: np.ndarray, lower, upper) -> np.ndarray:
    """Mask of the points inside the closed box [``lower``, ``upper``] (its dimension's coordinates)."""
    d = len(lower)
    lo, hi = np.asarray(lower, float), np.asarray(upper, float)
    return np.all((points[:, :d] >= lo) & (points[:, :d] <= hi), axis=1)
