"""Physics tests of the stabilized Navier–Stokes solver (issue #3). Total runtime ~1 min."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from mpi4py import MPI

from fcm_fsi.config.case import case_from_dict
from fcm_fsi.config.fluid import BoundaryCondition, FluidConfig
from fcm_fsi.config.loader import ConfigError
from fcm_fsi.fluid.forces import ReactionForce
from fcm_fsi.fluid.navier_stokes import NavierStokes, NonlinearSolveError
from fcm_fsi.fluid.steady import march_to_steady
from fcm_fsi.mesh.channel import rectangle

ROOT = Path(__file__).resolve().parents[2]


def poiseuille(n: int, mu: float = 0.1):
    """Steady channel flow [0,2]×[0,1], parabolic inflow U=1, do-nothing outflow."""
    tm = rectangle(MPI.COMM_WORLD, (0.0, 0.0), (2.0, 1.0), (2 * n, n))
    cfg = FluidConfig(density=1.0, viscosity=mu, theta=1.0, rtol=1e-10, atol=1e-12, boundaries=(
        BoundaryCondition(boundary="xmin", kind="parabolic_inflow", max_speed=1.0),
        BoundaryCondition(boundary="ymin", kind="no_slip"),
        BoundaryCondition(boundary="ymax", kind="no_slip"),
        BoundaryCondition(boundary="xmax", kind="do_nothing")))
    ns = NavierStokes(tm.mesh, cfg, 1.0, facet_tags=tm.facet_tags, boundary_names=tm.names)
    march_to_steady(ns, tol=1e-9, max_steps=60)
    X = ns.V.tabulate_dof_coordinates()
    u = ns.u.x.array.reshape(-1, 2)
    exact = 4 * X[:, 1] * (1 - X[:, 1])
    err_u = np.abs(u[:, 0] - exact).max()
    err_v = np.abs(u[:, 1]).max()
    # wall shear stress on the top wall by reaction: μ|du/dy| = 4μ per unit length, length 2
    top = ReactionForce(ns.W, ns.F_form, ns.boundary_facets("ymax"))()
    return err_u, err_v, top, ns


def test_poiseuille_converges_at_second_order():
    """Nodal error of P1/P1 SUPG/PSPG/LSIC for plane Poiseuille flow falls ~4× per halving of h."""
    e8, v8, _, _ = poiseuille(8)
    e16, v16, top, ns = poiseuille(16)
    assert e16 < 0.01
    assert np.log2(e8 / e16) > 1.8
    assert v16 < 0.01
    # pressure gradient −8μU/H² = −0.8, p = 0 at the outlet, so p_in = 1.6
    p = ns.p.x.array
    X = ns.Q.tabulate_dof_coordinates()
    slope = np.polyfit(X[:, 0], p, 1)[0]
    assert slope == pytest.approx(-0.8, rel=0.03)
    # reaction on the top wall's nodes: shear μ·4U/H over L = 2 (0.8), plus the inlet corner
    # node's share of the inlet traction, −p_in·h/2 (nodal reaction lumps half a facet)
    assert top[0] == pytest.approx(0.8 - 1.6 / (2 * 16), rel=0.01)
    # normal force: ∫ p dx over the top = 1.6, minus the corner node's share of the inlet shear
    # traction μ·4U/H·h/2
    assert top[1] == pytest.approx(1.6 - 0.4 / (2 * 16), rel=0.005)


def test_taylor_green_space_order():
    """Observed L2 order of the velocity at N = 8 → 16 → 32 (the verification case's quick level)."""
    from fcm_fsi.verify.cases.navier_stokes import _taylor_green_run
    errs = [_taylor_green_run(MPI.COMM_WORLD, n, 0.01, 0.1, 0.01)[1] for n in (8, 16, 32)]
    orders = np.log2(np.array(errs[:-1]) / np.array(errs[1:]))
    assert orders[-1] > 1.8, errs


def test_bad_boundary_kind_is_a_config_error():
    base = {"name": "x", "run": {"t_end": 1.0, "dt": 0.1}, "mesh": {"kind": "rectangle"}}
    with pytest.raises(ConfigError, match=r"fluid.boundaries\[0\].kind.*no_slip"):
        case_from_dict({**base, "fluid": {"boundaries": [{"boundary": "ymax", "kind": "noslip"}]}})
    with pytest.raises(ConfigError, match="more than one condition"):
        case_from_dict({**base, "fluid": {"boundaries": [{"boundary": "ymax", "kind": "no_slip"},
                                                         {"boundary": "ymax", "kind": "slip"}]}})


def test_unknown_boundary_name_is_a_config_error():
    """Also from the Python API, where no case file is checked: a former name gets its axis name."""
    tm = rectangle(MPI.COMM_WORLD, n=(4, 4))
    for name, message in (("lid", "'lid' is not a mesh boundary; known: xmax, xmin, ymax, ymin$"),
                          ("top", "'top' is not a mesh boundary.*in 2D 'top' is 'ymax'")):
        cfg = FluidConfig(boundaries=(BoundaryCondition(boundary=name, kind="no_slip"),))
        with pytest.raises(ConfigError, match=message):
            NavierStokes(tm.mesh, cfg, 0.1, facet_tags=tm.facet_tags, boundary_names=tm.names)


def test_nonconvergence_reports_step_time_and_history():
    """One nonlinear iteration allowed with an unreachable tolerance: a clear error, not a silent result."""
    tm = rectangle(MPI.COMM_WORLD, n=(8, 8))
    cfg = FluidConfig(density=1.0, viscosity=0.01, max_iterations=1, rtol=1e-15, atol=1e-300, startup_steps=0, boundaries=(
        BoundaryCondition(boundary="ymax", kind="velocity", value=(1.0, 0.0)),
        BoundaryCondition(boundary="xmin", kind="no_slip"), BoundaryCondition(boundary="xmax", kind="no_slip"),
        BoundaryCondition(boundary="ymin", kind="no_slip")))
    ns = NavierStokes(tm.mesh, cfg, 0.1, facet_tags=tm.facet_tags, boundary_names=tm.names)
    with pytest.raises(NonlinearSolveError) as info:
        ns.step()
    assert info.value.step == 1 and info.value.time == pytest.approx(0.1)
    assert len(info.value.residuals) == 2 and "residual history" in str(info.value)


SCRIPT = """
import json, sys
from mpi4py import MPI
from fcm_fsi.verify.cases.navier_stokes import cavity_solution
from fcm_fsi.fluid.forces import probe
import numpy as np
ns, steps = cavity_solution(MPI.COMM_WORLD, 100, 16)
vals = probe(ns.u, np.array([[0.5, 0.25, 0], [0.25, 0.5, 0], [0.8, 0.8, 0]]))
if MPI.COMM_WORLD.rank == 0:
    print("RESULT" + json.dumps({"steps": steps, "u": vals.tolist()}))
"""


def _run(np_: int) -> dict:
    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1",
               OMPI_MCA_rmaps_base_oversubscribe="1", OMP_NUM_THREADS="1")
    cmd = [sys.executable, "-c", SCRIPT]
    if np_ > 1:
        cmd = ["mpirun", "-n", str(np_), "--oversubscribe"] + cmd
    out = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    line = [ln for ln in out.stdout.splitlines() if ln.startswith("RESULT")][0]
    return json.loads(line[6:])


