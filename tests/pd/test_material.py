"""Material constants of the bond-based model: the micromodulus of eq 4 gives the classical
strain energy, the critical stretch of eq 10 gives G0 per crack area, the stable step, Weibull G0."""
import math

import numpy as np
import pytest

from fcm_fsi.config.loader import ConfigError, build
from fcm_fsi.config.pd import BOND_BASED_POISSON, PDConfig
from fcm_fsi.pd.builder import build_system, lattice_stable_time_step
from fcm_fsi.pd.material import (
    critical_stretch,
    family_radius,
    micromodulus,
    stable_time_step,
    volume_correction,
    weibull_fracture_energy,
)

E = 2.0e9
FORMS = ("plane_stress", "plane_strain", "3d")


def strain(dim):
    """A general homogeneous small strain: stretch, contraction and shear together."""
    eps = np.zeros((dim, dim))
    eps[0, 0], eps[1, 1], eps[0, 1] = 1e-3, -0.3e-3, 0.4e-3
    eps[1, 0] = eps[0, 1]
    if dim == 3:
        eps[2, 2], eps[0, 2], eps[2, 0] = 0.2e-3, -0.1e-3, -0.1e-3
    return eps


def classical_energy(form, eps):
    """½ ε:C:ε [J/m³] of the isotropic material with the bond-based ν (plane stress: the 2D moduli)."""
    nu = BOND_BASED_POISSON[form]
    mu = E / (2 * (1 + nu))
    lam = E * nu / (1 - nu ** 2) if form == "plane_stress" else E * nu / ((1 + nu) * (1 - 2 * nu))
    return 0.5 * lam * np.trace(eps) ** 2 + mu * (eps * eps).sum()


