"""Plain-NumPy twins of the Numba kernels of ``neighbours.py`` and ``forces.py`` (same
arguments, same results), for the tests."""
from __future__ import annotations

import numpy as np


def bond_lists(x: np.ndarray, horizon: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Every q ≠ p with |x_q − x_p| ≤ δ_p, by all pairs (O(N²)); ascending q within a point."""
    d2 = ((x[:, None, :] - x[None, :, :]) ** 2).sum(axis=2)
    hit = d2 <= (horizon[:, None] ** 2) * (1.0 + 1e-12)
    np.fill_diagonal(hit, False)
    p, q = np.nonzero(hit)
    offsets = np.zeros(len(x) + 1, np.int64)
    np.cumsum(np.bincount(p, minlength=len(x)), out=offsets[1:])
    return offsets, q.astype(np.int64)


def notch_keep(x, offsets, nbr, notches) -> np.ndarray:
    owner = np.repeat(np.arange(len(offsets) - 1), np.diff(offsets))
    p, q = x[owner], x[nbr]
    keep = np.ones(len(nbr), bool)
    for a, b, c in notches:
        if np.isnan(c[0]):
            def orient(u, v, w):
                return (v[..., 0] - u[..., 0]) * (w[..., 1] - u[..., 1]) - (v[..., 1] - u[..., 1]) * (w[..., 0] - u[..., 0])
            d1, d2 = orient(a, b, p), orient(a, b, q)
            d3, d4 = orient(p, q, a), orient(p, q, b)
            hit = (d1 * d2 <= 0) & (d3 * d4 <= 0) & ~((d1 == 0) & (d2 == 0))
        else:
            normal = np.cross(b, c)
            d1, d2 = (p - a) @ normal, (q - a) @ normal
            with np.errstate(divide="ignore", invalid="ignore"):
                t = d1 / (d1 - d2)
                r = p + t[:, None] * (q - p) - a
                u, v = r @ b / (b @ b), r @ c / (c @ c)
            hit = (d1 * d2 <= 0) & (d1 != d2) & (u >= 0) & (u <= 1) & (v >= 0) & (v <= 1)
        keep &= ~hit
    return keep


def _bonds(y, owner, nbr, length):
    e = y[nbr] - y[owner]
    r = np.linalg.norm(e, axis=1)
    return (r - length) / length, e / r[:, None]


def break_bonds(y, offsets, nbr, length, beta, s0, intact, modulus, vol):
    owner = np.repeat(np.arange(len(offsets) - 1), np.diff(offsets))
    s, _ = _bonds(y, owner, nbr, length)
    w = 0.5 * modulus[owner] * beta * s * s * length * vol[owner] * vol[nbr]
    live = intact == 1
    snap = live & (s >= s0)
    intact[snap] = 0
    n = len(offsets) - 1
    return (np.bincount(owner, weights=np.where(live & ~snap, w, 0.0), minlength=n),
            np.bincount(owner, weights=np.where(snap, w, 0.0), minlength=n))


def force_density(y, offsets, nbr, dual_offsets, dual_bond, owner, length, beta, intact, modulus, vol, out):
    s, e = _bonds(y, owner, nbr, length)
    g = (modulus[owner] * beta * s * intact)[:, None] * e
    out[:] = 0.0
    np.add.at(out, owner, g * vol[nbr][:, None])
    np.add.at(out, nbr, -g * vol[owner][:, None])


def damage(offsets, nbr, beta, intact, vol):
    owner = np.repeat(np.arange(len(offsets) - 1), np.diff(offsets))
    n = len(offsets) - 1
    whole = np.bincount(owner, weights=beta * vol[nbr], minlength=n)
    kept = np.bincount(owner, weights=beta * vol[nbr] * intact, minlength=n)
    return np.where(whole > 0, 1.0 - kept / np.where(whole > 0, whole, 1.0), 0.0)


def _state_sums(y, owner, nbr, length, beta, omega, live, vol, n):
    e = np.linalg.norm(y[nbr] - y[owner], axis=1) - length
    w = np.where(live, omega * beta * vol[nbr], 0.0)
    return (np.bincount(owner, weights=w * e * e, minlength=n), np.bincount(owner, weights=w * length * e, minlength=n),
            np.bincount(owner, weights=w * length * length, minlength=n)), e


def _state_energy(bulk, shear, m, sums):
    s_ee, s_ex, s_xx = sums
    safe = np.where(m > 0, m, 1.0)
    theta = np.where(m > 0, 3.0 * s_ex / safe, 0.0)
    dev = s_ee - 2.0 * theta / 3.0 * s_ex + theta ** 2 / 9.0 * s_xx
    return np.where(m > 0, 0.5 * bulk * theta ** 2 + 7.5 * shear / safe * dev, 0.0), theta


def state_update(y, offsets, nbr, length, beta, omega, s0, intact, vol, mvol, bulk, shear, theta):
    n = len(offsets) - 1
    owner = np.repeat(np.arange(n), np.diff(offsets))
    live = intact == 1
    before, e = _state_sums(y, owner, nbr, length, beta, omega, live, vol, n)
    snap = live & (e >= s0 * length) & (mvol[owner] > 0)
    intact[snap] = 0
    after, _ = _state_sums(y, owner, nbr, length, beta, omega, intact == 1, vol, n)
    w0, _ = _state_energy(bulk, shear, mvol, before)
    w1, theta[:] = _state_energy(bulk, shear, mvol, after)
    return w1 * vol, (w0 - w1) * vol


def state_force_density(y, offsets, nbr, dual_offsets, dual_bond, owner, length, beta, omega, intact, vol, mvol,
                        theta, bulk, shear, out):
    d = y[nbr] - y[owner]
    r = np.linalg.norm(d, axis=1)
    e = r - length
    p = owner
    t = omega * ((3.0 * bulk[p] - 5.0 * shear[p]) * theta[p] * length + 15.0 * shear[p] * e) / mvol[p]
    g = (t * beta * intact)[:, None] * d / r[:, None]
    out[:] = 0.0
    np.add.at(out, owner, g * vol[nbr][:, None])
    np.add.at(out, nbr, -g * vol[owner][:, None])
