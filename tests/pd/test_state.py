"""The ordinary state-based model (eqs 5–8, 3D, dual horizon): kernels against their NumPy twins,
the classical energy density and zero interior force of homogeneous deformations, forces as the
gradient of the energy, the critical stretch, the stable step and energy conservation."""
import math

import numpy as np
import pytest

from fcm_fsi.config.loader import ConfigError, build
from fcm_fsi.config.pd import PDConfig
from fcm_fsi.pd import reference as ref
from fcm_fsi.pd import state
from fcm_fsi.pd.builder import body_stable_time_step, build_system, lattice_stable_time_step
from fcm_fsi.pd.lattice import lattice_points
from fcm_fsi.pd.material import (
    bulk_and_shear,
    critical_stretch,
    influence,
    state_critical_stretch,
    weighted_volume,
)
from fcm_fsi.pd.neighbours import bond_lists, transpose

E, RHO = 30.0e9, 2400.0


def cube(nu=0.2, points=16, factor=3.015, **over):
    d = {"model": "state_based", "formulation": "3d",
         "material": {"youngs_modulus": E, "density": RHO, "poisson_ratio": nu},
         "lattice": {"lower": [0, 0, 0], "upper": [points * 1e-3] * 3, "spacing": 1e-3}, "horizon_factor": factor,
         "dt": 1e-12}
    d.update(over)
    return build(PDConfig, d, source="t.yaml", prefix="pd")


def classical_energy(nu, eps):
    """½ ε:C:ε = K (tr ε)²/2 + G ε_d:ε_d [J/m³]."""
    k, g = bulk_and_shear(E, nu)
    dev = eps - np.trace(eps) / 3.0 * np.eye(3)
    return 0.5 * k * np.trace(eps) ** 2 + g * (dev * dev).sum()


def strains():
    rng = np.random.default_rng(7)
    general = rng.normal(size=(3, 3))
    return {"pure_shear": np.array([[0, 1, 0], [1, 0, 0], [0, 0, 0]]) * 1e-6,
            "uniaxial": np.diag([1e-6, 0, 0]),
            "general": 0.5 * (general + general.T) * 1e-6}


def energy_density(s):
    """W_p per point [J/m³] at the current displacement (no bond breaks: s0 = ∞ here)."""
    b, law = s.bonds, s.law
    elastic, _ = state.state_update(s.x + s.u, b.offsets, b.nbr, b.length, b.beta, law.omega, b.s0,
                                    b.intact.copy(), s.vol, law.mvol, law.bulk, law.shear, law.theta.copy())
    return elastic / s.vol


def body(seed=0, broken=0.1):
    """A perturbed 3D lattice with a horizon per point, random β, broken bonds, s0 and moduli."""
    rng = np.random.default_rng(seed)
    x = lattice_points([0, 0, 0], [0.008, 0.006, 0.005], 0.001)
    x += rng.normal(0.0, 5e-5, x.shape)
    horizon = rng.uniform(0.0022, 0.0032, len(x))
    offsets, nbr = bond_lists(x, horizon)
    owner = np.repeat(np.arange(len(x)), np.diff(offsets))
    dual_offsets, dual_bond = transpose(offsets, nbr)
    length = np.linalg.norm(x[nbr] - x[owner], axis=1)
    beta = rng.uniform(0.5, 1.0, len(nbr))
    vol = rng.uniform(0.9e-9, 1.1e-9, len(x))
    omega = influence(length, horizon[owner])
    mvol = weighted_volume(owner, nbr, length, beta, omega, vol, len(x))
    return dict(y=x + rng.normal(0.0, 1e-5, x.shape), offsets=offsets, nbr=nbr, owner=owner, dual_offsets=dual_offsets,
                dual_bond=dual_bond, length=length, beta=beta, omega=omega, vol=vol, mvol=mvol,
                intact=(rng.uniform(size=len(nbr)) > broken).astype(np.uint8), s0=rng.uniform(0.0, 0.02, len(nbr)),
                bulk=rng.uniform(1e10, 2e10, len(x)), shear=rng.uniform(0.5e10, 1e10, len(x)))


