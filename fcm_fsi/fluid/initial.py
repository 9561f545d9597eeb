"""The initial liquid region of the phase field as a signed distance (numpy only, so that the
pre-run checks can sample it without building a mesh)."""
from __future__ import annotations

import numpy as np

from ..config.phase_field import InitialShape


def signed_distance(shape: InitialShape, x: np.ndarray, gdim: int) -> np.ndarray:
    """Signed distance to the initial liquid region (positive inside). x: (3, npts).

    The vertical axis (for surface_wave) is the last coordinate: y in 2D, z in 3D.
    """
    if shape.shape in ("circle", "sphere"):
        c = np.array(shape.center)
        r = np.sqrt(sum((x[i] - c[i]) ** 2 for i in range(len(c))))
        return shape.radius - r
    if shape.shape == "zalesak":
        cx, cy = shape.center[0], shape.center[1]
        disk = shape.radius - np.sqrt((x[0] - cx) ** 2 + (x[1] - cy) ** 2)
        y0 = cy - shape.radius - 1.0  # slot open to below the disk
        y1 = cy - shape.radius + shape.slot_depth
        slot = _box_sdf_inside(x[:2], np.array([cx - shape.slot_width / 2, y0]),
                               np.array([cx + shape.slot_width / 2, y1]))
        return np.minimum(disk, -slot)
    if shape.shape == "box":
        lo, hi = np.array(shape.lower), np.array(shape.upper)
        d = _box_sdf_inside(x[:len(lo)], lo, hi)
        if shape.bed_depth > 0:     # union with the wet bed below y = bed_depth
            d = np.maximum(d, shape.bed_depth - x[gdim - 1])
        return d
    if shape.shape == "surface_wave":
        return shape.depth + shape.amplitude * np.cos(np.pi * x[0] / shape.length) - x[gdim - 1]
    raise ValueError(shape.shape)


def _box_sdf_inside(x: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Exact signed distance to an axis-aligned box, positive inside."""
    c, h = 0.5 * (lo + hi), 0.5 * (hi - lo)
    q = np.abs(x - c[:, None]) - h[:, None]
    outside = np.sqrt(np.sum(np.maximum(q, 0.0) ** 2, axis=0))
    inside = np.minimum(np.max(q, axis=0), 0.0)
    return -(outside + inside)
