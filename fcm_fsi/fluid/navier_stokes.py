"""Stabilized P1/P1 incompressible Navier–Stokes (SPEC §1, paper eqs 1–10).

Weak form (eq 5) with θ-scheme in time (θ = 1/2: Crank–Nicolson):

    u_θ = θ u + (1 − θ) uⁿ,   a = advecting velocity (u_θ for Newton, frozen for Picard)
    R_M = ρ((u − uⁿ)/Δt + (a·∇)u_θ − f) − ∇·(2μ ε(u_θ)) + ∇p          (strong residual)
    F(u, p; w, q) = ∫ ρ((u − uⁿ)/Δt + (a·∇)u_θ − f)·w + 2μ ε(u_θ):ε(w) − p ∇·w + q ∇·u
                  + Σ_e ∫ (τ_supg (a·∇)w + τ_pspg ∇q/ρ)·R_M            (SUPG + PSPG, eqs 6–7)
                  + Σ_e ∫ τ_cont ρ (∇·w)(∇·u)                          (LSIC, eqs 8–10)
                  + extra terms (e.g. the finite-cover penalty ∫_Γ p̄ (u − ū)·w dΓ)

τ_supg, τ_cont are cell-wise (DG0) coefficients recomputed from the current iterate
before every nonlinear iteration (never differentiated), so the forms are polynomial
and the quadrature degree is set explicitly.
"""
from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
import ufl
from dolfinx import fem
from mpi4py import MPI
from petsc4py import PETSc

from .. import jit
from ..config.fluid import FluidConfig
from ..io.logging import get_logger
from . import solvers
from .boundary import build_bcs
from .krylov_guess import IncrementHistory
from .ns_forms import (
    FormParts,
    backflow_residual,
    cell_size,
    damping_rate,
    damping_residual,
    do_nothing_correction,
    galerkin_residual,
    lsic_residual,
    quadrature_degree,
    supg_pspg_residual,
    tau_expressions,
)
from .strain import StrainProjection
from .tagged_form import TaggedForm

log = get_logger("fluid")


class NonlinearSolveError(RuntimeError):
    """The nonlinear iteration of one time step failed (no convergence or NaN)."""

    def __init__(self, step: int, time: float, residuals: Sequence[float], reason: str) -> None:
        self.step, self.time, self.residuals = step, time, list(residuals)
        hist = ", ".join(f"{r:.3e}" for r in residuals)
        super().__init__(f"Navier–Stokes step {step} (t = {time:.6g} s): {reason}; residual history [{hist}]")


@dataclass
class StepInfo:
    """Outcome of one time step."""

    step: int
    time: float
    iterations: int
    residuals: list[float] = field(default_factory=list)
    krylov_iterations: int = 0
    assembly_seconds: float = 0.0   # τ update, residual and Jacobian assembly (this rank)
    solve_seconds: float = 0.0      # linear solves (this rank)


ExtraTerm = Callable[[FormParts], "ufl.Form"]

CHORD_CONTRACTION = 0.1   # a warm-started step keeps its Jacobian while each Newton step cuts ‖R‖ by this
#: the loosest relative tolerance of a retaken step's correction solve (``retake_tolerance``)
RETAKE_RTOL_MAX = 1e-2


def velocity_pressure_space(mesh) -> fem.FunctionSpace:
    """The P1 (u, p) space as one blocked space: per vertex the gdim velocity components and then
    the pressure, so the system matrix has dense (gdim + 1)² blocks (inserted and, with a
    block matrix, factored and applied block by block)."""
    gdim = mesh.geometry.dim
    return fem.FunctionSpace(mesh, ufl.VectorElement("Lagrange", mesh.ufl_cell(), 1, dim=gdim + 1))


def split_velocity_pressure(U, gdim: int):
    """(u, p) of a function, trial or test function of :func:`velocity_pressure_space`."""
    return ufl.as_vector([U[i] for i in range(gdim)]), U[gdim]


def subspace_maps(W: fem.FunctionSpace, V: fem.FunctionSpace, Q: fem.FunctionSpace) -> tuple[np.ndarray, np.ndarray]:
    """Indices into W's arrays of the P1 velocity space V's and the P1 pressure space Q's dofs
    (ghosts included), paired through the cells: the three spaces share the element layout, so
    the k-th vertex of a cell is the k-th entry of its dof list in each."""
    bs = W.dofmap.index_map_bs
    gdim = bs - 1
    w_nodes, v_nodes, q_nodes = W.dofmap.list.array, V.dofmap.list.array, Q.dofmap.list.array
    n_nodes = V.dofmap.index_map.size_local + V.dofmap.index_map.num_ghosts
    v_to_w = np.empty(n_nodes, dtype=np.int64)
    v_to_w[v_nodes] = w_nodes
    q_to_w = np.empty(Q.dofmap.index_map.size_local + Q.dofmap.index_map.num_ghosts, dtype=np.int64)
    q_to_w[q_nodes] = w_nodes
    V_map = (bs * v_to_w[:, None] + np.arange(gdim)).ravel()
    Q_map = bs * q_to_w + gdim
    return V_map.astype(np.int32), Q_map.astype(np.int32)