def test_state_kernels_match_their_twins_and_conserve_momentum():
    b = body()
    keys = ("y", "offsets", "nbr", "length", "beta", "omega", "s0")
    tail = ("vol", "mvol", "bulk", "shear")
    i1, i2 = b["intact"].copy(), b["intact"].copy()
    th1, th2 = np.zeros(len(b["y"])), np.zeros(len(b["y"]))
    e1, r1 = state.state_update(*[b[k] for k in keys], i1, *[b[k] for k in tail], th1)
    e2, r2 = ref.state_update(*[b[k] for k in keys], i2, *[b[k] for k in tail], th2)
    assert np.array_equal(i1, i2) and (i1 < b["intact"]).any()
    assert np.allclose(th1, th2, rtol=1e-12, atol=1e-14 * np.abs(th2).max())
    assert np.allclose(e1, e2, rtol=1e-10, atol=1e-12 * np.abs(e2).max())
    assert np.allclose(r1, r2, rtol=1e-10, atol=1e-12 * np.abs(r2).max()) and np.abs(r1).max() > 0
    args = [b[k] for k in ("y", "offsets", "nbr", "dual_offsets", "dual_bond", "owner", "length", "beta", "omega")]
    f, g = np.zeros_like(b["y"]), np.zeros_like(b["y"])
    state.state_force_density(*args, i1, b["vol"], b["mvol"], th1, b["bulk"], b["shear"], f)
    ref.state_force_density(*args, i1, b["vol"], b["mvol"], th1, b["bulk"], b["shear"], g)
    scale = np.abs(g).max()
    assert scale > 0 and np.abs(f - g).max() <= 1e-12 * scale
    total = (f * b["vol"][:, None]).sum(axis=0)                       # each bond's action and reaction
    assert np.abs(total).max() <= 1e-12 * (np.abs(f) * b["vol"][:, None]).sum()


def test_forces_are_the_gradient_of_the_elastic_energy():
    """f_i V_i = −∂(Σ W_p V_p)/∂y_i (t = ∂W/∂e of eq 6): the work of f along a displacement
    increment equals the energy change, by central differences."""
    b = body(seed=2, broken=0.0)
    b["s0"][:] = np.inf
    rng = np.random.default_rng(5)
    du = rng.normal(0.0, 1e-9, b["y"].shape)

    def energy(y):
        th = np.zeros(len(y))
        e, _ = state.state_update(y, *[b[k] for k in ("offsets", "nbr", "length", "beta", "omega", "s0")],
                                  b["intact"].copy(), b["vol"], b["mvol"], b["bulk"], b["shear"], th)
        return e.sum(), th

    _, th = energy(b["y"])
    f = np.zeros_like(b["y"])
    state.state_force_density(*[b[k] for k in ("y", "offsets", "nbr", "dual_offsets", "dual_bond", "owner",
                                               "length", "beta", "omega", "intact", "vol", "mvol")], th, b["bulk"],
                              b["shear"], f)
    work = (f * b["vol"][:, None] * du).sum()
    change = energy(b["y"] + du)[0] - energy(b["y"] - du)[0]
    assert change == pytest.approx(-2.0 * work, rel=1e-6)


@pytest.mark.parametrize("nu", [0.2, 0.3])
def test_interior_energy_density_of_a_homogeneous_strain_is_classical(nu):
    """An interior lattice point (δ = 3.015 Δx, β partial volumes, Gaussian ω): θ = tr ε exactly
    (the stencil's second moment Σ ω ξ⊗ξ βV is m I/3 by cubic symmetry), so the bulk part is
    exact; the deviatoric part carries the stencil's fourth moment, isotropic only up to the
    cubic lattice's anisotropy: measured 0.41 % (pure shear), 0.31 % (uniaxial) at ν = 0.2.
    Tolerance 1 %. The strains are 1e-6, so the finite kinematics add ~1e-6."""
    s = build_system(cube(nu, points=10))
    centre = np.argmin(np.linalg.norm(s.x - s.x.mean(axis=0), axis=1))
    for name, eps in strains().items():
        s.u[:] = s.x @ eps.T
        s._update_bonds()
        assert s.law.theta[centre] == pytest.approx(np.trace(eps), rel=1e-5, abs=1e-11), name
        w = energy_density(s)[centre]
        assert w == pytest.approx(classical_energy(nu, eps), rel=0.01), name


def test_a_linear_displacement_field_leaves_interior_points_without_force():
    """u = A x with A general (stretch, shear and rotation): every point whose family and its
    families' families lie in the body (2 hops of δ + Δx/2) feels no force, to round-off
    (each bond ξ of a point has its mirror −ξ with the same force state)."""
    s = build_system(cube(0.3, points=16))
    a = np.random.default_rng(3).normal(size=(3, 3)) * 1e-4
    s.u[:] = s.x @ a.T
    s._update_bonds()
    k = np.round(s.x / 1e-3 - 0.5).astype(int)
    inner = np.all((k >= 6) & (k <= 9), axis=1)
    scale = np.abs(s.f).max()
    assert inner.sum() == 64 and scale > 0
    assert np.abs(s.f[inner]).max() <= 1e-9 * scale


