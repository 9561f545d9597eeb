"""Exact measures of simplices cut by a linear (P1) function.

For a triangle or tetrahedron with vertex values s_i of a linear function, the part
{s ≥ 0} is a polygon/polyhedron bounded by the planar cut {s = 0}. Its area/volume and
the measure of the cut surface are computed exactly by splitting into simplices.
This is the geometry of the finite-cover cut cell (structure level set) and of the
phase-field volume {φ ≥ 0.5} (s = φ − 0.5) used by the volume correction (eqs 16–17).

Kernels take arrays only: ``coords (ncells, nv, gdim)`` and ``values (ncells, nv)``.
``cut_measures_reference`` is the plain-NumPy reference used by the tests.
"""
from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True)
def _tri_area(a, b, c):
    """Area of the triangle a, b, c (2D or 3D points), in scalars: no temporary arrays, so the
    whole cells, most of the mesh, cost no allocation."""
    if a.shape[0] == 2:
        return 0.5 * abs((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]))
    u0, u1, u2 = b[0] - a[0], b[1] - a[1], b[2] - a[2]
    v0, v1, v2 = c[0] - a[0], c[1] - a[1], c[2] - a[2]
    cx = u1 * v2 - u2 * v1
    cy = u2 * v0 - u0 * v2
    cz = u0 * v1 - u1 * v0
    return 0.5 * np.sqrt(cx * cx + cy * cy + cz * cz)


@numba.njit(cache=True)
def _tet_volume(a, b, c, d):
    """Volume of the tetrahedron a, b, c, d, in scalars (as :func:`_tri_area`)."""
    u0, u1, u2 = b[0] - a[0], b[1] - a[1], b[2] - a[2]
    v0, v1, v2 = c[0] - a[0], c[1] - a[1], c[2] - a[2]
    w0, w1, w2 = d[0] - a[0], d[1] - a[1], d[2] - a[2]
    return abs(u0 * (v1 * w2 - v2 * w1) - u1 * (v0 * w2 - v2 * w0) + u2 * (v0 * w1 - v1 * w0)) / 6.0


@numba.njit(cache=True)
def _edge_point(xa, xb, sa, sb):
    t = sa / (sa - sb)
    return xa + t * (xb - xa)


@numba.njit(cache=True)
def _triangle_cut(x, s):
    """(area of {s>=0}, length of {s=0}) for one triangle."""
    npos = 0
    for i in range(3):
        if s[i] >= 0.0:
            npos += 1
    if npos == 0:
        return 0.0, 0.0
    full = _tri_area(x[0], x[1], x[2])
    if npos == 3:
        return full, 0.0
    # lone vertex: the one whose sign differs from the other two
    lone = 0
    for i in range(3):
        if (s[i] >= 0.0) == (npos == 1):
            lone = i
    j = (lone + 1) % 3
    k = (lone + 2) % 3
    p = _edge_point(x[lone], x[j], s[lone], s[j])
    q = _edge_point(x[lone], x[k], s[lone], s[k])
    corner = _tri_area(x[lone], p, q)
    seg = p - q
    length = np.sqrt(np.sum(seg * seg))
    if npos == 1:
        return corner, length
    return full - corner, length


@numba.njit(cache=True)
def _tet_cut(x, s):
    """(volume of {s>=0}, area of {s=0}) for one tetrahedron."""
    npos = 0
    for i in range(4):
        if s[i] >= 0.0:
            npos += 1
    if npos == 0:
        return 0.0, 0.0
    full = _tet_volume(x[0], x[1], x[2], x[3])
    if npos == 4:
        return full, 0.0
    if npos == 1 or npos == 3:
        lone = 0
        for i in range(4):
            if (s[i] >= 0.0) == (npos == 1):
                lone = i
        o = np.empty(3, dtype=np.int64)
        m = 0
        for i in range(4):
            if i != lone:
                o[m] = i
                m += 1
        p0 = _edge_point(x[lone], x[o[0]], s[lone], s[o[0]])
        p1 = _edge_point(x[lone], x[o[1]], s[lone], s[o[1]])
        p2 = _edge_point(x[lone], x[o[2]], s[lone], s[o[2]])
        corner = _tet_volume(x[lone], p0, p1, p2)
        area = _tri_area(p0, p1, p2)
        if npos == 1:
            return corner, area
        return full - corner, area
    # two positive (a, b), two negative (c, d): the positive part is a wedge
    a = -1
    b = -1
    c = -1
    d = -1
    for i in range(4):
        if s[i] >= 0.0:
            if a < 0:
                a = i
            else:
                b = i
        else:
            if c < 0:
                c = i
            else:
                d = i
    pac = _edge_point(x[a], x[c], s[a], s[c])
    pad = _edge_point(x[a], x[d], s[a], s[d])
    pbc = _edge_point(x[b], x[c], s[b], s[c])
    pbd = _edge_point(x[b], x[d], s[b], s[d])
    # wedge A=(a, pac, pad) -> B=(b, pbc, pbd)
    vol = (_tet_volume(x[a], pac, pad, pbd) + _tet_volume(x[a], pac, pbc, pbd)
           + _tet_volume(x[a], x[b], pbc, pbd))
    area = _tri_area(pac, pbc, pbd) + _tri_area(pac, pbd, pad)
    return vol, area


