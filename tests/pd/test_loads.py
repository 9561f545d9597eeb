"""The borehole blast load (eq 12): the pressure history, the force on the wall, the hole's
geometry, the config errors, and the loads' work in the energy balance."""
import dataclasses
import math

import numpy as np
import pytest

from fcm_fsi.config.loader import ConfigError, build
from fcm_fsi.config.pd import PDConfig
from fcm_fsi.pd.builder import build_system, lattice_stable_time_step
from fcm_fsi.pd.loads import blast_pressure, decay_rates

P0, T0, K = 150e6, 5e-6, 5.0        # the seed's borehole (§3(2)): 150 MPa, rise time 5 µs, β/α = 5


def blast_plate(hole=None, **over):
    """A 12 × 12 mm plane-strain granite plate (Δx = 0.5 mm) with a hole of radius 1.3 mm at its centre."""
    d = {"formulation": "plane_strain", "thickness": 0.01,
         "material": {"youngs_modulus": 50e9, "density": 2660.0},
         "lattice": {"lower": [0.0, 0.0], "upper": [0.012, 0.012], "spacing": 0.0005}, "dt": 1e-12,
         "boreholes": [{"centre": [0.006, 0.006], "radius": 0.0013, "peak_pressure": P0, "rise_time": T0,
                        "beta_over_alpha": K, **(hole or {})}]}
    d.update(over)
    cfg = build(PDConfig, d, source="<test>", prefix="pd")
    return dataclasses.replace(cfg, dt=0.5 * lattice_stable_time_step(cfg))


def test_decay_rates_put_the_peak_at_the_rise_time():
    """t0 = ln(β/α)/(β − α) inverted: α = ln k/((k − 1) t0); the rates give back t0 and k."""
    alpha, beta = decay_rates(T0, K)
    assert beta / alpha == pytest.approx(K, rel=1e-14)
    assert math.log(beta / alpha) / (beta - alpha) == pytest.approx(T0, rel=1e-14)
    assert alpha == pytest.approx(math.log(5.0) / (4.0 * 5e-6), rel=1e-14)    # 8.047e4 1/s


def test_blast_pressure_rises_from_zero_to_p0_at_the_rise_time_then_decays():
    assert float(blast_pressure(0.0, P0, T0, K)) == 0.0
    assert float(blast_pressure(T0, P0, T0, K)) == pytest.approx(P0, rel=1e-14)
    t = np.linspace(0.0, 10 * T0, 200001)
    p = blast_pressure(t, P0, T0, K)
    assert t[np.argmax(p)] == pytest.approx(T0, abs=t[1])                      # the peak time
    assert p.max() <= P0 * (1 + 1e-12)
    alpha, _ = decay_rates(T0, K)
    tail = t > 8 * T0                                                           # the e^{−αt} tail
    assert np.allclose(p[tail][1:] / p[tail][:-1], np.exp(-alpha * t[1]), rtol=1e-3)
    with pytest.raises(ValueError):
        decay_rates(T0, 1.0)


def test_the_wall_force_adds_up_to_pressure_times_wall_area():
    """Σ |b| V = P × 2πR × h on the wall layer, every b radial and outward, the net force zero
    (the hole sits on a symmetry point of the lattice)."""
    cfg = blast_plate()
    s = build_system(cfg)
    (load,) = s.loads.pressures
    b = load.force_per_pascal * P0
    vol = s.vol[load.points]
    radial = s.x[load.points, :2] - 0.006
    assert (np.linalg.norm(b, axis=1) * vol).sum() == pytest.approx(P0 * 2 * math.pi * 0.0013 * 0.01, rel=1e-12)
    cosine = (b[:, :2] * radial).sum(axis=1) / (np.linalg.norm(b[:, :2], axis=1) * np.linalg.norm(radial, axis=1))
    assert np.allclose(cosine, 1.0, atol=1e-12)
    assert np.abs((b * vol[:, None]).sum(axis=0)).max() < 1e-9 * P0 * 0.0013 * 0.01
    r = np.linalg.norm(radial, axis=1)
    assert r.min() >= 0.0013 and r.max() < 0.0013 + 0.0005
    assert np.allclose(s.loads.body_force_at(T0)[load.points], b)


def test_the_hole_is_empty_and_no_bond_crosses_it():
    cfg = blast_plate()
    s = build_system(cfg)
    c, R = np.array([0.006, 0.006]), 0.0013
    assert np.hypot(*(s.x[:, :2] - c).T).min() >= R
    b = s.bonds
    lam = np.linspace(0.0, 1.0, 201)[:, None, None]
    pts = s.x[b.owner, :2][None] + lam * (s.x[b.nbr, :2] - s.x[b.owner, :2])[None]     # samples along each bond
    assert np.hypot(pts[..., 0] - c[0], pts[..., 1] - c[1]).min() >= R - 1e-12
    no_hole = build_system(dataclasses.replace(cfg, boreholes=()))
    assert no_hole.bonds.count > b.count


@pytest.mark.parametrize("change, key", [
    ({"beta_over_alpha": 1.0}, "pd.boreholes[0].beta_over_alpha"),
    ({"rise_time": 0.0}, "pd.boreholes[0].rise_time"),
    ({"centre": [0.001, 0.006]}, "pd.boreholes[0]"),
    ({"centre": [0.006]}, "pd.boreholes[0].centre"),
    ({"peak_pressure": -1.0}, "pd.boreholes[0].peak_pressure"),
    ({"raduis": 0.001}, "pd.boreholes[0].raduis"),
])
def test_bad_boreholes_are_refused_naming_the_key(change, key):
    with pytest.raises(ConfigError) as err:
        blast_plate(change)
    assert key in str(err.value)


def test_a_borehole_in_3d_or_without_points_inside_is_refused():
    with pytest.raises(ConfigError, match="boreholes are 2D"):
        blast_plate(formulation="3d", lattice={"lower": [0, 0, 0], "upper": [0.012, 0.012, 0.012],
                                               "spacing": 0.0005}, material={"youngs_modulus": 50e9,
                                                                             "density": 2660.0})
    cfg = blast_plate({"radius": 0.0002, "centre": [0.0060, 0.0060]})     # between four points
    with pytest.raises(ConfigError, match="holds no lattice point"):
        build_system(cfg)


def test_the_pressure_work_closes_the_energy_balance_to_second_order():
    """No fracture: K + W − work stays at zero up to velocity Verlet's bounded O(dt²) error; the
    blast's work is that of the pressure on the wall (the rise and part of the decay, 8 µs).
    Largest |balance| over the run / the final work: 1.0e-3 at 0.4 Δt_crit, 2.6e-4 at 0.2."""
    errors = []
    for fraction in (0.4, 0.2):
        cfg = blast_plate()
        cfg = dataclasses.replace(cfg, dt=fraction * lattice_stable_time_step(cfg))
        s = build_system(cfg)
        worst = 0.0
        while s.t < 8e-6:
            s.step()
            worst = max(worst, abs(s.energies()["energy_balance"]))
        en = s.energies()
        assert en["external_work"] > 0.0 and en["dissipated_energy"] == 0.0
        errors.append(worst / en["external_work"])
    assert errors[1] < 5e-4
    assert math.log2(errors[0] / errors[1]) >= 1.8
