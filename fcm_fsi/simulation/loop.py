"""The time loop shared by every model: step, report, write, checkpoint.

Every kind of case runs here (phase field, fluid, two-phase, coupled, DEM only). A model
provides ``mesh`` (None: no XDMF, the model writes its own output), ``output_functions``,
``series_units``, ``advance(t, dt)``, ``diagnostics()``, ``stable_dt()``, ``health()``,
``state()`` and ``load_state()``, and may provide ``write_output(t)``, ``close()`` and, to have
a failed step retaken as two half steps, ``snapshot()``, ``restore(s)`` and ``halves(dt)``.
The loop owns dt control and the retaken steps, logging (rank 0), the CSV series, XDMF output, checkpoints,
the stop on divergence (the last good checkpoint stays untouched), the stop on request and
the timing table.

Stop on request: a file named ``STOP`` in the output folder, or SIGTERM/SIGUSR1 to any rank
(a batch system's time limit, ``kill``), ends the run after the current step with a checkpoint
at that step, so no computed step is lost; the run then continues with ``--restart
OUT/checkpoint.h5``. A second SIGTERM ends the process at once. The check is one small
allreduce per step.
"""
from __future__ import annotations

import math
import signal
import time
from pathlib import Path
from typing import Protocol

import numpy as np
from mpi4py import MPI

from ..config.case import Case
from ..fluid.navier_stokes import NonlinearSolveError
from ..fluid.solvers import LinearSolveError
from ..io.checkpoint import accepted_fingerprints, case_fingerprint, read_checkpoint, write_checkpoint
from ..io.csv import TimeSeriesCSV
from ..io.fields import FieldWriter
from ..io.logging import get_logger
from ..io.threads import use_threads_per_rank
from ..io.timing import StageTimer, peak_memory_line, peak_memory_mib

log = get_logger("run")


class SimulationDiverged(RuntimeError):
    """A step produced non-finite or out-of-bounds values; the message says where."""


class StopRequested(RuntimeError):
    """The run was asked to stop (STOP file or signal) and wrote a checkpoint; the message says
    where and how to continue."""


#: name of the file in the output folder that asks a running case to stop after its step
STOP_FILE = "STOP"

_signalled: list[int] = []


def _on_signal(signum, frame) -> None:
    """Note the request; a second SIGTERM falls back to the default action (end now)."""
    _signalled.append(signum)
    if signum == signal.SIGTERM:
        signal.signal(signal.SIGTERM, signal.SIG_DFL)


def install_stop_handlers() -> dict:
    """SIGTERM and SIGUSR1 ask for a stop after the current step (main thread only); returns
    the handlers they replace (:func:`restore_handlers`)."""
    previous = {}
    try:
        for sig in (signal.SIGTERM, signal.SIGUSR1):
            previous[sig] = signal.signal(sig, _on_signal)
    except ValueError:        # not the main thread (e.g. under a test runner's worker)
        pass
    return previous


def restore_handlers(previous: dict) -> None:
    for sig, handler in previous.items():
        signal.signal(sig, handler)


class Model(Protocol):
    mesh: object
    output_functions: list
    series_units: dict[str, str]

    def advance(self, t: float, dt: float, timer: StageTimer) -> None: ...
    def diagnostics(self) -> dict[str, float]: ...
    def health(self, diag: dict[str, float]) -> str | None: ...
    def stable_dt(self, cfl: float) -> float: ...
    def state(self) -> tuple[dict[str, tuple[np.ndarray, np.ndarray]], dict[str, np.ndarray]]: ...
    def load_state(self, checkpoint) -> None: ...


#: failures of a step that stop the run unless the step can be retaken
STEP_FAILURES = (SimulationDiverged, LinearSolveError, NonlinearSolveError, FloatingPointError)
#: a failed step is retaken as two half steps, at most this many halvings deep
RETRIES = 2


def take_step(model: Model, t: float, dt: float, timer: StageTimer, retries: int = RETRIES) -> int:
    """Advance ``model`` from ``t`` by ``dt`` [s]. When the step fails and the model can take it
    again (``snapshot()``, ``restore(s)`` and ``halves(dt)``: the half steps are steps it can
    take), the start state is restored and the step retaken as two half steps, at most
    ``retries`` halvings deep; then the failure stops the run. Returns the steps retaken."""
    can_retake = retries > 0 and hasattr(model, "snapshot") and model.halves(dt)
    start = model.snapshot() if can_retake else None
    try:
        model.advance(t, dt, timer)
        return 0
    except STEP_FAILURES as err:
        if start is None:
            raise
        log.warning("t = %.6g s: %s — retrying as two steps of %.4g s", t, str(err).split(";")[0], dt / 2)
        model.restore(start)
        return (1 + take_step(model, t, dt / 2, timer, retries - 1)
                + take_step(model, t + dt / 2, dt / 2, timer, retries - 1))