def test_state_critical_stretch_is_the_bond_based_one_at_a_quarter_poisson():
    """Madenci & Oterkus's s0 = √(G0/((3G + (3/4)⁴(K − 5G/3)) δ)): at ν = 1/4, K = 5G/3 and it is
    the bond-based √(5G0/(6Eδ)); a larger ν (stiffer in bulk) breaks at a smaller stretch."""
    k, g = bulk_and_shear(E, 0.25)
    assert state_critical_stretch(k, g, 25.0, 0.003) == pytest.approx(critical_stretch("3d", E, 25.0, 0.003),
                                                                       rel=1e-12)
    k3, g3 = bulk_and_shear(E, 0.3)
    assert state_critical_stretch(k3, g3, 25.0, 0.003) < state_critical_stretch(k, g, 25.0, 0.003)


def largest_stable_step(s, iterations=200) -> float:
    """2/ω_max of the body's linearised stiffness (power iteration with the force kernel): the
    exact stability limit of velocity Verlet."""
    v = np.random.default_rng(0).normal(size=s.x.shape)
    h, lam = 1e-10, 0.0
    for _ in range(iterations):
        v /= np.linalg.norm(v)
        s.u[:] = h * v
        s._update_bonds()
        w = -s.f / (h * s.rho)
        lam, v = float((v * w).sum()), w
    return 2.0 / math.sqrt(lam)


@pytest.mark.parametrize("nu", [0.2, 0.45])
def test_stable_step_bound_is_safe_and_refuses_a_larger_dt(nu):
    """The Silling–Askari bound with the state-based bond stiffness (15G + 3|3K − 5G|) ω/m lies
    below the exact limit 2/ω_max and within a factor 3 of it (measured 0.47 at ν = 0.2, 0.41 at
    0.45; the bond-based bound is 0.47 of its exact limit); dt above it is refused."""
    cfg = cube(nu, points=7)
    dt_crit = lattice_stable_time_step(cfg)
    assert dt_crit == body_stable_time_step(cfg)
    exact = largest_stable_step(build_system(cfg))
    assert 0.33 * exact < dt_crit < exact
    build_system(cube(nu, points=7, dt=0.99 * dt_crit))
    with pytest.raises(ConfigError) as err:
        build_system(cube(nu, points=7, dt=1.01 * dt_crit))
    assert "pd.dt" in str(err.value) and f"{dt_crit:.4g}" in str(err.value)


def vibration_drift(dt_fraction: float) -> float:
    """Largest |E − E0|/E0 over one period of a free bar 12 × 4 × 4 Δx vibrating in its
    fundamental longitudinal mode (plus a transverse velocity), state-based, ν = 0.2."""
    over = {"lattice": {"lower": [0, 0, 0], "upper": [0.012, 0.004, 0.004], "spacing": 1e-3},
            "initial_velocity": [{"velocity": [0.05, 0.02, 0.0], "profile": "half_cosine", "axis": 0}]}
    cfg = cube(0.2, **over)
    dt = dt_fraction * lattice_stable_time_step(cfg)
    s = build_system(cube(0.2, dt=dt, **over))
    e0 = s.kinetic() + s.elastic
    worst = 0.0
    while s.t < 2 * 0.012 / math.sqrt(E / RHO):
        s.step()
        worst = max(worst, abs((s.kinetic() + s.elastic) / e0 - 1.0))
    return worst


def test_an_undamaged_vibrating_state_based_body_conserves_energy():
    """Velocity Verlet's energy error is bounded and second order: halving dt cuts the largest
    |E − E0|/E0 over a period by ≈ 4 (pass: order ≥ 1.8, and below 3e-3 at 0.4 Δt_crit;
    measured 6.9e-3, 1.69e-3, 4.2e-4 at 0.8, 0.4, 0.2 Δt_crit: the thin bar's initial field
    excites its short waves, for which ω dt is largest)."""
    coarse, fine = vibration_drift(0.4), vibration_drift(0.2)
    assert coarse < 3e-3
    assert math.log2(coarse / fine) >= 1.8, (coarse, fine)


@pytest.mark.parametrize("change, key", [
    ({"formulation": "plane_strain", "lattice": {"lower": [0, 0], "upper": [0.01, 0.01], "spacing": 1e-3}},
     "pd.formulation"),
    ({"material": {"youngs_modulus": E, "density": RHO}}, "pd.material.poisson_ratio"),
])
def test_state_based_sections_are_checked(change, key):
    with pytest.raises(ConfigError) as err:
        cube(**change)
    assert key in str(err.value)
