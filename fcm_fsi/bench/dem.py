"""DEM throughput benchmark (not a test): ``python -m fcm_fsi bench dem [--sizes 10000 100000 1000000]
[--threads 1 2] [--steps 200] [--write-docs]``.

Set-up (reproducible; the same packing can be given to another DEM code):

- clumps of three spheres, r = 5 mm, local centres (0, 0, 0), (6, 0, 0), (3, 5, 0) mm;
  solid density 2500 kg/m³ (mass from the spheres, overlaps not subtracted)
- N/3 clumps, all in the same orientation (plane of the three centres horizontal), on an
  orthorhombic lattice of spacings 0.999 × (3.2 r, 3.0 r, 2.0 r) — the clump's extents, so
  neighbouring clumps touch with 0.1 % overlap — sphere 0 of clump (i, j, k) at
  (r, r, r) + (i, j, k)·spacing, i fastest; n_x = ⌈1.5 (N/12)^{1/3}⌉, n_y = round(n_x·3.2/3.0),
  n_z = ⌈(N/3)/(n_x n_y)⌉; initial velocities uniform in [−0.5, 0.5] m/s per component
  (numpy default_rng(1)), no initial spin
- closed box walls from −1 mm to (n_x, n_y, n_z)·spacing + 1 mm; gravity (0, 0, −9.81) m/s²
- contact: K = 1e5 N/m (normal = tangential), e = 0.3, friction angle 30°, normal force
  clipped at zero; Verlet skin 1.5 mm (0.3 r), rebuild at skin/2
- dt = 2.5e-5 s (≈ 0.17 Δt_cr); 20 warm-up steps, then ``--steps`` timed steps; ledger off
- sphere-steps/s = N·steps / wall; contact updates/s = Σ over timed steps of active
  sphere–sphere contacts / wall; pair evaluations/s = Σ Verlet pairs / wall; load = the
  1-minute load average just before the timed steps (other people's jobs on the machine)
- no ledger and no controls, so the step runs fused (fcm_fsi/dem/fused.py: the pair kernel,
  then one pass over the blocks)
"""
from __future__ import annotations

import argparse
import math
import os
import re
import time
from pathlib import Path

import numpy as np

R = 0.005
SPHERES = [[0.0, 0.0, 0.0, R], [1.2 * R, 0.0, 0.0, R], [0.6 * R, 1.0 * R, 0.0, R]]


