"""Bond kernels of the dual-horizon bond-based model (eqs 2, 3, 9–11). Arrays only; NumPy twins
in ``reference.py``, compared in tests/pd/test_kernels.py.

Per owned bond b = (p → q), q in H_p: ``nbr[b]`` = q, ``owner[b]`` = p, reference length
``length[b]`` = |ξ|, volume correction ``beta[b]``, critical stretch ``s0[b]``, ``intact[b]``
(μ of eq 9: 1 intact, 0 broken, never restored). Per point: current position ``y`` (N, 3),
micromodulus ``modulus`` C(δ_p) (eq 4) and volume ``vol``. The bond pulls q toward p with
C_p β s V_p V_q along the deformed bond (eq 3) and p toward q with the same force.
"""
from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True)
def _stretch(y, i, j, length):
    """s = (|y_j − y_i| − |ξ|)/|ξ| and the unit vector from i to j."""
    e0 = y[j, 0] - y[i, 0]
    e1 = y[j, 1] - y[i, 1]
    e2 = y[j, 2] - y[i, 2]
    r = np.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
    return (r - length) / length, e0 / r, e1 / r, e2 / r


@numba.njit(parallel=True, cache=True)
def break_bonds(y, offsets, nbr, length, beta, s0, intact, modulus, vol):
    """Break every intact bond whose stretch reached its s0 (eq 10; tension only), in place.
    Returns per owner (elastic energy of its intact bonds, energy its bonds held when they broke
    now) [J]: ½ C_p β s² |ξ| V_p V_q each."""
    n = offsets.shape[0] - 1
    elastic = np.zeros(n)
    released = np.zeros(n)
    for p in numba.prange(n):
        ep = 0.0
        rp = 0.0
        for b in range(offsets[p], offsets[p + 1]):
            if intact[b] == 0:
                continue
            q = nbr[b]
            s, _, _, _ = _stretch(y, p, q, length[b])
            w = 0.5 * modulus[p] * beta[b] * s * s * length[b] * vol[p] * vol[q]
            if s >= s0[b]:
                intact[b] = 0
                rp += w
            else:
                ep += w
        elastic[p] = ep
        released[p] = rp
    return elastic, released


@numba.njit(parallel=True, cache=True)
def force_density(y, offsets, nbr, dual_offsets, dual_bond, owner, length, beta, intact, modulus, vol, out):
    """The bond force density on every point [N/m³] into ``out`` (N, 3): eq 2 in the discrete
    form of eq 11, the first sum over the bonds owned by others that reach i (dual horizon H'_i),
    the second over the bonds i owns (H_i). One pass per point, so no two threads write one row."""
    n = offsets.shape[0] - 1
    for i in numba.prange(n):
        f0 = 0.0
        f1 = 0.0
        f2 = 0.0
        ci = modulus[i]
        for b in range(offsets[i], offsets[i + 1]):
            if intact[b] == 0:
                continue
            q = nbr[b]
            s, e0, e1, e2 = _stretch(y, i, q, length[b])
            g = ci * beta[b] * s * vol[q]
            f0 += g * e0
            f1 += g * e1
            f2 += g * e2
        for k in range(dual_offsets[i], dual_offsets[i + 1]):
            b = dual_bond[k]
            if intact[b] == 0:
                continue
            p = owner[b]
            s, e0, e1, e2 = _stretch(y, i, p, length[b])
            g = modulus[p] * beta[b] * s * vol[p]
            f0 += g * e0
            f1 += g * e1
            f2 += g * e2
        out[i, 0] = f0
        out[i, 1] = f1
        out[i, 2] = f2


@numba.njit(parallel=True, cache=True)
def damage(offsets, nbr, beta, intact, vol):
    """D of eq 9 per point: 1 − (volume of the intact bonds' neighbours) / (volume of all of them)."""
    n = offsets.shape[0] - 1
    out = np.zeros(n)
    for p in numba.prange(n):
        whole = 0.0
        kept = 0.0
        for b in range(offsets[p], offsets[p + 1]):
            w = beta[b] * vol[nbr[b]]
            whole += w
            kept += w * intact[b]
        out[p] = 1.0 - kept / whole if whole > 0.0 else 0.0
    return out
