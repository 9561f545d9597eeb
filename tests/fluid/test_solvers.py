"""PETSc solver set-up (fluid/solvers.py): options the preconditioner reads only at its first
set-up reach it, leave PETSc's table afterwards, and a failed MUMPS factorisation is named."""
from __future__ import annotations

import pytest
from mpi4py import MPI
from petsc4py import PETSc

from fcm_fsi.fluid.solvers import LinearSolveError, check_converged, make_ksp, solve


def tridiagonal(n: int = 40, zero_row: int | None = None) -> PETSc.Mat:
    """The 1D Laplacian stencil (−1, 2, −1) on n unknowns; ``zero_row`` empties one row."""
    A = PETSc.Mat().createAIJ([n, n], nnz=3, comm=MPI.COMM_WORLD)
    r0, r1 = A.getOwnershipRange()
    for i in range(r0, r1):
        if i == zero_row:
            continue
        A[i, i] = 2.0
        if i > 0:
            A[i, i - 1] = -1.0
        if i < n - 1:
            A[i, i + 1] = -1.0
    A.assemble()
    return A


def laplacian_2d(m: int = 12) -> PETSc.Mat:
    """The 5-point Laplacian on an m × m grid: ILU(0) is not exact on it, LU is."""
    A = PETSc.Mat().createAIJ([m * m, m * m], nnz=5, comm=MPI.COMM_WORLD)
    r0, r1 = A.getOwnershipRange()
    for k in range(r0, r1):
        i, j = divmod(k, m)
        A[k, k] = 4.0
        for di, dj in ((-1, 0), (1, 0), (0, -1), (0, 1)):
            if 0 <= i + di < m and 0 <= j + dj < m:
                A[k, (i + di) * m + j + dj] = -1.0
    A.assemble()
    return A


def solve_ones(ksp: PETSc.KSP, A: PETSc.Mat) -> None:
    b = A.createVecLeft()
    b.set(1.0)
    solve(ksp, b, b.duplicate())


def left_with(prefix: str) -> list[str]:
    return [k for k in PETSc.Options().getAll() if k.startswith(prefix)]


def test_set_up_time_options_reach_the_preconditioner_and_leave_the_table():
    """mat_mumps_icntl_14 (read when MUMPS factorises) and bjacobi's sub_pc_type (read when the
    blocks are made) must still be in PETSc's table at the first solve: removed earlier, a case
    file's value was silently replaced by the default (20, ilu)."""
    A = tridiagonal()
    ksp = make_ksp(MPI.COMM_WORLD, A, "t_mumps_", {"ksp_type": "gmres", "pc_type": "lu",
                                                   "pc_factor_mat_solver_type": "mumps", "mat_mumps_icntl_14": 77})
    solve_ones(ksp, A)
    assert ksp.getPC().getFactorMatrix().getMumpsIcntl(14) == 77
    assert left_with("t_mumps_") == []
    L = laplacian_2d()                  # one process, one block: an exact LU solves in 1 iteration
    ksp = make_ksp(MPI.COMM_SELF, L, "t_bj_", {"ksp_type": "gmres", "pc_type": "bjacobi", "sub_pc_type": "lu",
                                               "ksp_rtol": 1e-10})
    solve_ones(ksp, L)
    assert ksp.getIterationNumber() == 1
    assert left_with("t_bj_") == []
    again = make_ksp(MPI.COMM_SELF, L, "t_bj_", {"ksp_type": "gmres", "pc_type": "bjacobi", "ksp_rtol": 1e-10})
    solve_ones(again, L)                # a later solver with the prefix gets the default ILU(0), not LU
    assert again.getIterationNumber() > 3
    make_ksp(MPI.COMM_SELF, L, "t_bj_", {"ksp_type": "gmres", "pc_type": "bjacobi", "sub_pc_type": "lu"})
    after = make_ksp(MPI.COMM_SELF, L, "t_bj_", {"ksp_type": "gmres", "pc_type": "bjacobi", "ksp_rtol": 1e-10})
    solve_ones(after, L)                # nor from one that was made and never solved
    assert after.getIterationNumber() > 3 and left_with("t_bj_") == []


