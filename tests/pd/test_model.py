"""The pd section through the product: strict config, the shared loop's output and restart."""
import h5py
import numpy as np
import pytest

from fcm_fsi.config.case import Case
from fcm_fsi.config.loader import ConfigError
from tests.conftest import ROOT, run_cli

CASE = ROOT / "cases" / "pd_plate_notch.yaml"


def plate_case(**pd_over):
    pd = {"formulation": "plane_stress",
          "material": {"youngs_modulus": 4.55e9, "density": 1230.0, "fracture_energy": 38.46, "weibull_shape": 10.0},
          "lattice": {"lower": [0, 0], "upper": [0.02, 0.01], "spacing": 0.0005}, "dt": 1.5e-7,
          "velocities": [{"lower": [0, 0], "upper": [0.0015, 0.01], "velocity": [-2.0, None]},
                         {"lower": [0.0185, 0], "upper": [0.02, 0.01], "velocity": [2.0, None]}],
          "notches": [{"points": [[0.01, 0.0], [0.01, 0.003]]}]}
    pd.update(pd_over)
    return {"name": "pd_t", "run": {"t_end": 3.0e-5, "dt": 1.5e-6, "checkpoint_every": 10, "output_every": 5},
            "pd": pd}


@pytest.mark.parametrize("change, key", [
    ({"materal": {}}, "pd.materal"),
    ({"formulation": "plane"}, "pd.formulation"),
    ({"horizon_factor": 0.5}, "pd.horizon_factor"),
    ({"material": {"youngs_modulus": 1e9, "density": 1000.0, "poisson_ratio": 0.3}}, "pd.material.poisson_ratio"),
    ({"lattice": {"lower": [0, 0, 0], "upper": [1, 1, 1], "spacing": 0.1}}, "pd.lattice.lower"),
    ({"velocities": [{"lower": [0, 0], "upper": [1, 1], "velocity": [1.0]}]}, "pd.velocities[0].velocity"),
    ({"notches": [{"points": [[0, 0]]}]}, "pd.notches[0].points"),
    ({"dt": 1.4e-7}, "run.dt"),
])
def test_bad_pd_sections_are_refused_naming_the_key(change, key):
    with pytest.raises(ConfigError) as err:
        Case.from_dict(plate_case(**change))
    assert key in str(err.value)


def test_a_case_with_only_pd_is_a_pd_case():
    assert Case.from_dict(plate_case()).physics == "pd"


def test_restart_reproduces_the_uninterrupted_run_bit_for_bit(tmp_path):
    """30 µs at once = 15 µs, checkpoint, restart, 15 µs: the same positions, velocities and
    broken bonds to the last bit (the run breaks bonds, so the bond state crosses the restart)."""
    from fcm_fsi.api import run
    whole = run(Case.from_dict(plate_case()), tmp_path / "whole")
    half_case = plate_case()
    half_case["run"]["t_end"] = 1.5e-5
    run(Case.from_dict(half_case), tmp_path / "half")
    resumed = run(Case.from_dict(plate_case()), tmp_path / "half", restart=tmp_path / "half" / "checkpoint.h5")
    with h5py.File(tmp_path / "whole" / "checkpoint.h5") as a, h5py.File(tmp_path / "half" / "checkpoint.h5") as b:
        for name in ("pd__u", "pd__v", "pd__intact", "pd__scalars"):
            assert np.array_equal(a["globals"][name][...], b["globals"][name][...]), name
    assert whole["broken_bonds"][-1] > 0 and resumed["broken_bonds"][-1] == whole["broken_bonds"][-1]
    vtp = sorted(p.name for p in (tmp_path / "half").glob("points_*.vtp"))
    assert vtp == sorted(p.name for p in (tmp_path / "whole").glob("points_*.vtp"))
    assert (tmp_path / "half" / "points.pvd").read_text() == (tmp_path / "whole" / "points.pvd").read_text()


def test_shipped_case_runs_on_two_ranks_and_only_rank_0_writes(tmp_path):
    out = tmp_path / "out"
    res = run_cli([str(CASE), "--output", str(out), "--set", "run.t_end=1.5e-5", "--log-level", "WARNING"], np_=2)
    assert res.returncode == 0, res.stderr[-2000:]
    rows = (out / "series.csv").read_text().strip().splitlines()
    assert len(rows) == 1 + 11                                   # header, t = 0 and 10 steps, written once
    assert len(list(out.glob("points_*.vtp"))) == 3 and (out / "checkpoint.h5").exists()


def test_shipped_state_based_particle_case_restarts_bit_for_bit(tmp_path):
    """cases/pd_state_cube.yaml (state-based, tetrahedron-centroid particles) for 12 µs at once and
    as 6 µs + restart + 6 µs: the same state to the last bit (the gmsh box is meshed again the same)."""
    from fcm_fsi.api import run
    state_case = ROOT / "cases" / "pd_state_cube.yaml"
    whole = run(Case.from_yaml(state_case, ["run.t_end=1.2e-5"]), tmp_path / "whole")
    run(Case.from_yaml(state_case, ["run.t_end=6e-6"]), tmp_path / "half")
    run(Case.from_yaml(state_case, ["run.t_end=1.2e-5"]), tmp_path / "half",
        restart=tmp_path / "half" / "checkpoint.h5")
    with h5py.File(tmp_path / "whole" / "checkpoint.h5") as a, h5py.File(tmp_path / "half" / "checkpoint.h5") as b:
        for name in ("pd__u", "pd__v", "pd__intact", "pd__scalars"):
            assert np.array_equal(a["globals"][name][...], b["globals"][name][...]), name
    assert whole["broken_bonds"][-1] > 0
    assert abs(whole["energy_balance"][-1]) < 0.05 * whole["external_work"][-1]
