"""Sloshing verification (issue #4, rulings of #44): the first mode of the paper's tank, the
two-layer period (``sloshing``), its thin 3D tank (``sloshing_3d``) and the single-fluid limit
(``sloshing_single_fluid``). Each runs the two-phase model through the normal time loop
(:func:`.two_phase.run_two_phase`) and reads its two wave gauges on the end walls from ``gauges.csv``
(:func:`.two_phase.with_wall_gauges`).
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from mpi4py import MPI

from ..registry import Metric, at_least, at_most, register, rel_error_metric, report_only
from .two_phase import FAST_STEP, agg_pyplot, run_two_phase, slip_walls, thin_slab_3d, with_wall_gauges

SLOSHING_PERIOD = 3.5520        # issue #4 target; SPEC §4.2: linear 3.5515338, weakly nonlinear 3.5519687 [s]

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
    """Wave gauges on the end walls (``output.gauges``): η = (liquid level there) − h.

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
        model, s, wall = run_two_phase(with_wall_gauges(data, thickness), out, comm)
        runs.append((band, model, s, wall, period_from_gauge(s["t"], s["gauge_left"] - SLOSH_DEPTH)))
    band, model, s, wall, period = runs[-1]          # the finest band
    wall_total = sum(r[3] for r in runs)
    t, eta_l, eta_r = s["t"], s["gauge_left"] - SLOSH_DEPTH, s["gauge_right"] - SLOSH_DEPTH
    a0 = abs(eta_l[0])
    if p["periods"] >= 5:
        window = (t >= 4.5 * period) & (t <= 5.5 * period)
        amp = at_least("amplitude_ratio_5T", float(np.abs(eta_l[window]).max() / a0), 0.9)
    else:
        window = t >= t[-1] - 0.6 * period
        amp = report_only("amplitude_ratio_5T", float(np.abs(eta_l[window]).max() / a0),
                          note=f"quick level: ratio over the last 0.6 T of {p['periods']} periods, not 5 T")
    if comm.rank == 0:
        plt = agg_pyplot()
        fig, ax = plt.subplots(figsize=(9, 3.8))
        for b, _, sb, _, tb in runs:
            ax.plot(sb["t"], sb["gauge_left"] - SLOSH_DEPTH, label=f"left wall, band {b:g}: T = {tb:.4f}")
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
    model, s, wall = run_two_phase(with_wall_gauges(data), out, comm)
    period = period_from_gauge(s["t"], s["gauge_left"] - SLOSH_DEPTH)
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
