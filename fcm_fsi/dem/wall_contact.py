"""Contact of spheres with the case's static walls (planes and triangle meshes), paper eqs
18–20 with the law of :mod:`.contact` (m* the block's mass): the Numba kernels, one pass over the
blocks (``wall_forces``), and the :class:`WallContact` interaction. A wall can be removed at a
given time (``until``: a gate). Tested against :func:`.contact_reference.wall_forces_ref`.
"""
from __future__ import annotations

import math

import numba as nb
import numpy as np

from ..geometry.surface_distance import closest_point_triangle
from . import L_DASHPOT, L_FRICTION, L_SPRING
from .contact import HIST, Materials, _add_load, _law, _pointvel, _release, material_table


@nb.njit(cache=True)
def _wall_contact(s, w, b, r, px, py, pz, delta, nx, ny, nz, wm, sph_material, pos, vel, omega, mass,
                  hist, held, tab, clip, dt, force, torque):
    """One sphere–wall contact (or release) of sphere s of block b with wall w (normal n into
    the sphere's side, overlap delta, wall material wm): adds into force[b], torque[b], updates
    hist[s, w] and held[s, w]; returns (spring energy, dashpot loss, slider loss). Not inlined:
    called only for the few spheres in reach of a wall."""
    a = r - 0.5 * delta
    cx = px + a * nx
    cy = py + a * ny
    cz = pz + a * nz
    rx = cx - pos[b, 0]
    ry = cy - pos[b, 1]
    rz = cz - pos[b, 2]
    ux, uy, uz = _pointvel(vel, omega, b, rx, ry, rz)
    ma = sph_material[s]
    k = tab[ma, wm, 0]
    kt = tab[ma, wm, 1]
    h = tab[ma, wm, 2]
    mu = tab[ma, wm, 3]
    if delta <= 0.0:
        dd, FN = _release(delta, nx, ny, nz, ux, uy, uz, hist[s, w], k, mass[b], dt)
        held[s, w] = 0
        if FN != 0.0:
            _add_load(force, torque, b, -FN * nx, -FN * ny, -FN * nz, rx, ry, rz)
        return 0.0, dd, 0.0
    c = 2.0 * h * math.sqrt(mass[b] * k)
    ct = 2.0 * h * math.sqrt(mass[b] * kt)
    fx, fy, fz, es, dd, df = _law(delta, nx, ny, nz, ux, uy, uz, hist[s, w],
                                  k, kt, c, ct, mu, clip, dt, mass[b])
    held[s, w] = 1
    _add_load(force, torque, b, fx, fy, fz, rx, ry, rz)
    return es, dd, df


@nb.njit(cache=True)
def _wall_one(s, w, b, r, px, py, pz, sph_material, pos, vel, omega, mass, planes, plane_mat, tris, tri_mesh,
              mesh_mat, active, hist, held, tab, clip, dt, force, torque):
    """Sphere s (of block b, centre p, radius r) against wall w when it is in reach or has a
    history (see :func:`wall_forces`). Returns (spring energy, dashpot loss, slider loss)."""
    npl = planes.shape[0]
    if not active[w]:
        delta = -1.0
        nx, ny, nz = 0.0, 0.0, 1.0
        wm = 0
        hist[s, w, 7] = 0.0        # no release correction for a removed wall
    elif w < npl:
        gap = planes[w, 0] * px + planes[w, 1] * py + planes[w, 2] * pz - planes[w, 3]
        delta = r - gap
        nx, ny, nz = -planes[w, 0], -planes[w, 1], -planes[w, 2]
        wm = plane_mat[w]
    else:
        m = w - npl
        best = 1e300
        qx = qy = qz = 0.0
        for t in range(tris.shape[0]):
            if tri_mesh[t] != m:
                continue
            cx, cy, cz = closest_point_triangle(px, py, pz, tris[t, 0], tris[t, 1], tris[t, 2])
            d2 = (px - cx) ** 2 + (py - cy) ** 2 + (pz - cz) ** 2
            if d2 < best:
                best = d2
                qx, qy, qz = cx, cy, cz
        gap = math.sqrt(best)
        delta = r - gap
        if gap > 0.0:
            nx, ny, nz = (qx - px) / gap, (qy - py) / gap, (qz - pz) / gap
        else:
            nx = ny = nz = 0.0
        wm = mesh_mat[m]
    if delta <= 0.0 and hist[s, w, 3] == 0.0 and hist[s, w, 4] == 0.0 and \
            hist[s, w, 5] == 0.0 and hist[s, w, 6] == 0.0 and hist[s, w, 7] <= 0.0:
        for q in range(hist.shape[2]):
            if hist[s, w, q] != 0.0:
                hist[s, w, q] = 0.0
        held[s, w] = 0
        return 0.0, 0.0, 0.0
    if nx == 0.0 and ny == 0.0 and nz == 0.0:
        for q in range(hist.shape[2]):
            hist[s, w, q] = 0.0
        held[s, w] = 0
        return 0.0, 0.0, 0.0
    return _wall_contact(s, w, b, r, px, py, pz, delta, nx, ny, nz, wm, sph_material, pos, vel, omega,
                         mass, hist, held, tab, clip, dt, force, torque)


