"""Benchmark (not a test): cost of one stabilized Navier–Stokes nonlinear iteration in 3D.

    python -m fcm_fsi bench navier_stokes --sizes 16 32 64 [--solver schur_gamg|schur|schur_ilu|ilu|asm|hypre|lu] [--no-reuse]
    mpirun -n 2 python -m fcm_fsi bench navier_stokes --sizes 16 24 32

Case: channel flow in the unit cube on an n×n×n structured tetrahedral mesh (6n³ cells),
parabolic inflow (U = 1) at x = 0, do-nothing outflow at x = 1, no-slip elsewhere,
ρ = 1, μ = 0.01, Δt = 0.05, Crank–Nicolson; one warm-up step, then the second time step is measured.
Per nonlinear iteration: assembly seconds (τ, residual, Jacobian), solve seconds, Krylov
iterations, µs per unknown; and the ratio of one nonlinear iteration to one P1 Poisson
solve (assembly + CG/BoomerAMG to rtol 1e-6) on the same mesh in the same run.
"""
from __future__ import annotations

import argparse
import sys
import time

import numpy as np
import ufl
from dolfinx import fem
from mpi4py import MPI
from petsc4py import PETSc

from .. import jit
from ..config.fluid import BoundaryCondition, FluidConfig
from ..fluid import solvers
from ..fluid.navier_stokes import NavierStokes
from ..mesh.channel import box

SOLVERS = {
    "ilu": solvers.ITERATIVE_3D,
    "asm": {**solvers.ITERATIVE_3D, "pc_type": "asm", "pc_asm_overlap": 1},
    "hypre": {"ksp_type": "gmres", "ksp_gmres_restart": 100, "ksp_rtol": 1e-6, "ksp_max_it": 1000,
              "pc_type": "hypre", "pc_hypre_type": "boomeramg"},
    "lu": solvers.DIRECT_LU,
    "schur": solvers.SCHUR_AMG,
    # Schur split with block-Jacobi/ILU(0) on the velocity block, BoomerAMG on the Schur complement only
    "schur_ilu": {**solvers.SCHUR_AMG, "fieldsplit_u_pc_type": "bjacobi", "fieldsplit_u_sub_pc_type": "ilu"},
    "schur_ilu1": {**solvers.SCHUR_AMG, "fieldsplit_u_pc_type": "bjacobi", "fieldsplit_u_sub_pc_type": "ilu",
                   "fieldsplit_u_sub_pc_factor_levels": 1},
    # Schur split with smoothed-aggregation AMG (PETSc GAMG) on the velocity block
    "schur_gamg": solvers.SCHUR_GAMG,
}


def poisson_seconds(mesh) -> tuple[float, int]:
    """Assemble and solve −Δφ = 1, φ = 0 on ∂Ω with P1, CG + BoomerAMG (rtol 1e-6)."""
    comm = mesh.comm
    comm.barrier()
    t0 = time.perf_counter()
    V = fem.FunctionSpace(mesh, ("Lagrange", 1))
    from dolfinx import mesh as dmesh
    fdim = mesh.topology.dim - 1
    facets = dmesh.locate_entities_boundary(mesh, fdim, lambda x: np.full(x.shape[1], True))
    bc = fem.dirichletbc(PETSc.ScalarType(0), fem.locate_dofs_topological(V, fdim, facets), V)
    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    a = jit.form(ufl.inner(ufl.grad(u), ufl.grad(v)) * ufl.dx)
    L = jit.form(v * ufl.dx)
    A = fem.petsc.assemble_matrix(a, bcs=[bc])
    A.assemble()
    b = fem.petsc.assemble_vector(L)
    fem.petsc.apply_lifting(b, [a], bcs=[[bc]])
    b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
    fem.petsc.set_bc(b, [bc])
    ksp = solvers.make_ksp(comm, A, "poisson_", {"ksp_type": "cg", "ksp_rtol": 1e-6,
                                                  "pc_type": "hypre", "pc_hypre_type": "boomeramg"})
    x = A.createVecRight()
    solvers.solve(ksp, b, x)
    comm.barrier()
    return time.perf_counter() - t0, ksp.getIterationNumber()