def test_one_and_two_ranks_agree():
    """Steady Re-100 cavity on 16×16: 1-rank and 2-rank solutions agree to solver tolerance."""
    one, two = _run(1), _run(2)
    assert np.allclose(one["u"], two["u"], atol=1e-7, rtol=0)
    assert abs(one["steps"] - two["steps"]) <= 1


def test_newton_and_picard_reach_the_same_solution():
    """Both linearisations solve the same discrete CN equations (5 steps of a Re-100 cavity)."""
    tm = rectangle(MPI.COMM_WORLD, n=(12, 12))
    bcs = (BoundaryCondition(boundary="ymax", kind="velocity", value=(1.0, 0.0)),
           BoundaryCondition(boundary="xmin", kind="no_slip"), BoundaryCondition(boundary="xmax", kind="no_slip"),
           BoundaryCondition(boundary="ymin", kind="no_slip"))
    out, its = {}, {}
    for nl in ("newton", "picard"):
        cfg = FluidConfig(density=1.0, viscosity=0.01, boundaries=bcs, nonlinear=nl, rtol=1e-10, atol=1e-13)
        ns = NavierStokes(tm.mesh, cfg, 0.05, facet_tags=tm.facet_tags, boundary_names=tm.names)
        its[nl] = sum(ns.step().iterations for _ in range(5))
        out[nl] = ns.U.x.array.copy()
    assert np.abs(out["newton"] - out["picard"]).max() < 1e-8
    assert its["newton"] < its["picard"]


