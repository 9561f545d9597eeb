"""Peridynamic runs on the shared time loop: ``python -m fcm_fsi run case.yaml`` with a ``pd``
section runs :class:`PDModel` under :class:`~.loop.TimeLoop`, with its STOP file, signals,
checkpoints (``checkpoint.h5``) and progress lines.

Time: the body advances in velocity-Verlet steps of ``pd.dt``; a loop step is ``run.dt`` (a
whole number of them) and carries the ``run`` cadence (progress lines, point output every
``run.output_every`` loop steps, checkpoints). Parallel: every rank runs the same deterministic
body (replicated; the Numba kernels use the rank's threads) and rank 0 writes.

Files in the output folder: ``series.csv`` (one row per loop step: energies, broken bonds,
damage), ``points_NNNNN.vtp`` + ``points.pvd`` (displacement, velocity, damage D of eq 9 per
point), ``checkpoint.h5``.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
from mpi4py import MPI

from ..config.case import Case
from ..config.loader import ConfigError
from ..io.logging import get_logger
from ..io.timing import StageTimer
from ..io.vtp import write_points_vtp, write_pvd
from ..pd.builder import build_system
from .loop import SimulationDiverged

log = get_logger("pd")


class PDModel:
    """A peridynamic case as a model of :mod:`.loop` (module docstring)."""

    mesh = None
    output_functions: list = []
    series_units = {"kinetic_energy": "J", "elastic_energy": "J", "dissipated_energy": "J", "external_work": "J",
                    "energy_balance": "J", "broken_bonds": "-", "broken_fraction": "-", "max_damage": "-"}

    def __init__(self, case: Case, comm: MPI.Comm, out_dir: Path, case_dir: Path | None = None) -> None:
        self.case, self.comm, self.out = case, comm, Path(out_dir)
        self.system = build_system(case.pd, case_dir)
        self.pvd: list[tuple[float, str]] = []
        s = self.system
        log.info("pd: %s %s, %d points, %d bonds, δ = %.4g … %.4g m (%.4g × spacing), dt = %.4g s, %d steps per "
                 "loop step", case.pd.model, case.pd.formulation, len(s.x), s.bonds.count, s.horizon.min(),
                 s.horizon.max(), case.pd.horizon_factor, case.pd.dt, self._steps(case.run.dt))

    def _steps(self, dt: float) -> int:
        n = max(round(dt / self.case.pd.dt), 1)
        if abs(n * self.case.pd.dt - dt) > 1e-9 * dt:
            raise SimulationDiverged(f"the loop asked for a step of {dt:.6g} s, not a whole number of pd.dt = "
                                     f"{self.case.pd.dt:.6g} s")
        return n

    def advance(self, t: float, dt: float, timer: StageTimer) -> None:
        """``dt`` [s] in whole steps of pd.dt."""
        s = self.system
        with timer("pd steps"):
            for _ in range(self._steps(dt)):
                s.step()
        if not (np.isfinite(s.u).all() and np.isfinite(s.v).all()):
            bad = int(np.flatnonzero(~np.isfinite(s.u).all(axis=1) | ~np.isfinite(s.v).all(axis=1))[0])
            raise SimulationDiverged(f"pd point {bad} at {s.x[bad, :self.case.pd.dim]} is not finite")

    def stable_dt(self, cfl: float) -> float:
        return self.case.run.dt

    def diagnostics(self) -> dict[str, float]:
        s = self.system
        broken = s.broken()
        return {**s.energies(), "broken_bonds": float(broken), "broken_fraction": broken / max(s.bonds.count, 1),
                "max_damage": float(s.damage().max()) if len(s.x) else 0.0}

    def health(self, diag: dict[str, float]) -> str | None:
        return None

    def write_output(self, t: float) -> None:
        """The points (VTP) and the collection (PVD) at an output time, by rank 0."""
        name = f"points_{len(self.pvd):05d}.vtp"
        self.pvd.append((self.system.t, name))
        if self.comm.rank == 0:
            s = self.system
            write_points_vtp(self.out / name, s.x + s.u, {"displacement": s.u, "velocity": s.v, "damage": s.damage()},
                             scalars="damage")
            write_pvd(self.out / "points.pvd", self.pvd)

    def state(self):
        out = self.system.arrays()
        out["pd__output_times"] = np.array([t for t, _ in self.pvd], np.float64)
        return {}, out

    def load_state(self, checkpoint) -> None:
        g = checkpoint.globals
        if g["pd__u"].shape != self.system.u.shape or g["pd__intact"].shape != self.system.bonds.intact.shape:
            raise ConfigError(f"the checkpoint has {g['pd__u'].shape[0]} points / {g['pd__intact'].shape[0]} bonds, "
                              f"the case {len(self.system.x)} / {self.system.bonds.count}")
        self.system.load_arrays(g)
        self.pvd = [(float(t), f"points_{i:05d}.vtp") for i, t in enumerate(g["pd__output_times"])]
