"""Peridynamics throughput benchmark (not a test): ``python -m fcm_fsi bench pd [--bonds 100000
1000000] [--threads 1 2] [--steps 100] [--dim 2]``.

Set-up (reproducible): a square plate (2D, plane stress; ``--dim 3``: a cube) of Homalite
(E = 4.55 GPa, ρ = 1230 kg/m³, G0 = 38.46 J/m²), Δx = 1 mm, δ = 3.015 Δx, as many points as
give the asked number of owned bonds (≈ 39 per interior point in 2D, 180 in 3D); initial
velocity 1 m/s × random normal per component (numpy default_rng(1)), no loads; dt = 0.5
Δt_crit. 5 warm-up steps, then ``--steps`` timed velocity-Verlet steps (bond breaking pass +
force pass + update). Bond updates/s = owned bonds × steps / wall. The O(N) check: the bond
list build time and the step time per bond at each size (both should stay flat as N grows).
Goal of issue #49: ≥ 5e7 bond updates/s on 2 cores at 1e6 bonds.
"""
from __future__ import annotations

import argparse
import dataclasses
import math
import os
import time

import numpy as np

BONDS_PER_POINT = {2: 38.8, 3: 182.0}


def plate_config(bonds: int, dim: int):
    from ..config.loader import build
    from ..config.pd import PDConfig
    from ..pd.builder import lattice_stable_time_step
    side = max(int(round((bonds / BONDS_PER_POINT[dim]) ** (1.0 / dim))), 4) * 1e-3
    d = {"formulation": "plane_stress" if dim == 2 else "3d",
         "material": {"youngs_modulus": 4.55e9, "density": 1230.0, "fracture_energy": 38.46},
         "lattice": {"lower": [0.0] * dim, "upper": [side] * dim, "spacing": 1e-3}, "dt": 1e-12}
    cfg = build(PDConfig, d, "<bench>", "pd")
    return dataclasses.replace(cfg, dt=0.5 * lattice_stable_time_step(cfg))


def measure(bonds: int, threads: int, steps: int, dim: int) -> dict:
    import numba

    from ..pd.builder import build_system
    from ..pd.neighbours import bond_lists
    numba.set_num_threads(threads)
    cfg = plate_config(bonds, dim)
    s = build_system(cfg)
    s.v[:, :dim] = np.random.default_rng(1).normal(size=(len(s.x), dim))
    t0 = time.perf_counter()
    bond_lists(s.x, np.full(len(s.x), cfg.horizon + 0.5 * cfg.lattice.spacing))
    build = time.perf_counter() - t0
    for _ in range(5):
        s.step()
    load = os.getloadavg()[0]
    t0 = time.perf_counter()
    for _ in range(steps):
        s.step()
    wall = time.perf_counter() - t0
    nb = s.bonds.count
    return {"points": len(s.x), "bonds": nb, "threads": threads, "steps": steps, "wall": wall,
            "bond_updates_per_s": nb * steps / wall, "ns_per_bond_update": 1e9 * wall / (nb * steps),
            "build_ns_per_bond": 1e9 * build / nb, "load": load}


def table(rows: list[dict]) -> str:
    out = ["| points | bonds | threads | steps | wall [s] | bond updates/s | ns per bond update | bond-list build "
           "ns/bond | load |", "|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        out.append(f"| {r['points']} | {r['bonds']} | {r['threads']} | {r['steps']} | {r['wall']:.2f} | "
                   f"{r['bond_updates_per_s']:.3g} | {r['ns_per_bond_update']:.2f} | {r['build_ns_per_bond']:.1f} | "
                   f"{r['load']:.1f} |")
    return "\n".join(out)


def run(argv: list[str]) -> int:
    p = argparse.ArgumentParser(prog="python -m fcm_fsi bench pd", description=__doc__.split("\n")[0])
    p.add_argument("--bonds", type=int, nargs="+", default=[100000, 1000000])
    p.add_argument("--threads", type=int, nargs="+", default=[1, 2])
    p.add_argument("--steps", type=int, default=100)
    p.add_argument("--dim", type=int, choices=(2, 3), default=2)
    a = p.parse_args(argv)
    rows = []
    for n in a.bonds:
        for th in a.threads:
            r = measure(n, th, a.steps, a.dim)
            rows.append(r)
            print(f"{r['bonds']:>9} bonds, {th} thread(s): {r['bond_updates_per_s']:.3g} bond updates/s "
                  f"({r['wall']:.2f} s, load {r['load']:.1f})", flush=True)
    print(table(rows))
    sizes = sorted({r["bonds"] for r in rows})
    if len(sizes) > 1:
        per = {b: min(r["ns_per_bond_update"] for r in rows if r["bonds"] == b) for b in sizes}
        print(f"O(N): ns per bond update {per[sizes[0]]:.2f} at {sizes[0]} bonds, {per[sizes[-1]]:.2f} at "
              f"{sizes[-1]} (ratio {per[sizes[-1]] / per[sizes[0]]:.2f}; 1 = linear)")
    return 0 if math.isfinite(sum(r["wall"] for r in rows)) else 1


if __name__ == "__main__":
    import sys
    sys.exit(run(sys.argv[1:]))
