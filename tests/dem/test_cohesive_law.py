"""Cohesive law of eq 28: identities, kernel vs NumPy reference, modes, breaking."""
import numpy as np
import pytest
from scipy.integrate import quad

from fcm_fsi.dem.cohesive import point_law_array, shape_g, shape_psi, traction_reference

SC, DF = 1.0e7, 0.02
K0 = 6.75 * SC / DF


def law(dn, dt=None, lam_max=None, broken=None, damage=False, dtc=DF, kpen=K0):
    dn = np.atleast_1d(np.asarray(dn, float))
    dt = np.zeros_like(dn) if dt is None else np.atleast_1d(np.asarray(dt, float))
    lm = np.zeros_like(dn) if lam_max is None else np.atleast_1d(np.asarray(lam_max, float))
    br = np.zeros(dn.shape, bool) if broken is None else np.atleast_1d(np.asarray(broken, bool))
    return point_law_array(dn, dt, lm, br, SC, DF, dtc, kpen, damage)


def test_peak_at_third_of_delta_f():
    x = np.linspace(0, 1, 300001)
    g = shape_g(x)
    assert abs(x[np.argmax(g)] - 1 / 3) < 1e-5
    assert abs(g.max() - 1.0) < 1e-12  # 27/4·(1/3)·(2/3)² = 1


def test_fracture_energy_and_potential():
    energy, _ = quad(lambda d: float(shape_g(d / DF)) * SC, 0, DF)
    assert energy == pytest.approx(9 / 16 * SC * DF, rel=1e-10)
    for x in (0.1, 0.33, 0.7):
        val, _ = quad(lambda s: float(shape_g(s)), 0, x)
        assert shape_psi(x) == pytest.approx(val, rel=1e-10)


def test_initial_stiffness_and_continuous_compression():
    h = 1e-9 * DF
    tn_plus = law(h)[0][0]
    tn_minus = law(-h)[0][0]
    assert tn_plus / h == pytest.approx(K0, rel=1e-6)
    assert tn_minus / -h == pytest.approx(K0, rel=1e-12)


def test_kernel_matches_numpy_reference():
    rng = np.random.default_rng(3)
    n = 4000
    dn = rng.uniform(-0.3, 1.2, n) * DF
    dt = np.abs(rng.normal(0, 0.4, n)) * DF
    lm = rng.uniform(0, 1.1, n)
    br = rng.random(n) < 0.1
    for damage in (False, True):
        got = law(dn, dt, lm, br, damage=damage, dtc=0.5 * DF)
        ref = traction_reference(dn, dt, lm, br, sigma_c=SC, delta_f=DF, delta_tc=0.5 * DF,
                                 k_pen=K0, damage=damage)
        for g, r in zip(got, ref):
            np.testing.assert_allclose(g, r, rtol=1e-12, atol=1e-6)


def test_tractions_are_gradient_of_stored_energy():
    """Mixed mode derives from the potential: Tn = ∂Φ/∂δn, Tt = ∂Φ/∂δt (reversible)."""
    rng = np.random.default_rng(5)
    dn = rng.uniform(-0.2, 0.6, 50) * DF
    dt = rng.uniform(0.01, 0.5, 50) * DF
    h = 1e-7 * DF
    tn, tt, _, _, _, _ = law(dn, dt, dtc=0.7 * DF)
    dphi_n = (law(dn + h, dt, dtc=0.7 * DF)[2] - law(dn - h, dt, dtc=0.7 * DF)[2]) / (2 * h)
    dphi_t = (law(dn, dt + h, dtc=0.7 * DF)[2] - law(dn, dt - h, dtc=0.7 * DF)[2]) / (2 * h)
    np.testing.assert_allclose(tn, dphi_n, rtol=1e-5, atol=1e-3 * SC * 1e-3)
    np.testing.assert_allclose(tt, dphi_t, rtol=1e-5, atol=1e-3 * SC * 1e-3)


def test_pure_shear_peak_and_energy():
    dtc = 0.5 * DF
    s = np.linspace(0, dtc, 200001)
    tt = law(np.zeros_like(s), s, dtc=dtc)[1]
    assert tt.max() == pytest.approx(SC * DF / dtc, rel=1e-8)
    work = np.trapz(tt, s)
    assert work == pytest.approx(9 / 16 * SC * DF, rel=1e-6)


def test_reversible_unloads_along_curve_damage_along_secant():
    d_peak = 0.5 * DF
    lm = np.zeros(1)
    br = np.zeros(1, bool)
    # load to 0.5 δ_f in damage mode, then unload to 0.25 δ_f
    _, _, _, _, lm, br = point_law_array(np.array([d_peak]), np.zeros(1), lm, br, SC, DF, DF, K0, True)
    assert lm[0] == pytest.approx(0.5)
    tn_dmg, _, st_dmg, di_dmg, lm2, _ = point_law_array(np.array([0.25 * DF]), np.zeros(1), lm, br,
                                                        SC, DF, DF, K0, True)
    tn_rev = law(0.25 * DF)[0][0]
    assert tn_rev == pytest.approx(SC * float(shape_g(0.25)), rel=1e-12)
    secant = SC * float(shape_g(0.5)) / 0.5
    assert tn_dmg[0] == pytest.approx(secant * 0.25, rel=1e-12)
    assert lm2[0] == pytest.approx(0.5)  # memory is kept
    # energy: stored + dissipated on the secant equals the work done to reach λ_max minus
    # what is returned on unloading to λ = 0.25
    work_in = float(shape_psi(0.5)) * SC * DF
    returned = 0.5 * secant * DF * (0.5 ** 2 - 0.25 ** 2)
    assert st_dmg[0] + di_dmg[0] == pytest.approx(work_in - returned, rel=1e-12)
    # reload to λ_max follows the secant, then joins the curve
    tn_back = point_law_array(np.array([0.5 * DF]), np.zeros(1), lm2, br, SC, DF, DF, K0, True)[0]
    assert tn_back[0] == pytest.approx(SC * float(shape_g(0.5)), rel=1e-12)


def test_damage_loading_stored_plus_dissipated_equals_work():
    """Monotonic loading in damage mode: stored + dissipated = ∫σ dδ, same as reversible."""
    d = np.linspace(0, 0.9 * DF, 200)
    _, _, st_r, di_r, _, _ = law(d)
    _, _, st_d, di_d, _, _ = law(d, damage=True)
    np.testing.assert_allclose(st_d + di_d, st_r + di_r, rtol=1e-12, atol=1e-9)
    assert np.all(di_r == 0.0) and np.all(di_d[1:] > 0.0)


def test_broken_for_good_in_both_modes():
    for damage in (False, True):
        tn, _, st, di, lm, br = law(1.0001 * DF, damage=damage)
        assert br[0] and tn[0] == 0.0 and st[0] == 0.0
        assert di[0] == pytest.approx(9 / 16 * SC * DF)
        # closing again: no tension, and no compression either (contact's job now)
        tn2, tt2, st2, _, _, br2 = law([0.1 * DF, -0.1 * DF], [0.1 * DF, 0.0], lm.repeat(2),
                                      br.repeat(2), damage=damage)
        assert br2.all() and np.all(tn2 == 0.0) and np.all(tt2 == 0.0) and np.all(st2 == 0.0)
