"""Two-phase free-surface verification (issue #4): still water, sloshing, Martin & Moyce dam break.

Every case runs the :class:`~fcm_fsi.simulation.two_phase.TwoPhaseModel` through the
normal :class:`~fcm_fsi.simulation.loop.TimeLoop` from a case mapping (the same schema as
``cases/*.yaml``) and reads the wall gauges from the loop's ``series.csv``.
"""
from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np
from mpi4py import MPI

from ...config import case_from_dict
from ...fluid import solvers
from ...simulation.loop import STOP_FILE, TimeLoop
from ...simulation.two_phase import TwoPhaseModel
from ..registry import (
    Metric,
    at_least,
    at_most,
    in_interval,
    register,
    rel_error_metric,
    report_only,
    resume_checkpoint,
)
from .phase_field import read_series

# ---------------------------------------------------------------- references
SLOSHING_PERIOD = 3.5520        # issue #4 target; SPEC §4.2: linear 3.5515338, weakly nonlinear 3.5519687 [s]
MM_A = 0.05715                  # Martin & Moyce column width a [m], n² = 2
MM_N2 = 2.0
# Martin & Moyce (1952), n² = 2, a = 2.25 in: front Z = x/a vs T = n t √(g/a) (SPEC §5)
MM_FRONT = np.array([(0.41, 1.11), (0.84, 1.22), (1.19, 1.44), (1.43, 1.67), (1.63, 1.89), (1.83, 2.11),
                     (1.98, 2.33), (2.20, 2.56), (2.32, 2.78), (2.51, 3.00), (2.65, 3.22), (2.83, 3.44),
                     (2.98, 3.67), (3.11, 3.89), (3.33, 4.11)])
G = 9.81

WATER_AIR = {"density": 998.2, "viscosity": 1.0e-3, "gas_density": 1.204, "gas_viscosity": 1.82e-5}
#: the fast step (docs/performance.md): one Oseen solve per step with extrapolated advection, one
#: linearised phase-field solve, Courant number 1 with no fixed cap below it
FAST_STEP = {"run": {"cfl": 1.0, "dt_max": 0.01, "dt_growth": 1.2},
             "fluid": {"nonlinear": "linearised", "petsc": solvers.ITERATIVE_2D},
             "phase_field": {"picard_max_iterations": 1}}


def slip_walls(names=("xmin", "xmax", "ymin", "ymax"), kind="slip") -> list[dict]:
    return [{"boundary": n, "kind": kind} for n in names]


def thin_slab_3d(data: dict, thickness: float, cells: int = 1) -> dict:
    """The 3D version of a 2D (x, y = vertical) case mapping: a slab of the given thickness [m]
    between slip walls ymin, ymax; vertical = z, so the 2D case's ymin, ymax become zmin, zmax.
    Refine zones, initial boxes and the pressure reference get the thickness as their y range."""
    out = {k: (dict(v) if isinstance(v, dict) else v) for k, v in data.items()}
    out["name"] = data["name"] + "_3d"
    mesh = out["mesh"]
    mesh["lower"] = [mesh["lower"][0], 0.0, mesh["lower"][1]]
    mesh["upper"] = [mesh["upper"][0], thickness, mesh["upper"][1]]
    if mesh["kind"] == "rectangle":
        mesh["kind"] = "box"
        mesh["cells"] = [mesh["cells"][0], cells, mesh["cells"][1]]
    mesh["refine"] = [{**z, "lower": [z["lower"][0], 0.0, z["lower"][1]],
                       "upper": [z["upper"][0], thickness, z["upper"][1]]} for z in mesh.get("refine", [])]
    pf = out["phase_field"] = dict(out["phase_field"])
    init = pf["initial"] = dict(pf["initial"])
    if init["shape"] == "box":
        init["lower"] = [init["lower"][0], -1.0, init["lower"][1]]
        init["upper"] = [init["upper"][0], thickness + 1.0, init["upper"][1]]
    fl = out["fluid"]
    fl["gravity"] = [fl["gravity"][0], 0.0, fl["gravity"][1]]
    ref = fl["pressure_reference"]
    fl["pressure_reference"] = [ref[0], 0.0, ref[1]]
    rename = {"ymin": "zmin", "ymax": "zmax"}
    fl["boundaries"] = ([{**bc, "boundary": rename.get(bc["boundary"], bc["boundary"])} for bc in fl["boundaries"]]
                        + slip_walls(("ymin", "ymax")))
    return out