def next_dt(case: Case, model: Model, t: float, last_dt: float | None = None) -> float:
    """Δt for the next step: fixed, or CFL-limited up to dt_max and, with ``run.dt_growth``, to
    that factor times the last step ``last_dt``; never past t_end."""
    run = case.run
    dt = run.dt
    if run.cfl is not None:
        dt = min(run.dt_max or run.dt, model.stable_dt(run.cfl))
        if run.dt_growth is not None and last_dt is not None:
            dt = min(dt, run.dt_growth * last_dt)
    remaining = run.t_end - t
    if remaining <= dt * (1 + 1e-6):      # last step lands on t_end
        return remaining
    if remaining < 1.5 * dt:              # two equal steps instead of a sliver
        return 0.5 * remaining
    return dt


def progress_line(step: int, t: float, dt: float, t_end: float, wall: float, t_start: float,
                  diag: dict[str, float]) -> str:
    """One progress line; the ETA extrapolates the wall time per simulated second of this run."""
    eta = wall / (t - t_start) * (t_end - t) if t > t_start else float("nan")
    health = " ".join(f"{k}={v:.4g}" for k, v in diag.items())
    return f"step {step:6d} t={t:.5g} dt={dt:.3g} wall={wall:.1f}s eta={eta:.0f}s {health}"