def test_line_search_turns_a_diverging_newton_solve_into_a_converging_one():
    """Re-1000 cavity, one backward-Euler step of Δt = 100 from rest (the steady problem in one
    step): the plain Newton iteration diverges (residual ~1e9 by iteration 11), the
    backtracking line search (``fluid.line_search``) converges to rtol 1e-10; with Δt = 1,
    where Newton converges, the line search never acts and the iterates are identical."""
    tm = rectangle(MPI.COMM_WORLD, n=(16, 16))
    bcs = (BoundaryCondition(boundary="ymax", kind="velocity", value=(1.0, 0.0)),
           BoundaryCondition(boundary="xmin", kind="no_slip"), BoundaryCondition(boundary="xmax", kind="no_slip"),
           BoundaryCondition(boundary="ymin", kind="no_slip"))

    def solver(dt, line_search):
        cfg = FluidConfig(density=1.0, viscosity=1e-3, boundaries=bcs, theta=1.0, startup_steps=0,
                          line_search=line_search, max_iterations=30, rtol=1e-10, atol=1e-13)
        return NavierStokes(tm.mesh, cfg, dt, facet_tags=tm.facet_tags, boundary_names=tm.names)

    with pytest.raises(NonlinearSolveError):
        solver(100.0, 0).step()
    ns = solver(100.0, 8)
    info = ns.step()
    assert info.residuals[-1] <= 1e-10 * info.residuals[0] and ns.backtracks > 0
    plain, searched = solver(1.0, 0), solver(1.0, 8)
    plain.step(), searched.step()
    assert searched.backtracks == 0
    assert np.array_equal(plain.U.x.array, searched.U.x.array)


def _box_channel(petsc: dict):
    from fcm_fsi.mesh.channel import box
    tm = box(MPI.COMM_WORLD, n=(8, 8, 8))
    cfg = FluidConfig(density=1.0, viscosity=0.01, rtol=1e-9, atol=1e-12, petsc=petsc, boundaries=(
        BoundaryCondition(boundary="xmin", kind="parabolic_inflow", max_speed=1.0),
        BoundaryCondition(boundary="xmax", kind="do_nothing"),
        *(BoundaryCondition(boundary=b, kind="no_slip") for b in ("ymin", "ymax", "zmin", "zmax"))))
    ns = NavierStokes(tm.mesh, cfg, 0.05, facet_tags=tm.facet_tags, boundary_names=tm.names)
    info = ns.step()
    return ns, info


@pytest.mark.parametrize("name", ["SCHUR_AMG", "SCHUR_GAMG"])
def test_schur_field_split_matches_direct_solve(name):
    """The velocity/pressure field split (Schur complement; BoomerAMG or GAMG on the velocity,
    BoomerAMG on the Schur block) solves the same stabilized system as LU: one CN step of a
    3D channel agrees to the Krylov tolerance, in a handful of iterations — also with the
    preconditioner reused over the Newton iterations of the step (the automatic setting)."""
    from fcm_fsi.fluid import solvers
    ns_lu, _ = _box_channel(solvers.DIRECT_LU)
    ns_fs, info = _box_channel({**getattr(solvers, name), "ksp_rtol": 1e-10})
    assert ns_fs.ksp.getPC().getType() == "fieldsplit"
    assert ns_fs.reuse_preconditioner and not ns_lu.reuse_preconditioner
    diff = np.abs(ns_fs.U.x.array - ns_lu.U.x.array).max()
    assert diff < 1e-6 * np.abs(ns_lu.U.x.array).max()
    assert info.krylov_iterations / info.iterations < 30