def case_output(data: dict, out: Path, comm: MPI.Comm):
    """(case, its output folder out/name, created on rank 0) for a case mapping."""
    case = case_from_dict(data, source=data["name"])
    sub = out / data["name"]
    if comm.rank == 0:
        sub.mkdir(parents=True, exist_ok=True)
    comm.barrier()
    return case, sub


def run_two_phase(data: dict, out: Path, comm: MPI.Comm) -> tuple[TwoPhaseModel, dict[str, np.ndarray], float]:
    """Run a two-phase case mapping; returns the model, its series (all ranks) and the wall time [s]."""
    case, sub = case_output(data, out, comm)
    t0 = time.perf_counter()
    model = TwoPhaseModel(case, comm)
    TimeLoop(case, model, sub, comm, restart=resume_checkpoint(sub), shared_stop=out / STOP_FILE).run()
    wall = comm.allreduce(time.perf_counter() - t0, op=MPI.MAX)
    comm.barrier()
    return model, read_series(sub / "series.csv"), wall


def _plt():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


# ---------------------------------------------------------------- still water
STILL = {"quick": {"cells": 20, "dt": 2.0e-3}, "full": {"cells": 40, "dt": 2.0e-3}}
STILL_DEPTH, STILL_HEIGHT = 0.5, 1.0


def still_water_case(cells: int, dt: float, t_end: float = 1.0) -> dict:
    return {
        "name": f"still_water_{cells}",
        "run": {"t_end": t_end, "dt": dt, "cfl": 0.5, "dt_max": dt, "log_every": 100, "checkpoint_every": 10 ** 6},
        "mesh": {"kind": "rectangle", "lower": [0.0, 0.0], "upper": [1.0, STILL_HEIGHT], "cells": [cells, cells]},
        "phase_field": {"width_factor": 0.6, "volume_correction": False, "reference_velocity": 1.0e-3,
                        **FAST_STEP["phase_field"],
                        "initial": {"shape": "box", "lower": [-1.0, -1.0], "upper": [2.0, STILL_DEPTH]}},
        "fluid": {**WATER_AIR, "gravity": [0.0, -G], "pressure_reference": [0.0, STILL_HEIGHT],
                  "boundaries": slip_walls(("xmin", "xmax", "ymin"), "no_slip") + slip_walls(("ymax",)),
                  "nonlinear": FAST_STEP["fluid"]["nonlinear"]},
        "output": {"xdmf": False, "checkpoint": False},
    }


@register("still_water", "water 0.5 m deep under air in a closed 1 m tank, at rest for 1 s: spurious velocity "
          "and hydrostatic bottom pressure", issue=4)
