"""PETSc linear solvers: one KSP per sub-problem, options under one prefix each.

Defaults (measured in docs/performance.md):
- ``DIRECT_LU``: MUMPS LU of the monolithic (u, p) system — small 2D cases.
- ``ITERATIVE_3D``: GMRES + block-Jacobi/ILU(0) on the monolithic stabilized system
  (PSPG makes the pressure block non-singular, so no field split is needed) — 3D.
"""
from __future__ import annotations

from petsc4py import PETSc

DIRECT_LU = {"ksp_type": "preonly", "pc_type": "lu", "pc_factor_mat_solver_type": "mumps"}
ITERATIVE_3D = {"ksp_type": "gmres", "ksp_gmres_restart": 100, "ksp_rtol": 1e-6, "ksp_max_it": 1000,
                "pc_type": "bjacobi", "sub_pc_type": "ilu", "sub_pc_factor_levels": 0}


class LinearSolveError(RuntimeError):
    """A Krylov solve diverged."""


def make_ksp(comm, A: PETSc.Mat, prefix: str, options: dict) -> PETSc.KSP:
    """KSP on matrix ``A`` configured from ``options`` under ``prefix`` (e.g. ``ns_``)."""
    opts = PETSc.Options()
    for key, val in options.items():
        opts[f"{prefix}{key}"] = val
    ksp = PETSc.KSP().create(comm)
    ksp.setOptionsPrefix(prefix)
    ksp.setOperators(A)
    ksp.setFromOptions()
    ksp.getPC().setFromOptions()
    for key in options:          # keep the global options table clean for other solvers
        opts.delValue(f"{prefix}{key}")
    return ksp


def check_converged(ksp: PETSc.KSP, step: int, time: float) -> None:
    """Raise when the last solve diverged (collective: the reason is the same on all ranks)."""
    reason = ksp.getConvergedReason()
    if reason < 0:
        raise LinearSolveError(f"linear solve {ksp.getOptionsPrefix()} diverged at step {step} "
                               f"(t = {time:.6g} s): reason {reason}, {ksp.getIterationNumber()} iterations, "
                               f"residual {ksp.getResidualNorm():.3e}")
