"""A sphere settling to its terminal velocity (issue #8, ``settling_sphere``), 3D coupled.

The case runs ``cases/settling_sphere.yaml`` (single-phase liquid, one DEM sphere) and reads
the sphere's vertical velocity from ``series.csv``.

Reference: the terminal velocity u_t at which the Schiller–Naumann drag
C_D = 24/Re (1 + 0.15 Re^0.687) (Re = ρ_f u d/μ; valid for Re < 800) balances the buoyant
weight, (ρ_s − ρ_f) g π d³/6 = C_D ½ ρ_f u² π d²/4, times the wall factor of Di Felice (1996,
Int. J. Multiphase Flow 22, 527) for a sphere in a tube, u/u_∞ = ((1 − λ)/(1 − 0.33 λ))^α,
α = (3.3 + 0.085 Re)/(1 + 0.1 Re), λ = d/W with W the tank width (a square tank is taken as a
tube of diameter W: the factor is the correction's size, not a fit to this geometry; both
u_∞ and the corrected value are reported).

Measured terminal velocity: the mean of −v_z over the last ``WINDOW`` of the run; its drift
over that window (how far the sphere still is from terminal) must stay below ``MAX_DRIFT``.
The full level (d/6) holds the velocity to ``TOLERANCE``; the quick level (d/4) reports it and
checks that the run completes at a terminal state with the exchange intact.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..registry import Metric, at_most, register, rel_error_metric, report_only
from .coupled import case_at_level, run_coupled

#: fraction of the run at its end over which the terminal velocity is averaged
WINDOW = 0.2
#: the terminal velocity's tolerance against the wall-corrected correlation (full level)
TOLERANCE = 0.05
#: largest relative change of the velocity over the window for the state to count as terminal:
#: the window's mean then lies within about half of it, a fifth of the tolerance, from the
#: velocity at the window's end
MAX_DRIFT = 0.4 * TOLERANCE


def schiller_naumann_cd(re: float) -> float:
    """Drag coefficient of a sphere, C_D = 24/Re (1 + 0.15 Re^0.687) (Schiller & Naumann 1935)."""
    return 24.0 / re * (1.0 + 0.15 * re ** 0.687)


def terminal_velocity(d: float, rho_s: float, rho_f: float, mu: float, g: float) -> float:
    """u_t [m/s] with (ρ_s − ρ_f) g V = C_D(Re) ½ ρ_f u² A, by bisection on u (C_D u² grows with u)."""
    weight = (rho_s - rho_f) * g * np.pi * d ** 3 / 6.0
    area = np.pi * d ** 2 / 4.0

    def excess(u):
        return schiller_naumann_cd(rho_f * u * d / mu) * 0.5 * rho_f * u ** 2 * area - weight
    lo, hi = 1e-12, 1.0
    while excess(hi) < 0:
        hi *= 2.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if excess(mid) < 0 else (lo, mid)
    return 0.5 * (lo + hi)


def di_felice_wall_factor(re: float, ratio: float) -> float:
    """u_t(confined)/u_t(unbounded) for a sphere of diameter ratio λ = d/D in a tube (Di Felice 1996)."""
    alpha = (3.3 + 0.085 * re) / (1.0 + 0.1 * re)
    return ((1.0 - ratio) / (1.0 - 0.33 * ratio)) ** alpha


def terminal_reference(data: dict) -> dict[str, float]:
    """The correlation's u_∞, Re, wall factor and corrected u_t for the case mapping ``data``."""
    blk = data["dem"]["blocks"][0]
    d = 2.0 * blk["radius"]
    rho_s = data["dem"]["materials"][0]["density"]
    rho_f, mu = data["fluid"]["density"], data["fluid"]["viscosity"]
    g = float(np.linalg.norm(data["fluid"]["gravity"]))
    width = min(u - lo for u, lo in zip(data["mesh"]["upper"][:2], data["mesh"]["lower"][:2]))
    u_inf = terminal_velocity(d, rho_s, rho_f, mu, g)
    re = rho_f * u_inf * d / mu
    # the wall factor at the confined Re (one fixed-point pass; it changes Re by a few %)
    factor = di_felice_wall_factor(re, d / width)
    factor = di_felice_wall_factor(re * factor, d / width)
    return {"u_inf": u_inf, "re": re, "wall_factor": factor, "u_t": factor * u_inf, "d": d, "width": width}


