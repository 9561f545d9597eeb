"""Pure-DEM runs: ``python -m fcm_fsi run case.yaml`` with only a ``dem`` section calls
:func:`run_dem_case`.

Time: the DEM advances in steps of ``dem.dt``; an *outer step* is ``run.dt`` (a whole
number of DEM steps) and carries the cadence of the ``run`` section: a progress line every
``run.log_every`` outer steps, sphere output every ``run.output_every`` (0 = first and
last), a checkpoint every ``run.checkpoint_every`` and at the end. Every rank runs the
same (deterministic) DEM; rank 0 writes.

Files in ``out_dir``: ``dem_energy.csv`` (ledger, every ``dem.ledger_every`` DEM steps),
``dem_force_displacement.csv`` (controlled blocks), ``spheres_NNNNN.vtp`` + ``spheres.pvd``,
``dem_checkpoint.h5``.
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from ..config.loader import ConfigError
from ..io.csv import TimeSeriesCSV
from ..io.logging import get_logger
from ..io.timing import StageTimer
from .ledger import COLUMNS
from .model import build_system
from .output import read_checkpoint, write_checkpoint, write_pvd, write_vtp
from .system import substep_count

log = get_logger("dem")


def _substeps(run_dt: float, dem_dt: float) -> int:
    """DEM steps per outer step; a mismatch is a case-file error on ``run.dt``."""
    try:
        return substep_count(run_dt, dem_dt)
    except ValueError as err:
        raise ConfigError(f"key 'run.dt' / 'dem.dt': {err}") from None


def fd_columns(n: int) -> dict[str, str]:
    cols = {"t": "s"}
    for i in range(n):
        for a in "xyz":
            cols[f"u{a}_{i}"] = "m"
        for a in "xyz":
            cols[f"f{a}_{i}"] = "N"
        for a in "xyz":
            cols[f"r{a}_{i}"] = "N"
    return cols


def run_dem_case(case, out_dir: Path, comm, restart: str | None) -> None:
    """Run a pure-DEM case to ``case.run.t_end`` (see module docstring)."""
    out_dir = Path(out_dir)
    rank = comm.rank if comm is not None else 0
    if rank == 0:
        out_dir.mkdir(parents=True, exist_ok=True)
    timer = StageTimer()
    cfg, run = case.dem, case.run
    with timer("setup"):
        system = build_system(cfg)
    st = system.state
    nsub = _substeps(run.dt, cfg.dt)
    pvd_entries: list[tuple[float, str]] = []
    n_out = 0
    if restart is not None:
        extra = read_checkpoint(Path(restart), system)
        n_out = int(extra.get("n_out", 0))
        pvd_entries = [(float(t), f"spheres_{i:05d}.vtp") for i, t in enumerate(extra.get("out_times", []))]
        log.info("restarted from %s at t = %.6g s (DEM step %d)", restart, st.t, st.step)
    # a restart keeps the rows up to the checkpoint and drops the later ones (written again)
    resume = dict(append=True, resume_at=st.t) if restart is not None else {}
    energy = TimeSeriesCSV(out_dir / "dem_energy.csv", COLUMNS, rank, **resume)
    ctrl = system.controls
    fd = TimeSeriesCSV(out_dir / "dem_force_displacement.csv", fd_columns(len(ctrl.items)), rank,
                       **resume) if ctrl is not None else None
    log.info("DEM: %d blocks, %d spheres, %d materials, dt = %.4g s, %d DEM steps per outer step %.4g s",
             st.nb, st.ns, len(cfg.materials), cfg.dt, nsub, run.dt)

    def output():
        nonlocal n_out
        if rank == 0:
            name = f"spheres_{n_out:05d}.vtp"
            write_vtp(out_dir / name, st)
            pvd_entries.append((st.t, name))
            write_pvd(out_dir / "spheres.pvd", pvd_entries)
        n_out += 1

    def checkpoint():
        if rank == 0:
            write_checkpoint(out_dir / "dem_checkpoint.h5", system,
                             {"n_out": n_out, "out_times": np.array([t for t, _ in pvd_entries], dtype=np.float64)})

    n_outer = int(round(run.t_end / run.dt))
    k0 = st.step // nsub
    if restart is None:
        output()
    wall0 = time.perf_counter()
    for k in range(k0, n_outer):
        with timer("dem steps"):
            for _ in range(nsub):
                system.step()
                if system.ledger is not None and st.step % cfg.ledger_every == 0:
                    energy.write(**system.ledger.last)
                    if fd is not None:
                        _fd_row(fd, system)
        done = k + 1
        with timer("output"):
            if (run.output_every and done % run.output_every == 0) or done == n_outer:
                output()
            if done % run.checkpoint_every == 0 or done == n_outer:
                checkpoint()
        if done % run.log_every == 0 or done == n_outer:
            el = time.perf_counter() - wall0
            eta = el / (done - k0) * (n_outer - done)
            led = system.ledger.last if system.ledger is not None else {}
            log.info("t = %.5g s (%d/%d), contacts %d, neighbour builds %d, energy balance %.2e, ETA %.0f s",
                     st.t, done, n_outer, system.interactions[0].n_contacts,
                     system.interactions[0].neighbours.builds, led.get("balance_rel", float("nan")), eta)
    energy.close()
    if fd is not None:
        fd.close()
    log.info("DEM run finished at t = %.6g s\n%s", st.t, timer.table())


def _fd_row(fd: TimeSeriesCSV, system) -> None:
    c = system.controls
    u = c.displacement(system.state)
    row = {"t": system.state.t}
    for i, item in enumerate(c.items):
        b = item.block
        for d, a in enumerate("xyz"):
            row[f"u{a}_{i}"] = u[i, d]
            row[f"f{a}_{i}"] = system.interaction_force[b, d]
            row[f"r{a}_{i}"] = c.F[b, d]
    fd.write(**row)