class NavierStokes:
    """Monolithic P1/P1 SUPG/PSPG/LSIC Navier–Stokes solver with a θ-scheme (CN by default).

    Parameters
    ----------
    mesh, config: the dolfinx mesh and the ``fluid`` section.
    dt: time step (s); change later with ``ns.dt.value = ...``.
    facet_tags, boundary_names: facet MeshTags and name → tag mapping for ``config.boundaries``.
    rho, mu: density (kg/m³) and dynamic viscosity (Pa s) as UFL expressions or ``fem.Function``s
        (e.g. ρ(φ), μ(φ)); default the constants of ``config``.
    dx: integration measure of the volume terms (e.g. a cut-cell quadrature measure).
    extra_terms: callables ``term(parts) -> ufl.Form`` added to the residual; the Jacobian
        follows by differentiation (e.g. the finite-cover penalty term of eq 5).
    extra_bcs: additional ``fem.DirichletBC`` on the (u, p) space ``ns.W``.
    velocity_functions: boundary name → ``fn(x, t)`` velocity (gdim × n array), replacing
        the configured condition there (e.g. an exact solution).
    petsc_prefix, petsc_options: options prefix of the (u, p) solve and extra options.
    pspg_density: density in the PSPG test function ∇q/ρ (default ``rho``). With a density
        jump inside a cell (two-phase), a cell-wise mean ρ keeps the PSPG term from weighting
        the pressure residual by 1/ρ_gas on the gas side of interface cells.
    cell_viscosity: a cell-wise (DG0) viscosity to go with ``pspg_density`` (terms that need
        a coefficient constant per cell, e.g. the cut wall's penalty; default ``mu``).
    static_pressure: a known pressure field Π (e.g. the P2 hydrostatic part of
        :mod:`.hydrostatic`); the unknown is then p' and every term uses p' + Π.
    retaken_steps: the caller takes steps again with the same Δt (an implicit coupling's passes,
        :meth:`warm_start`): a linearised step's Krylov solve keeps its update and the residual it
        left, and a retaken step solves for the correction of that update (:meth:`_krylov_system`).
    retake_tolerance: the relative change of the data (an implicit coupling's wall velocity) below
        which the caller stops taking a step again (``coupling.iteration_tol``): a retaken step's
        correction is solved until its residual is within this fraction of its right-hand side (not
        tighter than the Krylov rtol, not looser than :data:`RETAKE_RTOL_MAX`) and within the Krylov
        rtol of the step's full right-hand side (:meth:`_correction_rtol`); without it, to the
        Krylov rtol of its own right-hand side.
    """

    def __init__(self, mesh, config: FluidConfig, dt: float, *, facet_tags=None,
                 boundary_names: dict[str, int] | None = None, rho=None, mu=None,
                 dx: ufl.Measure | None = None, extra_terms: Sequence[ExtraTerm] = (),
                 extra_bcs: Sequence[fem.DirichletBC] = (),
                 velocity_functions: dict[str, Callable] | None = None, petsc_prefix: str = "ns_",
                 petsc_options: dict | None = None, pspg_density=None, static_pressure=None,
                 cell_viscosity=None, retaken_steps: bool = False, retake_tolerance: float | None = None) -> None:
        self.mesh, self.config, self.comm = mesh, config, mesh.comm
        gdim = mesh.geometry.dim
        self.gdim = gdim
        self.W = velocity_pressure_space(mesh)
        self.V = fem.VectorFunctionSpace(mesh, ("Lagrange", 1))
        self.Q = fem.FunctionSpace(mesh, ("Lagrange", 1))
        self.V_map, self.Q_map = subspace_maps(self.W, self.V, self.Q)
        self.U = fem.Function(self.W, name="U")          # (u, p) at t^{n+1}
        self.U_n = fem.Function(self.W, name="U_n")      # (u, p) at t^n
        self.u_adv = fem.Function(self.V, name="u_adv")  # advecting velocity for τ (and Picard)
        self.u_nm1 = fem.Function(self.V, name="u_nm1")  # velocity at t^{n-1} (strain extrapolation)
        self.dt = fem.Constant(mesh, PETSc.ScalarType(dt))
        self.t, self.step_count = 0.0, 0
        self.theta = fem.Constant(mesh, PETSc.ScalarType(config.theta))   # switched during start-up
        self.facet_tags, self.boundary_names = facet_tags, dict(boundary_names or {})
        self.rho = rho if rho is not None else fem.Constant(mesh, PETSc.ScalarType(config.density))
        self.rho_pspg = pspg_density
        self.mu_cell = cell_viscosity
        self.static_pressure = static_pressure
        self.mu = mu if mu is not None else fem.Constant(mesh, PETSc.ScalarType(config.viscosity))
        g = tuple(config.gravity) + (0.0,) * max(0, gdim - len(config.gravity))
        self.f = fem.Constant(mesh, np.asarray(g[:gdim], dtype=PETSc.ScalarType))
        field_props = isinstance(self.rho, fem.Function) or isinstance(self.mu, fem.Function)
        q = quadrature_degree(config, field_props)
        self.quadrature_degree = q
        self.dx = dx if dx is not None else ufl.Measure("dx", domain=mesh, metadata={"quadrature_degree": q})
        self.h = cell_size(mesh)
        V0 = self.h.function_space
        self.tau_supg = fem.Function(V0, name="tau_supg")
        self.tau_cont = fem.Function(V0, name="tau_cont")

        self._strain = None
        if config.stabilization.viscous_reconstruction:
            u_n, _ = self.split(self.U_n)
            self._strain = StrainProjection(mesh, dx, self.theta, u_n, self.u_nm1)
        self.strain = None if self._strain is None else self._strain.field
        self.parts = self._parts()
        self.residual_ufl = self._residual(extra_terms)
        dU = ufl.TrialFunction(self.W)
        # compiled once; a cut measure's cell tags may change between steps (TaggedForm)
        self._F = TaggedForm(self.residual_ufl)
        self._J = TaggedForm(ufl.derivative(self.residual_ufl, self.U, dU))
        self._tau_exprs = self._tau_interpolation()

        self.bc_set = build_bcs(self, config.boundaries, velocity_functions)
        self._fixed_bcs = self.bc_set.bcs + list(extra_bcs)
        self.bcs: list[fem.DirichletBC] = list(self._fixed_bcs)

        self.b = fem.petsc.create_vector(self.F_form)
        self._bc_gap = self.b.duplicate()
        self.dU = fem.Function(self.W)
        # 3D default: GAMG on the velocity block; on a cut (fictitious-domain) system BoomerAMG,
        # which the cut cases were verified with — GAMG stalled there (submerged_box, 567k tets)
        schur = solvers.SCHUR_AMG if dx is not None else solvers.SCHUR_GAMG
        opts = dict(config.petsc) or dict(solvers.DIRECT_LU if gdim == 2 else schur)
        opts.update(petsc_options or {})
        self.A = fem.petsc.create_matrix(self.J_form, solvers.matrix_type(opts))
        reuse = config.reuse_preconditioner
        # automatic: reuse with a Krylov method (a stale preconditioner only costs iterations),
        # never with a direct solve, where it would turn Newton into a chord iteration
        self.reuse_preconditioner = reuse if reuse is not None else opts.get("ksp_type") != "preonly"
        self.ksp = solvers.make_ksp(self.comm, self.A, petsc_prefix, opts, fields=self.field_index_sets())
        self.history: list[StepInfo] = []
        self.backtracks = 0   # line-search halvings over the run (``_backtrack``)
        self._preconditioner_built: int | None = None   # step whose first solve built the preconditioner
        self._last_krylov = 0                           # Krylov iterations of the last solve
        self._guess: np.ndarray | None = None           # start of the next step's iteration (warm_start)
        # fluid.krylov_start: extrapolated: the linearised step's Krylov solve starts from its update
        # extrapolated from the last steps'
        krylov = opts.get("ksp_type") != "preonly"
        self._krylov = krylov
        self.increments = IncrementHistory() if krylov and config.krylov_start == "extrapolated" else None
        self._correction = None        # (rhs, solution) work vectors of a retaken step's correction solve
        self._leftover = None          # (step, Δt, b − A dU, dU): the step's first solve's residual, the last update
        self.retaken_steps = retaken_steps
        self.retake_rtol = None        # relative tolerance of a retaken step's correction solve
        if retake_tolerance is not None and krylov:
            rtol = self.ksp.getTolerances()[0]
            self.retake_rtol = min(max(retake_tolerance, rtol), RETAKE_RTOL_MAX)
        self._operator_of = None       # (step, Δt) whose coefficients the assembled A holds (linearised step)

    def field_index_sets(self) -> dict[str, PETSc.IS]:
        """Owned global rows of velocity ("u") and pressure ("p") in the monolithic system, for
        ``pc_type: fieldsplit`` (options ``fieldsplit_u_*``, ``fieldsplit_p_*``)."""
        imap, bs = self.W.dofmap.index_map, self.W.dofmap.index_map_bs
        n_owned, first = bs * imap.size_local, bs * imap.local_range[0]
        sets = {}
        for name, dofs in (("u", self.V_map), ("p", self.Q_map)):
            dofs = np.asarray(dofs, dtype=np.int64)
            owned = np.sort(dofs[dofs < n_owned]) + first
            sets[name] = PETSc.IS().createGeneral(owned.astype(PETSc.IntType), comm=self.comm)
        return sets

    # ------------------------------------------------------------------ forms
    @property
    def F_form(self) -> fem.FormMetaClass:
        """The residual form (current for the cut's cell tags)."""
        return self._F.form

    @property
    def J_form(self) -> fem.FormMetaClass:
        """The Jacobian form (current for the cut's cell tags)."""
        return self._J.form

    def _parts(self) -> FormParts:
        u, p = self.split(self.U)
        if self.static_pressure is not None:
            p = p + self.static_pressure
        u_n, _ = self.split(self.U_n)
        w, q = self.split(ufl.TestFunction(self.W))
        u_theta = self.theta * u + (1 - self.theta) * u_n
        a = u_theta if self.config.nonlinear == "newton" else self.u_adv
        return FormParts(u=u, p=p, u_n=u_n, u_theta=u_theta, a=a, w=w, q=q, rho=self.rho, mu=self.mu,
                         f=self.f, dt=self.dt, dx=self.dx, tau_supg=self.tau_supg, tau_cont=self.tau_cont,
                         strain=self.strain, rho_pspg=self.rho_pspg, mu_cell=self.mu_cell,
                         sigma=damping_rate(self.mesh, self.config.damping_zones))

    def _residual(self, extra_terms: Sequence[ExtraTerm]):
        s, st = self.parts, self.config.stabilization
        F = galerkin_residual(s)
        stab = supg_pspg_residual(s, st.supg, st.pspg)
        if stab is not None:
            F = F + stab
        if st.lsic:
            F = F + lsic_residual(s)
        ds_nat = self._natural_measure()
        if ds_nat is not None:
            F = F + do_nothing_correction(s, ds_nat)
            if self.config.backflow > 0:
                F = F + backflow_residual(s, ds_nat, self.config.backflow)
        if s.sigma is not None:
            F = F + damping_residual(s)
        for term in extra_terms:
            F = F + term(s)
        return F

    def _natural_measure(self):
        """ds over the boundaries marked do_nothing in the config (None when there are none)."""
        ids = [self.boundary_names[bc.boundary] for bc in self.config.boundaries
               if bc.kind == "do_nothing" and bc.boundary in self.boundary_names]
        if not ids or self.facet_tags is None:
            return None
        ds = ufl.Measure("ds", domain=self.mesh, subdomain_data=self.facet_tags,
                         metadata={"quadrature_degree": self.quadrature_degree})
        return sum((ds(i) for i in ids[1:]), ds(ids[0]))

    def _tau_interpolation(self):
        V0 = self.h.function_space
        pts = V0.element.interpolation_points()
        ts, tc = tau_expressions(self.u_adv, self.rho, self.mu, self.h, self.dt,
                                 self.config.stabilization.time_term)
        return jit.expression(ts, pts), jit.expression(tc, pts)

    # ------------------------------------------------------------ time stepping
    def split(self, U):
        """(u, p) of a function, trial or test function of ``W`` (UFL)."""
        return split_velocity_pressure(U, self.gdim)

    def velocity_subspace(self, axis: int) -> fem.FunctionSpace:
        """The subspace of W of one velocity component (for Dirichlet conditions)."""
        return self.W.sub(axis)

    @property
    def pressure_subspace(self) -> fem.FunctionSpace:
        """The subspace of W of the pressure (for Dirichlet conditions)."""
        return self.W.sub(self.gdim)

    @property
    def u(self) -> fem.Function:
        """Velocity at the latest time (a copy in ``V``, m/s)."""
        out = fem.Function(self.V)
        out.x.array[:] = self.U.x.array[self.V_map]
        return out

    @property
    def p(self) -> fem.Function:
        """Pressure at the latest time (a copy in ``Q``, Pa)."""
        out = fem.Function(self.Q)
        out.x.array[:] = self.U.x.array[self.Q_map]
        return out

    def set_step_bcs(self, bcs: Sequence[fem.DirichletBC]) -> None:
        """Dirichlet conditions on ``W`` for the coming steps on top of the case's and the
        constructor's (replacing any set before; ``()`` removes them): e.g. the pressure held in
        sealed pockets of a coupled run."""
        self.bcs = list(self._fixed_bcs) + list(bcs)
        self._operator_of = None       # the assembled matrix has the old conditions' rows

    def set_velocity(self, fn: Callable[[np.ndarray], np.ndarray]) -> None:
        """Set the initial velocity u(x) (both U and U_n)."""
        tmp = fem.Function(self.V)
        tmp.interpolate(fn)
        for F in (self.U, self.U_n):
            F.x.array[self.V_map] = tmp.x.array
            F.x.scatter_forward()
        self.u_nm1.x.array[:] = tmp.x.array

    def update_tau(self) -> None:
        """Advecting velocity a, then τ_supg and τ_cont cell-wise (eqs 6–10): a = θ u^k + (1 − θ) uⁿ
        of the current iterate, or for the linearised step the extrapolation (1 + θ)uⁿ − θuⁿ⁻¹,
        which is second order at t^{n+θ} and known before the solve."""
        th = float(self.theta.value)
        if self.config.nonlinear == "linearised":
            self.u_adv.x.array[:] = (1 + th) * self.U_n.x.array[self.V_map] - th * self.u_nm1.x.array
        else:
            self.u_adv.x.array[:] = (th * self.U.x.array[self.V_map] + (1 - th) * self.U_n.x.array[self.V_map])
        self.tau_supg.interpolate(self._tau_exprs[0])
        self.tau_cont.interpolate(self._tau_exprs[1])

    def update_strain(self) -> None:
        """G, the P1 strain of the viscous reconstruction, for this step (:mod:`.strain`)."""
        if self._strain is not None:
            self._strain.update()

    def _assemble_residual(self) -> float:
        with self.b.localForm() as loc:
            loc.set(0.0)
        fem.petsc.assemble_vector(self.b, self.F_form)
        if not self._bcs_hold():      # else the lifting −J (g − U) is zero: skip its second Jacobian pass
            fem.petsc.apply_lifting(self.b, [self.J_form], bcs=[self.bcs], x0=[self.U.vector], scale=-1.0)
        self.b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        fem.petsc.set_bc(self.b, self.bcs, self.U.vector, -1.0)
        return self.b.norm()

    def _impose_dirichlet_values(self) -> None:
        """U takes this step's Dirichlet values g at their dofs before the step's first residual.
        The residual is then assembled where U meets the boundary conditions, so neither it nor the
        Newton updates (zero at those dofs) need the lifting −J (g − U), a second pass over every
        cell's Jacobian kernel. The same U as a Newton update onto g would give, to round-off; with
        inhomogeneous data the update itself lands on g only to round-off, which the lifting's
        exact test (:meth:`_bcs_hold`) does not accept."""
        fem.set_bc(self.U.x.array, self.bcs)

    def _bcs_hold(self) -> bool:
        """Whether U already takes every Dirichlet value g at its dofs (on all ranks)."""
        gap = self._bc_gap
        with gap.localForm() as loc:
            loc.set(0.0)
        fem.petsc.set_bc(gap, self.bcs, self.U.vector, 1.0)     # g − U at the constrained dofs
        return gap.norm(PETSc.NormType.NORM_INFINITY) == 0.0

    def _assemble_jacobian(self) -> None:
        self.A.zeroEntries()
        fem.petsc.assemble_matrix(self.A, self.J_form, bcs=self.bcs)
        self.A.assemble()

    def warm_start(self, guess: np.ndarray) -> None:
        """Start the next step's nonlinear iteration from ``guess`` (this rank's ``U`` array,
        ghosts included) instead of the last step's solution: for a step taken again on nearly
        the same data (the passes of an implicit coupling, ``coupling.iterations``). With a kept
        preconditioner (``reuse_preconditioner``) built at this step number, the retaken step
        keeps it and also the last assembled Jacobian as long as each Newton step cuts ‖R‖ by
        ``CHORD_CONTRACTION`` (chord steps; GMRES solves with that Jacobian). The stopping rule
        is the same as from a cold start: ‖R‖ ≤ rtol × ‖R‖ at uⁿ (assembled once more for it),
        or ≤ atol; a guess that already meets it is accepted without a solve."""
        self._guess = guess

    def step(self, same_operator: bool = False) -> StepInfo:
        """Advance one time step Δt (collective).

        The first ``config.startup_steps`` steps are each made of two backward-Euler half
        steps (Rannacher start-up): they damp the incompatible part of the initial data,
        which Crank–Nicolson alone never damps, without losing second order.

        ``same_operator``: the step is taken again (from the same start, :meth:`warm_start`) with
        every coefficient of the Jacobian as in its last solve — ρ, μ, the cut and the advecting
        velocity, only data of the right-hand side such as the wall velocity changed (an implicit
        coupling's later pass): the linearised step then keeps the assembled matrix, which it would
        assemble again to the bit. Ignored by the Newton step and during the start-up.
        """
        if self.step_count >= self.config.startup_steps or self.config.theta == 1.0:
            return self._advance(same_operator)
        self._guess = None                          # a guess for the whole step fits neither half
        dt, theta = float(self.dt.value), float(self.theta.value)
        self.dt.value, self.theta.value = 0.5 * dt, 1.0
        try:
            first = self._advance()
            second = self._advance()
        finally:
            self.dt.value, self.theta.value = dt, theta
        self.step_count -= 1
        second.step = self.step_count
        second.iterations += first.iterations
        second.residuals = first.residuals + second.residuals
        second.krylov_iterations += first.krylov_iterations
        second.assembly_seconds += first.assembly_seconds
        second.solve_seconds += first.solve_seconds
        self.history[-2:] = [second]
        return second

    def _advance(self, same_operator: bool = False) -> StepInfo:
        """uⁿ ← u, t ← t + Δt, nonlinear solve to rtol/atol (collective); ``same_operator`` as
        in :meth:`step`."""
        self.u_nm1.x.array[:] = self.U_n.x.array[self.V_map]
        self.U_n.x.array[:] = self.U.x.array
        if not self._operator_kept(same_operator, self.step_count + 1):
            self.update_strain()        # (a retaken linearised step: the same uⁿ, uⁿ⁻¹ and cut, the same G)
        self.t += float(self.dt.value)
        self.step_count += 1
        self.bc_set.update(self.t)
        self._impose_dirichlet_values()
        cfg = self.config
        info = StepInfo(self.step_count, self.t, 0)
        r0, guess, self._guess = None, self._guess, None
        warm = guess is not None
        if cfg.nonlinear == "linearised":   # a linear system: a guess changes nothing but the kept preconditioner
            return self._linear_solve(info, warm and self.reuse_preconditioner
                                      and self._preconditioner_built == self.step_count, same_operator)
        if warm:
            t0 = time.perf_counter()
            self.update_tau()
            r0 = self._assemble_residual()          # at the cold start uⁿ: the reference of the stopping rule
            self.U.x.array[:] = guess
            info.assembly_seconds += time.perf_counter() - t0
        keep = warm and self.reuse_preconditioner and self._preconditioner_built == self.step_count
        for it in range(cfg.max_iterations + 1):
            t0 = time.perf_counter()
            tau_before = None
            if not info.residuals or info.residuals[-1] > cfg.tau_freeze * r0:
                if it > 0 and cfg.line_search:
                    tau_before = (self.tau_supg.x.array.copy(), self.tau_cont.x.array.copy())
                self.update_tau()
            r = self._assemble_residual()
            if it > 0:
                r = self._backtrack(r, info.residuals[-1], tau_before)
            info.assembly_seconds += time.perf_counter() - t0
            info.residuals.append(r)
            if not np.isfinite(r):
                raise NonlinearSolveError(self.step_count, self.t, info.residuals, "residual is not finite (NaN/inf)")
            r0 = r if r0 is None else r0
            if r <= cfg.atol or ((it > 0 or warm) and r <= cfg.rtol * r0):
                info.iterations = it
                self.history.append(info)
                return info
            if it == cfg.max_iterations:
                break
            # a warm start on its kept factorisation: the Jacobian too is kept (chord steps) while each
            # step cuts ‖R‖ by CHORD_CONTRACTION; the passes' Jacobians differ only by the small change
            # of the flow between them
            chord = keep and (it == 0 or info.residuals[-1] <= CHORD_CONTRACTION * info.residuals[-2])
            self._update(info, assemble=not chord, reuse=bool(it > 0 or keep))
        raise NonlinearSolveError(self.step_count, self.t, info.residuals,
                                  f"no convergence in {cfg.max_iterations} {cfg.nonlinear} iterations "
                                  f"(rtol {cfg.rtol:g}, atol {cfg.atol:g})")

    def _linear_solve(self, info: StepInfo, keep: bool, same_operator: bool = False) -> StepInfo:
        """The linearised step (``nonlinear: linearised``): the Oseen system with the extrapolated
        advecting velocity and its τ is linear in (u, p), so one Newton update from uⁿ solves it
        exactly; no second residual is assembled. ``same_operator`` (:meth:`step`): the matrix
        assembled for this step and Δt is kept."""
        t0 = time.perf_counter()
        dt = float(self.dt.value)
        kept = self._operator_kept(same_operator, self.step_count)
        if not kept:                    # (kept: τ of the same advecting velocity, ρ and μ)
            self.update_tau()
        r = self._assemble_residual()
        info.assembly_seconds += time.perf_counter() - t0
        info.residuals.append(r)
        if not np.isfinite(r):
            raise NonlinearSolveError(self.step_count, self.t, info.residuals, "residual is not finite (NaN/inf)")
        if r > self.config.atol:
            # taken before with this Δt (an implicit coupling's later pass): the correction of the last update
            retaken = self._leftover is not None and self._leftover[:2] == (self.step_count, dt)
            if retaken:
                start = self._leftover[3]
            else:
                start = None if self.increments is None else self.increments.guess(self.step_count, dt)
            self._update(info, assemble=not kept, reuse=keep, start=start, from_start=retaken)
            self._operator_of = (self.step_count, dt)
            if self.increments is not None:
                self.increments.record(self.step_count, dt, self.dU.x.array)
            if self.retaken_steps and self._krylov:
                self._keep_leftover(dt, retaken)
            info.iterations = 1
        self.history.append(info)
        return info

    def _operator_kept(self, same_operator: bool, step: int) -> bool:
        """Whether step number ``step`` with the current Δt is retaken on the assembled matrix
        (``same_operator`` and the matrix is that step's and Δt's, :meth:`step`)."""
        return same_operator and self._operator_of == (step, float(self.dt.value))

    def _update(self, info: StepInfo, assemble: bool, reuse: bool, start: np.ndarray | None = None,
                from_start: bool = False) -> None:
        """One Newton update U ← U − J⁻¹R on the assembled residual ``self.b``: assemble J unless
        ``assemble`` is False (a chord step), solve with the preconditioner kept when ``reuse``
        (or when an earlier step's is still good), and retry with a fresh one when a kept one
        has gone stale. A Krylov solve starts from ``start`` (an estimate of the update) if given;
        ``from_start``: solve for the start's correction instead (:meth:`_krylov_system`)."""
        t0 = time.perf_counter()
        if assemble:
            self._assemble_jacobian()
        t1 = time.perf_counter()
        rhs, x = self._krylov_system(start, from_start)
        reuse = bool(self.reuse_preconditioner and (reuse or self._preconditioner_still_good()))
        self.ksp.getPC().setReusePreconditioner(reuse)
        if rhs is not None:
            tolerances = self.ksp.getTolerances()
            if x is not self.dU.vector and self.retake_rtol is not None:   # a retaken step's correction
                self.ksp.setTolerances(rtol=self._correction_rtol(rhs, tolerances[0]))
            try:
                solvers.solve(self.ksp, rhs, x)
                if reuse and self.ksp.getConvergedReason() < 0:   # the kept preconditioner has gone stale
                    info.krylov_iterations += self.ksp.getIterationNumber()
                    self.ksp.getPC().setReusePreconditioner(False)
                    solvers.solve(self.ksp, rhs, x)
                    reuse = False
            finally:
                self.ksp.setTolerances(*tolerances)
            self._last_krylov = self.ksp.getIterationNumber()
            solvers.check_converged(self.ksp, self.step_count, self.t, atol=self.config.atol)
            info.krylov_iterations += self.ksp.getIterationNumber()
            if x is not self.dU.vector:
                self.dU.vector.axpy(1.0, x)
        if not reuse:
            self._preconditioner_built = self.step_count
        info.assembly_seconds += t1 - t0
        info.solve_seconds += time.perf_counter() - t1
        self.dU.x.scatter_forward()
        self.U.x.array[:] -= self.dU.x.array

    def _krylov_system(self, start: np.ndarray | None, from_start: bool):
        """The right-hand side and solution vector of the update's Krylov solve.

        By default the system J dU = R itself, started from ``start`` (else zero). Not screened by
        its residual: on the dam break the extrapolated start's ‖b − A dU‖ exceeds ‖b‖ in two thirds
        of the steps, yet the solves need fewer iterations (21.7 per step against 26.1 from zero);
        under the stopping rule ‖b − A dU‖ ≤ rtol ‖b‖ a poor start costs iterations, never accuracy.

        ``from_start`` (the step taken again with the same Δt by a Krylov solver with
        ``retaken_steps``: an implicit coupling's later pass, whose data differ from the last pass's
        in the wall velocity): ``start`` is the last pass's update dU₀; the step's first solve left
        the residual e₀ = b₀ − A₀ dU (:meth:`_keep_leftover`), and the solve is for the correction
        J δ = (R − J dU₀) − e₀, from zero to its tolerance (:meth:`_correction_rtol`, or the Krylov
        rtol of its own right-hand side); dU = dU₀ + δ leaves e₀ and that solve's own error, which
        the next pass's right-hand side contains and corrects. So the passes differ by the response
        of the flow to the change of their data, resolved to that tolerance, and the Krylov error of
        the first pass is the same in every pass. (Started from dU₀ under the rule above, a pass
        whose data differ by less than rtol ‖b‖ accepted dU₀ untouched, and the coupling iterated on
        a flow that did not respond to the wall velocity.) A correction whose right-hand side is
        within the step's ``atol`` or at round-off (1e-12 ‖b‖) is zero: returns (None, None)."""
        if start is None or not from_start:
            if start is not None:
                self.dU.x.array[:] = start
            if self.increments is not None:
                self.ksp.setInitialGuessNonzero(start is not None)
            return self.b, self.dU.vector
        self.dU.x.array[:] = start
        if self._correction is None:
            self._correction = (self.b.duplicate(), self.b.duplicate())
        rhs, x = self._correction
        self.A.mult(self.dU.vector, rhs)
        rhs.aypx(-1.0, self.b)                            # R − J dU₀
        rhs.axpy(-1.0, self._leftover[2])
        if rhs.norm() <= max(self.config.atol, 1e-12 * self.b.norm()):
            return None, None
        self.ksp.setInitialGuessNonzero(False)
        return rhs, x

    def _correction_rtol(self, rhs: PETSc.Vec, rtol: float) -> float:
        """Relative tolerance of a retaken step's correction solve with right-hand side ``rhs``:
        its residual within both ``retake_rtol`` ‖rhs‖ (the response to the change resolved as far
        as the caller resolves the change) and rtol ‖b‖ (the flow as accurate as the step's first
        solve left it, the Krylov ``rtol`` of the full right-hand side b)."""
        r = rhs.norm()
        return min(self.retake_rtol, rtol * self.b.norm() / r) if r > 0 else self.retake_rtol

    def _keep_leftover(self, dt: float, retaken: bool) -> None:
        """Keep the update dU the solve just gave and, after the step's first solve (not
        ``retaken``), the residual b − A dU it left (:meth:`_krylov_system`)."""
        if retaken:
            self._leftover[3][:] = self.dU.x.array
            return
        e = self.b.duplicate() if self._leftover is None else self._leftover[2]
        self.A.mult(self.dU.vector, e)
        e.aypx(-1.0, self.b)
        self._leftover = (self.step_count, dt, e, self.dU.x.array.copy())

    def _preconditioner_still_good(self) -> bool:
        """At a step's first solve: keep the preconditioner of an earlier step when
        ``preconditioner_steps`` > 1, it is younger than that and the last solve needed at most
        ``preconditioner_max_iterations`` Krylov iterations."""
        cfg = self.config
        built = self._preconditioner_built
        return (cfg.preconditioner_steps > 1 and built is not None
                and self.step_count - built < cfg.preconditioner_steps
                and self._last_krylov <= cfg.preconditioner_max_iterations)

    def _backtrack(self, r: float, r_prev: float, tau_before=None) -> float:
        """Backtracking line search on the residual norm: when the full update U ← U − dU did
        not lower ‖R‖, halve it (λ = ½, ¼, …, at most ``line_search`` times) until it does;
        returns ‖R‖ at the accepted λ. The search runs on the residual whose Jacobian gave dU,
        so τ goes back to its values before this iteration's update (``tau_before``), for
        which dU is a descent direction. A full update that lowers ‖R‖ — every iteration of
        a converging Newton solve — is accepted untouched, at no extra cost."""
        if not self.config.line_search or (np.isfinite(r) and r < r_prev):
            return r
        if tau_before is not None:
            self.tau_supg.x.array[:], self.tau_cont.x.array[:] = tau_before
            r = self._assemble_residual()
        lam, n = 1.0, 0
        while (not np.isfinite(r) or r >= r_prev) and n < self.config.line_search:
            lam *= 0.5
            self.U.x.array[:] += lam * self.dU.x.array
            r = self._assemble_residual()
            n += 1
        self.backtracks += n
        return r

    # ---------------------------------------------------------------- helpers
    def boundary_facets(self, name: str) -> np.ndarray:
        """Local facet indices of the named boundary."""
        if self.facet_tags is None or name not in self.boundary_names:
            raise KeyError(f"unknown boundary {name!r}; known: {sorted(self.boundary_names)}")
        return self.facet_tags.find(self.boundary_names[name])

    def force(self, name: str) -> np.ndarray:
        """Force of the fluid on the named boundary (N; N/m in 2D) at the current state, by the
        variational reaction of the momentum residual (``forces.ReactionForce``). Collective."""
        from .forces import ReactionForce
        cache = self.__dict__.setdefault("_reactions", {})
        if name not in cache:
            cache[name] = ReactionForce(self.W, self.F_form, self.boundary_facets(name))
        return cache[name]()

    def divergence_l2(self) -> float:
        """‖∇·u‖_L2 of the current velocity (1/s)."""
        u, _ = self.split(self.U)
        val = fem.assemble_scalar(jit.form(ufl.div(u) ** 2 * self.dx))
        return float(np.sqrt(self.comm.allreduce(val, op=MPI.SUM)))
