"""NumPy references of the contact kernels (:mod:`.contact`, :mod:`.wall_contact`): the same
law written vectorised over contacts, for the kernel tests."""
from __future__ import annotations

import numpy as np


def _eps_ref(Dk, delta, dprev, grow, aoth, k, c, un, mstar, clip, dt, release):
    """NumPy reference of :func:`_onset_release_eps` (vectorised)."""
    w = dt * dt / mstar
    eps = np.zeros_like(delta)
    ok = np.ones(delta.shape, bool)
    for _ in range(3):
        if release:
            FN = k * eps
        else:
            FN = k * (delta + eps) + c * un
            if clip:
                FN = np.maximum(FN, 0.0)
        den = 2 * delta - 2 * dprev - w * FN + aoth
        ok &= (den < grow) if release else (den > grow)
        eps = np.where(ok, 2 * Dk / np.where(ok, den, 1.0), 0.0)
    return eps


def _release_force_ref(delta, un, hist, k, mstar, dt):
    """NumPy reference of the release correction in :func:`_release`: F_N (≤ 0) per contact."""
    p = hist[:, 7]
    on = (p > 0) & (hist[:, 10] > 0)
    eps = _eps_ref(hist[:, 8] - 0.5 * p * delta, delta, p, delta - p, delta - hist[:, 9], k, 0.0, un, mstar,
                   False, dt, True)
    return np.where(on, k * eps, 0.0)


def _law_ref(delta, n, un, ut, hist, k, kt, c, ct, mu, clip, dt, mstar):
    """NumPy reference of the contact law (eqs 18–20 + slider) for one batch of contacts:
    relative contact velocity split into un, ut; ``hist`` rows = (tangential spring
    elongation (3), previous dashpot normal force, previous tangential dashpot force (3), last
    overlap, deferred onset deficit, self-predicted overlap, last F_N).
    Returns (force on the first body, spring energy, dashpot work, friction work, new history)."""
    inprev = hist[:, 7] > 0
    Dk = np.where(inprev, hist[:, 8], 0.0)
    aoth = np.where(inprev, delta - hist[:, 9], 0.0)
    dprev = np.where(inprev, hist[:, 7], delta - un * dt)
    eps = _eps_ref(Dk, delta, dprev, delta - dprev, aoth, k, c, un, mstar, clip, dt, False)
    eps = np.where(delta + eps < 0, -delta, eps)
    deff = delta + eps
    FN = k * deff + c * un
    if clip:
        FN = np.maximum(FN, 0.0)
    fdn = FN - k * deff
    corr = np.stack([delta, np.where(~inprev & (dprev < 0), 0.5 * dprev * delta, 0.0),
                     2 * delta - dprev - dt * dt * FN / mstar, FN], axis=1)
    d_dash = 0.5 * (fdn + hist[:, 3]) * un * dt
    hh = hist[:, :3]
    h2 = np.sum(hh * hh, axis=1)
    hp = hh - np.sum(hh * n, axis=1)[:, None] * n
    p2 = np.sum(hp * hp, axis=1)
    scale = np.where((h2 > 0) & (p2 > 0), np.sqrt(h2 / np.where(p2 > 0, p2, 1)), 1.0)
    hold = np.where((h2 > 0)[:, None], hp * scale[:, None], hh)
    hh = hold + ut * dt
    ft = -kt[:, None] * hh - ct[:, None] * ut
    ftn = np.linalg.norm(ft, axis=1)
    fmax = mu * FN
    slip = ftn > fmax
    ft_s = ft * np.where(ftn > 0, fmax / np.where(ftn > 0, ftn, 1), 0)[:, None]
    h_s = -ft_s / kt[:, None]
    d_fric = np.where(slip, 0.5 * kt * np.sum((hh - h_s) * (hold + h_s), axis=1), 0.0)
    g = np.where(slip[:, None], 0.0, -ct[:, None] * ut)
    d_dash = d_dash - 0.5 * np.sum((g + hist[:, 4:7]) * ut, axis=1) * dt
    ft = np.where(slip[:, None], ft_s, ft)
    hh = np.where(slip[:, None], h_s, hh)
    f = -FN[:, None] * n + ft
    e_s = 0.5 * k * delta ** 2 + 0.5 * kt * np.sum(hh * hh, axis=1)
    new_hist = np.concatenate([hh, fdn[:, None], g, corr], axis=1)
    return f, e_s, d_dash, d_fric, new_hist