def test_fieldsplit_without_fields_is_a_clear_error():
    from petsc4py import PETSc

    from fcm_fsi.fluid import solvers
    A = PETSc.Mat().createAIJ([4, 4], comm=MPI.COMM_WORLD)
    A.setUp()
    A.assemble()
    with pytest.raises(ValueError, match="fieldsplit"):
        solvers.make_ksp(MPI.COMM_WORLD, A, "t_", {"pc_type": "fieldsplit"})


def test_sponge_layer_damps_a_uniform_stream_at_its_rate():
    """A uniform stream with do-nothing ends inside a damping zone at full rate σ decays as
    du/dt = −σu; Crank–Nicolson gives the factor (1 − σΔt/2)/(1 + σΔt/2) per step, exactly
    (the sink is in the strong residual too, so SUPG/PSPG leave the uniform state alone)."""
    from fcm_fsi.config.fluid import DampingZone
    tm = rectangle(MPI.COMM_WORLD, (0.0, 0.0), (2.0, 1.0), (8, 4))
    sigma, dt, steps = 3.0, 0.05, 6
    zone = DampingZone(axis="x", start=-2.0, end=-1.0, rate=sigma)     # ξ ≥ 2 on the mesh: σ = rate
    # the stream enters through the left do-nothing end: plain do-nothing (backflow 0), which the
    # directional form would otherwise damp there by design
    cfg = FluidConfig(density=2.0, viscosity=0.01, startup_steps=0, rtol=1e-12, atol=1e-13, backflow=0.0,
                      damping_zones=(zone,), boundaries=(
                          BoundaryCondition(boundary="xmin", kind="do_nothing"),
                          BoundaryCondition(boundary="xmax", kind="do_nothing"),
                          BoundaryCondition(boundary="ymin", kind="slip"),
                          BoundaryCondition(boundary="ymax", kind="slip")))
    ns = NavierStokes(tm.mesh, cfg, dt, facet_tags=tm.facet_tags, boundary_names=tm.names)
    ns.set_velocity(lambda x: np.vstack([np.ones(x.shape[1]), np.zeros(x.shape[1])]))
    for _ in range(steps):
        ns.step()
    u = ns.u.x.array.reshape(-1, 2)
    factor = ((1 - 0.5 * sigma * dt) / (1 + 0.5 * sigma * dt)) ** steps
    assert np.abs(u[:, 0] - factor).max() < 1e-10
    assert np.abs(u[:, 1]).max() < 1e-10


def test_sponge_layer_input_errors_name_the_key():
    from fcm_fsi.config.fluid import DampingZone
    with pytest.raises(ConfigError, match=r"fluid.damping_zones\[0\].*start ≠ end"):
        FluidConfig(damping_zones=(DampingZone(axis="x", start=1.0, end=1.0, rate=1.0),))
    with pytest.raises(ConfigError, match=r"fluid.damping_zones\[0\].axis"):
        FluidConfig(gravity=(0.0, -9.81), damping_zones=(DampingZone(axis="z", start=0.0, end=1.0, rate=1.0),))


def test_backflow_term_acts_only_where_fluid_enters_an_open_boundary():
    """Directional do-nothing (fluid.backflow): a uniform stream through a channel with open
    ends stays exactly uniform with the plain condition; with β = 1 it loses kinetic energy
    through the end where it enters. (Where u·n > 0 the term vanishes: the Poiseuille outflow
    tests above run with the default β = 1 and are unchanged.)"""
    tm = rectangle(MPI.COMM_WORLD, (0.0, 0.0), (2.0, 1.0), (8, 4))

    def stream(beta: float) -> np.ndarray:
        cfg = FluidConfig(density=2.0, viscosity=0.01, startup_steps=0, rtol=1e-12, atol=1e-13, backflow=beta,
                          boundaries=(BoundaryCondition(boundary="xmin", kind="do_nothing"),
                                      BoundaryCondition(boundary="xmax", kind="do_nothing"),
                                      BoundaryCondition(boundary="ymin", kind="slip"),
                                      BoundaryCondition(boundary="ymax", kind="slip")))
        ns = NavierStokes(tm.mesh, cfg, 0.05, facet_tags=tm.facet_tags, boundary_names=tm.names)
        ns.set_velocity(lambda x: np.vstack([np.ones(x.shape[1]), np.zeros(x.shape[1])]))
        for _ in range(3):
            ns.step()
        return ns.u.x.array.reshape(-1, 2)[:, 0]

    assert np.abs(stream(0.0) - 1.0).max() < 1e-10
    damped = stream(1.0)
    assert MPI.COMM_WORLD.allreduce(float(damped.max()), op=MPI.MAX) < 1.0 - 1e-3


