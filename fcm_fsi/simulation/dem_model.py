"""Pure-DEM runs on the shared time loop: ``python -m fcm_fsi run case.yaml`` with only a ``dem``
section runs :class:`DEMModel` under :class:`~.loop.TimeLoop`, with the same STOP file,
signals, checkpoints (``checkpoint.h5``) and progress lines as every other case.

Time: the DEM advances in steps of ``dem.dt``; a loop step is ``run.dt`` (a whole number of DEM
steps) and carries the cadence of the ``run`` section: a progress line every ``run.log_every``
steps, sphere output every ``run.output_every`` (0 = first and last), a checkpoint every
``run.checkpoint_every`` and at the end. Every rank runs the same (deterministic) DEM; rank 0
writes.

Files in the output folder: ``series.csv`` (one row per loop step: contacts, neighbour-list
builds, energy balance), ``dem_energy.csv`` (the ledger, every ``dem.ledger_every`` DEM steps),
``dem_force_displacement.csv`` (controlled blocks), ``spheres_NNNNN.vtp`` + ``spheres.pvd``,
``checkpoint.h5``.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
from mpi4py import MPI

from ..config.case import Case
from ..config.loader import ConfigError
from ..dem.ledger import COLUMNS
from ..dem.model import build_system
from ..dem.output import write_vtp
from ..dem.state import kinetic_energy
from ..dem.system import substep_count
from ..io.csv import TimeSeriesCSV
from ..io.logging import get_logger
from ..io.timing import StageTimer
from ..io.vtp import write_pvd
from .loop import SimulationDiverged

log = get_logger("dem")


def force_displacement_columns(n: int) -> dict[str, str]:
    """Columns of ``dem_force_displacement.csv`` for ``n`` controlled blocks: displacement,
    interaction force and control reaction per block."""
    cols = {"t": "s"}
    for i in range(n):
        cols.update({f"u{a}_{i}": "m" for a in "xyz"})
        cols.update({f"f{a}_{i}": "N" for a in "xyz"})
        cols.update({f"r{a}_{i}": "N" for a in "xyz"})
    return cols


class DEMModel:
    """A DEM-only case as a model of :mod:`.loop` (module docstring)."""

    mesh = None
    output_functions: list = []
    series_units = {"contacts": "-", "neighbour_builds": "-", "kinetic_energy": "J", "energy_balance": "-"}

    def __init__(self, case: Case, comm: MPI.Comm, out_dir: Path, restart: bool = False) -> None:
        self.case, self.comm, self.out = case, comm, Path(out_dir)
        self.rank = comm.rank
        self.system = build_system(case.dem)
        st = self.system.state
        try:
            self.substeps = substep_count(case.run.dt, case.dem.dt)
        except ValueError as err:
            raise ConfigError(f"key 'run.dt' / 'dem.dt': {err}") from None
        steps = case.run.t_end / case.run.dt
        if abs(steps - round(steps)) > 1e-9 * max(steps, 1.0):
            raise ConfigError(f"key 'run.t_end' = {case.run.t_end:.10g} s: a DEM case runs whole steps of run.dt = "
                              f"{case.run.dt:.10g} s; allowed: a whole multiple of it (e.g. "
                              f"{max(round(steps), 1) * case.run.dt:.10g} s)")
        self.pvd: list[tuple[float, str]] = []
        # a restart keeps the rows up to the checkpoint and drops the later ones (written again at load_state)
        self._resume = restart
        self.energy = self.force_displacement = None
        if not restart:
            self._open_csv({})
        self.last_dt = case.run.dt
        log.info("DEM: %d blocks, %d spheres, %d materials, dt = %.4g s, %d DEM steps per loop step %.4g s",
                 st.nb, st.ns, len(case.dem.materials), case.dem.dt, self.substeps, case.run.dt)

    def _open_csv(self, resume: dict) -> None:
        self.energy = TimeSeriesCSV(self.out / "dem_energy.csv", COLUMNS, self.rank, **resume)
        ctrl = self.system.controls
        if ctrl is not None:
            self.force_displacement = TimeSeriesCSV(self.out / "dem_force_displacement.csv",
                                                    force_displacement_columns(len(ctrl.items)), self.rank, **resume)

    # ------------------------------------------------------------ the step
    def advance(self, t: float, dt: float, timer: StageTimer) -> None:
        """``dt`` [s] in whole DEM steps (the loop's steps are ``run.dt``, a whole number of them)."""
        system, st = self.system, self.system.state
        try:
            n = substep_count(dt, self.case.dem.dt)
        except ValueError as err:
            raise SimulationDiverged(f"the loop asked for a step of {dt:.6g} s: {err}") from None
        every = self.case.dem.ledger_every
        with timer("dem steps"):
            for _ in range(n):
                system.step()
                if system.ledger is not None and st.step % every == 0:
                    self.energy.write(**system.ledger.last)
                    if self.force_displacement is not None:
                        self._force_displacement_row()
        if not (np.isfinite(st.pos).all() and np.isfinite(st.vel).all()):
            bad = int(np.flatnonzero(~np.isfinite(st.pos).all(axis=1) | ~np.isfinite(st.vel).all(axis=1))[0])
            raise SimulationDiverged(f"block {bad} is not finite at DEM step {st.step}")
        self.last_dt = dt

    def _force_displacement_row(self) -> None:
        system = self.system
        c = system.controls
        u = c.displacement(system.state)
        row = {"t": system.state.t}
        for i, item in enumerate(c.items):
            b = item.block
            for d, a in enumerate("xyz"):
                row[f"u{a}_{i}"] = u[i, d]
                row[f"f{a}_{i}"] = system.interaction_force[b, d]
                row[f"r{a}_{i}"] = c.F[b, d]
        self.force_displacement.write(**row)

    def stable_dt(self, cfl: float) -> float:
        return self.case.run.dt

    # ------------------------------------------------------------ report, output
    def diagnostics(self) -> dict[str, float]:
        contact = self.system.interactions[0]
        led = self.system.ledger.last if self.system.ledger is not None else {}
        st = self.system.state
        kinetic = kinetic_energy(st, st.mass, st.inertia)
        return {"contacts": float(contact.n_contacts), "neighbour_builds": float(contact.neighbours.builds),
                "kinetic_energy": kinetic, "energy_balance": float(led.get("balance_rel", np.nan))}

    def health(self, diag: dict[str, float]) -> str | None:
        return None

    def write_output(self, t: float) -> None:
        """The spheres (VTP) and the collection (PVD) at an output time."""
        if self.rank == 0:
            name = f"spheres_{len(self.pvd):05d}.vtp"
            write_vtp(self.out / name, self.system.state)
            self.pvd.append((self.system.state.t, name))
            write_pvd(self.out / "spheres.pvd", self.pvd)
        else:
            self.pvd.append((self.system.state.t, ""))

    # ------------------------------------------------------------ checkpoint
    def state(self):
        out = self.system.arrays()
        out["dem__output_times"] = np.array([t for t, _ in self.pvd], np.float64)
        return {}, out

    def load_state(self, checkpoint) -> None:
        g, st = checkpoint.globals, self.system.state
        if g["dem__pos"].shape != st.pos.shape or g["dem__sph_pos"].shape != st.sph_pos.shape:
            raise ConfigError(f"the checkpoint has {g['dem__pos'].shape[0]} blocks / {g['dem__sph_pos'].shape[0]} "
                              f"spheres, the case {st.nb} / {st.ns}")
        self.system.load_arrays(g)
        self.pvd = [(float(t), f"spheres_{i:05d}.vtp") for i, t in enumerate(g["dem__output_times"])]
        self._open_csv(dict(append=True, resume_at=st.t))

    def close(self) -> None:
        for csv in (self.energy, self.force_displacement):
            if csv is not None:
                csv.close()