def test_a_failed_mumps_factorisation_is_named():
    """A singular matrix (an empty row) makes MUMPS fail; the error says INFOG(1) = −10 and
    what it means, not only KSP reason −11."""
    A = tridiagonal(zero_row=7)
    ksp = make_ksp(MPI.COMM_WORLD, A, "t_sing_", {"ksp_type": "preonly", "pc_type": "lu",
                                                  "pc_factor_mat_solver_type": "mumps"})
    solve_ones(ksp, A)
    with pytest.raises(LinearSolveError, match=r"reason -11.*MUMPS INFOG\(1\) = -10.*singular"):
        check_converged(ksp, step=3, time=0.5)


def test_a_mumps_factorisation_out_of_workspace_is_retried_with_more_and_no_other():
    """INFOG(1) = −9 (or −8): ICNTL(14) is doubled, at least to 50 %, and the operator is
    marked changed so that the next solve factorises again. No deterministic small matrix
    makes MUMPS run out of workspace, so a stand-in factor reports it; a singular matrix
    (−10, the real MUMPS) is not retried."""
    from types import SimpleNamespace

    from fcm_fsi.fluid.solvers import more_mumps_workspace
    seen = {"icntl": {14: 20}, "state": 0, "reuse": None}
    factor = SimpleNamespace(getType=lambda: "mumps", getMumpsInfog=lambda k: -9,
                             getMumpsIcntl=lambda k: seen["icntl"][k],
                             setMumpsIcntl=lambda k, v: seen["icntl"].__setitem__(k, v))
    pc = SimpleNamespace(getType=lambda: PETSc.PC.Type.LU, getFactorMatrix=lambda: factor,
                         setReusePreconditioner=lambda flag: seen.__setitem__("reuse", flag))
    P = SimpleNamespace(stateIncrease=lambda: seen.__setitem__("state", seen["state"] + 1))
    ksp = SimpleNamespace(getConvergedReason=lambda: PETSc.KSP.ConvergedReason.DIVERGED_PCSETUP_FAILED,
                          getPC=lambda: pc, getOperators=lambda: (P, P), getOptionsPrefix=lambda: "t_ws_")
    assert more_mumps_workspace(ksp)
    assert seen["icntl"][14] == 50 and seen["state"] == 1 and seen["reuse"] is False
    assert more_mumps_workspace(ksp) and seen["icntl"][14] == 100
    A = tridiagonal(zero_row=7)
    real = make_ksp(MPI.COMM_WORLD, A, "t_sing2_", {"ksp_type": "preonly", "pc_type": "lu",
                                                    "pc_factor_mat_solver_type": "mumps"})
    solve_ones(real, A)
    assert real.getConvergedReason() == PETSc.KSP.ConvergedReason.DIVERGED_PCSETUP_FAILED
    assert not more_mumps_workspace(real)


def test_a_solve_stopped_below_the_nonlinear_atol_is_accepted():
    """A Krylov solve that hits its iteration limit is a failure, unless its true residual is
    already below the nonlinear iteration's atol (a step at rest, where rtol‖b‖ lies below
    round-off): then the step's stopping rule is met and the solve is accepted."""
    L = laplacian_2d()
    ksp = make_ksp(MPI.COMM_SELF, L, "t_atol_", {"ksp_type": "gmres", "pc_type": "none", "ksp_rtol": 1e-14,
                                                "ksp_max_it": 2})
    x, b = L.createVecs()
    b.set(1e-9)                          # tiny right-hand side: two iterations leave ‖r‖ ≈ 1e-9
    solve(ksp, b, x)
    assert ksp.getConvergedReason() == PETSc.KSP.ConvergedReason.DIVERGED_MAX_IT
    with pytest.raises(LinearSolveError, match="reason -3"):
        check_converged(ksp, step=1, time=0.0)
    with pytest.raises(LinearSolveError, match="reason -3"):
        check_converged(ksp, step=1, time=0.0, atol=1e-14)
    check_converged(ksp, step=1, time=0.0, atol=1e-6)


def test_incomplete_factorisations_get_a_block_matrix_and_the_rest_aij():
    from fcm_fsi.fluid import solvers
    assert solvers.matrix_type(solvers.ITERATIVE_2D) == "baij"
    assert solvers.matrix_type(solvers.ITERATIVE_3D) == "baij"
    assert solvers.matrix_type({"pc_type": "ilu"}) == "baij"
    for opts in (solvers.DIRECT_LU, solvers.SCHUR_AMG, solvers.SCHUR_GAMG, {"pc_type": "bjacobi", "sub_pc_type": "lu"}):
        assert solvers.matrix_type(opts) is None