def test_gmres_breakdown_is_accepted_only_when_the_true_residual_meets_rtol():
    """solvers.check_converged accepts a KSP 'breakdown' only if ‖b − A x‖ ≤ rtol ‖b‖: the helper
    says yes for a solved system and no once the solution is perturbed."""
    from petsc4py import PETSc

    from fcm_fsi.fluid.solvers import _true_residual_met
    n = 20
    A = PETSc.Mat().createAIJ([n, n], nnz=3, comm=PETSc.COMM_SELF)
    for i in range(n):
        A.setValue(i, i, 4.0)
        if i > 0:
            A.setValue(i, i - 1, -1.0)
        if i < n - 1:
            A.setValue(i, i + 1, -1.0)
    A.assemble()
    b = A.createVecLeft()
    b.setArray(np.linspace(1.0, 2.0, n))
    x = A.createVecRight()
    ksp = PETSc.KSP().create(PETSc.COMM_SELF)
    ksp.setOperators(A)
    ksp.setType("gmres")
    ksp.getPC().setType("none")
    ksp.setTolerances(rtol=1e-8)
    ksp.solve(b, x)
    assert _true_residual_met(ksp)
    x.array[0] += 1e-3            # ‖A δx‖ ≈ 4e-3 ≫ 1e-8 ‖b‖
    assert not _true_residual_met(ksp)


def test_lu_kept_over_time_steps_as_gmres_preconditioner_gives_the_same_flow():
    """``fluid.preconditioner_steps``: an LU factorisation kept for several steps as the GMRES
    preconditioner reaches the same solution as factorising every step (to the Krylov and
    Newton tolerances), with one factorisation while the solves stay cheap."""
    from fcm_fsi.mesh.channel import box
    tm = box(MPI.COMM_WORLD, n=(6, 6, 6))

    def run(steps: int):
        cfg = FluidConfig(density=1.0, viscosity=0.01, rtol=1e-9, atol=1e-12, preconditioner_steps=steps, startup_steps=0,
                          petsc={"ksp_type": "gmres", "pc_type": "lu", "ksp_rtol": 1e-10}, boundaries=(
                              BoundaryCondition(boundary="xmin", kind="parabolic_inflow", max_speed=1.0),
                              BoundaryCondition(boundary="xmax", kind="do_nothing"),
                              *(BoundaryCondition(boundary=b, kind="no_slip") for b in ("ymin", "ymax", "zmin", "zmax"))))
        ns = NavierStokes(tm.mesh, cfg, 0.05, facet_tags=tm.facet_tags, boundary_names=tm.names)
        built, its = [], 0
        for _ in range(6):
            its += ns.step().krylov_iterations
            built.append(ns._preconditioner_built)
        return ns, built, its

    fresh, built_fresh, its_fresh = run(1)
    kept, built_kept, its_kept = run(10)
    assert built_fresh == list(range(1, 7))        # one factorisation per step
    assert set(built_kept) == {1}                  # the first step's, kept
    assert its_kept > its_fresh                    # paid for with Krylov iterations
    diff = np.abs(kept.U.x.array - fresh.U.x.array).max()
    assert diff < 1e-6 * np.abs(fresh.U.x.array).max()


