"""Numba threads per rank (fcm_fsi/io/threads.py)."""
from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys

import numba
import numpy as np
from mpi4py import MPI

from fcm_fsi.dem.neighbours import max_displacement
from fcm_fsi.io.threads import SERIAL_SPHERES, serial_below, threads_per_rank
from tests.conftest import mpi_env


def test_a_rank_gets_its_share_of_the_cores_and_at_least_one():
    n = threads_per_rank(MPI.COMM_WORLD)
    assert 1 <= n <= numba.config.NUMBA_NUM_THREADS


def test_two_ranks_on_a_node_do_not_run_more_numba_threads_than_cores():
    """Without NUMBA_NUM_THREADS each process would start one thread per core."""
    env = {k: v for k, v in mpi_env().items() if k != "NUMBA_NUM_THREADS"}
    code = ("from mpi4py import MPI; from fcm_fsi.io.threads import threads_per_rank; "
            "print(f'<{threads_per_rank(MPI.COMM_WORLD)}>', flush=True)")
    out = subprocess.run([shutil.which("mpirun"), "-n", "2", sys.executable, "-c", code], env=env,
                         capture_output=True, text=True, timeout=120, check=True).stdout
    threads = [int(x) for x in re.findall(r"<(\d+)>", out)]
    assert len(threads) == 2 and min(threads) >= 1
    assert sum(threads) <= max(2, os.cpu_count())


def test_small_work_runs_on_one_thread_and_the_count_comes_back():
    numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
    before = numba.get_num_threads()
    with serial_below(10):
        assert numba.get_num_threads() == 1
        x = np.random.default_rng(0).random((100, 3))
        assert max_displacement(x, np.zeros_like(x)) == np.sqrt((x ** 2).sum(axis=1)).max()
    assert numba.get_num_threads() == before
    with serial_below(SERIAL_SPHERES):
        assert numba.get_num_threads() == before