def directions(dim, n=64):
    """Unit vectors and quadrature weights on the circle / sphere (exact for these polynomials)."""
    if dim == 2:
        th = 2 * np.pi * np.arange(n) / n
        return np.stack([np.cos(th), np.sin(th)], 1), np.full(n, 2 * np.pi / n)
    mu, wmu = np.polynomial.legendre.leggauss(n // 2)
    ph = 2 * np.pi * np.arange(n) / n
    m, p = np.meshgrid(mu, ph, indexing="ij")
    s = np.sqrt(1 - m ** 2)
    dirs = np.stack([s * np.cos(p), s * np.sin(p), m], -1).reshape(-1, 3)
    return dirs, (wmu[:, None] * np.full(n, 2 * np.pi / n)[None, :]).ravel()


@pytest.mark.parametrize("form", FORMS)
def test_micromodulus_stores_the_classical_energy_of_a_homogeneous_deformation(form):
    """W = ∫_H ½ C s² |ξ| dV over the bonds a point owns (dual form) equals ½ ε:C:ε: this is how
    eq 4 is derived, for any strain when ν is the bond-based value."""
    dim = 3 if form == "3d" else 2
    eps, delta = strain(dim), 0.004
    n, w = directions(dim)
    s2 = np.einsum("bi,ij,bj->b", n, eps, n) ** 2
    radial = delta ** (dim + 1) / (dim + 1)                 # ∫_0^δ r · r^(d−1) dr
    c = micromodulus(form, E, BOND_BASED_POISSON[form], delta)
    pd = 0.5 * c * radial * (w * s2).sum()
    assert pd == pytest.approx(classical_energy(form, eps), rel=1e-10)


@pytest.mark.parametrize("form", ("plane_stress", "3d"))
def test_lattice_energy_converges_to_the_classical_one_as_the_horizon_spans_more_points(form):
    """The lattice sum with the volume correction β (interior point): the quadrature error falls
    like Δx/δ (4× finer: at least 3× smaller)."""
    dim = 3 if form == "3d" else 2
    eps = strain(dim)
    errors = []
    for m in (3.015, 12.015):
        dx, delta = 1e-3, m * 1e-3
        k = int(math.ceil(m)) + 1
        ax = np.arange(-k, k + 1) * dx
        g = np.stack(np.meshgrid(*([ax] * dim), indexing="ij"), -1).reshape(-1, dim)
        r = np.linalg.norm(g, axis=1)
        keep = (r > 0) & (r <= family_radius(delta, dx))
        g, r = g[keep], r[keep]
        s = np.einsum("bi,ij,bj->b", g / r[:, None], eps, g / r[:, None])
        c = micromodulus(form, E, BOND_BASED_POISSON[form], delta)
        w = (0.5 * c * volume_correction(r, delta, dx) * s ** 2 * r * dx ** dim).sum()
        errors.append(abs(w / classical_energy(form, eps) - 1))
    assert errors[1] < errors[0] / 3, errors


@pytest.mark.parametrize("form", FORMS)
def test_critical_stretch_makes_a_crack_absorb_g0(form):
    """Eq 10: the bonds crossing a unit crack area, each pair owned twice, hold G0 at stretch s0:
    G = 2 ∫_{ξ·n>0} ½ C s0² |ξ| (ξ·n) dV (each ξ crosses the plane from ξ·n of heights)."""
    dim = 3 if form == "3d" else 2
    delta, g0 = 0.003, 40.0
    x, wx = np.polynomial.legendre.leggauss(16)
    if dim == 2:                                             # ∫_0^π sin θ dθ
        angular = (0.5 * np.pi * wx * np.sin(0.5 * np.pi * (x + 1))).sum()
    else:                                                    # 2π ∫_0^1 cos θ d(cos θ)
        angular = 2 * np.pi * (0.5 * wx * 0.5 * (x + 1)).sum()
    radial = delta ** (dim + 2) / (dim + 2)                 # ∫_0^δ r · r · r^(d−1) dr
    c = micromodulus(form, E, BOND_BASED_POISSON[form], delta)
    s0 = critical_stretch(form, E, g0, delta)
    absorbed = c * s0 ** 2 * radial * angular
    assert absorbed == pytest.approx(g0, rel=1e-10)


def plate(**over):
    d = {"formulation": "plane_strain", "material": {"youngs_modulus": E, "density": 2000.0},
         "lattice": {"lower": [0, 0], "upper": [0.02, 0.01], "spacing": 0.001}, "dt": 1e-9}
    d.update(over)
    return build(PDConfig, d, source="t.yaml", prefix="pd")


def test_stable_step_of_the_stencil_equals_that_of_the_bonds_and_refuses_larger_dt():
    cfg = plate()
    s = build_system(cfg)
    b = s.bonds
    dt_bonds = stable_time_step(2000.0, s.vol, b.owner, b.nbr, b.length, b.beta, s.modulus)
    dt_crit = lattice_stable_time_step(cfg)
    assert dt_bonds == pytest.approx(dt_crit, rel=1e-12)
    # the 1D chain bound, Δx/c with c = √(E/ρ), is of the same order
    assert 0.2 < dt_crit / (1e-3 / math.sqrt(E / 2000.0)) < 2
    build_system(plate(dt=0.99 * dt_crit))
    with pytest.raises(ConfigError) as err:
        build_system(plate(dt=1.01 * dt_crit))
    assert "pd.dt" in str(err.value) and f"{dt_crit:.4g}" in str(err.value)


def test_weibull_fracture_energy_has_the_mean_and_shape_asked_for():
    n, mean, shape = 200_000, 38.0, 6.0
    g = weibull_fracture_energy(mean, shape, n, seed=4)
    sd = mean * math.sqrt(math.gamma(1 + 2 / shape) / math.gamma(1 + 1 / shape) ** 2 - 1)
    assert abs(g.mean() - mean) < 4 * sd / math.sqrt(n)
    shape_est = math.pi / (math.sqrt(6) * np.log(g).std())         # sd of ln G = π / (m √6)
    assert abs(shape_est / shape - 1) < 0.01                       # sampling error ≈ 0.25 % at this n
    assert np.array_equal(g, weibull_fracture_energy(mean, shape, n, seed=4))
    assert not np.array_equal(g, weibull_fracture_energy(mean, shape, n, seed=5))
    assert (weibull_fracture_energy(mean, None, 10, seed=0) == mean).all()