def still_water(level: str, out: Path, comm: MPI.Comm) -> list[Metric]:
    """max|u| over the run and the mean bottom pressure at t = 1 s against the two-layer
    hydrostatic ρ_w g h + ρ_a g (H − h) (p = 0 pinned at the top corner, in the air).

    Runs with the default well-balanced pressure p' + Π (fluid/hydrostatic.py), which makes the
    layered rest state exact; what remains is the phase field's own regularisation (mobility
    γ = 1e-3 m/s) moving φ slightly out of layers at the side walls. Without the split the
    spurious velocity of the P1/P1 PSPG scheme at a density jump scales with Δt (the PSPG mass
    source is τ·(∇p − ρg)/ρ with τ ≈ Δt/2): Δt = 2 ms at both levels.
    """
    p = STILL[level]
    data = still_water_case(p["cells"], p["dt"])
    model, s, wall = run_two_phase(data, out, comm)
    fl = data["fluid"]
    p_ref = G * (fl["density"] * STILL_DEPTH + fl["gas_density"] * (STILL_HEIGHT - STILL_DEPTH))
    if comm.rank == 0:
        plt = _plt()
        fig, ax = plt.subplots(1, 2, figsize=(10, 3.8))
        ax[0].semilogy(s["t"], np.maximum(s["u_max"], 1e-12))
        ax[0].axhline(1e-3, color="k", ls="--", label="target 1e-3 m/s")
        ax[0].set_xlabel("t [s]")
        ax[0].set_ylabel("max |u| [m/s]")
        ax[0].legend()
        ax[0].grid(alpha=0.3)
        ax[1].plot(s["t"][1:], 100 * (s["p_bottom"][1:] - p_ref) / p_ref)
        ax[1].set_xlabel("t [s]")
        ax[1].set_ylabel("bottom pressure error [%]")
        ax[1].grid(alpha=0.3)
        fig.suptitle(f"still water, {p['cells']}² cells, Δt = {p['dt']} s, {comm.size} rank(s), wall {wall:.0f} s")
        fig.tight_layout()
        fig.savefig(out / "still_water.png", dpi=110)
        plt.close(fig)
    return [
        at_most("spurious_velocity", float(s["u_max"].max()), 1e-3, unit="m/s"),
        at_most("bottom_pressure_error", abs(s["p_bottom"][-1] - p_ref) / p_ref, 5e-3),
        report_only("bottom_pressure", float(s["p_bottom"][-1]), unit="Pa", reference=p_ref,
                    note="mean over the bottom at t = 1 s"),
        report_only("volume_error", abs(float(s["volume_error"][-1])), note="|{φ ≥ 0.5}| drift, no correction"),
        report_only("wall_time", wall, unit="s", note=f"{p['cells']}² cells, {comm.size} rank(s)"),
    ]


# ---------------------------------------------------------------- sloshing
#: bands: the refined surface band's cell sizes; the full level runs two (the finer one is the
#: paper's 0.0025) and extrapolates the period. 3D: one cell (0.01) across the thickness.
SLOSH = {"quick": {"size": 0.05, "bands": (0.01,), "half_width": 0.06, "dt": 0.04, "periods": 1.6},
         "full": {"size": 0.04, "bands": (0.005, 0.0025), "half_width": 0.04, "dt": 0.02, "periods": 5.3}}
SLOSH_HEIGHT = 1.4
SLOSH_DEPTH = 1.0
SLOSH_THICKNESS = 0.01         # the paper's 3D tank (SPEC §4.2)
SLOSH_3D = {"quick": {"size": 0.05, "bands": (0.01,), "half_width": 0.06, "dt": 0.04, "periods": 1.6},
            "full": {"size": 0.05, "bands": (0.01,), "half_width": 0.06, "dt": 0.04, "periods": 5.3}}
#: the period error falls at first order in the band cell (0.01 → 0.005: 1.6 % → 0.83 % of the
#: two-layer value), so one band allows ≈ 1.6 %/cm of band cell: 2 % at the quick level's 0.01
SLOSH_BAND_ORDER = 1.0
SLOSH_COARSE_TOL = 0.02
SLOSH_FINE_TOL = 0.01          # the finest band at the full level (issue #44)
SLOSH_EXTRAPOLATED_TOL = 5e-3  # the period extrapolated from the two finest bands (issue #44)


#: cells grow by this much per metre of distance from the surface band: with a jump from the
#: 0.0025 band to 0.04 at the band's edge the flow went unstable there after ≈ 3 periods
SLOSH_BAND_GRADING = 0.5
#: ε_K = max(ε, 0.5 h_K) (``phase_field.width_floor``): with the band's ε in the 16× coarser cells
#: below it the sharpening flux amplified φ's small deviations from 1 in the bulk liquid, and the
#: 0.0025 band went unstable after ≈ 3 periods (docs/two-phase.md); the band's cells keep ε
SLOSH_WIDTH_FLOOR = 0.5