def pair_forces_ref(pairs, hist, sph_pos, sph_radius, sph_block, sph_material, pos, vel, omega,
                    mass, fixed, mat_k, mat_kt, mat_h, mat_mu, clip, dt):
    """Vectorised NumPy version of :func:`pair_forces` + :func:`gather_pair_forces`.
    Returns (force, torque, new_hist, (e_spring, d_dash, d_fric))."""
    i, j = pairs[:, 0], pairs[:, 1]
    d = sph_pos[j] - sph_pos[i]
    dist = np.linalg.norm(d, axis=1)
    delta = sph_radius[i] + sph_radius[j] - dist
    on = delta > 0
    n = d / np.where(dist > 0, dist, 1)[:, None]
    xc = sph_pos[i] + (sph_radius[i] - 0.5 * delta)[:, None] * n
    bi, bj = sph_block[i], sph_block[j]
    u = (vel[bi] + np.cross(omega[bi], xc - pos[bi])) - (vel[bj] + np.cross(omega[bj], xc - pos[bj]))
    mi, mj = mass[bi], mass[bj]
    mstar = np.where(fixed[bi], mj, np.where(fixed[bj], mi, mi * mj / (mi + mj)))
    a, b = sph_material[i], sph_material[j]
    k = 2 * mat_k[a] * mat_k[b] / (mat_k[a] + mat_k[b])
    kt = 2 * mat_kt[a] * mat_kt[b] / (mat_kt[a] + mat_kt[b])
    h = 0.5 * (mat_h[a] + mat_h[b])
    mu = np.minimum(mat_mu[a], mat_mu[b])
    c, ct = 2 * h * np.sqrt(mstar * k), 2 * h * np.sqrt(mstar * kt)
    un = np.sum(u * n, axis=1)
    ut = u - un[:, None] * n
    f, e_s, d_dash, d_fric, new_hist = _law_ref(delta, n, un, ut, hist, k, kt, c, ct, mu, clip, dt, mstar)
    # released contacts: last half of the dashpot trapezoid, release correction, history reset
    rel = 0.5 * hist[:, 3] * un * dt - 0.5 * np.sum(hist[:, 4:7] * ut, axis=1) * dt
    d_dash = np.where(on, d_dash, rel)
    f_rel = -_release_force_ref(delta, un, hist, k, mstar, dt)[:, None] * n
    f[~on] = f_rel[~on]
    new_hist[~on] = 0
    force = np.zeros_like(pos)
    torque = np.zeros_like(pos)
    np.add.at(force, bi, f)
    np.add.at(force, bj, -f)
    np.add.at(torque, bi, np.cross(xc - pos[bi], f))
    np.add.at(torque, bj, np.cross(xc - pos[bj], -f))
    return force, torque, new_hist, (e_s[on].sum(), d_dash.sum(), d_fric[on].sum())


def wall_forces_ref(blk_sph_start, sph_pos, sph_radius, sph_material, sph_block, pos, vel, omega, mass,
                    fixed, planes, plane_mat, hist, mat_k, mat_kt, mat_h, mat_mu, clip, dt):
    """NumPy reference of :func:`wall_forces` for half-space walls only (loops over the
    planes, vectorised over spheres). Returns (force, torque, new_hist, (e, d_dash, d_fric))."""
    force = np.zeros_like(pos)
    torque = np.zeros_like(pos)
    hist = hist.copy()
    tot = np.zeros(3)
    b = sph_block
    live = ~fixed[b]
    for w in range(planes.shape[0]):
        nrm = -planes[w, :3]
        delta = sph_radius - (sph_pos @ planes[w, :3] - planes[w, 3])
        n = np.tile(nrm, (len(delta), 1))
        xc = sph_pos + (sph_radius - 0.5 * delta)[:, None] * n
        u = vel[b] + np.cross(omega[b], xc - pos[b])
        wm = plane_mat[w]
        a = sph_material
        k = 2 * mat_k[a] * mat_k[wm] / (mat_k[a] + mat_k[wm])
        kt = 2 * mat_kt[a] * mat_kt[wm] / (mat_kt[a] + mat_kt[wm])
        h = 0.5 * (mat_h[a] + mat_h[wm])
        mu = np.minimum(mat_mu[a], mat_mu[wm])
        c, ct = 2 * h * np.sqrt(mass[b] * k), 2 * h * np.sqrt(mass[b] * kt)
        un = np.sum(u * n, axis=1)
        ut = u - un[:, None] * n
        H = hist[:, w]
        f, e_s, d_dash, d_fric, new = _law_ref(delta, n, un, ut, H, k, kt, c, ct, mu, clip, dt, mass[b])
        on = (delta > 0) & live
        rel = 0.5 * H[:, 3] * un * dt - 0.5 * np.sum(H[:, 4:7] * ut, axis=1) * dt
        f_rel = -_release_force_ref(delta, un, H, k, mass[b], dt)[:, None] * n   # before H (a view) is updated
        new[~on] = 0.0
        hist[:, w] = np.where(live[:, None], new, H)
        f = np.where(on[:, None], f, np.where(live[:, None], f_rel, 0.0))
        np.add.at(force, b, f)
        np.add.at(torque, b, np.cross(xc - pos[b], f))
        tot += [e_s[on].sum(), np.where(on, d_dash, np.where(live, rel, 0.0)).sum(), d_fric[on].sum()]
    return force, torque, hist, tuple(tot)