@numba.njit(cache=True)
def cut_measures(coords, values):
    """Per cell: measure of {values ≥ 0} and of the cut surface {values = 0}.

    coords: (ncells, nv, gdim) vertex coordinates; values: (ncells, nv), nv = 3 or 4.
    """
    n = coords.shape[0]
    inside = np.zeros(n)
    surface = np.zeros(n)
    nv = coords.shape[1]
    for c in range(n):
        if nv == 3:
            inside[c], surface[c] = _triangle_cut(coords[c], values[c])
        else:
            inside[c], surface[c] = _tet_cut(coords[c], values[c])
    return inside, surface


def _clip_polygon(poly: list, s: list) -> list:
    out = []
    for i in range(len(poly)):
        j = (i + 1) % len(poly)
        if s[i] >= 0:
            out.append(poly[i])
        if (s[i] >= 0) != (s[j] >= 0):
            t = s[i] / (s[i] - s[j])
            out.append(poly[i] + t * (poly[j] - poly[i]))
    return out


def cut_measures_reference(coords: np.ndarray, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """NumPy reference by a different route: polygon clipping (2D) and the divergence
    theorem over the clipped faces (3D)."""
    n, nv = values.shape
    inside, surface = np.zeros(n), np.zeros(n)
    for c in range(n):
        x, s = coords[c].astype(float), values[c].astype(float)
        if nv == 3:
            poly = _clip_polygon([x[i] for i in range(3)], list(s))
            if len(poly) >= 3:
                P = np.array(poly)
                inside[c] = 0.5 * abs(np.dot(P[:, 0], np.roll(P[:, 1], -1)) - np.dot(P[:, 1], np.roll(P[:, 0], -1)))
            pts = [x[i] + s[i] / (s[i] - s[j]) * (x[j] - x[i])
                   for i in range(3) for j in range(i + 1, 3) if (s[i] >= 0) != (s[j] >= 0)]
            if len(pts) == 2:
                surface[c] = np.linalg.norm(pts[0] - pts[1])
            continue
        # 3D: V = (1/3) Σ_faces (x_f · n_f) A_f over the clipped polyhedron's faces
        centroid = x.mean(axis=0)
        vol = 0.0
        faces = [(0, 1, 2), (0, 1, 3), (0, 2, 3), (1, 2, 3)]
        for f in faces:
            poly = _clip_polygon([x[i] for i in f], [s[i] for i in f])
            if len(poly) < 3:
                continue
            P = np.array(poly)
            area_vec = 0.5 * sum(np.cross(P[k] - P[0], P[k + 1] - P[0]) for k in range(1, len(P) - 1))
            if np.dot(area_vec, P.mean(axis=0) - centroid) < 0:
                area_vec = -area_vec
            vol += np.dot(P[0] - centroid, area_vec) / 3.0
        pts = [x[i] + s[i] / (s[i] - s[j]) * (x[j] - x[i])
               for i in range(4) for j in range(i + 1, 4) if (s[i] >= 0) != (s[j] >= 0)]
        if len(pts) >= 3:
            P = np.array(pts)
            # order the planar polygon around its centre
            g = np.array([s[1] - s[0], s[2] - s[0], s[3] - s[0]])
            J = np.array([x[1] - x[0], x[2] - x[0], x[3] - x[0]])
            normal = np.linalg.solve(J, g)
            normal /= np.linalg.norm(normal)
            e1 = P[0] - P.mean(axis=0)
            e1 /= np.linalg.norm(e1)
            e2 = np.cross(normal, e1)
            ang = np.arctan2((P - P.mean(axis=0)) @ e2, (P - P.mean(axis=0)) @ e1)
            P = P[np.argsort(ang)]
            surface[c] = 0.5 * np.linalg.norm(sum(np.cross(P[k] - P[0], P[k + 1] - P[0]) for k in range(1, len(P) - 1)))
            # the cut face closes the polyhedron; its outward normal is -grad s/|grad s|
            vol += np.dot(P[0] - centroid, -normal * surface[c]) / 3.0
        inside[c] = abs(vol)
    return inside, surface
