"""The pushover tool (``python -m fcm_fsi load-factor``): a slow load ramp finds a bonded
joint's strength, and the recorded load is read from a run's bodies.csv."""
import numpy as np
import pytest

from fcm_fsi.config.loader import ConfigError
from fcm_fsi.dem.builder import assemble
from fcm_fsi.dem.cohesive import CohesiveLaw
from fcm_fsi.tools.load_factor import RecordedLoad, ramp_to_first_break, recorded_load

SC, DF = 1.0e7, 0.02


def test_ramp_finds_the_strength_of_a_bonded_cantilever_joint():
    """Block 0 fixed, block 1 bonded to it on a face b × h = 0.4 × 0.2 m (2 × 2 Gauss points),
    a force F0 down at block 1's centre 0.5 m from the face. The joint's strength with two rows
    of points: the tension row at σ_c (λ = 1/3) balanced by the compressed row, lever h/√3, so
    M_u = σ_c·b·h²/(2√3) and α_u = M_u/(F0·0.5). The ramp (1 s against the joint's ≈ 0.05 s
    period) is quasi-static to about 1 %. The break (λ = 1) follows at a larger factor, in the
    tension (top) row."""
    from fcm_fsi.dem.system import DEMSystem
    s = assemble([[0, 0, 0], [0.5, 0, 0]], [[0.5, 0.4, 0.2], [1.5, 0.4, 0.2]], density=2400.0,
                 sphere_radius=0.05)
    bonds = s.bonds(CohesiveLaw(sigma_c=SC, delta_f=DF, delta_tc=DF, penalty_factor=1.0, mode="reversible"), 2)
    st = s.to_state()
    st.fixed[0] = True
    system = DEMSystem(st, [bonds], 1.0e-4, gravity=(0.0, 0.0, 0.0))
    f0 = 5.0e4
    load = RecordedLoad(0.0, np.array([[0.0, 0.0, 0.0], [0.0, 0.0, -f0]]), np.zeros((2, 3)))
    alpha_u = SC * 0.4 * 0.2 ** 2 / (2 * np.sqrt(3)) / (f0 * 0.5)
    r = ramp_to_first_break(system, bonds, load, max_factor=1.5 * alpha_u, ramp_time=1.0, settle_time=0.0)
    assert r.first_peak == pytest.approx(alpha_u, rel=0.02)
    assert r.first_break is not None and alpha_u < r.first_break < 1.5 * alpha_u
    z = (s.to_state().pos[bonds.pt_a] + bonds.pt_ra)[r.broken_points, 2]
    assert np.all(z > 0.1)
    assert np.all(np.diff(r.history[:, 0]) > 0) and r.history[-1, 2] == r.broken_points.size


def test_recorded_load_reads_the_nearest_row_and_refuses_another_case(tmp_path):
    p = tmp_path / "bodies.csv"
    cols = ["t [s]", "block [-]", "fx [N]", "fy [N]", "fz [N]", "tx [N m]", "ty [N m]", "tz [N m]"]
    rows = [[t, b, 10 * t + b, 0, 0, 0, 0, -b] for t in (0.1, 0.2, 0.3) for b in (0, 1)]
    p.write_text(",".join(cols) + "\n" + "\n".join(",".join(str(v) for v in r) for r in rows) + "\n")
    load = recorded_load(p, 0.21, 2)
    assert load.time == pytest.approx(0.2)
    np.testing.assert_allclose(load.force[:, 0], [2.0, 3.0])
    np.testing.assert_allclose(load.torque[:, 2], [0.0, -1.0])
    with pytest.raises(ConfigError, match="has 2 blocks, the case builds 3"):
        recorded_load(p, 0.2, 3)
    with pytest.raises(ConfigError, match="outside the recorded"):
        recorded_load(p, 0.5, 2)
    with p.open("a") as f:                 # a run killed mid-write: half a step at the end
        f.write("0.4,0,9,0,0,0,0,0\n")
    assert recorded_load(p, 0.3, 2).time == pytest.approx(0.3)