def test_warm_start_retakes_a_step_to_the_same_flow_with_kept_jacobian():
    """``NavierStokes.warm_start`` (the coupling's later passes): a step taken again from the
    converged flow is accepted without a solve; one taken again from a perturbed flow converges
    to the cold start's flow (to the Newton tolerance) on the kept factorisation and Jacobian
    (chord steps: no Jacobian assembled, no new factorisation)."""
    from fcm_fsi.mesh.channel import box
    tm = box(MPI.COMM_WORLD, n=(5, 5, 5))
    cfg = FluidConfig(density=1.0, viscosity=0.01, rtol=1e-9, atol=1e-12, startup_steps=0,
                      petsc={"ksp_type": "gmres", "pc_type": "lu", "ksp_rtol": 1e-11}, boundaries=(
                          BoundaryCondition(boundary="xmin", kind="parabolic_inflow", max_speed=1.0),
                          BoundaryCondition(boundary="xmax", kind="do_nothing"),
                          *(BoundaryCondition(boundary=b, kind="no_slip") for b in ("ymin", "ymax", "zmin", "zmax"))))
    ns = NavierStokes(tm.mesh, cfg, 0.1, facet_tags=tm.facet_tags, boundary_names=tm.names)
    ns.step()
    start = (ns.U.x.array.copy(), ns.U_n.x.array.copy(), ns.u_nm1.x.array.copy(), ns.t, ns.step_count)

    def restore():
        ns.U.x.array[:], ns.U_n.x.array[:], ns.u_nm1.x.array[:], ns.t, ns.step_count = (
            start[0].copy(), start[1].copy(), start[2].copy(), start[3], start[4])

    cold = ns.step()
    solution = ns.U.x.array.copy()
    assert cold.iterations >= 2
    restore()
    ns.warm_start(solution)
    assert ns.step().iterations == 0                       # the converged flow meets the rule already
    np.testing.assert_array_equal(ns.U.x.array, solution)

    built = ns._preconditioner_built
    jacobians = []
    original = ns._assemble_jacobian
    ns._assemble_jacobian = lambda: (jacobians.append(1), original())
    restore()
    rng = np.random.default_rng(1)
    ns.warm_start(solution * (1 + 1e-3 * rng.standard_normal(solution.shape)))
    info = ns.step()
    assert info.iterations >= 1
    assert not jacobians                                   # chord steps on the kept Jacobian
    assert ns._preconditioner_built == built               # and the kept factorisation
    scale = np.abs(solution).max()
    assert np.abs(ns.U.x.array - solution).max() < 1e-6 * scale
    assert info.residuals[-1] <= cfg.rtol * cold.residuals[0] * 1.0001 or info.residuals[-1] <= cfg.atol


def test_linearised_step_solves_its_oseen_system_in_one_solve():
    """``nonlinear: linearised``: the system with the extrapolated advecting velocity and its τ is
    linear in (u, p), so after the single solve its residual is at round-off."""
    from fcm_fsi.verify.cases.navier_stokes import _taylor_green_run
    ns, _ = _taylor_green_run(MPI.COMM_WORLD, 12, 0.02, 0.1, 0.01, nonlinear="linearised")
    assert all(info.iterations == 1 for info in ns.history[-3:])
    r_start = ns.history[-1].residuals[0]
    assert ns._assemble_residual() <= 1e-9 * r_start


def test_linearised_step_departs_from_newton_at_second_order_in_time():
    """Taylor–Green on one mesh: the linearised step (one Oseen solve, a extrapolated) against
    the Newton-converged Crank–Nicolson step at Δt = 0.08, 0.04, 0.02 — their difference falls
    at least 4× per halving (measured ≈ 8×) and stays far below the solution's own error."""
    from fcm_fsi.mesh.channel import rectangle as rect
    from fcm_fsi.verify.cases.navier_stokes import _l2_diff, _taylor_green_run
    tm = rect(MPI.COMM_WORLD, (0.0, 0.0), (1.0, 1.0), (16, 16), diagonal="crossed")
    diffs, errors = [], []
    for dt in (0.08, 0.04, 0.02):
        lin, err = _taylor_green_run(MPI.COMM_WORLD, 16, dt, 0.4, 0.01, tm=tm, nonlinear="linearised")
        newton, _ = _taylor_green_run(MPI.COMM_WORLD, 16, dt, 0.4, 0.01, tm=tm)
        diffs.append(_l2_diff(lin, newton))
        errors.append(err)
    orders = np.log2(np.array(diffs[:-1]) / np.array(diffs[1:]))
    assert orders.min() > 2.0, diffs
    assert max(d / e for d, e in zip(diffs, errors)) < 1e-2, (diffs, errors)


