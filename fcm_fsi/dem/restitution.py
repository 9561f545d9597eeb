"""Restitution and damping of the linear spring–dashpot contact (paper eq 20, tutorial §5).

c = 2 h √(m* k) with h = −ln e / √(ln² e + π²) gives restitution e when the normal force may
turn attractive; clipped at zero (the default of ``dem.contact``) the sphere leaves earlier,
with a higher restitution (:func:`restitution_clipped`).
"""
from __future__ import annotations

import math


def damping_ratio(e: float) -> float:
    """h of eq 20 for restitution e in (0, 1]."""
    if e >= 1.0:
        return 0.0
    le = math.log(e)
    return -le / math.sqrt(le * le + math.pi ** 2)


def restitution_unclipped(h: float) -> float:
    """e = exp(−hπ/√(1−h²)) of the linear spring–dashpot with attraction allowed."""
    return math.exp(-h * math.pi / math.sqrt(1 - h * h))


def restitution_clipped(h: float) -> float:
    """Closed-form restitution of the linear spring–dashpot whose force is clipped at 0.

    In units ω₀ = √(k/m*) = 1: δ'' + 2hδ' + δ = 0, δ(0) = 0, δ'(0) = 1 gives
    δ = e^{−ht} sin(ω_d t)/ω_d with ω_d = √(1−h²). The force kδ + cδ' ∝
    (1 − 2h²) sin ω_d t + 2hω_d cos ω_d t first vanishes at
    ω_d t* = π − atan2(2hω_d, 1 − 2h²), before δ returns to 0; the body separates there
    and e = −δ'(t*). (e = 0.2 → 0.3249, 0.5 → 0.5503, 0.9 → 0.9020.)
    """
    if h == 0.0:
        return 1.0
    wd = math.sqrt(1 - h * h)            # in units of ω₀
    # F ∝ δ + 2h δ'  (units ω₀ = 1): e^{-ht}[ (1 − 2h²) sin(wd t) + 2h wd cos(wd t) ] / wd = 0
    t_star = (math.pi - math.atan2(2 * h * wd, 1 - 2 * h * h)) / wd
    dv = math.exp(-h * t_star) * (math.cos(wd * t_star) - h / wd * math.sin(wd * t_star))
    return -dv