class TimeLoop:
    """Runs ``model`` for ``case`` writing into ``out_dir``."""

    def __init__(self, case: Case, model: Model, out_dir: Path, comm: MPI.Comm, restart: str | None,
                 shared_stop: Path | None = None, on_step=None):
        """``shared_stop``: a further STOP file that stops this run and is left in place (the
        verification runner's case folder: it stops every run of a set). ``on_step(step, t,
        row)``: called on every rank after each step (and at the start) with the series row."""
        self.case, self.model, self.out, self.comm = case, model, Path(out_dir), comm
        self.on_step = on_step
        self.rows: list[dict[str, float]] = []      # the series rows of this process (api.run returns them)
        self.shared_stop = shared_stop
        self.fingerprint = case_fingerprint(case)
        self.timer = StageTimer()
        threads = use_threads_per_rank(comm)     # Numba: this rank's share of the node's cores
        log.info("Numba threads per rank: %d", threads)
        self.step, self.t = 0, 0.0
        self.last_dt = case.run.dt        # the step before the next one (run.dt_growth)
        if restart:
            ck = read_checkpoint(Path(restart), comm, accepted_fingerprints(case))
            model.load_state(ck)
            self.step, self.t, self.last_dt = ck.step, ck.time, ck.dt
            log.info("restarted from %s at step %d, t = %.6g s", restart, ck.step, ck.time)
        self.retried = 0                  # steps retaken as two half steps (take_step)
        self.series = TimeSeriesCSV(self.out / "series.csv", {"step": "-", "t": "s", "dt": "s", "retried_steps": "-",
                                                              **model.series_units},
                                    comm.rank, append=bool(restart), resume_at=self.t if restart else None)
        self.probes = None                # output.probes, gauges, sensors (probes.csv, gauges.csv)
        out = case.output
        if out.probes or out.gauges or out.sensors:
            from .probes import ProbeRecorder
            self.probes = ProbeRecorder(case, model, self.out, comm.rank, resume_at=self.t if restart else None)
        self.fields, self._fields_t = None, None
        if case.output.xdmf and model.mesh is not None:
            name = "fields.xdmf" if not restart else f"fields_from_step{self.step}.xdmf"
            self.fields = FieldWriter(self.out / name, model.mesh, model.output_functions)
        # a model without a mesh (DEM only) writes its own output (write_output) at the output steps
        self.writes_fields = self.fields is not None or model.mesh is None

    def checkpoint(self, dt: float) -> None:
        if self.case.output.checkpoint:
            with self.timer("checkpoint"):
                fields, globals_ = self.model.state()
                write_checkpoint(self.out / "checkpoint.h5", self.comm, self.fingerprint, self.step, self.t,
                                 dt, fields, globals_)

    def write_fields(self) -> None:
        """The fluid fields (XDMF) and whatever else the model writes at an output time
        (coupled runs: the blocks, ``write_output``)."""
        if self.t == self._fields_t:        # already written at this time (an output step that then stopped)
            return
        self._fields_t = self.t
        if self.fields is not None:
            self.fields.write(self.t)
        extra = getattr(self.model, "write_output", None)
        if extra is not None:
            extra(self.t)

    def close(self) -> None:
        """Close the field output, the series and the model's own files."""
        if self.fields is not None:
            self.fields.close()
        self.series.close()
        if self.probes is not None:
            self.probes.close()
        close = getattr(self.model, "close", None)
        if close is not None:
            close()

    def record(self, dt: float, diag: dict[str, float]) -> None:
        with self.timer("output"):
            row = {"step": self.step, "t": self.t, "dt": dt, "retried_steps": float(self.retried), **diag}
            self.series.write(**row)
            self.rows.append(row)
            if self.probes is not None:
                self.probes.record(self.t)
        if self.on_step is not None:
            self.on_step(self.step, self.t, row)

    def stop_requested(self) -> str | None:
        """Why the run should stop now (a STOP file in the output folder, a signal to any rank),
        the same answer on every rank; None to go on."""
        local = 0
        if _signalled:
            local = 2
        elif self.comm.rank == 0 and (self.out / STOP_FILE).exists():
            local = 1
        elif self.comm.rank == 0 and self.shared_stop is not None and self.shared_stop.exists():
            local = 3
        why = self.comm.allreduce(local, op=MPI.MAX)
        if why == 0:
            return None
        if why == 1:
            return f"the file {self.out / STOP_FILE} (removed)"
        if why == 3:
            return f"the file {self.shared_stop}"
        return "a signal (SIGTERM/SIGUSR1)"

    def _stop_on_request(self, why: str, dt: float) -> None:
        """Checkpoint at this step, write the fields, remove the STOP file and raise StopRequested."""
        self.checkpoint(dt)
        if self.writes_fields:
            with self.timer("output"):
                self.write_fields()
        self.close()
        _signalled.clear()
        if self.comm.rank == 0:
            (self.out / STOP_FILE).unlink(missing_ok=True)
        self._log_cost_at_stop()
        where = (f"checkpoint {self.out / 'checkpoint.h5'} at this step; continue with --restart "
                 f"{self.out / 'checkpoint.h5'}" if self.case.output.checkpoint else
                 "no checkpoint (output.checkpoint is off)")
        raise StopRequested(f"stopped on request ({why}) after step {self.step}, t = {self.t:.6g} s: {where}")

    def _log_cost_at_stop(self) -> None:
        """The timing table and this rank's peak memory up to a divergence (not collective: the
        ranks may not all reach the stop together)."""
        log.info("stopped %s after %d steps at t = %.6g s\n%s\npeak memory (max RSS) of this rank %.0f MiB",
                 self.case.name, self.step, self.t, self.timer.table(), peak_memory_mib())

    def run(self) -> dict[str, float]:
        previous = install_stop_handlers()
        try:
            return self._run()
        finally:
            restore_handlers(previous)

    def _run(self) -> dict[str, float]:
        run, wall0 = self.case.run, time.perf_counter()
        t0 = self.t
        diag = self.model.diagnostics()
        if self.step == 0:
            self.record(0.0, diag)
            if self.writes_fields:
                self.write_fields()
        dt = run.dt
        while self.t < run.t_end * (1 - 1e-12):
            dt = next_dt(self.case, self.model, self.t, self.last_dt)
            try:
                self.retried += take_step(self.model, self.t, dt, self.timer)
            except STEP_FAILURES as err:
                self._log_cost_at_stop()
                raise SimulationDiverged(f"step {self.step + 1}, t = {self.t:.6g} s → {self.t + dt:.6g} s: "
                                         f"{err}; "
                                         f"last good checkpoint: {self.out / 'checkpoint.h5'}") from err
            self.step += 1
            self.t += dt
            self.last_dt = dt
            with self.timer("diagnostics"):
                diag = self.model.diagnostics()
            problem = self.model.health(diag)
            if problem:
                self._log_cost_at_stop()
                raise SimulationDiverged(f"step {self.step}, t = {self.t:.6g} s: {problem}; "
                                         f"last good checkpoint: {self.out / 'checkpoint.h5'}")
            self.record(dt, diag)
            done = self.t >= run.t_end * (1 - 1e-12)
            if self.writes_fields and (done or (run.output_every and self.step % run.output_every == 0)):
                with self.timer("output"):
                    self.write_fields()
            if done or self.step % run.checkpoint_every == 0:
                self.checkpoint(dt)
            if done or self.step % run.log_every == 0:
                wall = time.perf_counter() - wall0
                log.info(progress_line(self.step, self.t, dt, run.t_end, wall, t0, diag))
            if not done:
                why = self.stop_requested()
                if why:
                    self._stop_on_request(why, dt)
        self.close()
        memory = peak_memory_line(self.comm)
        log.info("finished %s: %d steps to t = %.6g s\n%s\n%s", self.case.name, self.step, self.t,
                 self.timer.table(), memory)
        return diag


def finite_or_message(diag: dict[str, float]) -> str | None:
    """The first non-finite diagnostic, as a message (None when all are finite)."""
    for k, v in diag.items():
        if not math.isfinite(v):
            return f"{k} is {v}"
    return None