@nb.njit(cache=True, inline="always")
def _block_walls(b, blk_sph_start, sph_pos, sph_radius, sph_material, pos, vel, omega, mass,
                 planes, plane_mat, tris, tri_mesh, mesh_mat, nmesh, active, hist, held, tab, clip, dt,
                 force, torque):
    """Wall contacts of the spheres of (free) block b (see :func:`wall_forces`); adds into
    force[b], torque[b]; returns (spring energy, dashpot loss, slider loss)."""
    npl = planes.shape[0]
    e_s = 0.0
    d_d = 0.0
    d_f = 0.0
    for s in range(blk_sph_start[b], blk_sph_start[b + 1]):
        r = sph_radius[s]
        px, py, pz = sph_pos[s, 0], sph_pos[s, 1], sph_pos[s, 2]
        for w in range(npl + nmesh):
            if held[s, w] == 0:
                if not active[w]:
                    continue
                if w < npl and r <= planes[w, 0] * px + planes[w, 1] * py + planes[w, 2] * pz - planes[w, 3]:
                    continue                # out of reach, history all zero: nothing to do
            es, dd, df = _wall_one(s, w, b, r, px, py, pz, sph_material, pos, vel, omega, mass, planes, plane_mat,
                                   tris, tri_mesh, mesh_mat, active, hist, held, tab, clip, dt, force, torque)
            e_s += es
            d_d += dd
            d_f += df
    return e_s, d_d, d_f


@nb.njit(cache=True, parallel=True)
def wall_forces(blk_sph_start, sph_pos, sph_radius, sph_material, pos, vel, omega, mass, fixed,
                planes, plane_mat, tris, tri_mesh, mesh_mat, nmesh, active, hist, held,
                mat_k, mat_kt, mat_h, mat_mu, clip, dt, force, torque):
    """Sphere–wall contact: half-spaces ``planes`` (n_x, n_y, n_z, d) with the unit normal n
    pointing into the domain (spheres live where n·x ≥ d) and triangle meshes (one
    contact per sphere and mesh: the nearest triangle); walls with ``active[w]`` False are
    skipped (their contacts released). History ``hist`` is (ns, nplanes + nmesh, HIST);
    ``held`` (ns, nplanes + nmesh) uint8 is 1 where that history may be non-zero and 0 where
    it is all zero (kept up to date here): a sphere out of reach of a plane with ``held`` 0
    is skipped after the gap test, without touching its history (the common case).
    Adds into force/torque; returns (spring energy, dashpot loss, slider loss)."""
    tab = material_table(mat_k, mat_kt, mat_h, mat_mu)
    e_s = 0.0
    d_d = 0.0
    d_f = 0.0
    for b in nb.prange(pos.shape[0]):
        if fixed[b]:
            continue
        es, dd, df = _block_walls(b, blk_sph_start, sph_pos, sph_radius, sph_material, pos, vel, omega, mass,
                                  planes, plane_mat, tris, tri_mesh, mesh_mat, nmesh, active, hist, held, tab,
                                  clip, dt, force, torque)
        e_s += es
        d_d += dd
        d_f += df
    return e_s, d_d, d_f


class WallContact:
    """Interaction: spheres against static planes (boxes are 6 inward planes) and
    triangle meshes."""

    name = "walls"

    def __init__(self, materials: Materials, planes, plane_mat, tris, tri_mesh, mesh_mat, ns,
                 clip_normal: bool = True, until=None):
        self.mat = materials
        self.clip = bool(clip_normal)
        self.planes = np.asarray(planes, np.float64).reshape(-1, 4)
        self.plane_mat = np.asarray(plane_mat, np.int64).reshape(-1)
        self.tris = np.asarray(tris, np.float64).reshape(-1, 3, 3)
        self.tri_mesh = np.asarray(tri_mesh, np.int64).reshape(-1)
        self.mesh_mat = np.asarray(mesh_mat, np.int64).reshape(-1)
        self.hist = np.zeros((ns, len(self.planes) + len(self.mesh_mat), HIST))
        self.held = np.zeros(self.hist.shape[:2], np.uint8)     # 1 where hist may be non-zero
        nw = self.hist.shape[1]
        self.until = np.full(nw, np.inf) if until is None else np.asarray(until, np.float64).reshape(nw)

    def add_forces(self, state, force, torque, ledger, dt):
        if self.hist.shape[1] == 0:
            return
        m = self.mat
        es, dd, df = wall_forces(state.blk_sph_start, state.sph_pos, state.sph_radius, state.sph_material,
                                 state.pos, state.vel, state.omega, state.mass, state.fixed,
                                 self.planes, self.plane_mat, self.tris, self.tri_mesh, self.mesh_mat,
                                 len(self.mesh_mat), self.until > state.t, self.hist, self.held,
                                 m.k, m.kt, m.h, m.mu, self.clip, dt,
                                 force, torque)
        ledger[L_SPRING] += es
        ledger[L_DASHPOT] += dd
        ledger[L_FRICTION] += df

    def material_table(self):
        """Mixed (k, k_t, h, μ) per material pair (for the fused step)."""
        if getattr(self, "_tab", None) is None:
            m = self.mat
            self._tab = material_table(m.k, m.kt, m.h, m.mu)
        return self._tab

    def stiffness_bound(self):
        return float(self.mat.k.max()), float(self.mat.h.max())

    def checkpoint_arrays(self):
        return {"hist": self.hist}

    def restore(self, arrays):
        self.hist = np.asarray(arrays["hist"], np.float64).reshape(self.hist.shape)
        self.held = np.any(self.hist != 0.0, axis=2).astype(np.uint8)
