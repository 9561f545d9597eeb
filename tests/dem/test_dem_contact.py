"""Closed-form contact results: restitution (eq 20, clipped and not), Δt_cr, Coulomb sliding."""
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from fcm_fsi.dem.restitution import damping_ratio, restitution_clipped, restitution_unclipped
from fcm_fsi.dem.system import critical_time_step
from fcm_fsi.verify.cases.dem import _measure_restitution, _slide


def ode_restitution(h: float, clip: bool) -> float:
    """Integrate m δ'' = −(kδ + cδ') (m = k = 1) from δ = 0, δ' = 1 until the force (clip)
    or δ (no clip) returns to zero; e = −δ'(end)."""
    def rhs(t, y):
        return [y[1], -(y[0] + 2 * h * y[1])]

    def end(t, y):
        return (y[0] + 2 * h * y[1]) if clip else y[0]
    end.terminal, end.direction = True, -1
    sol = solve_ivp(rhs, (0, 10), [0.0, 1.0], events=end, rtol=1e-12, atol=1e-14, first_step=1e-6)
    return -sol.y_events[0][0][1]


@pytest.mark.parametrize("e", [0.2, 0.5, 0.9])
def test_restitution_closed_forms_match_ode(e):
    h = damping_ratio(e)
    assert restitution_unclipped(h) == pytest.approx(e, rel=1e-12)
    assert ode_restitution(h, clip=False) == pytest.approx(e, rel=1e-8)
    assert restitution_clipped(h) == pytest.approx(ode_restitution(h, clip=True), rel=1e-8)


def test_clipping_raises_restitution_as_spec_says():
    # SPEC §2 / issue #6: with the force clipped, target e = 0.5 comes out ≈ 0.55
    assert restitution_clipped(damping_ratio(0.5)) == pytest.approx(0.5503, abs=1e-4)


@pytest.mark.parametrize("clip", [True, False])
@pytest.mark.parametrize("e", [0.2, 0.5, 0.9])
def test_dem_bounce_restitution_matches_model(e, clip):
    meas, pred = _measure_restitution(e, clip, 100.0)
    assert abs(meas - pred) / pred < 0.01


def test_critical_time_step_formula():
    # tutorial §6: m = k = 1, h = 0.5 → Δt_cr = 1.236068
    assert critical_time_step(1.0, 1.0, 0.5) == pytest.approx(1.236068, abs=1e-6)


@pytest.mark.parametrize("dt,stable", [(1.23, True), (1.24, False)])
def test_leapfrog_spring_dashpot_stability_limit(dt, stable):
    """The tutorial's check (Fig. 16): m u'' + c u'(lagged) + k u = 0 by leapfrog."""
    m, k, h = 1.0, 1.0, 0.5
    c = 2 * h * math.sqrt(m * k)
    u0, u1 = 1.0, 1.0
    for _ in range(4000):
        u0, u1 = u1, (2 - c / m * dt - k / m * dt * dt) * u1 + (c / m * dt - 1) * u0
    assert (abs(u1) < 1.0) == stable


def test_sliding_block_acceleration_is_coulomb():
    s, t, x, v = _slide(30.0, 20.0, 0.3)
    a = np.polyfit(t[t > 0.1] - 0.5 * s.dt, v[t > 0.1], 1)[0]
    ref = 9.81 * (math.sin(math.radians(30)) - math.tan(math.radians(20)) * math.cos(math.radians(30)))
    assert a == pytest.approx(ref, rel=1e-6)
    L = s.ledger.last
    assert abs(L["balance_error"]) < 1e-5 * abs(L["friction_loss"])


