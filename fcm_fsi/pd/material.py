"""Material constants of the dual-horizon form: bond-based (seed paper eqs 4 and 10) and ordinary
state-based (eqs 6–8: K, G, influence ω, weighted volume m, critical stretch), the volume
correction of the bonds near the horizon's edge, G0 per bond from a Weibull distribution and the
stable time step.

Dual-horizon convention (eq 2): a bond (p, q) with q in the horizon H_p of p is *owned* by p and
acts with the micromodulus C(δ_p) of its owner (eq 3). With one horizon for all points every pair
is owned twice (p → q and q → p), so C of eq 4 is half the micromodulus c of the standard
(single-horizon) form: 3D c = 18K/(πδ⁴) = 6E/(πδ⁴(1−2ν)) = 2C. The strain energy of an owned
bond is ½ C s² |ξ| V_p V_q (J); ``tests/pd/test_material.py`` checks that a homogeneous
deformation then stores the classical energy density.
"""
from __future__ import annotations

import math

import numpy as np

#: eq 4: C δ^k / E per formulation, with the exponent k of δ
_MICROMODULUS = {
    "plane_stress": (lambda nu: 3.0 / (math.pi * (1.0 - nu)), 3),
    "plane_strain": (lambda nu: 3.0 / (math.pi * (1.0 + nu) * (1.0 - 2.0 * nu)), 3),
    "3d": (lambda nu: 3.0 / (math.pi * (1.0 - 2.0 * nu)), 4),
}

#: eq 10 as derived (module docstring of :func:`critical_stretch`): s0² E δ / G0
_STRETCH = {"plane_stress": 4.0 * math.pi / 9.0, "plane_strain": 5.0 * math.pi / 12.0, "3d": 5.0 / 6.0}


def micromodulus(formulation: str, youngs_modulus: float, poisson_ratio: float, horizon, thickness: float = 1.0):
    """C(δ) of eq 4 [N/m⁶ per unit stretch] for horizon(s) ``horizon`` [m]; in 2D divided by the
    ``thickness`` [m], since the point volumes are Δx² × thickness (eq 4 is per unit thickness)."""
    factor, power = _MICROMODULUS[formulation]
    c = factor(poisson_ratio) * youngs_modulus / np.asarray(horizon, float) ** power
    return c if formulation == "3d" else c / thickness


def critical_stretch(formulation: str, youngs_modulus: float, fracture_energy, horizon):
    """s0 of eq 10 [-]: the stretch at which the bonds crossing a unit crack area together hold
    ``fracture_energy`` G0 [J/m²]. Plane stress √(4πG0/(9Eδ)), plane strain √(5πG0/(12Eδ)),
    3D √(5G0/(6Eδ)) — the standard values (Silling & Askari 2005; Ha & Bobaru 2010), which the
    dual-horizon C of eq 4 reproduces because each pair is owned twice. The seed's print of eq 10
    carries an extra π in every denominator; with it a crack would absorb G0/π (checked by
    quadrature in tests/pd/test_material.py)."""
    g = np.asarray(fracture_energy, float)
    return np.sqrt(_STRETCH[formulation] * g / (youngs_modulus * np.asarray(horizon, float)))


def volume_correction(length, horizon, spacing):
    """Fraction β of a neighbour's cell (width Δx) inside the horizon δ, linear in |ξ|: 1 for
    |ξ| ≤ δ − Δx/2, (δ + Δx/2 − |ξ|)/Δx up to δ + Δx/2, 0 beyond (a linear partial-volume
    correction, as compared by Seleson 2014). The family of a point is therefore every point
    within δ + Δx/2: a homogeneous deformation then stores the classical energy to 2.7 % at
    δ = 3.015 Δx in 2D (6.6 % in 3D), the error falling as Δx/δ (tests/pd/test_material.py)."""
    length, horizon, spacing = (np.asarray(a, float) for a in (length, horizon, spacing))
    return np.clip((horizon + 0.5 * spacing - length) / spacing, 0.0, 1.0)


def family_radius(horizon, spacing):
    """δ + Δx/2 [m]: the farthest neighbour with a part of its cell inside the horizon."""
    return np.asarray(horizon, float) + 0.5 * np.asarray(spacing, float)


def weibull_fracture_energy(mean: float, shape: float | None, count: int, seed: int) -> np.ndarray:
    """G0 per bond [J/m²]: Weibull with shape m = ``shape`` and mean ``mean`` (scale mean/Γ(1+1/m)),
    drawn with ``seed``; every bond ``mean`` when ``shape`` is None."""
    if shape is None:
        return np.full(count, float(mean))
    scale = mean / math.gamma(1.0 + 1.0 / shape)
    return scale * np.random.default_rng(seed).weibull(shape, size=count)