@pytest.mark.parametrize("dim", [2, 3])
def test_the_blocked_space_pairs_velocity_and_pressure_of_each_vertex(dim):
    """(u, p) live in one blocked P1 space, gdim + 1 values per vertex; V_map and Q_map take the
    velocity and pressure dofs out of it at the same vertices as the separate P1 spaces' dofs
    (every dof, ghosts included), and a block matrix carries the ILU solvers' systems."""
    from dolfinx import fem

    from fcm_fsi.fluid import solvers
    from fcm_fsi.mesh.channel import box
    tm = rectangle(MPI.COMM_WORLD, n=(6, 4)) if dim == 2 else box(MPI.COMM_WORLD, n=(3, 3, 2))
    cfg = FluidConfig(density=1.0, viscosity=0.01, petsc=solvers.ITERATIVE_2D if dim == 2 else solvers.ITERATIVE_3D,
                      boundaries=(BoundaryCondition(boundary="xmin", kind="no_slip"),))
    ns = NavierStokes(tm.mesh, cfg, 0.1, facet_tags=tm.facet_tags, boundary_names=tm.names)
    assert ns.W.dofmap.index_map_bs == dim + 1 and ns.A.getType().endswith("baij")
    xw = ns.W.tabulate_dof_coordinates()                       # one row per vertex (block)
    xv, xq = ns.V.tabulate_dof_coordinates(), ns.Q.tabulate_dof_coordinates()
    assert np.array_equal(np.sort(ns.V_map), np.sort(np.setdiff1d(np.arange(len(ns.U.x.array)), ns.Q_map)))
    assert np.allclose(xw[ns.V_map.reshape(-1, dim)[:, 0] // (dim + 1)], xv)
    assert np.allclose(xw[ns.Q_map // (dim + 1)], xq)
    assert np.array_equal(ns.V_map.reshape(-1, dim) % (dim + 1), np.tile(np.arange(dim), (len(xv), 1)))
    f = fem.Function(ns.V)
    f.interpolate(lambda x: np.stack([x[i] + 10 * i for i in range(dim)]))
    ns.U.x.array[ns.V_map] = f.x.array
    assert np.allclose(ns.u.x.array, f.x.array)


@pytest.mark.parametrize("retake_tolerance", [None, 1e-3])
def test_a_retaken_linearised_step_resolves_a_change_below_the_krylov_tolerance(retake_tolerance):
    """An implicit coupling's later pass retakes the step with data that differ from the last
    pass's by less than rtol ‖b‖ (here a body force of 1e-10 m/s² in a water-filled lid-driven
    cavity, ‖δb‖ ≈ 8e-9 between the step's atol 1e-10 and rtol ‖b‖ ≈ 1e-7). The
    retaken solve starts from the last pass's update and solves for its correction, so the
    change of (u, p) is the linear response to the change, the same per unit force as for a
    10⁶ × larger force. (Started from the last update under ‖b − A dU‖ ≤ rtol ‖b‖, the solve
    accepted that update untouched: no response.) With the coupling's tolerance 1e-3 the
    correction is solved to 1e-3 of its right-hand side, in fewer iterations, and the response
    agrees to that."""
    from fcm_fsi.fluid import solvers
    from fcm_fsi.simulation.fluid import ns_restore, ns_snapshot
    tm = rectangle(MPI.COMM_WORLD, n=(12, 12))
    walls = tuple(BoundaryCondition(boundary=b, kind="no_slip") for b in ("xmin", "xmax", "ymin"))
    cfg = FluidConfig(density=1000.0, viscosity=10.0, nonlinear="linearised", krylov_start="extrapolated",
                      petsc=dict(solvers.ITERATIVE_2D),
                      boundaries=walls + (BoundaryCondition(boundary="ymax", kind="velocity", value=(1.0, 0.0)),))
    ns = NavierStokes(tm.mesh, cfg, 0.1, facet_tags=tm.facet_tags, boundary_names=tm.names, retaken_steps=True,
                      retake_tolerance=retake_tolerance)
    assert ns.retake_rtol == retake_tolerance
    for _ in range(3):
        ns.step()
    start = ns_snapshot(ns)

    def pass_with_force(fx: float) -> np.ndarray:
        ns_restore(ns, start)
        ns.f.value[:] = (fx, 0.0)
        ns.step()
        return ns.U.x.array.copy()

    first = pass_with_force(0.0)
    first_iterations = ns.history[-1].krylov_iterations     # the step's first solve
    small, large = 1.0e-10, 1.0e-4
    response_small = (pass_with_force(small) - first) / small
    assert ns.history[-1].krylov_iterations > 0
    response_large = (pass_with_force(large) - first) / large
    scale = MPI.COMM_WORLD.allreduce(np.abs(response_large).max(), op=MPI.MAX)
    assert scale > 0.1                                   # the pressure takes up ρ f x
    diff = MPI.COMM_WORLD.allreduce(np.abs(response_small - response_large).max(), op=MPI.MAX)
    assert diff <= 1e-3 * scale, (diff, scale)
    assert first_iterations > 0
    if retake_tolerance is not None:
        assert 0 < ns.history[-1].krylov_iterations < first_iterations


def test_a_retaken_linearised_step_keeps_the_matrix_it_would_assemble_again():
    """A later pass of an implicit coupling changes only data of the right-hand side (here the body
    force): ``step(same_operator=True)`` keeps the matrix assembled for the step and gives the
    flow of a pass that assembles it again, to round-off; a step of another Δt or under new
    Dirichlet conditions assembles anew."""
    from fcm_fsi.fluid import solvers
    from fcm_fsi.simulation.fluid import ns_restore, ns_snapshot
    tm = rectangle(MPI.COMM_WORLD, n=(12, 12))
    walls = tuple(BoundaryCondition(boundary=b, kind="no_slip") for b in ("xmin", "xmax", "ymin"))
    cfg = FluidConfig(density=1000.0, viscosity=10.0, nonlinear="linearised", krylov_start="extrapolated",
                      petsc=dict(solvers.ITERATIVE_2D),
                      boundaries=walls + (BoundaryCondition(boundary="ymax", kind="velocity", value=(1.0, 0.0)),))
    flows, counts = [], []
    for same_operator in (True, False):
        ns = NavierStokes(tm.mesh, cfg, 0.1, facet_tags=tm.facet_tags, boundary_names=tm.names,
                          retaken_steps=True)
        for _ in range(3):
            ns.step()
        start = ns_snapshot(ns)
        assembled = []
        assemble = ns._assemble_jacobian
        ns._assemble_jacobian = lambda assemble=assemble, assembled=assembled: assembled.append(1) or assemble()

        def pass_with_force(fx: float, same: bool, ns=ns, start=start) -> np.ndarray:
            ns_restore(ns, start)
            ns.f.value[:] = (fx, 0.0)
            ns.step(same_operator=same)
            return ns.U.x.array.copy()

        pass_with_force(0.0, False)
        flows.append(pass_with_force(1.0e-3, same_operator))
        counts.append(len(assembled))
        if same_operator:
            ns.dt.value = 0.05                              # another Δt: another matrix
            pass_with_force(1.0e-3, True)
            ns.set_step_bcs(())                             # new conditions: their rows anew
            pass_with_force(1.0e-3, True)
            counts.append(len(assembled))
    assert counts == [1, 3, 2]
    kept, fresh = flows
    scale = MPI.COMM_WORLD.allreduce(np.abs(fresh).max(), op=MPI.MAX)
    assert MPI.COMM_WORLD.allreduce(np.abs(kept - fresh).max(), op=MPI.MAX) <= 1e-13 * scale