def sloshing_case(size: float, band: float, dt: float, t_end: float, half_width: float = 0.06) -> dict:
    """The refined band |y − 1| ≤ half_width must hold the interface tails (≈ ±6 ε, ε = band
    cell): tails in the coarse cells outside it roughen φ and drive spurious currents. Outside
    the band the cells grow gradually (:data:`SLOSH_BAND_GRADING`) and carry their own interface
    width (:data:`SLOSH_WIDTH_FLOOR`). The fast step's solver settings (:data:`FAST_STEP`; Δt
    stays fixed, the wave is far below Courant number 1)."""
    return {
        "name": f"sloshing_{band:g}",
        "run": {"t_end": t_end, "dt": dt, "cfl": 0.5, "dt_max": dt, "log_every": 50, "checkpoint_every": 10 ** 6},
        "mesh": {"kind": "gmsh_box", "lower": [0.0, 0.0], "upper": [1.0, SLOSH_HEIGHT], "size": size,
                 "refine": [{"lower": [0.0, SLOSH_DEPTH - half_width], "upper": [1.0, SLOSH_DEPTH + half_width],
                             "size": band, "grading": SLOSH_BAND_GRADING}]},
        "phase_field": {"width_factor": 1.0, "width_floor": SLOSH_WIDTH_FLOOR, "volume_correction": True,
                        "reference_velocity": 0.02, **FAST_STEP["phase_field"],
                        "initial": {"shape": "surface_wave", "depth": SLOSH_DEPTH, "amplitude": 0.01, "length": 1.0}},
        "fluid": {"density": 1.0, "viscosity": 1.0e-5, "gas_density": 0.1, "gas_viscosity": 1.0e-6,
                  "gravity": [0.0, -1.0], "pressure_reference": [0.0, SLOSH_HEIGHT], "boundaries": slip_walls(),
                  "nonlinear": FAST_STEP["fluid"]["nonlinear"]},
        "output": {"xdmf": False, "checkpoint": False},
    }


