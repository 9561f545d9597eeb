"""Runner and phase-field verification cases at the quick level (full levels: docs/phase-field.md)."""
from __future__ import annotations

import json
import subprocess
import sys

import pytest

from tests.conftest import ROOT, mpi_env


def run_verify(args: list[str], timeout: float = 900) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "fcm_fsi", "verify", *args], cwd=ROOT, env=mpi_env(),
                          capture_output=True, text=True, timeout=timeout)


def test_list_names_every_family():
    res = run_verify(["--list"])
    assert res.returncode == 0
    for name in ("rotating_cylinder", "zalesak_disk", "rotating_sphere"):
        assert name in res.stdout


def test_unknown_case_is_a_clear_error():
    res = run_verify(["no_such_case"])
    assert res.returncode != 0 and "unknown verification case" in res.stderr and "Traceback" not in res.stderr


@pytest.mark.mpi
def test_rotating_sphere_quick_on_two_ranks_writes_metrics_plot_and_report(tmp_path):
    res = run_verify(["rotating_sphere", "--level", "quick", "--np", "2", "--out", str(tmp_path),
                      "--report", str(tmp_path / "report")])
    assert res.returncode == 0, res.stdout + res.stderr
    result = json.loads((tmp_path / "rotating_sphere" / "metrics.json").read_text())
    assert result["case"] == "rotating_sphere" and result["level"] == "quick" and result["ranks"] == 2
    assert {"value", "reference", "tolerance", "unit", "pass"} <= set(result["metrics"]["volume_error"])
    assert all(m["pass"] for m in result["metrics"].values())
    assert (tmp_path / "rotating_sphere" / "rotating_sphere.png").exists()
    report = (tmp_path / "report" / "README.md").read_text()
    assert "## rotating_sphere" in report and "rotating_sphere__rotating_sphere.png" in report


@pytest.mark.parametrize("name", ["rotating_cylinder", pytest.param("zalesak_disk", marks=pytest.mark.slow), "dam_break"])
def test_phase_field_quick_levels_pass(name, tmp_path):
    """The quick level of each case passes and draws its plot. zalesak_disk (≈ 50 s) is `slow`:
    `python -m fcm_fsi verify zalesak_disk --level quick` runs the same check."""
    res = run_verify([name, "--level", "quick", "--out", str(tmp_path)])
    assert res.returncode == 0, res.stdout + res.stderr
    assert list((tmp_path / name).glob("*.png"))


def test_resume_picks_the_runs_own_checkpoint_only_when_asked(tmp_path):
    """``--resume``: a run continues from the checkpoint.h5 in its own folder (the time loop
    then checks it is of the same case); without the flag, or without a checkpoint, it starts over."""
    from fcm_fsi.verify.registry import resume_checkpoint, set_resume
    try:
        set_resume(True)
        assert resume_checkpoint(tmp_path) is None
        (tmp_path / "checkpoint.h5").write_bytes(b"")
        assert resume_checkpoint(tmp_path) == str(tmp_path / "checkpoint.h5")
        set_resume(False)
        assert resume_checkpoint(tmp_path) is None
    finally:
        set_resume(False)
