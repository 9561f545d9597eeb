"""The command line (fcm_fsi/cli.py): one ``python -m fcm_fsi COMMAND`` per tool, each with its
own help; a case file as first argument runs it as before; the former module paths still work."""
from __future__ import annotations

import subprocess
import sys

import pytest

from fcm_fsi.cli import COMMANDS, main
from tests.conftest import ROOT, mpi_env, run_cli

#: every command's options, as the README and docs name them
OPTIONS = {
    "run": ["case", "--output", "--restart", "--validate", "--set", "--log-level"],
    "validate": ["case", "--set", "--log-level"],
    "verify": ["name", "--level", "--np", "--out", "--list", "--report", "--log-level", "--resume", "--ranks-per-run"],
    "bench": ["NAME", "--list", "building", "coupling", "cut", "dem", "navier_stokes", "peer"],
    "mesh": ["case", "--set", "--write"],
    "snapshots": ["output", "--times", "--png-dir"],
    "bond-report": ["case", "checkpoint", "--top", "--set", "--members"],
    "load-factor": ["case", "bodies", "--time", "--max-factor", "--ramp", "--set"],
    "failure-sequence": ["output"],
    "strength": ["case", "--fck", "--flexural-strength", "--depth", "--set"],
}


def help_text(args: list[str], capsys) -> str:
    with pytest.raises(SystemExit) as exit_:
        main(args)
    assert exit_.value.code == 0
    return capsys.readouterr().out


def test_every_command_is_listed_in_the_help(capsys):
    assert set(OPTIONS) == set(COMMANDS)
    text = help_text(["--help"], capsys)
    for command in COMMANDS:
        assert f"    {command}" in text, command


@pytest.mark.parametrize("command", sorted(OPTIONS))
def test_each_command_has_a_help_that_names_its_options(command, capsys):
    text = help_text([command, "--help"], capsys)
    assert text.startswith(f"usage: python -m fcm_fsi {command} ")
    for option in OPTIONS[command]:
        assert option in text, f"{command} --help does not name {option}"


def test_a_benchmark_s_own_help_is_reached_through_bench(capsys):
    text = help_text(["bench", "dem", "--help"], capsys)
    assert text.startswith("usage: python -m fcm_fsi bench dem ") and "--sizes" in text


def test_a_case_file_first_is_run_and_validate_is_run_validate():
    """``python -m fcm_fsi CASE --validate`` (the form before the commands) and ``python -m
    fcm_fsi validate CASE`` check a shipped case the same way; a missing case file is bad input
    (exit 2) in both forms, the first argument taken as a case file, not a command."""
    case = "cases/still_water.yaml"
    legacy = run_cli([case, "--validate"])
    command = run_cli(["validate", case])
    assert legacy.returncode == 0 and command.returncode == 0, legacy.stderr[-2000:] + command.stderr[-2000:]
    verdict = legacy.stdout.splitlines()[-1]          # after the log lines (timestamped)
    assert verdict.startswith(f"{case}: valid (fluid case 'still_water'; mesh ≈ ")
    assert command.stdout.splitlines()[-1] == verdict
    for args in (["cases/no_such_case.yaml", "--validate"], ["validate", "cases/no_such_case.yaml"]):
        res = run_cli(args)
        assert res.returncode == 2 and "cases/no_such_case.yaml: case file not found" in res.stderr, args


@pytest.mark.parametrize("module, command", [
    ("fcm_fsi.verify", "verify"), ("fcm_fsi.bench", "bench"), ("fcm_fsi.mesh", "mesh"),
    ("fcm_fsi.io.snapshots", "snapshots"), ("fcm_fsi.dem.bond_report", "bond-report"),
    ("fcm_fsi.dem.load_factor", "load-factor"), ("fcm_fsi.dem.failure_sequence", "failure-sequence"),
    ("fcm_fsi.dem.strength", "strength"),
])
def test_the_former_module_paths_call_the_commands(module, command):
    """``python -m fcm_fsi.dem.bond_report ...`` and the like, as the docs showed them before
    the commands, still run: the same parser as ``python -m fcm_fsi bond-report``."""
    res = subprocess.run([sys.executable, "-m", module, "--help"], cwd=ROOT, env=mpi_env(),
                         capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr[-2000:]
    assert res.stdout.startswith(f"usage: python -m fcm_fsi {command} ")
    assert "Warning" not in res.stderr, res.stderr