def quick_column(data: dict) -> None:
    """Quick level: cells d/4 in the sphere's column (d/6 at the full level), the same fall.
    (A quick level stopped at 0.4 s measured the velocity before the plateau: −6.7 %.)"""
    data["mesh"]["refine"] = [{"lower": [-0.03, -0.03, 0.02], "upper": [0.03, 0.03, 0.29], "size": 0.006},
                              {"lower": [-0.012, -0.012, 0.08], "upper": [0.012, 0.012, 0.265], "size": 0.0025}]


@register("settling_sphere", "sphere settling in a viscous liquid reaches the Schiller–Naumann terminal velocity "
                             "(wall-corrected) at Re ≈ 13 (3D)", issue=8)
def settling_sphere(level, out_dir: Path, comm) -> list[Metric]:
    data = case_at_level("settling_sphere", level, out_dir, quick_column)
    series, wall, failure = run_coupled(data, out_dir, comm)
    ref = terminal_reference(data)
    t, v = series["t"], -series["b0_vz"]
    window = t >= t[-1] * (1.0 - WINDOW)
    u_end = float(v[window].mean()) if failure is None else float("nan")
    drift = float((v[window][-1] - v[window][0]) / v[window].mean()) if failure is None else float("nan")
    re_end = data["fluid"]["density"] * u_end * ref["d"] / data["fluid"]["viscosity"]
    if comm.rank == 0:
        _plot(out_dir, t, v, ref, u_end, t[window][0])
    cells = data["mesh"]["refine"][-1]["size"]
    if level == "full":
        accuracy = rel_error_metric("terminal_velocity_rel_error", u_end, ref["u_t"], TOLERANCE, unit="m/s")
    else:
        accuracy = report_only("terminal_velocity_rel_error", (u_end - ref["u_t"]) / ref["u_t"], reference=ref["u_t"],
                               note=f"d/4 cells: the cut wall's excess drag, first order in h, is larger than the "
                                    f"{TOLERANCE:.0%} the full level (d/6) is held to; reported, not checked")
    return [accuracy,
            report_only("terminal_velocity_unbounded_rel_error", (u_end - ref["u_inf"]) / ref["u_inf"],
                        reference=ref["u_inf"], note="against the correlation without the wall factor"),
            report_only("wall_factor", ref["wall_factor"], note=f"Di Felice, λ = d/W = {ref['d'] / ref['width']:.3g}"),
            report_only("particle_reynolds", re_end, reference=ref["re"] * ref["wall_factor"],
                        note="ρ u d/μ at the measured terminal velocity"),
            at_most("window_drift", abs(drift), MAX_DRIFT),
            at_most("exchange_error", float(series["exchange_error"].max()), 1e-10),
            report_only("wall_seconds", wall, note=f"column cells {cells} m = d/{ref['d'] / cells:.2g}, "
                                                   f"t_end {data['run']['t_end']} s, {comm.size} rank(s)"
                                                   + ("" if failure is None else f"; diverged: {failure[:80]}"))]


def _plot(out: Path, t, v, ref, u_end, t_window) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(7, 3.6))
    ax.plot(t, 100 * v, label="sphere, −v_z")
    ax.axhline(100 * ref["u_inf"], color="k", ls=":", label=f"Schiller–Naumann, unbounded: {100 * ref['u_inf']:.2f} cm/s")
    ax.axhline(100 * ref["u_t"], color="k", ls="--",
               label=f"× Di Felice wall factor {ref['wall_factor']:.3f}: {100 * ref['u_t']:.2f} cm/s")
    ax.axvspan(t_window, t[-1], color="0.9", label=f"averaging window: {100 * u_end:.2f} cm/s")
    ax.set_xlabel("t [s]"), ax.set_ylabel("settling velocity [cm/s]")
    ax.set_title(f"settling sphere, Re ≈ {ref['re'] * ref['wall_factor']:.1f}")
    ax.legend(fontsize=8, loc="lower right"), ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(out / "settling_sphere.png", dpi=110)
    plt.close(fig)
