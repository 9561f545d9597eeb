"""Peer benchmark (not a test): our two-phase step against OpenFOAM's interFoam in one run.

    python -m fcm_fsi bench peer [--levels quick full] [--np 1] [--repeat 3] [--out bench_peer]
    python -m fcm_fsi bench peer --impact 0.23 1.0 --np 2      (3D dam break onto a fixed box)
    python -m fcm_fsi bench peer --impact-study 1.0 --np 2      (the same at several sizes in both codes)

Case: Martin & Moyce's dam break (``verify dam_break``): quick = a/8 (48 × 20 cells), full =
a/20 (120 × 50 cells), to T = 3.47. Ours runs as a user would, ``python -m fcm_fsi verify
dam_break --level L --np N`` in a fresh process; interFoam (when on PATH; Debian packages
``openfoam`` and ``openfoam-examples``, optional) runs the same tank with the same number of
cells (quads, one cell thick, slip walls, the laminar damBreak tutorial's numerics). For each:
process wall time, solver wall time (our model set-up and time loop; interFoam's run), time
steps, and the accuracy measure the verification checks — the mean front deviation from
Martin & Moyce unshifted and after the best delay of the experiment's clock. The ratio is ours
over interFoam's, process against process and solver against solver. Run it on an idle machine
with warm JIT caches (run it twice; the first run compiles the forms).
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from ..verify.cases.two_phase import (
    DAM,
    best_time_shift,
    dam_break_cells,
    dam_break_t_end,
    front_deviation,
    front_scaled,
)
from ..verify.runner import mpi_env
from . import _openfoam


def ours(level: str, ranks: int, out: Path) -> dict:
    """Run ``verify dam_break`` in a fresh process; its wall, steps and front metrics."""
    cmd = [sys.executable, "-m", "fcm_fsi", "verify", "dam_break", "--level", level, "--np", str(ranks),
           "--out", str(out)]
    t0 = time.perf_counter()
    subprocess.run(cmd, env=mpi_env(), check=False, stdout=subprocess.DEVNULL)
    process = time.perf_counter() - t0
    metrics = json.loads((out / "dam_break" / "metrics.json").read_text())["metrics"]
    steps = int(metrics["wall_time"]["criterion"].split(" steps")[0].split()[-1])
    return {"process": process, "solver": metrics["wall_time"]["value"], "steps": steps,
            "dev": metrics["front_mean_abs_dev"]["value"], "dev_shifted": metrics["front_mean_abs_dev_shifted"]["value"],
            "shift": metrics["front_time_shift"]["value"]}


def interfoam(level: str, ranks: int, out: Path) -> dict:
    """The same tank and cell count in interFoam; wall (process and interFoam alone), steps, front metrics."""
    cells_x, cells_y = dam_break_cells(DAM[level]["per_a"])
    t0 = time.perf_counter()
    res = _openfoam.dam_break_2d(cells_x, cells_y, out / f"interfoam_{level}", dam_break_t_end(), np=ranks)
    process = time.perf_counter() - t0
    T, Z = front_scaled(res["t"], res["front"])
    shift, dev_shifted = best_time_shift(T, Z)
    return {"process": process, "solver": res["wall"], "steps": res["steps"], "dev": front_deviation(T, Z),
            "dev_shifted": dev_shifted, "shift": shift}


IMPACT_CASE = Path(__file__).resolve().parents[2] / "cases" / "impact_box_3d.yaml"
#: the fast step for the 3D impact (coupled: the block is fixed, so no passes), the Krylov solve
#: started from the extrapolated update, Courant number 1 (interFoam's maxCo) with the step growing
#: by at most 20 % (as the 2D fast step; docs/performance.md has the load at Courant number 0.4 too)
IMPACT_FAST = ("fluid.nonlinear=linearised", "fluid.krylov_start=extrapolated", "phase_field.picard_max_iterations=1",
               "run.cfl=1.0", "run.dt_growth=1.2", "output.xdmf=false")


def hex_size(cells: int) -> float:
    """Edge [m] of cubes that fill impact_box_3d's tank less the box (284.8 m³) with ``cells`` cells."""
    return ((12.0 * 4.0 * 6.0 - 1.0 * 1.6 * 2.0) / cells) ** (1.0 / 3.0)