def bench_config(n_spheres: int) -> dict:
    """The DEM section of the benchmark box (see module docstring)."""
    nc = n_spheres // 3
    spacing = np.array([3.2 * R, 3.0 * R, 2.0 * R]) * 0.999        # clump extents: neighbours just touch
    nx = max(int(math.ceil((nc / 4.0) ** (1 / 3) * 1.5)), 1)          # column ≈ 2× as tall as wide
    ny = max(int(round(nx * spacing[0] / spacing[1])), 1)
    nz = int(math.ceil(nc / (nx * ny)))
    idx = np.arange(nc)
    ijk = np.stack([idx % nx, (idx // nx) % ny, idx // (nx * ny)], axis=1)
    origin = ijk * spacing + np.array([R, R, R])                     # sphere 0 of each clump
    blocks = [{"shape": "clump", "material": "g", "position": [float(v) for v in o], "spheres": SPHERES}
              for o in origin]
    hi = (np.array([nx, ny, nz]) * spacing + 1e-3).tolist()
    return {"dt": 2.5e-5, "skin": 0.3 * R, "gravity": [0, 0, -9.81],
            "materials": [{"name": "g", "stiffness": 1e5, "restitution": 0.3, "friction_angle": 30.0,
                           "density": 2500.0}],
            "blocks": blocks,
            "walls": [{"kind": "box", "material": "g", "lo": [-1e-3] * 3, "hi": hi}]}


def measure(n_spheres: int, threads: int, steps: int) -> dict:
    import numba

    from ..config.dem import DEMConfig
    from ..config.loader import build
    from ..dem.model import build_system
    numba.set_num_threads(threads)
    s = build_system(build(DEMConfig, bench_config(n_spheres), "<bench>", "dem"), with_ledger=False)
    rng = np.random.default_rng(1)
    s.state.vel[:] = rng.uniform(-0.5, 0.5, size=s.state.vel.shape)
    contact = s.interactions[0]
    s.run(20)
    builds0 = contact.neighbours.builds
    ncon = npair = 0
    load = os.getloadavg()[0]
    t0 = time.perf_counter()
    for _ in range(steps):
        s.step()
        ncon += contact.n_contacts
        npair += len(contact.neighbours.pairs)
    wall = time.perf_counter() - t0
    ns = s.state.ns
    return {"spheres": ns, "threads": threads, "steps": steps, "wall": wall,
            "sphere_steps_per_s": ns * steps / wall, "contact_updates_per_s": ncon / wall,
            "pair_evals_per_s": npair / wall, "contacts_per_sphere": ncon / steps / ns,
            "rebuilds": contact.neighbours.builds - builds0, "dt_over_dt_cr": s.dt / s.critical_time_step(),
            "load": load}


def table(rows: list[dict]) -> str:
    out = ["| spheres | threads | steps | wall [s] | sphere-steps/s | contact updates/s | pair evals/s "
           "| contacts/sphere | list rebuilds | load |",
           "|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        out.append(f"| {r['spheres']} | {r['threads']} | {r['steps']} | {r['wall']:.2f} | {r['sphere_steps_per_s']:.3g} | "
                   f"{r['contact_updates_per_s']:.3g} | {r['pair_evals_per_s']:.3g} | {r['contacts_per_sphere']:.2f} | "
                   f"{r['rebuilds']} | {r.get('load', float('nan')):.1f} |")
    return "\n".join(out)


def write_docs(rows: list[dict], path: Path) -> None:
    """Replace (or append) the ``## DEM`` section of docs/performance.md."""
    import platform
    best = max((r["sphere_steps_per_s"] for r in rows if r["spheres"] >= 99999), default=0.0)
    goal = ("reached" if best >= 5e6 else f"not reached (best {best:.3g} at 100k)")
    head = ("## DEM\n\n`NUMBA_NUM_THREADS=2 python -m fcm_fsi bench dem --write-docs` (fcm_fsi/bench/dem.py; "
            "defaults: 10k, 100k and 1M spheres, 1 and 2 threads, 200 steps). Set-up, exactly:\n\n"
            + "\n".join(line[2:] if line.startswith("  ") else line for line in
                        (__doc__.split("Set-up (reproducible; the same packing can be given to another DEM code):")[1]
                         .strip("\n").splitlines()))
            + f"\n\nMachine: {platform.processor() or platform.machine()}, {os.cpu_count()} logical cores, "
              f"load average {os.getloadavg()[0]:.1f} when the table was written (per row: the load column; "
              "with other jobs on the cores the 2-thread rows measure contention, not scaling); Numba kernels "
              "cached (compile time excluded). contacts/sphere = active sphere–sphere contacts (pairs) per "
              "sphere and step; wall contacts are computed but not counted. Goal of issue #6: "
              f"≥ 5e6 sphere-steps/s at 100k spheres on 2 cores — {goal} (see docs/dem.md §5).\n\n")
    body = head + table(rows) + "\n"
    text = path.read_text() if path.exists() else "# Performance\n"
    m = re.search(r"^## DEM\n.*?(?=^## |\Z)", text, flags=re.S | re.M)
    text = text[:m.start()] + body + "\n" + text[m.end():] if m else text.rstrip("\n") + "\n\n" + body
    path.write_text(text)


def run(argv: list[str]) -> int:
    p = argparse.ArgumentParser(prog="python -m fcm_fsi bench dem", description=__doc__.split("\n")[0])
    p.add_argument("--sizes", type=int, nargs="+", default=[10000, 100000, 1000000])
    p.add_argument("--threads", type=int, nargs="+", default=[1, 2])
    p.add_argument("--steps", type=int, default=200)
    p.add_argument("--write-docs", action="store_true", help="write the table into docs/performance.md")
    a = p.parse_args(argv)
    rows = []
    for n in a.sizes:
        for th in a.threads:
            r = measure(n, th, a.steps)
            rows.append(r)
            print(f"{r['spheres']:>8} spheres, {th} thread(s): {r['sphere_steps_per_s']:.3g} sphere-steps/s, "
                  f"{r['contact_updates_per_s']:.3g} contact updates/s ({r['wall']:.2f} s, "
                  f"{r['contacts_per_sphere']:.2f} contacts/sphere, dt/Δt_cr = {r['dt_over_dt_cr']:.3f}, "
                  f"load {r['load']:.1f})", flush=True)
    print(table(rows))
    if a.write_docs:
        write_docs(rows, Path(__file__).resolve().parents[2] / "docs" / "performance.md")
    return 0


if __name__ == "__main__":
    import sys
    sys.exit(run(sys.argv[1:]))
