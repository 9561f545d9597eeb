"""Benchmark (not a test): cost of rebuilding the level set and the cut data per fluid step.

    python -m fcm_fsi bench cut [--sizes 16 32 48] [--bodies 1 27 216] [--reps 5]
    mpirun -n 2 python -m fcm_fsi bench cut

Case: the unit cube on an n×n×n structured tetrahedral mesh (6n³ cells) holding N boxes
(edge 0.4/∛N × 0.3/∛N × 0.2/∛N, random orientations, on a lattice, so the cut surface per
body shrinks as N grows and the total cut area grows like ∛N). One rebuild = structure level
set at all mesh nodes (``StructureLevelSet.evaluate``, Numba, binned search) + moment-fitted
cut weights and wall velocity (``CutDomain.update``); each repetition moves the bodies by
a small random step, as the DEM would. The reference is one Crank–Nicolson fluid step
(Newton, default 3D solver) on the same cut mesh with one body, timed in the same run.
Printed per (n, N): rebuild seconds, µs per node, and rebuild / fluid step (goal ≤ 10 %).
"""
from __future__ import annotations

import argparse
import sys
import time

import numpy as np
from mpi4py import MPI

from ..config.fluid import BoundaryCondition, FluidConfig
from ..fcm.levelset import Shapes, StructureLevelSet
from ..fluid.cut_walls import CutDomain
from ..fluid.navier_stokes import NavierStokes
from ..mesh.channel import box


def random_quaternions(rng, n: int) -> np.ndarray:
    q = rng.normal(size=(n, 4))
    return q / np.linalg.norm(q, axis=1)[:, None]


def body_lattice(nbodies: int, rng) -> tuple[Shapes, np.ndarray, float]:
    """N boxes, one per body, centred on a k³ lattice in the unit cube (k = ∛N)."""
    k = int(round(nbodies ** (1 / 3)))
    if k ** 3 != nbodies:
        raise SystemExit(f"--bodies: {nbodies} is not a cube number (1, 8, 27, 64, 125, 216, ...)")
    scale = 1.0 / k
    size = np.array([0.4, 0.3, 0.2]) * scale
    shapes = Shapes.concat([Shapes.box((0.0, 0.0, 0.0), size, body=b) for b in range(nbodies)])
    g = (np.arange(k) + 0.5) * scale
    pos = np.array([[x, y, z] for x in g for y in g for z in g])
    return shapes, pos, 0.25 * scale


def rebuild_seconds(cut: CutDomain, ls: StructureLevelSet, pos, quat, rng, reps: int) -> float:
    """Mean wall time of level set + cut update over ``reps`` moved poses (max over ranks)."""
    times = []
    for _ in range(reps + 1):
        p = pos + rng.normal(scale=1e-3, size=pos.shape)
        cut.comm.barrier()
        t0 = time.perf_counter()
        level, owner = ls.evaluate(cut.nodes, p, quat)
        ubar = np.zeros((len(level), cut.gdim))
        cut.update(level, owner, ubar)
        times.append(cut.comm.allreduce(time.perf_counter() - t0, op=MPI.MAX))
    return float(np.mean(times[1:]))          # the first call compiles/warms the kernels


def fluid_step_seconds(tm, cut: CutDomain) -> tuple[float, int]:
    """One CN step of a driven flow (u = (1, 0, 0) on the x = 0 face, do-nothing at x = 1)
    on the cut mesh; returns (seconds, Newton iterations) after a warm-up step."""
    cfg = FluidConfig(density=1.0, viscosity=0.01, rtol=1e-6, atol=1e-12, quadrature_degree=cut.degree,
                      boundaries=(BoundaryCondition(boundary="xmin", kind="velocity", value=(1.0, 0.0, 0.0)),
                                  BoundaryCondition(boundary="xmax", kind="do_nothing"),
                                  *(BoundaryCondition(boundary=b, kind="slip")
                                    for b in ("ymin", "ymax", "zmin", "zmax"))))
    ns = NavierStokes(tm.mesh, cfg, 0.02, facet_tags=tm.facet_tags, boundary_names=tm.names, dx=cut.dx,
                      extra_terms=[cut.penalty_term()])
    ns.step()
    cut.comm.barrier()
    t0 = time.perf_counter()
    info = ns.step()
    cut.comm.barrier()
    return time.perf_counter() - t0, info.iterations


def run(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m fcm_fsi bench cut", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", type=int, nargs="+", default=[16, 32, 48])
    ap.add_argument("--bodies", type=int, nargs="+", default=[1, 27, 216])
    ap.add_argument("--reps", type=int, default=5)
    args = ap.parse_args(argv)
    comm = MPI.COMM_WORLD
    rng = np.random.default_rng(1)
    if comm.rank == 0:
        print("| n | cells | nodes | bodies | cut cells | rebuild s | µs/node | fluid step s (Newton its) "
              "| rebuild / fluid step |\n|---|---|---|---|---|---|---|---|---|", flush=True)
    for n in args.sizes:
        tm = box(comm, n=(n, n, n))
        cut = CutDomain(tm.mesh)
        # the fluid step with one body, the reference of every row of this mesh
        shapes, pos, cutoff = body_lattice(1, rng)
        ls = StructureLevelSet(shapes, 1, cutoff)
        quat = random_quaternions(rng, 1)
        level, owner = ls.evaluate(cut.nodes, pos, quat)
        cut.update(level, owner, np.zeros((len(level), 3)))
        step_s, its = fluid_step_seconds(tm, cut)
        nodes = tm.mesh.geometry.index_map().size_global
        cells = tm.mesh.topology.index_map(3).size_global
        for nb in args.bodies:
            shapes, pos, cutoff = body_lattice(nb, rng)
            ls = StructureLevelSet(shapes, nb, cutoff)
            quat = random_quaternions(rng, nb)
            sec = rebuild_seconds(cut, ls, pos, quat, rng, args.reps)
            level, _ = ls.evaluate(cut.nodes, pos, quat)
            stats = cut.statistics(np.ascontiguousarray(level[cut.geom_cells]))
            if comm.rank == 0:
                print(f"| {n} | {cells:,} | {nodes:,} | {nb} | {stats.cut_cells:,} | {sec:.3f} "
                      f"| {1e6 * sec * comm.size / nodes:.2f} | {step_s:.2f} ({its}) | {100 * sec / step_s:.1f} % |",
                      flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(run())
