"""Fluid ⇄ DEM coupling verification (issue #8): a floating box settling to its draft.

The case runs ``cases/floating_box.yaml`` through the normal time loop
(:class:`~fcm_fsi.simulation.coupled.CoupledModel`), with the end time and mesh of the
level, and reads ``series.csv``.

Reference: a 2D box of density ρ_b = ρ_w/2 floats at the hydrostatic draft
d = (ρ_b/ρ_w) H (Archimedes; air buoyancy 1.2/1000 of it is included in the target
below). Its heave period is compared with the hydrostatic + added-mass estimate
T = 2π √((m + m_a)/(ρ_w g B)) per unit depth with the flat-plate added mass
m_a = ρ_w π B²/8 of a section on the free surface (report only: the true added mass
of a rectangle of B/d = 4 depends on frequency; the estimate is the usual first guess).
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import yaml
from mpi4py import MPI

from ...simulation.coupled import CoupledModel
from ...io.logging import get_logger
from ...simulation.loop import SimulationDiverged, TimeLoop
from ..registry import Metric, at_least, at_most, register, rel_error_metric, report_only
from .phase_field import read_series
from .two_phase import case_output

log = get_logger("verify")
CASES = Path(__file__).resolve().parents[3] / "cases"


def run_coupled(data: dict, out: Path, comm: MPI.Comm) -> tuple[dict[str, np.ndarray], float, str | None]:
    """Run a coupled case mapping; returns its series (all ranks), the wall time [s] and the
    divergence message (None when the run reached t_end)."""
    case, sub = case_output(data, out, comm)
    t0 = time.perf_counter()
    model = CoupledModel(case, comm, out_dir=sub)
    failure = None
    try:
        TimeLoop(case, model, sub, comm, restart=None).run()
    except SimulationDiverged as err:
        failure = str(err)
        log.error("%s diverged: %s", data["name"], failure)
    wall = comm.allreduce(time.perf_counter() - t0, op=MPI.MAX)
    return read_series(sub / "series.csv"), wall, failure


def settled_mean(t, draft, y, window: float) -> tuple[float, float]:
    """Mean draft and centre height over the whole heave periods in the last ``window``
    seconds (between the first and last upward crossings of the mean), so a residual
    oscillation does not bias the mean."""
    sel = t >= t[-1] - window
    ts, ds, ys = t[sel], draft[sel], y[sel]
    s = ys - ys.mean()
    up = np.flatnonzero((s[:-1] < 0) & (s[1:] >= 0))
    if len(up) >= 2:
        span = slice(up[0], up[-1] + 1)
        ts, ds, ys = ts[span], ds[span], ys[span]
    w = np.gradient(ts)
    return float((ds * w).sum() / w.sum()), float((ys * w).sum() / w.sum())


def heave_period(t: np.ndarray, y: np.ndarray, y_eq: float) -> float:
    """Mean period from the upward zero crossings of y − y_eq (linear interpolation); NaN
    with fewer than two crossings."""
    s = y - y_eq
    up = np.flatnonzero((s[:-1] < 0) & (s[1:] >= 0))
    times = t[up] - s[up] * (t[up + 1] - t[up]) / (s[up + 1] - s[up])
    return float(np.diff(times).mean()) if len(times) >= 2 else float("nan")


@register("floating_box", "box of half the density of water released at the surface settles at draft H/2 (2D)", issue=8)
def floating_box(level, out_dir: Path, comm) -> list[Metric]:
    data = yaml.safe_load((CASES / "floating_box.yaml").read_text())
    data["output"]["directory"] = str(out_dir)
    data["output"]["xdmf"] = level == "full"
    if level == "quick":
        data["run"]["t_end"] = 3.0
        data["mesh"]["cells"] = [50, 25]
    series, wall, failure = run_coupled(data, out_dir, comm)
    blk = data["dem"]["blocks"][0]
    width, height = blk["size"][0], blk["size"][1]
    rho_w, rho_a = data["fluid"]["density"], data["fluid"]["gas_density"]
    rho_b = data["dem"]["materials"][0]["density"]
    draft_ref = (rho_b - rho_a) / (rho_w - rho_a) * height
    t, y = series["t"], series["b0_y"]
    level_wall = 0.5 * (series["level_left"] + series["level_right"])
    draft = level_wall - (y - 0.5 * height)
    d_end, y_eq = settled_mean(t, draft, y, window=2.0)
    g = abs(data["fluid"]["gravity"][1])
    m = rho_b * width * height
    m_a = rho_w * np.pi * width ** 2 / 8
    t_est = 2 * np.pi * np.sqrt((m + m_a) / (rho_w * g * width))
    period = heave_period(t, y, y_eq)
    if comm.rank == 0:
        _plot(out_dir, t, draft, draft_ref, period, t_est)
    t_reached = float(t[-1])
    if failure is not None:
        d_end = period = float("nan")
    return [at_least("completed", float(failure is None), 1.0),
            report_only("t_reached", t_reached, note=f"of t_end {data['run']['t_end']} s"),
            rel_error_metric("draft_rel_error", d_end, draft_ref, 0.02),
            report_only("heave_period", period, reference=float(t_est),
                        note="zero crossings of the centre height; reference: hydrostatic + flat-plate added mass"),
            at_most("exchange_error", float(series["exchange_error"].max()), 1e-10),
            report_only("volume_error", float(np.abs(series["volume_error"]).max())),
            report_only("wall_seconds", wall, note=f"{data['mesh']['cells']} cells, t_end {data['run']['t_end']} s")]


def _plot(out: Path, t, draft, draft_ref, period, t_est) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(7, 3.6))
    ax.plot(t, 100 * draft, label="draft (wall water level − box bottom)")
    ax.axhline(100 * draft_ref, color="k", ls="--", label="hydrostatic draft (ρ_b/ρ_w) H")
    ax.set_xlabel("t [s]"), ax.set_ylabel("draft [cm]")
    ax.set_title(f"floating box: heave period {period:.3f} s (estimate {t_est:.3f} s)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out / "floating_box_draft.png", dpi=110)
    plt.close(fig)