def ns_iterations(mesh_n: int, comm, solver: str, reuse: bool = True) -> dict:
    """One CN step of the channel flow; returns per-iteration averages. ``reuse``: the
    preconditioner is built in the first Newton iteration of the step only."""
    tm = box(comm, n=(mesh_n, mesh_n, mesh_n))
    cfg = FluidConfig(density=1.0, viscosity=0.01, rtol=1e-6, atol=1e-12, max_iterations=10,
                      reuse_preconditioner=reuse,
                      petsc=SOLVERS[solver], boundaries=(
                          BoundaryCondition(boundary="xmin", kind="parabolic_inflow", max_speed=1.0),
                          BoundaryCondition(boundary="xmax", kind="do_nothing"),
                          *(BoundaryCondition(boundary=b, kind="no_slip")
                            for b in ("ymin", "ymax", "zmin", "zmax"))))
    ns = NavierStokes(tm.mesh, cfg, 0.05, facet_tags=tm.facet_tags, boundary_names=tm.names)
    ns.set_velocity(lambda x: np.vstack([16 * x[1] * (1 - x[1]) * x[2] * (1 - x[2]),
                                         0 * x[0], 0 * x[0]]))
    ns.step()                      # warm-up step: first-call and JIT-cache costs are not counted
    comm.barrier()
    t0 = time.perf_counter()
    info = ns.step()
    comm.barrier()
    total = time.perf_counter() - t0
    solve_s = comm.allreduce(info.solve_seconds, op=MPI.MAX)
    nunk = ns.W.dofmap.index_map.size_global * ns.W.dofmap.index_map_bs
    n_it = max(info.iterations, 1)
    per_it = total / n_it
    poisson_seconds(tm.mesh)       # warm-up
    poisson, p_its = poisson_seconds(tm.mesh)
    ncells = tm.mesh.topology.index_map(3).size_global
    return {"n": mesh_n, "cells": ncells, "unknowns": nunk, "ranks": comm.size,
            "solver": solver + ("+reuse" if reuse else ""),
            "newton_its": info.iterations, "assembly_s": (total - solve_s) / n_it,
            "solve_s": solve_s / n_it, "krylov_its": info.krylov_iterations / n_it,
            "us_per_unknown": 1e6 * per_it / nunk, "iteration_s": per_it, "poisson_s": poisson,
            "poisson_its": p_its, "ratio": per_it / poisson}


HEADER = ("| n | cells | unknowns | ranks | solver | Newton its | assembly s/it | solve s/it | Krylov its/it "
          "| µs/unknown/it | Poisson s (CG its) | NS it / Poisson |")


def row(r: dict) -> str:
    return (f"| {r['n']} | {r['cells']:,} | {r['unknowns']:,} | {r['ranks']} | {r['solver']} | {r['newton_its']} "
            f"| {r['assembly_s']:.2f} | {r['solve_s']:.2f} | {r['krylov_its']:.0f} | {r['us_per_unknown']:.1f} "
            f"| {r['poisson_s']:.2f} ({r['poisson_its']}) | {r['ratio']:.1f} |")


def run(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m fcm_fsi bench navier_stokes", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", type=int, nargs="+", default=[24, 36, 48])
    ap.add_argument("--solver", choices=sorted(SOLVERS), default="schur_gamg",
                    help="schur_gamg = the 3D default (solvers.SCHUR_GAMG)")
    ap.add_argument("--no-reuse", dest="reuse", action="store_false",
                    help="rebuild the preconditioner every Newton iteration (default: once per time step, "
                         "fluid.reuse_preconditioner)")
    args = ap.parse_args(argv)
    comm = MPI.COMM_WORLD
    rows = []
    for n in args.sizes:
        rows.append(ns_iterations(n, comm, args.solver, args.reuse))
        if comm.rank == 0:
            if len(rows) == 1:
                print(HEADER, "\n" + "|---" * 12 + "|", flush=True)
            print(row(rows[-1]), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(run())
