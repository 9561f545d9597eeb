"""Wall-time accounting by named stage, reported as a table at the end of a run."""
from __future__ import annotations

import resource
import time
from collections import defaultdict
from contextlib import contextmanager

from mpi4py import MPI


class StageTimer:
    """Accumulates wall seconds per stage: ``with timer("assembly"): ...``."""

    def __init__(self) -> None:
        self.seconds: dict[str, float] = defaultdict(float)
        self.calls: dict[str, int] = defaultdict(int)
        self.t0 = time.perf_counter()

    @contextmanager
    def __call__(self, stage: str):
        t = time.perf_counter()
        try:
            yield
        finally:
            self.seconds[stage] += time.perf_counter() - t
            self.calls[stage] += 1

    def table(self) -> str:
        total = time.perf_counter() - self.t0
        lines = [f"{'stage':<24}{'calls':>8}{'seconds':>12}{'share':>8}"]
        for stage, sec in sorted(self.seconds.items(), key=lambda kv: -kv[1]):
            lines.append(f"{stage:<24}{self.calls[stage]:>8}{sec:>12.3f}{100 * sec / max(total, 1e-12):>7.1f}%")
        lines.append(f"{'total wall':<24}{'':>8}{total:>12.3f}")
        return "\n".join(lines)


def peak_memory_mib() -> float:
    """This process's peak resident set size [MiB] (Linux ru_maxrss is in KiB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def peak_memory_line(comm) -> str:
    """Collective: 'peak memory ... MiB' summed over the ranks and of the largest rank."""
    mine = peak_memory_mib()
    total, largest = comm.allreduce(mine, op=MPI.SUM), comm.allreduce(mine, op=MPI.MAX)
    return f"peak memory (max RSS) {total:.0f} MiB over {comm.size} rank(s), largest rank {largest:.0f} MiB"