def impact_ours(size: float, t_end: float, ranks: int, out: Path) -> dict:
    """``cases/impact_box_3d.yaml`` with cells of ``size`` [m] and the fast step, under mpirun;
    wall (process, and the time loop's 'total wall'), steps, tetrahedra and the box's force history."""
    cmd = ["mpirun", "-n", str(ranks), sys.executable, "-m", "fcm_fsi", "run", str(IMPACT_CASE), "--output", str(out),
           "--log-level", "INFO", "--set", f"mesh.size={size}", "--set", f"run.t_end={t_end}"]
    for item in IMPACT_FAST:
        cmd += ["--set", item]
    t0 = time.perf_counter()
    res = subprocess.run(cmd, env=mpi_env(), capture_output=True, text=True)
    process = time.perf_counter() - t0
    if res.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed:\n{res.stderr[-3000:]}")
    log = res.stdout + res.stderr
    (out / "run.log").write_text(log)
    solver = float(log.split("total wall")[1].split()[0])
    cells = int(log.split("mesh gmsh_box: ")[1].split()[0])
    data = np.genfromtxt(out / "bodies.csv", delimiter=",", names=True)
    return {"process": process, "solver": solver, "steps": len(data), "cells": cells,
            "t": data["t_s"], "fx": data["fx_N"]}


def impact_interfoam(size: float, t_end: float, ranks: int, out: Path) -> dict:
    """The impact case in interFoam with hex cells of ``size`` [m]; as :func:`impact_ours`."""
    t0 = time.perf_counter()
    res = _openfoam.impact_box_3d(size, out, t_end, np=ranks)
    return {"process": time.perf_counter() - t0, "solver": res["wall"], "steps": res["steps"],
            "cells": res["cells"], "t": res["t"], "fx": res["force"][:, 0]}


def load_measures(r: dict) -> dict:
    """Peak streamwise force [N], its time [s] and the impulse ∫ F_x dt [N s] of a run."""
    i = int(np.argmax(r["fx"]))
    return {"peak": float(r["fx"][i]), "t_peak": float(r["t"][i]), "impulse": float(np.trapz(r["fx"], r["t"]))}


def load_error(r: dict, ref: dict) -> float:
    """Mean |F_x − F_x,ref| over the reference's time span, relative to the mean |F_x,ref|:
    the load history's error against a reference run (both interpolated to its times)."""
    t = ref["t"]
    f = np.interp(t, r["t"], r["fx"])
    return float(np.trapz(np.abs(f - ref["fx"]), t) / np.trapz(np.abs(ref["fx"]), t))


def study_table(runs: list[tuple[str, float, dict]], ref: dict) -> str:
    """One line per run of the mesh study: who, cell edge, cells, solver wall, steps, impulse and
    the load-history and impulse errors against ``ref``."""
    imp_ref = load_measures(ref)["impulse"]
    lines = [f"{'who':<10}{'size m':>8}{'cells':>10}{'solver s':>10}{'steps':>7}{'impulse N s':>13}"
             f"{'impulse err':>12}{'history err':>12}"]
    for who, size, r in runs:
        imp = load_measures(r)["impulse"]
        lines.append(f"{who:<10}{size:>8.3f}{r['cells']:>10d}{r['solver']:>10.1f}{r['steps']:>7d}{imp:>13.0f}"
                     f"{(imp - imp_ref) / imp_ref:>12.3f}{load_error(r, ref):>12.3f}")
    return "\n".join(lines)


