"""Quadrature samples on the blocks' surfaces: points, outward normals and the length (2D) or
area (3D) each one carries, for boxes, spheres, cylinders and triangle surfaces — the samples
of the hidden-surface closure (fcm/hidden.py)."""
from __future__ import annotations

import numpy as np

from .shapes import BOX, CYLINDER, MESH, SPHERE


def perimeter_samples(kind: int, half: np.ndarray, offset: np.ndarray, rot: np.ndarray,
                      spacing: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Section z = 0 of one primitive in its body frame, counter-clockwise: segment midpoints
    (n, 2) [m], outward unit normals (n, 2) and segment lengths (n,) [m], every segment
    ≤ ``spacing``. Box: the rectangle of its x, y half extents (its z axis must be the body
    z axis); sphere, or a cylinder along z: the circle of its radius."""
    if kind == BOX:
        if abs(abs(rot[2, 2]) - 1.0) > 1e-12:
            raise ValueError("a box tilted out of the plane has no rectangular section at z = 0")
        e1, e2 = rot[:2, 0], rot[:2, 1]
        if e1[0] * e2[1] - e1[1] * e2[0] < 0:           # keep the corners counter-clockwise
            e2 = -e2
        hx, hy = half[0], half[1]
        corners = [offset[:2] + sx * hx * e1 + sy * hy * e2 for sx, sy in ((1, -1), (1, 1), (-1, 1), (-1, -1))]
        normals = [e1, e2, -e1, -e2]
        pts, nrm, lens = [], [], []
        for k in range(4):
            a, b = corners[k], corners[(k + 1) % 4]
            length = float(np.linalg.norm(b - a))
            m = max(1, int(np.ceil(length / spacing)))
            s = (np.arange(m) + 0.5) / m
            pts.append(a[None, :] + s[:, None] * (b - a)[None, :])
            nrm.append(np.repeat(normals[k][None, :], m, axis=0))
            lens.append(np.full(m, length / m))
        return np.concatenate(pts), np.concatenate(nrm), np.concatenate(lens)
    if kind == SPHERE or (kind == CYLINDER and abs(abs(rot[2, 2]) - 1.0) <= 1e-12):
        r = half[0]
        m = max(8, int(np.ceil(2 * np.pi * r / spacing)))
        a = 2 * np.pi * (np.arange(m) + 0.5) / m
        n = np.column_stack([np.cos(a), np.sin(a)])
        return offset[:2] + r * n, n, np.full(m, 2 * np.pi * r / m)
    raise ValueError(f"primitive kind {kind}: no section at z = 0 that this module samples")


def _centred_cells(length: float, spacing: float) -> np.ndarray:
    """Midpoints of the fewest equal cells no longer than ``spacing`` covering
    [−length/2, length/2] [m]."""
    m = max(1, int(np.ceil(length / spacing)))
    return length * ((np.arange(m) + 0.5) / m - 0.5)


def box_surface_samples(half: np.ndarray, offset: np.ndarray, rot: np.ndarray,
                        spacing: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The six faces of a box of half extents ``half`` [m] in grids of cells no wider than
    ``spacing``: midpoints (n, 3) [m], outward unit normals (n, 3), areas (n,) [m²], in the
    frame where the box sits at ``offset`` rotated by ``rot``."""
    pts, nrm, area = [], [], []
    for axis in range(3):
        a, b = (k for k in range(3) if k != axis)
        ua, ub = _centred_cells(2 * half[a], spacing), _centred_cells(2 * half[b], spacing)
        ga, gb = np.meshgrid(ua, ub, indexing="ij")
        cell = 4 * half[a] * half[b] / ga.size
        for sign in (-1.0, 1.0):
            local = np.zeros((ga.size, 3))
            local[:, a], local[:, b], local[:, axis] = ga.ravel(), gb.ravel(), sign * half[axis]
            normal = np.zeros(3)
            normal[axis] = sign
            pts.append(local)
            nrm.append(np.repeat(normal[None, :], ga.size, axis=0))
            area.append(np.full(ga.size, cell))
    local, normals = np.concatenate(pts), np.concatenate(nrm)
    return offset + local @ rot.T, normals @ rot.T, np.concatenate(area)


def _rings(radius: float, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """A disc of ``radius`` in rings no wider than ``spacing``, each ring in arcs no longer
    than ``spacing``: arc points (n, 2) [m] and areas (n,) [m²] (each ring's exact area)."""
    edges = np.linspace(0.0, radius, max(1, int(np.ceil(radius / spacing))) + 1)
    pts, area = [], []
    for r0, r1 in zip(edges[:-1], edges[1:]):
        rho = np.sqrt(0.5 * (r0 * r0 + r1 * r1))              # halves the ring's area
        m = max(3, int(np.ceil(2 * np.pi * rho / spacing)))
        a = 2 * np.pi * (np.arange(m) + 0.5) / m
        pts.append(rho * np.column_stack([np.cos(a), np.sin(a)]))
        area.append(np.full(m, np.pi * (r1 * r1 - r0 * r0) / m))
    return np.concatenate(pts), np.concatenate(area)


def sphere_surface_samples(radius: float, offset: np.ndarray,
                           spacing: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A sphere in zones between circles of latitude no farther apart than ``spacing`` along
    the surface, each zone in arcs no longer than ``spacing``: points on the sphere at the
    zones' mid latitudes, outward normals, areas (each zone's exact area 2π r² Δcos θ)."""
    nz = max(2, int(np.ceil(np.pi * radius / spacing)))
    theta = np.linspace(0.0, np.pi, nz + 1)
    pts, area = [], []
    for t0, t1 in zip(theta[:-1], theta[1:]):
        t = 0.5 * (t0 + t1)
        m = max(3, int(np.ceil(2 * np.pi * radius * np.sin(t) / spacing)))
        a = 2 * np.pi * (np.arange(m) + 0.5) / m
        pts.append(np.column_stack([np.sin(t) * np.cos(a), np.sin(t) * np.sin(a), np.full(m, np.cos(t))]))
        area.append(np.full(m, 2 * np.pi * radius * radius * (np.cos(t0) - np.cos(t1)) / m))
    normals = np.concatenate(pts)
    return offset + radius * normals, normals, np.concatenate(area)


def cylinder_surface_samples(radius: float, half_length: float, offset: np.ndarray, rot: np.ndarray,
                             spacing: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A capped cylinder along its frame's z axis: the side in arcs × rows no larger than
    ``spacing``, each cap in rings (:func:`_rings`): points, outward normals, areas."""
    m = max(3, int(np.ceil(2 * np.pi * radius / spacing)))
    a = 2 * np.pi * (np.arange(m) + 0.5) / m
    zs = _centred_cells(2 * half_length, spacing)
    ga, gz = np.meshgrid(a, zs, indexing="ij")
    side_n = np.column_stack([np.cos(ga.ravel()), np.sin(ga.ravel()), np.zeros(ga.size)])
    side_x = radius * side_n + np.column_stack([np.zeros((ga.size, 2)), gz.ravel()])
    disc, disc_area = _rings(radius, spacing)
    pts, nrm, area = [side_x], [side_n], [np.full(ga.size, 2 * np.pi * radius * 2 * half_length / ga.size)]
    for sign in (-1.0, 1.0):
        pts.append(np.column_stack([disc, np.full(len(disc), sign * half_length)]))
        nrm.append(np.repeat([[0.0, 0.0, sign]], len(disc), axis=0))
        area.append(disc_area)
    local, normals = np.concatenate(pts), np.concatenate(nrm)
    return offset + local @ rot.T, normals @ rot.T, np.concatenate(area)


def triangle_surface_samples(corners: np.ndarray, offset: np.ndarray, rot: np.ndarray,
                             spacing: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A triangle surface (corners (nt, 3, 3) [m], outward, counter-clockwise), each triangle
    cut into m² similar ones, m the fewest that make their edges ≤ ``spacing``: the small
    triangles' centroids (n, 3) [m], outward unit normals, areas [m²] (summing to the
    surface's area exactly), in the frame where the surface sits at ``offset`` rotated by ``rot``."""
    pts, nrm, area = [], [], []
    edges = np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=2).max(axis=1)
    m_of = np.maximum(1, np.ceil(edges / spacing).astype(np.int64))
    for m in np.unique(m_of):
        c = corners[m_of == m]
        a, e1, e2 = c[:, 0], (c[:, 1] - c[:, 0]) / m, (c[:, 2] - c[:, 0]) / m
        i, j = np.meshgrid(np.arange(m), np.arange(m), indexing="ij")
        up = (i + j) < m                                  # (i, j) upright, (i+1, j+1) inverted cells
        down = (i + j) < m - 1
        u = np.concatenate([i[up] + 1 / 3, i[down] + 2 / 3])
        v = np.concatenate([j[up] + 1 / 3, j[down] + 2 / 3])
        pts.append((a[:, None] + u[None, :, None] * e1[:, None] + v[None, :, None] * e2[:, None]).reshape(-1, 3))
        cross = np.cross(e1, e2)
        norm = np.linalg.norm(cross, axis=1)
        nrm.append(np.repeat(cross / norm[:, None], len(u), axis=0))
        area.append(np.repeat(0.5 * norm, len(u)))
    local, normals = np.concatenate(pts), np.concatenate(nrm)
    return offset + local @ rot.T, normals @ rot.T, np.concatenate(area)


def surface_samples(kind: int, half: np.ndarray, offset: np.ndarray, rot: np.ndarray, spacing: float,
                    dim: int, triangles: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One primitive's surface in its body frame: points (n, 3) [m], outward normals (n, 3)
    and lengths [m] (``dim`` 2: the section z = 0, :func:`perimeter_samples`) or areas [m²].
    A mesh primitive needs its ``triangles`` (shape frame) and a 3D fluid."""
    if kind == MESH:
        if dim != 3 or triangles is None:
            raise ValueError("a surface mesh is sampled in 3D only, from its triangles")
        return triangle_surface_samples(triangles, offset, rot, spacing)
    if dim == 2:
        x, n, ds = perimeter_samples(kind, half, offset, rot, spacing)
        return np.column_stack([x, np.zeros(len(x))]), np.column_stack([n, np.zeros(len(n))]), ds
    if kind == BOX:
        return box_surface_samples(half, offset, rot, spacing)
    if kind == SPHERE:
        return sphere_surface_samples(half[0], offset, spacing)
    if kind == CYLINDER:
        return cylinder_surface_samples(half[0], half[1], offset, rot, spacing)
    raise ValueError(f"primitive kind {kind}: no surface that this module samples")