def stable_time_step(density, vol, owner, nbr, length, beta, modulus) -> float:
    """Δt_crit = min_i √(2ρ_i / Σ_j V_j c_ij / |ξ_ij|) [s] (the stability bound of Silling &
    Askari 2005 for velocity Verlet / central differences), with the stiffness c_ij of both bonds of the pair in
    the dual form: the bond owned by i (C_i) and the one owned by j (C_j). Arrays per owned bond
    (``owner``, ``nbr``, ``length`` |ξ|, ``beta``) and per point (``density``, ``vol``,
    ``modulus`` C)."""
    return verlet_bound(density, vol, owner, nbr, modulus[owner] * beta / length)


def verlet_bound(density, vol, owner, nbr, bond_stiffness) -> float:
    """min_i √(2ρ_i / Σ_j V_j k_ij) [s] with k of each owned bond (its force density per unit
    extension and neighbour volume, N/m⁶ per m) counted at both ends of the pair."""
    n = len(vol)
    k = bond_stiffness
    stiff = np.bincount(owner, weights=k * vol[nbr], minlength=n) + np.bincount(nbr, weights=k * vol[owner],
                                                                                 minlength=n)
    bonded = stiff > 0
    if not bonded.any():
        return math.inf
    return float(np.sqrt(2.0 * np.asarray(density * np.ones(n))[bonded] / stiff[bonded]).min())


# ------------------------------------------------------------------ ordinary state-based (eqs 5–8)
def bulk_and_shear(youngs_modulus: float, poisson_ratio: float) -> tuple[float, float]:
    """K = E / (3(1 − 2ν)), G = E / (2(1 + ν)) [Pa] (3D isotropic)."""
    return youngs_modulus / (3.0 * (1.0 - 2.0 * poisson_ratio)), youngs_modulus / (2.0 * (1.0 + poisson_ratio))


def influence(length, horizon):
    """ω⟨ξ⟩ = exp(−|ξ|²/δ²) of eq 8 (Gaussian; δ the owner's horizon) [-]."""
    length, horizon = np.asarray(length, float), np.asarray(horizon, float)
    return np.exp(-(length / horizon) ** 2)


def weighted_volume(owner, nbr, length, beta, omega, vol, n: int) -> np.ndarray:
    """m_i = Σ_j ω |ξ|² β V_j over the bonds i owns (eq 7, discrete) [m⁵], in the reference
    configuration with all bonds (constant in time)."""
    return np.bincount(owner, weights=omega * length * length * beta * vol[nbr], minlength=n)


def state_critical_stretch(bulk, shear, fracture_energy, horizon):
    """s0 of a state-based bond [-]: √(G0 / ((3G + (3/4)⁴ (K − 5G/3)) δ)) (Madenci & Oterkus 2014,
    3D ordinary state-based; the seed's eq 10 gives only the bond-based values). At ν = 1/4
    (K = 5G/3) it is the bond-based 3D value √(5G0/(6Eδ))."""
    bulk, shear = np.asarray(bulk, float), np.asarray(shear, float)
    stiff = 3.0 * shear + 0.75 ** 4 * (bulk - 5.0 * shear / 3.0)
    return np.sqrt(np.asarray(fracture_energy, float) / (stiff * np.asarray(horizon, float)))


def state_bond_stiffness(bulk, shear, omega, mvol):
    """Equivalent bond stiffness k = (15G + 3|3K − 5G|) ω / m [N/m⁶ per m] of a state-based bond for
    the Silling–Askari bound (:func:`verlet_bound`). The force state of eq 6 is
    t = (15G/m) ω e + ((3K − 5G)/m) ω |ξ| θ: the first term is a pair spring (the whole model at
    ν = 1/4, where the bound is then exactly the bond-based one); the second couples the bond to
    the dilatation θ = (3/m) Σ ω |ξ| e V of its owner, whose row sum is ≈ 3|3K − 5G| ω/m (exactly
    for a bond of the family's mean weighted length). The resulting bound is 0.41–0.47 of the
    exact limit 2/ω_max (tests/pd/test_state.py). ``bulk``, ``shear``, ``mvol`` per owner of the
    bond, ``omega`` per bond."""
    return (15.0 * shear + 3.0 * np.abs(3.0 * bulk - 5.0 * shear)) * omega / mvol