def test_displacement_controlled_block_force_and_ledger():
    """A box pushed 2 mm (ramped) against a fixed box 0.5 mm away: 9 face-sphere contacts in
    parallel, so the reaction is 9 k (2 − 0.5) mm; the ledger balances the control work."""
    from fcm_fsi.config.dem import DEMConfig
    from fcm_fsi.config.loader import build
    from fcm_fsi.dem.model import build_system
    k = 1e5
    box = {"shape": "box", "material": "m", "size": [0.1, 0.1, 0.1], "radius": 0.02}
    cfg = build(DEMConfig, {"dt": 1e-5, "gravity": [0, 0, 0],
                            "materials": [{"name": "m", "stiffness": k, "restitution": 0.5, "friction_angle": 20.0}],
                            "blocks": [{**box, "position": [0, 0, 0]}, {**box, "position": [0.1005, 0, 0], "fixed": True}],
                            "controls": [{"block": 0, "modes": ["displacement"] + ["velocity"] * 5,
                                          "values": [0.002, 0, 0, 0, 0, 0], "ramp": 0.01}]}, "t", "dem")
    s = build_system(cfg)
    s.run(2000)
    assert s.controls.displacement(s.state)[0, 0] == pytest.approx(0.002, rel=1e-12)
    assert s.controls.F[0, 0] == pytest.approx(9 * k * 0.0015, rel=1e-9)
    assert s.interaction_force[0, 0] == pytest.approx(-9 * k * 0.0015, rel=1e-9)
    L = s.ledger.last
    assert L["spring"] == pytest.approx(9 * 0.5 * k * 0.0015 ** 2, rel=1e-9)
    assert L["dashpot_loss"] > 0.1 * L["work_control"]
    assert abs(L["balance_error"]) < 1e-9 * L["work_control"]


def _elastic_pair_or_wall(pair: bool, gap: float, frac: float = 10.0):
    """e = 1, μ = 0, no gravity: a sphere (v = 1 m/s) against a floor, or two spheres head on
    (±0.5 m/s), starting ``gap`` apart, dt = Δt_cr/frac."""
    import dataclasses

    from fcm_fsi.config.dem import DEMConfig
    from fcm_fsi.config.loader import build
    from fcm_fsi.dem.model import build_system
    r = 0.01
    sph = {"shape": "sphere", "material": "m", "radius": r}
    if pair:
        blocks = [{**sph, "position": [0, 0, 0], "velocity": [0.5, 0, 0]},
                  {**sph, "position": [2 * r + gap, 0, 0], "velocity": [-0.5, 0, 0]}]
        walls = []
    else:
        blocks = [{**sph, "position": [0, 0, r + gap], "velocity": [0, 0, -1.0]}]
        walls = [{"kind": "plane", "material": "m", "point": [0, 0, 0], "normal": [0, 0, 1]}]
    cfg = build(DEMConfig, {"dt": 1.0, "dt_safety": 1.0, "gravity": [0, 0, 0],
                            "materials": [{"name": "m", "stiffness": 1e5, "restitution": 1.0,
                                           "friction_angle": 0.0, "density": 2500.0}],
                            "blocks": blocks, "walls": walls}, "t", "dem")
    s = build_system(dataclasses.replace(cfg, dt=1e-12))
    s.dt = s.critical_time_step() / frac
    return s


@pytest.mark.parametrize("pair", [False, True])
def test_elastic_impact_conserves_energy_across_onset_and_release(pair):
    """The onset/release correction of the spring force (contact.py docstring): with e = 1
    the impact returns the kinetic energy exactly (the leapfrog's own energy), whatever the
    phase of contact onset and release within a step; without it the error is
    O((ωΔt)²) ≈ 1e-2 at Δt_cr/10."""
    errs = []
    for gap in np.linspace(0.0, 1e-4, 7)[1:]:
        s = _elastic_pair_or_wall(pair, gap)
        E_in = 0.5 * float(np.sum(s.state.mass[:, None] * s.state.vel ** 2))
        for _ in range(400):
            s.step()
        v = s.state.vel
        E_out = 0.5 * float(np.sum(s.state.mass[:, None] * v ** 2))
        assert (v[0, 0] < 0) if pair else (v[0, 2] > 0)      # rebounded and separated
        assert s.ledger.last["spring"] == 0.0
        errs.append(abs(E_out / E_in - 1))
        assert abs(s.ledger.last["balance_error"]) < 1e-9 * E_in
    assert max(errs) < 1e-8
