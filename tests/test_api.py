"""The Python API: a case from a file or a mapping, run from a script, its series returned."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import yaml

import fcm_fsi
from fcm_fsi import Case, run

ROOT = Path(__file__).resolve().parents[1]


def test_a_case_runs_from_python_and_returns_its_series(tmp_path):
    case = Case.from_yaml(ROOT / "cases" / "still_water.yaml", ["run.t_end=0.006", "output.xdmf=false"])
    seen = []
    series = run(case, tmp_path / "a", on_step=lambda step, t, row: seen.append((step, t, row["volume_error"])))
    assert [s for s, _, _ in seen] == [0, 1, 2, 3]
    np.testing.assert_allclose(series["t"], [0.0, 0.002, 0.004, 0.006])
    np.testing.assert_array_equal(series["volume_error"], [v for _, _, v in seen])
    on_disk = np.genfromtxt(tmp_path / "a" / "series.csv", delimiter=",", names=True)
    np.testing.assert_allclose(series["kinetic_energy"], on_disk["kinetic_energy_J_Jm_in_2D"], rtol=1e-12)
    assert (tmp_path / "a" / "case.resolved.yaml").exists()


def test_a_case_from_a_mapping_is_the_case_from_its_file():
    data = yaml.safe_load((ROOT / "cases" / "still_water.yaml").read_text())
    assert Case.from_dict(data) == Case.from_yaml(ROOT / "cases" / "still_water.yaml")
    assert fcm_fsi.run is run and fcm_fsi.Case is Case
