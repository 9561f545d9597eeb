"""Benchmark: cost split of one coupled fluid step of ``cases/block_overturn.yaml`` (issue #8).

    mpirun -n 2 python -m fcm_fsi bench coupling [--cells 128x48 256x96] [--t-end 0.25] [--out DIR]

Runs the case (friction 30°) through the normal time loop from t = 0 to ``--t-end`` at each
mesh size — by default to 0.25 s, before the bore reaches the block at ≈ 0.3 s, so every
size runs the same, stable part of the flow — and prints, per fluid step, the wall time of
each stage of SPEC §3: cut rebuild (level set, cut weights, wall velocity), phase field,
properties (ρ, μ from φ), Navier–Stokes, exchange (forces and torques, the momentum check),
DEM sub-steps, and the loop's own diagnostics/output. One JSON line per size follows the
table (for docs/performance.md).
"""
from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

from mpi4py import MPI

from ..io.logging import setup_logging

STAGES = ("cut rebuild", "phase field", "properties", "navier-stokes", "exchange", "dem sub-steps",
          "diagnostics", "output", "checkpoint")


def run_size(cells: tuple[int, int], t_end: float, out: Path, comm) -> dict:
    from ..simulation.coupled import CoupledModel
    from ..simulation.loop import TimeLoop
    from ..verify.cases.coupled import case_at_level, shorter_coarser
    from ..verify.cases.two_phase import case_output
    data = case_at_level("block_overturn", "quick", out, shorter_coarser(t_end, list(cells)))
    case, sub = case_output(data, out, comm)
    t0 = time.perf_counter()
    model = CoupledModel(case, comm, out_dir=sub)
    setup = time.perf_counter() - t0
    loop = TimeLoop(case, model, sub, comm, restart=None)
    loop.run()
    timer = loop.timer
    steps = max(loop.step, 1)
    sec = {k: comm.allreduce(timer.seconds.get(k, 0.0), op=MPI.MAX) for k in STAGES}
    total = comm.allreduce(time.perf_counter() - t0 - setup, op=MPI.MAX)
    dem_sub = model.dem.last.n_sub if model.dem.last else 0
    return {"cells": int(model.mesh.topology.index_map(2).size_global), "grid": list(cells), "ranks": comm.size,
            "fluid_steps": loop.step, "dem_substeps_per_step": int(dem_sub), "setup_s": setup,
            "ms_per_step": {k: 1e3 * v / steps for k, v in sec.items()}, "total_ms_per_step": 1e3 * total / steps}


def run(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(prog="python -m fcm_fsi bench coupling", description=__doc__.split("\n\n")[0])
    ap.add_argument("--cells", nargs="+", default=["128x48", "256x96"],
                    help="mesh sizes NXxNY (default 128x48 256x96)")
    ap.add_argument("--t-end", type=float, default=0.25, help="simulated time per size [s] (default 0.25)")
    ap.add_argument("--out", type=Path, default=None, help="output folder (default: a temporary folder)")
    args = ap.parse_args(argv)
    comm = MPI.COMM_WORLD
    setup_logging("WARNING", rank=comm.rank)
    try:
        sizes = [tuple(int(v) for v in c.lower().split("x")) for c in args.cells]
        if any(len(s) != 2 or min(s) < 4 for s in sizes):
            raise ValueError
    except ValueError:
        print(f"error: --cells takes NXxNY with NX, NY ≥ 4 (got {' '.join(args.cells)})")
        return 2
    out = args.out or Path(tempfile.mkdtemp(prefix="fcm_bench_coupling_"))
    rows = [run_size(s, args.t_end, out / f"{s[0]}x{s[1]}", comm) for s in sizes]
    if comm.rank == 0:
        head = f"{'stage [ms/fluid step]':<24}" + "".join(f"{r['cells']:>12d}" for r in rows)
        print(f"\nblock_overturn, {comm.size} rank(s), t = 0 … {args.t_end:g} s (before the impact)\n{head}")
        for k in STAGES:
            print(f"{k:<24}" + "".join(f"{r['ms_per_step'][k]:>12.2f}" for r in rows))
        print(f"{'total':<24}" + "".join(f"{r['total_ms_per_step']:>12.2f}" for r in rows))
        print(f"{'fluid steps':<24}" + "".join(f"{r['fluid_steps']:>12d}" for r in rows))
        print(f"{'DEM sub-steps / step':<24}" + "".join(f"{r['dem_substeps_per_step']:>12d}" for r in rows))
        for r in rows:
            print(json.dumps(r))
    return 0