def zero_crossings(t: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Times where y changes sign (linear interpolation)."""
    i = np.flatnonzero(np.sign(y[:-1]) * np.sign(y[1:]) < 0)
    return t[i] - y[i] * (t[i + 1] - t[i]) / (y[i + 1] - y[i])


def period_from_gauge(t: np.ndarray, eta: np.ndarray) -> float:
    """Period from the first and last zero crossing of a gauge signal (two per period)."""
    tc = zero_crossings(t, eta)
    if len(tc) < 3:
        return float("nan")
    return 2.0 * (tc[-1] - tc[0]) / (len(tc) - 1)


def two_layer_period(depth: float, gas_depth: float, rho_l: float, rho_g: float, g: float = 1.0,
                     length: float = 1.0) -> float:
    """Linear first-mode period of two superposed inviscid layers between a rigid bottom and lid:
    ω² = g k (ρ_l − ρ_g) / (ρ_l coth(k h_l) + ρ_g coth(k h_g)), k = π/L. For ρ_g → 0 it is the
    single-fluid T0 = 3.5515338 of SPEC §4.2; with ρ_g = 0.1 the gas inertia lengthens it ≈ 11 %."""
    k = math.pi / length
    w2 = g * k * (rho_l - rho_g) / (rho_l / math.tanh(k * depth) + rho_g / math.tanh(k * gas_depth))
    return 2.0 * math.pi / math.sqrt(w2)


def case_two_layer_period(data: dict) -> float:
    """:func:`two_layer_period` of a sloshing case mapping: its densities, liquid depth, the gas
    layer up to the lid, g and the tank length."""
    fl, mesh = data["fluid"], data["mesh"]
    depth = data["phase_field"]["initial"]["depth"]
    vertical = len(mesh["upper"]) - 1
    return two_layer_period(depth, mesh["upper"][vertical] - depth, fl["density"], fl["gas_density"],
                            abs(fl["gravity"][vertical]), mesh["upper"][0] - mesh["lower"][0])


def extrapolated_period(bands: tuple[float, ...], periods: list[float], order: float = SLOSH_BAND_ORDER) -> float:
    """Richardson extrapolation to band cell 0 from the two finest bands at the given order."""
    (h1, t1), (h2, t2) = sorted(zip(bands, periods))[:2]
    r = (h2 / h1) ** order
    return t1 + (t1 - t2) / (r - 1.0)


@register("sloshing", "first sloshing mode, L = h = 1, η = 0.01 cos(πx), g = 1, ρ_g/ρ_l = 0.1 (paper §4(2)): "
          "period against linear two-layer theory, amplitude, from wall gauges", issue=4)
def sloshing(level: str, out: Path, comm: MPI.Comm) -> list[Metric]:
    """Wall gauges η = (liquid level at the wall) − h from ∫φ ds over each side wall.

    The reference is the linear two-layer standing-wave period of the closed tank with the
    case's own densities, depths and g (:func:`case_two_layer_period`, 3.9569): 3.5520 is the
    single-fluid period, which a gas of density 0.1 lengthens. The full level runs 5.3 periods
    with the bands 0.005 and the paper's 0.0025: the finer one's period within 1 %, the period
    extrapolated from both within 0.5 %, the 5-period amplitude ≥ 0.9. The quick level runs
    1.6 periods on the 0.01 band: within the 2 % its band allows (the 5-period amplitude is
    replaced by the amplitude over its last 0.6 T, reported).
    """
    return _sloshing(SLOSH[level], out, comm)


@register("sloshing_3d", "the paper's thin 3D sloshing tank (thickness 0.01, slip side walls, tetrahedra): "
          "period and amplitude from wall gauges, as `sloshing`", issue=4)
def sloshing_3d(level: str, out: Path, comm: MPI.Comm) -> list[Metric]:
    """``sloshing`` in the paper's 3D tank, 1 × 0.01 × 1.4 (vertical z), gmsh tetrahedra with the
    refined surface band; the band cell is 0.01 at both levels (one cell across the thickness),
    so its period is checked within the 2 % of that band (the band convergence study is the 2D
    case's). Quick: 1.6 periods; full: 5.3 periods (the 5-period amplitude)."""
    return _sloshing(SLOSH_3D[level], out, comm, thickness=SLOSH_THICKNESS)


def _sloshing(p: dict, out: Path, comm: MPI.Comm, thickness: float | None = None) -> list[Metric]:
    runs = []
    for band in p["bands"]:
        data = sloshing_case(p["size"], band, p["dt"], 1.0, p["half_width"])
        t_two = case_two_layer_period(data)
        data["run"]["t_end"] = p["periods"] * t_two
        if thickness is not None:
            data = thin_slab_3d(data, thickness)
        model, s, wall = run_two_phase(data, out, comm)
        runs.append((band, model, s, wall, period_from_gauge(s["t"], s["level_left"] - SLOSH_DEPTH)))
    band, model, s, wall, period = runs[-1]          # the finest band
    wall_total = sum(r[3] for r in runs)
    t, eta_l, eta_r = s["t"], s["level_left"] - SLOSH_DEPTH, s["level_right"] - SLOSH_DEPTH
    a0 = abs(eta_l[0])
    if p["periods"] >= 5:
        window = (t >= 4.5 * period) & (t <= 5.5 * period)
        amp = at_least("amplitude_ratio_5T", float(np.abs(eta_l[window]).max() / a0), 0.9)
    else:
        window = t >= t[-1] - 0.6 * period
        amp = report_only("amplitude_ratio_5T", float(np.abs(eta_l[window]).max() / a0),
                          note=f"quick level: ratio over the last 0.6 T of {p['periods']} periods, not 5 T")
    if comm.rank == 0:
        plt = _plt()
        fig, ax = plt.subplots(figsize=(9, 3.8))
        for b, _, sb, _, tb in runs:
            ax.plot(sb["t"], sb["level_left"] - SLOSH_DEPTH, label=f"left wall, band {b:g}: T = {tb:.4f}")
        ax.plot(t, eta_r, lw=0.8, label=f"right wall, band {band:g}")
        ax.plot(t, a0 * np.cos(2 * np.pi * t / SLOSHING_PERIOD), "k:", lw=1, label=f"single fluid, T = {SLOSHING_PERIOD}")
        ax.plot(t, a0 * np.cos(2 * np.pi * t / t_two), "k--", lw=1, label=f"two-layer theory, T = {t_two:.4f}")
        ax.set_xlabel("t [s]")
        ax.set_ylabel("η [m]")
        ax.legend(fontsize=7, loc="lower left")
        ax.grid(alpha=0.3)
        ax.set_title(f"sloshing{' 3D' if thickness else ''}: Δt = {p['dt']}, {comm.size} rank(s), "
                     f"wall {wall_total:.0f} s", fontsize=10)
        fig.tight_layout()
        fig.savefig(out / ("sloshing_3d.png" if thickness else "sloshing.png"), dpi=110)
        plt.close(fig)
    fine = len(p["bands"]) > 1
    metrics = [rel_error_metric("period", period, t_two, SLOSH_FINE_TOL if fine else SLOSH_COARSE_TOL, unit="s")]
    if fine:
        t_ext = extrapolated_period(p["bands"], [r[4] for r in runs])
        metrics.append(rel_error_metric("period_extrapolated", t_ext, t_two, SLOSH_EXTRAPOLATED_TOL, unit="s"))
        metrics += [report_only(f"period_band_{b:g}", tb, unit="s", reference=t_two) for b, _, _, _, tb in runs[:-1]]
    cells = model.mesh.topology.index_map(model.mesh.topology.dim).size_global
    return metrics + [
        report_only("period_single_fluid_error", period / SLOSHING_PERIOD - 1.0, reference=SLOSHING_PERIOD,
                    note="relative to the single-fluid period (not the reference: the gas has density 0.1)"),
        amp,
        at_most("volume_error", max(float(np.abs(r[2]["volume_error"]).max()) for r in runs), 1e-3),
        report_only("antisymmetry", float(np.abs(eta_l + eta_r).max() / a0),
                    note="max |η_left + η_right| / a0 (first mode: the gauges are in antiphase)"),
        report_only("u_max", float(s["u_max"].max()), unit="m/s",
                    note="largest speed (linear theory at the surface: a ω ≈ 0.016–0.018)"),
        report_only("wall_time", wall_total, unit="s", note=f"bands {', '.join(f'{b:g}' for b in p['bands'])}; "
                    f"finest {cells} cells, {len(t) - 1} steps; {comm.size} rank(s)"),
    ]


@register("sloshing_single_fluid", "the sloshing tank with ρ_gas = 0.001: the period against the "
          "single-fluid 3.5520 (Tadjbakhsh–Keller, a = 0.01)", issue=4)
def sloshing_single_fluid(level: str, out: Path, comm: MPI.Comm) -> list[Metric]:
    """Same tank, mesh and gauges as ``sloshing`` at the same level (its finest band), gas density
    0.001 (ρ_l/ρ_g = 1000), run for 1.6 periods (three zero crossings of the left gauge)."""
    p = SLOSH[level]
    band = p["bands"][-1]
    data = sloshing_case(p["size"], band, p["dt"], 1.6 * 3.56, p["half_width"])
    data["fluid"]["gas_density"] = 1.0e-3
    data["name"] = f"sloshing_gas_1e-3_{band:g}"
    model, s, wall = run_two_phase(data, out, comm)
    period = period_from_gauge(s["t"], s["level_left"] - SLOSH_DEPTH)
    t_two = case_two_layer_period(data)
    return [
        rel_error_metric("period", period, SLOSHING_PERIOD, 5e-3, unit="s"),
        report_only("period_two_layer_error", period / t_two - 1.0, reference=t_two,
                    note="relative to linear two-layer theory at ρ_g = 0.001"),
        at_most("volume_error", float(np.abs(s["volume_error"]).max()), 1e-3),
        report_only("u_max", float(s["u_max"].max()), unit="m/s", note="largest speed (theory ≈ 0.018)"),
        report_only("wall_time", wall, unit="s", note=f"band cell {band}, {len(s['t']) - 1} steps, {comm.size} rank(s)"),
    ]


# ---------------------------------------------------------------- dam break
DAM = {"quick": {"per_a": 8}, "full": {"per_a": 20}}
DAM_3D = {"quick": {"per_a": 8, "cfl": 0.5}, "full": {"per_a": 12, "cfl": 0.5}}
DAM_LENGTH, DAM_HEIGHT = 6.0 * MM_A, 2.5 * MM_A
T_FRONT_MAX = 3.3


def dam_break_cells(per_a: int) -> list[int]:
    """Cells along x and y of the 6a × 2.5a tank at h = a/``per_a``."""
    h = MM_A / per_a
    return [int(round(DAM_LENGTH / h)), int(round(DAM_HEIGHT / h))]


def dam_break_t_end() -> float:
    """End of the dam-break runs [s]: 5 % past T = 3.3, the last front point checked."""
    return 1.05 * T_FRONT_MAX / (math.sqrt(MM_N2) * math.sqrt(G / MM_A))


def dam_break_case(per_a: int, t_end: float) -> dict:
    """Martin & Moyce's tank at a/h = ``per_a`` with the fast step (:data:`FAST_STEP`)."""
    cells = dam_break_cells(per_a)
    return {
        "name": f"dam_break_{per_a}",
        "run": {"t_end": t_end, "dt": 1.0e-3, "log_every": 50, "checkpoint_every": 10 ** 6, **FAST_STEP["run"]},
        "mesh": {"kind": "rectangle", "lower": [0.0, 0.0], "upper": [DAM_LENGTH, DAM_HEIGHT], "cells": cells},
        "phase_field": {"width_factor": 0.6, "volume_correction": True, **FAST_STEP["phase_field"],
                        "initial": {"shape": "box", "lower": [-1.0, -1.0], "upper": [MM_A, MM_N2 * MM_A]}},
        "fluid": {**WATER_AIR, "gravity": [0.0, -G], "pressure_reference": [DAM_LENGTH, DAM_HEIGHT],
                  "boundaries": slip_walls(), **FAST_STEP["fluid"]},
        "output": {"xdmf": False, "checkpoint": False},
    }


def front_deviation(T: np.ndarray, Z: np.ndarray) -> float:
    """Mean |Z_sim(T_i) − Z_i| over the Martin & Moyce points with T_i ≤ 3.3."""
    ref = MM_FRONT[MM_FRONT[:, 0] <= T_FRONT_MAX]
    return float(np.mean(np.abs(np.interp(ref[:, 0], T, Z) - ref[:, 1])))


#: the experiment's clock starts before the water moves freely (a diaphragm was removed), so
#: the front is compared after the best delay of the data, which must lie in this range
#: (interFoam on the same tank and mesh needs ΔT = 0.255; Lethe's dam-break example 0.175)
FRONT_SHIFT_RANGE = (0.10, 0.30)
FRONT_SHIFTED_TOL = 0.05


def best_time_shift(T: np.ndarray, Z: np.ndarray) -> tuple[float, float]:
    """(ΔT, mean |ΔZ|) for the delay ΔT ∈ [0, 1] of the experiment that minimises the mean front
    deviation, Z_sim(T_i − ΔT) against Z_i (Martin & Moyce's time origin is the diaphragm's
    release, before the column moves freely)."""
    shifts = np.linspace(0.0, 1.0, 201)
    ref = MM_FRONT[MM_FRONT[:, 0] <= T_FRONT_MAX]
    dev = [float(np.mean(np.abs(np.interp(ref[:, 0] - d, T, Z) - ref[:, 1]))) for d in shifts]
    i = int(np.argmin(dev))
    return float(shifts[i]), dev[i]


def front_scaled(t: np.ndarray, front: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Martin & Moyce's (T, Z) = (n t √(g/a), front/a) from times [s] and front positions [m]."""
    return math.sqrt(MM_N2) * t * math.sqrt(G / MM_A), front / MM_A


def dam_break_scaled(s: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(T, Z, τ, H) of Martin & Moyce from the series: Z = front/a, H = level at the left wall/(n² a)."""
    tau = s["t"] * math.sqrt(G / MM_A)
    T, Z = front_scaled(s["t"], s["wetted_bottom"])
    return T, Z, tau, s["level_left"] / (MM_N2 * MM_A)


@register("dam_break", "Martin & Moyce (1952) water column n² = 2, a = 0.05715 m in air: front and "
          "residual height against the experiment", issue=4)
def dam_break(level: str, out: Path, comm: MPI.Comm) -> list[Metric]:
    """Front = wetted length of the bottom (∫φ ds), height = liquid level at the left wall.

    Slip walls (no boundary layer at these resolutions). The checked metric is the mean front
    deviation after the best delay of the experiment's clock, ``front_mean_abs_dev_shifted``
    ≤ 0.05, with the delay ``front_time_shift`` in [0.10, 0.30]; the unshifted deviation is
    reported. SPEC §5 lists only the front points, so ``height_mean_abs_dev`` has no
    reference: H(τ) is plotted and its value at τ = 1.5 reported.
    """
    return _dam_break(DAM[level], out, comm)


@register("dam_break_3d", "Martin & Moyce dam break in a 3D slab (two tetrahedron layers between slip side "
          "walls): front against the experiment, as `dam_break`", issue=4)
def dam_break_3d(level: str, out: Path, comm: MPI.Comm) -> list[Metric]:
    """``dam_break`` on a structured tetrahedral slab 2h thick (2 cells), vertical z. Quick a/8,
    full a/12 (the 2D full level's a/20 is ≈ 25× the cost of a/8 in 3D)."""
    return _dam_break(DAM_3D[level], out, comm, dim=3)


def _dam_break(p: dict, out: Path, comm: MPI.Comm, dim: int = 2) -> list[Metric]:
    data = dam_break_case(p["per_a"], dam_break_t_end())
    if dim == 3:
        data = thin_slab_3d(data, 2 * MM_A / p["per_a"], cells=2)
        data["run"]["cfl"] = p.get("cfl", data["run"]["cfl"])
        del data["fluid"]["petsc"]          # the 3D default (Schur complement with AMG)
    model, s, wall = run_two_phase(data, out, comm)
    T, Z, tau, H = dam_break_scaled(s)
    dev = front_deviation(T, Z)
    shift, dev_shifted = best_time_shift(T, Z)
    if comm.rank == 0:
        plt = _plt()
        fig, ax = plt.subplots(1, 2, figsize=(10, 4))
        ax[0].plot(T, Z, label=f"computed, a/h = {p['per_a']}")
        ax[0].plot(T + shift, Z, ":", color="C0", lw=1, label=f"computed, delayed by ΔT = {shift:.3f}")
        ax[0].plot(MM_FRONT[:, 0], MM_FRONT[:, 1], "ko", label="Martin & Moyce (1952)")
        ax[0].set_xlabel("T = n t √(g/a)")
        ax[0].set_ylabel("Z = front / a")
        ax[0].legend()
        ax[0].grid(alpha=0.3)
        ax[1].plot(tau, H, label="computed")
        ax[1].set_xlabel("τ = t √(g/a)")
        ax[1].set_ylabel("H = height / (n² a)")
        ax[1].legend()
        ax[1].grid(alpha=0.3)
        fig.suptitle(f"dam break {dim}D n² = 2, a = {MM_A} m: mean |ΔZ| = {dev:.3f}, after ΔT: {dev_shifted:.3f} "
                     f"({comm.size} rank(s), wall {wall:.0f} s)")
        fig.tight_layout()
        fig.savefig(out / ("dam_break_3d.png" if dim == 3 else "dam_break.png"), dpi=110)
        plt.close(fig)
    return [
        at_most("front_mean_abs_dev_shifted", dev_shifted, FRONT_SHIFTED_TOL),
        in_interval("front_time_shift", shift, *FRONT_SHIFT_RANGE),
        report_only("front_mean_abs_dev", dev, note="unshifted (the experiment's clock starts at the diaphragm's release)"),
        report_only("height_mean_abs_dev", float("nan"),
                    note=f"no H(τ) reference points in SPEC §5; computed H(τ=1.5) = {np.interp(1.5, tau, H):.3f}"),
        at_most("volume_error", float(np.abs(s["volume_error"]).max()), 5e-3),
        report_only("wall_time", wall, unit="s", note=f"a/h = {p['per_a']}, {len(s['t']) - 1} steps, "
                    f"{model.mesh.topology.index_map(dim).size_global} cells, {comm.size} rank(s)"),
    ]
