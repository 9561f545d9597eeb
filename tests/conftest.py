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
    """The environment of the tests' subprocesses: mpirun as root, one thread per process
    (OpenMP and Numba: the ranks are the parallelism, and the 2 cores are shared)."""
    env = dict(os.environ)
    env.update({"OMPI_ALLOW_RUN_AS_ROOT": "1", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1",
                "OMPI_MCA_rmaps_base_oversubscribe": "1", "OMP_NUM_THREADS": "1", "NUMBA_NUM_THREADS": "1"})
    return env


def run_cli(args: list[str], np_: int = 1, cwd: Path = ROOT, timeout: float = 600) -> subprocess.CompletedProcess:
    """``python -m fcm_fsi ARGS`` (under ``mpirun -n np_`` when np_ > 1)."""
    cmd = [sys.executable, "-m", "fcm_fsi", *args]
    if np_ > 1:
        cmd = [shutil.which("mpirun"), "-n", str(np_), *cmd]
    return subprocess.run(cmd, cwd=cwd, env=mpi_env(), capture_output=True, text=True, timeout=timeout)


def run_half_and_resume(case: Path, out: Path, t_half: float, np_: int = 1) -> None:
    """The restart tests' second run: ``case`` to ``t_half`` [s] into ``out``, then continued
    from ``out/checkpoint.h5`` to the case's own t_end; both must succeed."""
    half = run_cli([str(case), "--output", str(out), "--set", f"run.t_end={t_half}"], np_)
    assert half.returncode == 0, half.stderr[-2000:]
    resumed = run_cli([str(case), "--output", str(out), "--restart", str(out / "checkpoint.h5")], np_)
    assert resumed.returncode == 0, resumed.stderr[-2000:]


@pytest.fixture
def root() -> Path:
    return ROOT


@pytest.fixture(autouse=True)
def one_numba_thread():
    """Every test runs its Numba kernels on one thread: the 2 cores are shared (with mpirun's
    second rank, other runs), and a parallel region then waits for a busy core at every call —
    a 12-block DEM step took 15 ms on 2 threads against 60 µs on one. Results do not depend on
    the thread count (test_result_does_not_depend_on_thread_count sets 2 threads itself)."""
    import numba
    old = numba.get_num_threads()
    numba.set_num_threads(1)
    yield
    numba.set_num_threads(old)