def study_plot(runs: list[tuple[str, float, dict]], path: Path) -> None:
    """F_x(t) of every run of the study, ours solid, interFoam dashed."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(7, 4))
    for who, size, r in runs:
        ax.plot(r["t"], r["fx"] / 1e3, "-" if who == "fcm_fsi" else "--", lw=1.2,
                label=f"{who} {size:g} m ({r['cells'] / 1e3:.0f}k cells)")
    ax.set_xlabel("t [s]"), ax.set_ylabel("F_x on the box [kN]"), ax.legend(fontsize=7), ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def impact_study(ours_sizes: list[float], foam_sizes: list[float], t_end: float, ranks: int, out: Path) -> str:
    """The impact case at several cell sizes in both codes (interFoam's only when on PATH); the
    finest interFoam run is the reference of the errors (else our finest)."""
    runs = []
    for size in ours_sizes:
        runs.append(("fcm_fsi", size, impact_ours(size, t_end, ranks, out / f"study_ours_{size:g}")))
        print(study_table(runs[-1:], runs[-1][2]).split("\n")[1], flush=True)
    if _openfoam.interfoam_available():
        for size in foam_sizes:
            runs.append(("interFoam", size, impact_interfoam(size, t_end, ranks, out / f"study_foam_{size:g}")))
            print(study_table(runs[-1:], runs[-1][2]).split("\n")[1], flush=True)
    ref = min(runs, key=lambda r: (r[0] != "interFoam", r[1]))[2]     # interFoam's finest, else our finest
    for who, size, r in runs:
        np.savetxt(out / f"study_{who}_{size:g}.csv", np.c_[r["t"], r["fx"]], delimiter=",", header="t [s],fx [N]")
    study_plot(runs, out / "peer_impact_study.png")
    return study_table(runs, ref)


def median_run(runs: list[dict]) -> dict:
    """One run's record with the median process and solver times of repeated identical runs
    (the accuracy measures and steps are the same in each)."""
    return {**runs[0], "process": float(np.median([r["process"] for r in runs])),
            "solver": float(np.median([r["solver"] for r in runs])), "repeats": len(runs)}


def ratio_row(pad: int, a: dict, b: dict, gap: int = 0) -> str:
    """The line of ours / interFoam's process time, solver time and steps: ``pad`` blank columns,
    the label, ``gap`` blank columns, the ratios."""
    return (f"{'':<{pad}}{'ratio':<10}{'':<{gap}}{a['process'] / b['process']:>10.2f}"
            f"{a['solver'] / b['solver']:>10.2f}{a['steps'] / b['steps']:>7.2f}")


def impact_table(size: float, ranks: int, a: dict, b: dict | None) -> str:
    lines = [f"{'impact_box_3d':<16}{'ranks':>5}  {'who':<10}{'cells':>9}{'process s':>10}{'solver s':>10}{'steps':>7}"
             f"{'peak F_x N':>12}{'at s':>7}{'impulse N s':>13}"]
    for who, r in (("fcm_fsi", a), ("interFoam", b)):
        if r is None:
            lines.append(f"{'':<16}{ranks:>5}  {who:<10}  (not on PATH)")
            continue
        m = load_measures(r)
        lines.append(f"{'':<16}{ranks:>5}  {who:<10}{r['cells']:>9d}{r['process']:>10.1f}{r['solver']:>10.1f}"
                     f"{r['steps']:>7d}{m['peak']:>12.0f}{m['t_peak']:>7.3f}{m['impulse']:>13.0f}")
    if b is not None:
        lines.append(ratio_row(16 + 5 + 2, a, b, gap=9))
    return "\n".join(lines)


def table(rows: list[tuple[str, int, dict, dict | None]]) -> str:
    head = (f"{'case':<22}{'ranks':>5}  {'who':<10}{'process s':>10}{'solver s':>10}{'steps':>7}"
            f"{'|ΔZ|':>8}{'|ΔZ| shifted':>14}{'ΔT':>7}")
    lines = [head]
    for name, ranks, a, b in rows:
        for who, r in (("fcm_fsi", a), ("interFoam", b)):
            if r is None:
                lines.append(f"{name:<22}{ranks:>5}  {who:<10}  (not on PATH: apt-get install openfoam openfoam-examples)")
                continue
            lines.append(f"{name:<22}{ranks:>5}  {who:<10}{r['process']:>10.2f}{r['solver']:>10.2f}{r['steps']:>7d}"
                         f"{r['dev']:>8.3f}{r['dev_shifted']:>14.4f}{r['shift']:>7.3f}")
        if b is not None:
            lines.append(ratio_row(22 + 5 + 2, a, b))
    return "\n".join(lines)


def run(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(prog="python -m fcm_fsi bench peer", description=__doc__.split("\n\n")[0])
    ap.add_argument("--levels", nargs="+", choices=sorted(DAM), default=["quick", "full"])
    ap.add_argument("--np", type=int, nargs="+", default=[1], help="rank counts (each level is run on each)")
    ap.add_argument("--out", type=Path, default=Path("bench_peer"))
    ap.add_argument("--repeat", type=int, default=1,
                    help="dam break: run each side this many times, alternating, and report the median times "
                         "(a shared or virtual machine varies ±15 %% between identical runs)")
    ap.add_argument("--impact", type=float, nargs=2, metavar=("SIZE", "T_END"),
                    help="instead: the 3D dam break onto a fixed box (cases/impact_box_3d.yaml) with cells of "
                         "SIZE m (0.23: 114k tetrahedra) to T_END s, interFoam with as many hex cells")
    ap.add_argument("--impact-study", type=float, metavar="T_END",
                    help="instead: the 3D impact to T_END s at the cell sizes of --ours and --foam (a mesh study; "
                         "errors against the finest interFoam run)")
    ap.add_argument("--ours", type=float, nargs="+", default=[0.35, 0.23, 0.17], help="--impact-study: our cell sizes [m]")
    ap.add_argument("--foam", type=float, nargs="+", default=[0.3, 0.2, 0.14, 0.1],
                    help="--impact-study: interFoam's hex sizes [m]")
    args = ap.parse_args(argv)
    args.out = args.out.resolve()     # OpenFOAM's tools run inside the case folders
    args.out.mkdir(parents=True, exist_ok=True)
    have_foam = _openfoam.interfoam_available()
    if args.impact_study:
        text = impact_study(args.ours, args.foam, args.impact_study, args.np[0], args.out)
        print("\n" + text)
        (args.out / "peer_impact_study.txt").write_text(text + "\n")
        return 0
    if args.impact:
        size, t_end = args.impact
        texts = []
        for ranks in args.np:
            a = impact_ours(size, t_end, ranks, args.out / f"ours_impact_np{ranks}")
            b = (impact_interfoam(hex_size(a["cells"]), t_end, ranks, args.out / f"interfoam_impact_np{ranks}")
                 if have_foam else None)
            texts.append(impact_table(size, ranks, a, b))
            print(texts[-1], flush=True)
            np.savetxt(args.out / f"impact_np{ranks}_fcm_fsi.csv", np.c_[a["t"], a["fx"]], delimiter=",",
                       header="t [s],fx [N]")
            if b is not None:
                np.savetxt(args.out / f"impact_np{ranks}_interfoam.csv", np.c_[b["t"], b["fx"]], delimiter=",",
                           header="t [s],fx [N]")
        (args.out / "peer_impact.txt").write_text("\n".join(texts) + "\n")
        return 0
    rows = []
    for level in args.levels:
        for ranks in args.np:
            name = f"dam_break a/{DAM[level]['per_a']}"
            runs_a, runs_b = [], []
            for _ in range(max(1, args.repeat)):
                runs_a.append(ours(level, ranks, args.out / f"ours_{level}_np{ranks}"))
                if have_foam:
                    runs_b.append(interfoam(level, ranks, args.out / f"np{ranks}"))
            rows.append((name, ranks, median_run(runs_a), median_run(runs_b) if runs_b else None))
            print(table(rows[-1:]).split("\n", 1)[1], flush=True)
    text = table(rows)
    print("\n" + text)
    (args.out / "peer.txt").write_text(text + "\n")
    (args.out / "peer.json").write_text(json.dumps([{"case": n, "ranks": r, "fcm_fsi": a, "interfoam": b}
                                                    for n, r, a, b in rows], indent=1))
    return 0
