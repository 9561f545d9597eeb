"""Moment-fitted quadrature on cells cut by a linear (P1) level set (SPEC §1 and §6).

A cut cell K keeps the points x_q of the standard degree-``q`` rule of the uncut mesh and
gets new weights, chosen so that every monomial of degree ≤ 2 integrates exactly over

- the fluid part K ∩ {s ≥ 0}   (volume weights), and
- the planar cut surface K ∩ {s = 0}   (surface weights),

of the cell's P1 level set s (Müller, Kummer & Oberlack 2013, moment fitting). The exact
moments come from splitting the fluid part into simplices (or full cell minus a corner
simplex) and the cut surface into segments/triangles, each integrated by a rule exact for
degree 2. Among all weights with the right moments the kernel takes the one closest (in
the Euclidean norm) to the uncut weights scaled by the fluid fraction (volume) or by
area/|K| (surface), so uncut-like cells keep near-standard weights.

The weights are returned as *factors* c_q = w_q / (ŵ_q |det J|): a dolfinx Quadrature-space
function holding c_q turns ``f * c * dx`` into Σ_q w_q f(x_q). Fully fluid cells have
c = 1, solid cells 0; surface factors are 0 off the cut.

Monomials are evaluated in cell-local scaled coordinates (x − x_K)/h_K so the moment
system stays well conditioned at any mesh size.
"""
from __future__ import annotations

import numba
import numpy as np

_TET_A = 0.5854101966249685   # 4-point degree-2 tetrahedron rule (Keast)
_TET_B = 0.1381966011250105


def cut_cells(values: np.ndarray) -> np.ndarray:
    """Cells (rows of vertex level-set values) that Γ cuts: some vertex in the body, some not."""
    return (values.min(axis=1) < 0) & (values.max(axis=1) >= 0)


@numba.njit(cache=True)
def _n_monomials(gdim):
    return 6 if gdim == 2 else 10


@numba.njit(cache=True)
def _monomials(xi, out):
    """Monomials of degree ≤ 2 at local point xi (gdim,) into out (6 or 10,)."""
    out[0] = 1.0
    if xi.shape[0] == 2:
        x, y = xi[0], xi[1]
        out[1], out[2] = x, y
        out[3], out[4], out[5] = x * x, x * y, y * y
        return
    x, y, z = xi[0], xi[1], xi[2]
    out[1], out[2], out[3] = x, y, z
    out[4], out[5], out[6] = x * x, y * y, z * z
    out[7], out[8], out[9] = x * y, x * z, y * z


@numba.njit(cache=True)
def _measure(pts):
    """Measure of a simplex given as (k+1, gdim) points: length, area or volume."""
    k = pts.shape[0] - 1
    if k == 1:
        d = pts[1] - pts[0]
        return np.sqrt(np.sum(d * d))
    if k == 2:
        u = pts[1] - pts[0]
        v = pts[2] - pts[0]
        if pts.shape[1] == 2:
            return 0.5 * abs(u[0] * v[1] - u[1] * v[0])
        cx = u[1] * v[2] - u[2] * v[1]
        cy = u[2] * v[0] - u[0] * v[2]
        cz = u[0] * v[1] - u[1] * v[0]
        return 0.5 * np.sqrt(cx * cx + cy * cy + cz * cz)
    u = pts[1] - pts[0]
    v = pts[2] - pts[0]
    w = pts[3] - pts[0]
    return abs(u[0] * (v[1] * w[2] - v[2] * w[1]) - u[1] * (v[0] * w[2] - v[2] * w[0])
               + u[2] * (v[0] * w[1] - v[1] * w[0])) / 6.0


@numba.njit(cache=True)
def _add_simplex_moments(pts, centre, scale, sign, m, tmp):
    """m += sign · ∫_simplex monomials((x − centre)/scale), exact for degree ≤ 2."""
    k = pts.shape[0] - 1
    meas = _measure(pts)
    if meas == 0.0:
        return
    gdim = pts.shape[1]
    xi = np.empty(gdim)
    if k == 1:      # 2-point Gauss on a segment
        g = 0.5 / np.sqrt(3.0)
        for t in (0.5 - g, 0.5 + g):
            for d in range(gdim):
                xi[d] = (pts[0, d] + t * (pts[1, d] - pts[0, d]) - centre[d]) / scale
            _monomials(xi, tmp)
            m += sign * 0.5 * meas * tmp
    elif k == 2:    # edge midpoints
        for a in range(3):
            b = (a + 1) % 3
            for d in range(gdim):
                xi[d] = (0.5 * (pts[a, d] + pts[b, d]) - centre[d]) / scale
            _monomials(xi, tmp)
            m += sign * meas / 3.0 * tmp
    else:           # 4-point rule
        for a in range(4):
            for d in range(3):
                xi[d] = (_TET_B * (pts[0, d] + pts[1, d] + pts[2, d] + pts[3, d])
                         + (_TET_A - _TET_B) * pts[a, d] - centre[d]) / scale
            _monomials(xi, tmp)
            m += sign * 0.25 * meas * tmp


