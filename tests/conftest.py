"""Shared helpers: run the CLI or the verification runner in a subprocess (optionally under MPI)."""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def mpi_env() -> dict:
    env = dict(os.environ)
    env.update({"OMPI_ALLOW_RUN_AS_ROOT": "1", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1",
                "OMPI_MCA_rmaps_base_oversubscribe": "1", "OMP_NUM_THREADS": "1"})
    return env


def run_cli(args: list[str], np_: int = 1, cwd: Path = ROOT, timeout: float = 600) -> subprocess.CompletedProcess:
    """``python -m fcm_fsi ARGS`` (under ``mpirun -n np_`` when np_ > 1)."""
    cmd = [sys.executable, "-m", "fcm_fsi", *args]
    if np_ > 1:
        cmd = [shutil.which("mpirun"), "-n", str(np_), *cmd]
    return subprocess.run(cmd, cwd=cwd, env=mpi_env(), capture_output=True, text=True, timeout=timeout)


@pytest.fixture
def root() -> Path:
    return ROOT
