"""Kernels of the dual-horizon ordinary state-based model (seed eqs 5–9, 3D). Arrays only; NumPy
twins in ``reference.py``, compared in tests/pd/test_state.py.

Per owned bond b = (p → q), q in H_p: as in ``forces.py`` (``nbr``, ``length`` |ξ|, ``beta``,
``s0``, ``intact``) plus its influence ``omega`` ω = exp(−|ξ|²/δ_p²) (eq 8). Per point: the
weighted volume ``mvol`` m_p = Σ ω |ξ|² β V_q over all its bonds (eq 7, reference
configuration), bulk and shear moduli ``bulk`` K, ``shear`` G [Pa], volume ``vol``.

Point p owns its family: its dilatation θ_p = (3/m_p) Σ μ ω |ξ| e β V_q (extension
e = |ξ+η| − |ξ|) and the force state of each owned bond (eq 6)

    t_b = (3Kθ_p/m_p) ω |ξ| + (15G/m_p) ω e^d,   e^d = e − θ_p |ξ| / 3   [N/m⁶],

which pulls p toward q with t_b β V_q and q toward p with t_b β V_p (its reaction, the dual
horizon's term of eq 2). With one horizon for all points each pair is owned twice and the sum
is Silling et al.'s (2007) T[x]⟨ξ⟩ − T[x']⟨−ξ⟩. The strain energy density of p is
W_p = Kθ²/2 + (15G/2m_p) Σ μ ω (e^d)² β V_q, and t_b β V_q = ∂W_p/∂e_b, so the forces derive
from the total energy Σ W_p V_p.
"""
from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True)
def _extension(y, i, j, length):
    """e = |y_j − y_i| − |ξ| [m] and the unit vector from i to j."""
    e0 = y[j, 0] - y[i, 0]
    e1 = y[j, 1] - y[i, 1]
    e2 = y[j, 2] - y[i, 2]
    r = np.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
    return r - length, e0 / r, e1 / r, e2 / r


@numba.njit(cache=True)
def _energy_density(k, g, m, s_ee, s_ex, s_xx):
    """W = Kθ²/2 + (15G/2m) Σ ω (e − θ|ξ|/3)² βV [J/m³] from the sums Σ ωe²βV, Σ ω|ξ|eβV and
    Σ ω|ξ|²βV over the intact bonds; θ = 3 s_ex / m."""
    theta = 3.0 * s_ex / m
    dev = s_ee - 2.0 * theta / 3.0 * s_ex + theta * theta / 9.0 * s_xx
    return 0.5 * k * theta * theta + 7.5 * g / m * dev, theta


@numba.njit(parallel=True, cache=True)
def state_update(y, offsets, nbr, length, beta, omega, s0, intact, vol, mvol, bulk, shear, theta):
    """Break every intact bond whose stretch e/|ξ| reached its s0 (eq 10; tension only), in place,
    and the dilatation θ of every point after the breaks into ``theta``. Returns per point (elastic
    energy W_p V_p after the breaks, energy released by the breaks (W_before − W_after) V_p) [J]."""
    n = offsets.shape[0] - 1
    elastic = np.zeros(n)
    released = np.zeros(n)
    for p in numba.prange(n):
        m = mvol[p]
        if m <= 0.0:
            theta[p] = 0.0
            continue
        ee0 = ex0 = xx0 = 0.0      # sums before the breaks
        ee1 = ex1 = xx1 = 0.0      # after
        snapped = False
        for b in range(offsets[p], offsets[p + 1]):
            if intact[b] == 0:
                continue
            q = nbr[b]
            x = length[b]
            e, _, _, _ = _extension(y, p, q, x)
            w = omega[b] * beta[b] * vol[q]
            ee0 += w * e * e
            ex0 += w * x * e
            xx0 += w * x * x
            if e >= s0[b] * x:
                intact[b] = 0
                snapped = True
            else:
                ee1 += w * e * e
                ex1 += w * x * e
                xx1 += w * x * x
        w1, th = _energy_density(bulk[p], shear[p], m, ee1, ex1, xx1)
        theta[p] = th
        elastic[p] = w1 * vol[p]
        if snapped:
            w0, _ = _energy_density(bulk[p], shear[p], m, ee0, ex0, xx0)
            released[p] = (w0 - w1) * vol[p]
    return elastic, released


@numba.njit(cache=True)
def _force_state(k, g, m, th, omega, x, e):
    """t of eq 6 [N/m⁶]: (3Kθ/m) ω|ξ| + (15G/m) ω (e − θ|ξ|/3)."""
    return omega * ((3.0 * k - 5.0 * g) * th * x + 15.0 * g * e) / m


@numba.njit(parallel=True, cache=True)
def state_force_density(y, offsets, nbr, dual_offsets, dual_bond, owner, length, beta, omega, intact, vol, mvol,
                        theta, bulk, shear, out):
    """The force density on every point [N/m³] into ``out`` (N, 3): over the bonds i owns, t_b β V_q
    toward q; over the bonds of its dual family (owned by p, reaching i), t_b β V_p toward p
    (eq 2 in the discrete form of eq 11). ``theta`` from :func:`state_update` at the same ``y``."""
    n = offsets.shape[0] - 1
    for i in numba.prange(n):
        f0 = 0.0
        f1 = 0.0
        f2 = 0.0
        for b in range(offsets[i], offsets[i + 1]):
            if intact[b] == 0:
                continue
            q = nbr[b]
            e, n0, n1, n2 = _extension(y, i, q, length[b])
            g = _force_state(bulk[i], shear[i], mvol[i], theta[i], omega[b], length[b], e) * beta[b] * vol[q]
            f0 += g * n0
            f1 += g * n1
            f2 += g * n2
        for k in range(dual_offsets[i], dual_offsets[i + 1]):
            b = dual_bond[k]
            if intact[b] == 0:
                continue
            p = owner[b]
            e, n0, n1, n2 = _extension(y, i, p, length[b])
            g = _force_state(bulk[p], shear[p], mvol[p], theta[p], omega[b], length[b], e) * beta[b] * vol[p]
            f0 += g * n0
            f1 += g * n1
            f2 += g * n2
        out[i, 0] = f0
        out[i, 1] = f1
        out[i, 2] = f2