@numba.njit(cache=True)
def _fluid_vertices(s):
    """Number of vertices on the fluid side (s ≥ 0)."""
    n = 0
    for i in range(s.shape[0]):
        if s[i] >= 0.0:
            n += 1
    return n


@numba.njit(cache=True)
def _edge_point(xa, xb, sa, sb):
    return xa + sa / (sa - sb) * (xb - xa)


@numba.njit(cache=True)
def _cut_moments(x, s, centre, scale, mv, ms, tmp):
    """Exact moments of the fluid part {s ≥ 0} (mv) and of the cut {s = 0} (ms) of one
    triangle/tetrahedron x (nv, gdim) with vertex values s. Returns (fluid measure, cut measure)."""
    nv = x.shape[0]
    mv[:] = 0.0
    ms[:] = 0.0
    npos = _fluid_vertices(s)
    full = _measure(x)
    if npos == nv:
        _add_simplex_moments(x, centre, scale, 1.0, mv, tmp)
        return full, 0.0
    if npos == 0:
        return 0.0, 0.0
    gdim = x.shape[1]
    if nv == 3 or npos != 2:
        # one vertex on its own side: a corner simplex cut off by a segment/triangle
        lone = 0
        for i in range(nv):
            if (s[i] >= 0.0) == (npos == 1):
                lone = i
        corner = np.empty((nv, gdim))
        corner[0] = x[lone]
        m = 1
        for i in range(nv):
            if i != lone:
                corner[m] = _edge_point(x[lone], x[i], s[lone], s[i])
                m += 1
        cut = corner[1:]
        if npos == 1:
            _add_simplex_moments(corner, centre, scale, 1.0, mv, tmp)
        else:
            _add_simplex_moments(x, centre, scale, 1.0, mv, tmp)
            _add_simplex_moments(corner, centre, scale, -1.0, mv, tmp)
        _add_simplex_moments(cut, centre, scale, 1.0, ms, tmp)
        vol = _measure(corner)
        return (vol if npos == 1 else full - vol), _measure(cut)
    # tetrahedron with two vertices on each side: the fluid part is a wedge
    pos = np.empty(2, np.int64)
    neg = np.empty(2, np.int64)
    ip = 0
    ineg = 0
    for i in range(4):
        if s[i] >= 0.0:
            pos[ip] = i
            ip += 1
        else:
            neg[ineg] = i
            ineg += 1
    a, b, c, d = pos[0], pos[1], neg[0], neg[1]
    pac = _edge_point(x[a], x[c], s[a], s[c])
    pad = _edge_point(x[a], x[d], s[a], s[d])
    pbc = _edge_point(x[b], x[c], s[b], s[c])
    pbd = _edge_point(x[b], x[d], s[b], s[d])
    tets = np.empty((3, 4, 3))
    tets[0, 0], tets[0, 1], tets[0, 2], tets[0, 3] = x[a], pac, pad, pbd
    tets[1, 0], tets[1, 1], tets[1, 2], tets[1, 3] = x[a], pac, pbc, pbd
    tets[2, 0], tets[2, 1], tets[2, 2], tets[2, 3] = x[a], x[b], pbc, pbd
    vol = 0.0
    for k in range(3):
        _add_simplex_moments(tets[k], centre, scale, 1.0, mv, tmp)
        vol += _measure(tets[k])
    tris = np.empty((2, 3, 3))
    tris[0, 0], tris[0, 1], tris[0, 2] = pac, pbc, pbd
    tris[1, 0], tris[1, 1], tris[1, 2] = pac, pbd, pad
    area = 0.0
    for k in range(2):
        _add_simplex_moments(tris[k], centre, scale, 1.0, ms, tmp)
        area += _measure(tris[k])
    return vol, area


@numba.njit(cache=True)
def _point_monomials(x, ref_points, centre, scale, A, xq, tmp):
    """A (nm, nq): the monomials of the cell-local scaled coordinates at the standard points
    of the cell with vertices x, x = x0 + Σ_k ξ_k (x_k − x0)."""
    gdim = x.shape[1]
    for q in range(ref_points.shape[0]):
        for d in range(gdim):
            xq[d] = x[0, d]
            for k in range(gdim):
                xq[d] += ref_points[q, k] * (x[k + 1, d] - x[0, d])
            xq[d] = (xq[d] - centre[d]) / scale
        _monomials(xq, tmp)
        A[:, q] = tmp


