"""Numba threads: how many per MPI rank, and one thread for small kernels.

Numba starts one thread per core of the machine in every process. Under MPI each rank does so,
and a parallel kernel then waits for a thread whose core another rank (or another job) holds:
a parallel region's launch, a few microseconds on idle cores, becomes a scheduler time slice,
milliseconds. The DEM of a coupled run calls several small kernels per sub-step and 40
sub-steps per fluid step, so it suffers most: on ``cases/block_overturn.yaml`` (2 blocks, 1 rank,
another process on the second core) the DEM stage took 29.3 s for 15 fluid steps with the
machine's 2 threads and 0.15 s with one (docs/performance.md).

- :func:`use_threads_per_rank` (at start-up): the cores this rank may run on (its CPU affinity;
  when the ranks are not pinned, the node's cores shared out over the node's ranks), at least 1
  and at most ``NUMBA_NUM_THREADS``.
- :func:`serial_below`: one thread for the calls inside it when the work is small (fewer than
  :data:`SERIAL_SPHERES` spheres), whatever the rank's share.
"""
from __future__ import annotations

import contextlib
import os

import numba
from mpi4py import MPI

#: below this many spheres a DEM step runs its kernels on one thread: the work per kernel
#: (≈ 0.1 µs per sphere) is then below the cost of waking a second thread
SERIAL_SPHERES = 4096


def threads_per_rank(comm: MPI.Comm) -> int:
    """Numba threads for this rank: its share of the node's cores (≥ 1, ≤ NUMBA_NUM_THREADS)."""
    local = comm.Split_type(MPI.COMM_TYPE_SHARED)
    ranks_here = local.size
    local.Free()
    cores = len(os.sched_getaffinity(0))
    if cores >= (os.cpu_count() or cores):       # not pinned: the node's ranks share its cores
        cores //= ranks_here
    return max(1, min(cores, numba.config.NUMBA_NUM_THREADS))


def use_threads_per_rank(comm: MPI.Comm) -> int:
    """Set :func:`threads_per_rank` for this process's Numba kernels; returns it."""
    n = threads_per_rank(comm)
    numba.set_num_threads(n)
    return n


@contextlib.contextmanager
def serial_below(work: int, limit: int = SERIAL_SPHERES):
    """Numba kernels inside run on one thread when ``work`` < ``limit``."""
    if work >= limit:
        yield
        return
    before = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        yield
    finally:
        numba.set_num_threads(before)