@numba.njit(cache=True)
def _centre_scale(x):
    """The cell's vertex centroid and size |K|^(1/gdim), the frame of its scaled monomials."""
    nv, gdim = x.shape
    centre = np.zeros(gdim)
    for i in range(nv):
        centre += x[i] / nv
    return centre, _measure(x) ** (1.0 / gdim)


@numba.njit(cache=True)
def moment_pinv(coords, ref_points):
    """(ncells, nq, nm) the pseudo-inverse of each cell's moment matrix A (nm, nq), the scaled
    monomials at its standard points (by SVD, so near-degenerate cells do not square the
    condition number). A depends on the cell's geometry only: a fixed mesh computes it once per
    cell (:class:`MomentInverses`)."""
    n, nv, gdim = coords.shape
    nq = ref_points.shape[0]
    nm = _n_monomials(gdim)
    out = np.empty((n, nq, nm))
    A = np.empty((nm, nq))
    xq = np.empty(gdim)
    tmp = np.empty(nm)
    for c in range(n):
        centre, scale = _centre_scale(coords[c])
        _point_monomials(coords[c], ref_points, centre, scale, A, xq, tmp)
        out[c] = np.linalg.pinv(A)
    return out


class MomentInverses:
    """The moment matrices' pseudo-inverses (:func:`moment_pinv`) of the cells of a fixed mesh
    that have been cut, computed when a cell is first cut and kept (nq × nm numbers per such
    cell: 1.1 kB for a tetrahedron's 14 points)."""

    def __init__(self, ncells: int) -> None:
        self.slot = np.full(ncells, -1, np.int64)     # row of each cell in ``pinv``, −1 not yet cut
        self.pinv = None

    def of(self, coords: np.ndarray, values: np.ndarray, ref_points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(slot, pinv) with every cell that ``values`` (ncells, nv) cuts in it; ``coords``
        (ncells, nv, gdim) the cells' vertices."""
        new = np.flatnonzero(cut_cells(values) & (self.slot < 0))
        if new.size or self.pinv is None:
            fresh = moment_pinv(np.ascontiguousarray(coords[new]), ref_points)
            start = 0 if self.pinv is None else len(self.pinv)
            self.slot[new] = start + np.arange(len(new))
            self.pinv = fresh if self.pinv is None else np.concatenate([self.pinv, fresh])
        return self.slot, self.pinv


def fitted_weights(coords, values, ref_points, ref_weights, inverses: MomentInverses | None = None):
    """Moment-fitted volume and surface weight factors per cell and quadrature point.

    coords (ncells, nv, gdim) vertex coordinates [m]; values (ncells, nv) level set at the
    vertices (fluid where ≥ 0); ref_points (nq, tdim), ref_weights (nq,) the standard rule
    on the reference simplex; ``inverses`` the cells' kept moment inverses (a fixed mesh cut
    again and again), else computed for this call. Returns (cv, cs, fluid, surface): factors
    (ncells, nq) and the exact fluid measure and cut-surface measure of each cell.
    """
    inverses = MomentInverses(len(coords)) if inverses is None else inverses
    slot, pinv = inverses.of(coords, values, ref_points)
    return _fitted_weights(coords, values, ref_points, ref_weights, slot, pinv)


@numba.njit(cache=True)
def _fit_factors(A, P, m, share, det, ref_weights, w0, r, out):
    """out (nq,) ← the factors w / (ŵ |det J|) of w = w0 + A⁺ (m − A w0), w0 = ŵ |det J| × ``share``
    (the part's measure over the cell's): the least-norm change of the scaled standard weights that
    gives the moments m. ``P`` = A⁺; ``w0``, ``r`` work arrays."""
    nm, nq = A.shape
    for q in range(nq):
        w0[q] = ref_weights[q] * det * share
    for i in range(nm):
        r[i] = m[i]
        for q in range(nq):
            r[i] -= A[i, q] * w0[q]
    for q in range(nq):
        w = w0[q]
        for i in range(nm):
            w += P[q, i] * r[i]
        out[q] = w / (ref_weights[q] * det)


@numba.njit(cache=True)
def _fitted_weights(coords, values, ref_points, ref_weights, slot, pinv):
    """:func:`fitted_weights` with the cut cells' moment inverses ``pinv[slot[c]]``: the
    weights w = w0 + A⁺ (m − A w0), the least-norm change of the scaled standard weights w0
    that gives the moments m."""
    n, nv, gdim = coords.shape
    nq = ref_points.shape[0]
    nm = _n_monomials(gdim)
    cv = np.zeros((n, nq))
    cs = np.zeros((n, nq))
    fluid = np.zeros(n)
    surface = np.zeros(n)
    mv = np.empty(nm)
    ms = np.empty(nm)
    tmp = np.empty(nm)
    A = np.empty((nm, nq))
    xq = np.empty(gdim)
    w0 = np.empty(nq)
    r = np.empty(nm)
    for c in range(n):
        x = coords[c]
        s = values[c]
        npos = _fluid_vertices(s)
        full = _measure(x)
        if npos == nv:
            cv[c, :] = 1.0
            fluid[c] = full
            continue
        if npos == 0:
            continue
        centre, scale = _centre_scale(x)
        vol, area = _cut_moments(x, s, centre, scale, mv, ms, tmp)
        fluid[c], surface[c] = vol, area
        _point_monomials(x, ref_points, centre, scale, A, xq, tmp)
        P = pinv[slot[c]]
        det = full / ref_weights.sum()     # |det J| = |K| / |K̂|
        _fit_factors(A, P, mv, vol / full, det, ref_weights, w0, r, cv[c])
        if area > 0.0:
            _fit_factors(A, P, ms, area / full, det, ref_weights, w0, r, cs[c])
    return cv, cs, fluid, surface


def fitted_weights_reference(coords, values, ref_points, ref_weights):
    """NumPy reference by a different route: the fluid part is the convex hull of its
    vertices and edge cut points, split by ``scipy.spatial.Delaunay``; the cut polygon is
    ordered around its centroid and fan-split; simplices are integrated with basix's
    degree-4 rule; the weights come from ``numpy.linalg.lstsq`` on the same closeness
    objective. Returns (cv, cs) like :func:`fitted_weights`."""
    n, nv, gdim = coords.shape
    nq = ref_points.shape[0]
    cv = np.zeros((n, nq))
    cs = np.zeros((n, nq))
    for c in range(n):
        x, s = coords[c], values[c]
        if np.all(s >= 0):
            cv[c] = 1.0
            continue
        if not np.any(s >= 0):
            continue
        centre = x.mean(axis=0)
        full = _measure(x)
        scale = full ** (1.0 / gdim)
        cut_pts = np.array([x[i] + s[i] / (s[i] - s[j]) * (x[j] - x[i])
                            for i in range(nv) for j in range(i + 1, nv) if (s[i] >= 0) != (s[j] >= 0)])
        fluid_pts = np.vstack([x[s >= 0], cut_pts])
        def mono(X, centre=centre, scale=scale):
            return np.array([_monomials_np((p - centre) / scale) for p in X])
        mv = _hull_moments(fluid_pts, mono)
        ms = _planar_moments(cut_pts, mono)
        xq = x[0] + ref_points @ (x[1:] - x[0])
        A = mono(xq).T
        det = full / ref_weights.sum()
        for m, out in ((mv, cv), (ms, cs)):
            w0 = ref_weights * det * m[0] / full
            w = w0 + np.linalg.lstsq(A, m - A @ w0, rcond=None)[0]
            out[c] = w / (ref_weights * det)
    return cv, cs


def _monomials_np(xi):
    if len(xi) == 2:
        x, y = xi
        return np.array([1, x, y, x * x, x * y, y * y])
    x, y, z = xi
    return np.array([1, x, y, z, x * x, y * y, z * z, x * y, x * z, y * z])


def _simplex_integral(P, mono):
    """∫ mono over the simplex with vertices P (physical measure), basix degree-4 rule."""
    import basix
    cell = {1: basix.CellType.interval, 2: basix.CellType.triangle, 3: basix.CellType.tetrahedron}[len(P) - 1]
    pts, wts = basix.make_quadrature(cell, 4)
    return (wts / wts.sum() * _measure(np.ascontiguousarray(P))) @ mono(P[0] + pts @ (P[1:] - P[0]))


def _hull_moments(P, mono):
    from scipy.spatial import Delaunay
    return sum(_simplex_integral(P[simp], mono) for simp in Delaunay(P).simplices)


def _planar_moments(P, mono):
    if P.shape[1] == 2:
        return _simplex_integral(P, mono)
    c = P.mean(axis=0)
    normal = np.cross(P[1] - P[0], P[2] - P[0])
    e1 = (P[0] - c) / np.linalg.norm(P[0] - c)
    e2 = np.cross(normal / np.linalg.norm(normal), e1)
    P = P[np.argsort(np.arctan2((P - c) @ e2, (P - c) @ e1))]
    return sum(_simplex_integral(P[[0, k, k + 1]], mono) for k in range(1, len(P) - 1))
