"""Two-phase free-surface flow: Navier–Stokes with ρ(φ), μ(φ) and a conservative Allen–Cahn φ.

One time step tⁿ → tⁿ⁺¹ is three named stages (staggered, each second order on its own):

1. **phase field**: φⁿ → φⁿ⁺¹ by :class:`~fcm_fsi.fluid.phase_field.PhaseField` (eq 11, 14–15),
   advected by the extrapolated velocity u* = 3/2 uⁿ − 1/2 uⁿ⁻¹ ≈ uⁿ⁺¹ᐟ², then the optional
   volume correction (eqs 16–17);
2. **properties**: ρ, μ at φⁿ⁺¹ᐟ² = (φⁿ + φⁿ⁺¹)/2 by eqs 12–13 with φ clipped to [0, 1]
   (an over/undershoot of φ must never produce a negative or super-liquid density):
   ρ = ρ_g + (ρ_l − ρ_g) φ̂,  μ = μ_g + (μ_l − μ_g) φ̂,  φ̂ = min(max(φ, 0), 1);
3. **navier-stokes**: uⁿ → uⁿ⁺¹, pⁿ⁺ᶿ by :class:`~fcm_fsi.fluid.navier_stokes.NavierStokes`
   (eq 5, Crank–Nicolson) with those properties and gravity ``fluid.gravity``; the PSPG
   test function uses the cell-mean density, ∇q/ρ̄_K (``pspg_density``): with the pointwise
   ρ the PSPG term weights the pressure–gravity residual of an interface cell by 1/ρ_gas on
   its gas side.

Well-balanced gravity (``fluid.well_balanced``, on by default without blocks): the pressure is
p' + Π with Π the P2 static pressure of :mod:`~fcm_fsi.fluid.hydrostatic`, re-solved whenever ρ
changes. The plain P1 pressure cannot balance ρ(φ)g in the cells where ρ varies, so at rest the
PSPG term leaves a spurious velocity ∝ Δt (≈ 0.5 m/s² · Δt for water/air on the still-water
tank) that excites the tank's seiche; with Π a layered fluid at rest is exact (docs/two-phase.md).

Time-step rule (with ``run.cfl``): Δt = min(dt_max, C·h_min/max|u|) — the Courant number C
measured with the smallest cell h_min (the refined surface band), capped by ``run.dt_max``
(default ``run.dt``), the stated maximum. ``run.cfl_gas`` allows a larger Courant number at the
gas nodes (φ < 0.05): the gas's spurious jets along walls hit by the liquid (docs/two-phase.md,
"Gas Courant number") would otherwise set the step of the whole run.

Diagnostics include the liquid level at the two vertical walls normal to x (``xmin``,
``xmax``) and the wetted length of the bottom (the plane normal to the last axis: ``ymin`` in
2D, ``zmin`` in 3D), each from ∫φ ds over that boundary divided by its extent across the
measured direction (parallel-safe; exact up to the exponentially small profile tails).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import ufl
from dolfinx import fem
from mpi4py import MPI
from petsc4py import PETSc

from .. import jit
from ..config.case import Case
from ..config.fluid import FluidConfig
from ..config.mesh import box_boundary_names
from ..fluid.hydrostatic import StaticPressure, static_pressure_space
from ..fluid.navier_stokes import NavierStokes, NonlinearSolveError
from ..fluid.phase_field import PhaseField, property_map
from ..io.timing import StageTimer
from ..mesh.build import build_mesh, min_cell_size
from ..mesh.channel import tag_box_boundaries
from .fluid import ns_load_state, ns_restore, ns_snapshot, ns_state
from .loop import SimulationDiverged
from .phase_field import phase_field_health

GAS_PHI = 0.05   # velocity nodes with φ below this are gas for run.cfl_gas (the interface's outer tail, ≈ 3ε out)


def phase_field_state(pf) -> tuple:
    """Copies of what a step changes in the PhaseField ``pf``: φ, φⁿ, φⁿ⁻¹, the steps done and the
    outflow (:func:`set_phase_field_state`)."""
    return (pf.phi.x.array.copy(), pf.phi_n.x.array.copy(), pf.phi_nm1.x.array.copy(), pf.steps_done,
            pf.outflow_total)


def set_phase_field_state(pf, state: tuple) -> None:
    """Inverse of :func:`phase_field_state`."""
    phi, phi_n, phi_nm1, pf.steps_done, pf.outflow_total = state
    pf.phi.x.array[:], pf.phi_n.x.array[:], pf.phi_nm1.x.array[:] = phi, phi_n, phi_nm1


def mass_defect_term(rho_rate: fem.Function):
    """The Navier–Stokes term ½ (∂ρ/∂t + ∇·(ρa))·u_θ·w (``fluid.mass_consistent_convection``).

    Testing ρ(∂u/∂t + a·∇u) with u gives d/dt ∫½ρ|u|² − ∫½|u|²(∂ρ/∂t + ∇·(ρa)) (plus boundary
    fluxes): where ρ does not obey the mass equation the convective form is a source of kinetic
    energy. Adding half the mass defect times u cancels it (Guermond & Quartapelle 2000,
    variable-density Temam term); ∂ρ/∂t is the step's (ρ(φⁿ⁺¹) − ρ(φⁿ))/Δt in ``rho_rate``."""
    def term(s):
        defect = rho_rate + ufl.div(s.rho * s.a)
        return 0.5 * defect * ufl.inner(s.u_theta, s.w) * s.dx
    return term


def gamma_velocity_scale(case: Case) -> float:
    """Velocity scale U of the phase-field mobility γ = mobility_factor·U [m/s].

    ``phase_field.reference_velocity`` when given, else the gravity-wave speed √(|g| H)
    of the domain height H (the largest speed a free surface reaches in a tank).
    """
    pf = case.phase_field
    if pf.reference_velocity is not None:
        return pf.reference_velocity
    g = float(np.linalg.norm(case.fluid.gravity))
    height = case.mesh.upper[-1] - case.mesh.lower[-1]
    return max(np.sqrt(g * height), 1e-12)


def interface_cell_size(case: Case, h_min: float) -> float:
    """Cell size h of the interface width ε = width_factor·h [m]: the smallest refine-zone size
    of a gmsh mesh (the surface band; gmsh also makes a few smaller cells at corners, which
    would give an ε the band cannot resolve), else the smallest cell size of the mesh."""
    zones = case.mesh.refine if case.mesh.kind == "gmsh_box" else ()
    return min(z.size for z in zones) if zones else h_min


class TwoPhaseModel:
    """Navier–Stokes + phase field on one mesh; the model protocol of :mod:`.loop`."""

    series_units = {"volume": "m^d", "volume_error": "-", "mass_drift": "-", "u_max": "m/s", "cfl": "-",
                    "level_left": "m", "level_right": "m", "wetted_bottom": "m", "p_bottom": "Pa",
                    "kinetic_energy": "J (J/m in 2D)", "phi_min": "-", "phi_max": "-",
                    "ns_iterations": "-", "pf_iterations": "-"}

    def __init__(self, case: Case, comm: MPI.Comm, case_dir: Path | None = None, *, mesh=None,
                 ns_options: dict | None = None):
        """``mesh`` and ``ns_options`` (extra NavierStokes keywords, e.g. the cut measure and
        wall term of :mod:`.coupled`) let a coupled model reuse this one."""
        self.case = case
        self.mesh = mesh if mesh is not None else build_mesh(case.mesh, comm, case_dir)
        self.gdim = self.mesh.geometry.dim
        tagged = tag_box_boundaries(self.mesh, case.mesh.lower, case.mesh.upper)
        self.h_min = min_cell_size(self.mesh)
        fl: FluidConfig = case.fluid
        S = fem.FunctionSpace(self.mesh, ("Lagrange", 1))
        self.rho = fem.Function(S, name="rho")
        self.mu = fem.Function(S, name="mu")
        self.rho_cell = fem.Function(fem.FunctionSpace(self.mesh, ("DG", 0)), name="rho_cell")
        self.mu_cell = fem.Function(self.rho_cell.function_space, name="mu_cell")
        ns_options = dict(ns_options or {})
        coupled = "extra_terms" in ns_options   # a cut-domain (coupled) run
        self.well_balanced = fl.well_balanced if fl.well_balanced is not None else not coupled
        self.rho_rate = None    # (ρ(φⁿ⁺¹) − ρ(φⁿ))/Δt [kg/(m³ s)] with fluid.mass_consistent_convection
        if fl.mass_consistent_convection:
            self.rho_rate = fem.Function(S, name="rho_rate")
            ns_options["extra_terms"] = list(ns_options.get("extra_terms", ())) + [mass_defect_term(self.rho_rate)]
        if self.well_balanced:
            ns_options["static_pressure"] = fem.Function(static_pressure_space(self.mesh), name="p_static")
        self.ns = NavierStokes(self.mesh, fl, case.run.dt, facet_tags=tagged.facet_tags,
                               boundary_names=tagged.names, rho=self.rho, mu=self.mu,
                               pspg_density=self.rho_cell, cell_viscosity=self.mu_cell, **ns_options)
        self.static = None
        if self.well_balanced:
            gravity = (tuple(fl.gravity) + (0.0,) * 3)[:self.gdim]
            self.static = StaticPressure(self.ns, ns_options["static_pressure"], self.rho, np.array(gravity))
        self.u_adv = fem.Function(self.ns.V, name="u_advect")   # velocity seen by φ
        self._v_to_phi = None   # φ dof at each velocity node (phi_at_velocity_nodes, built on first use)
        self.cut = None         # the cut domain the flow lives on in a coupled run (follow_cut)
        self.h_interface = interface_cell_size(case, self.h_min)
        self.pf = PhaseField(self.mesh, case.phase_field, self.h_interface, self.u_adv,
                             gamma_velocity_scale(case), case.run.dt)
        self.pf.set_initial(case.phase_field.initial)
        self._advective_dofs = None   # DG0 dof of each cell of pf.advective_cells (follow_cut)
        self.update_properties(self.pf.phi.x.array)
        self.u_out = fem.Function(self.ns.V, name="u")
        self.p_out = fem.Function(self.ns.Q, name="p")
        self.output_functions = [self.pf.phi, self.u_out, self.p_out, self.rho]
        self.last_dt = case.run.dt
        self.ns_iterations = self.pf_iterations = 0
        self._taken = None      # ((step, t, Δt), φ state after it, iterations) of the last step taken (advance)
        self._boundary_forms(tagged)
        self.set_output()              # the initial output: the static pressure where there is one

    # ------------------------------------------------------------------ set-up
    def _boundary_forms(self, tagged) -> None:
        """∫φ ds and ∫p ds on the walls, with the divisors that turn them into lengths/means."""
        ds = ufl.Measure("ds", domain=self.mesh, subdomain_data=tagged.facet_tags,
                         metadata={"quadrature_degree": 2})
        p = self.ns.parts.p      # total pressure (p' + Π when well balanced)
        lo, hi = np.array(self.case.mesh.lower), np.array(self.case.mesh.upper)
        one = fem.Constant(self.mesh, PETSc.ScalarType(1.0))
        comm = self.mesh.comm

        def measure(name):
            return comm.allreduce(fem.assemble_scalar(jit.form(one * ds(tagged.names[name]))), op=MPI.SUM)
        vertical = hi[-1] - lo[-1]
        bottom = box_boundary_names(self.gdim)[-2]   # the lower plane of the last (vertical) axis
        self._phi_forms = {"level_left": (jit.form(self.pf.phi * ds(tagged.names["xmin"])), measure("xmin") / vertical),
                           "level_right": (jit.form(self.pf.phi * ds(tagged.names["xmax"])),
                                           measure("xmax") / vertical),
                           "wetted_bottom": (jit.form(self.pf.phi * ds(tagged.names[bottom])),
                                             measure(bottom) / (hi[0] - lo[0]))}
        self._p_bottom = (jit.form(p * ds(tagged.names[bottom])), measure(bottom))
        u, _ = self.ns.split(self.ns.U)
        dx = ufl.Measure("dx", domain=self.mesh, metadata={"quadrature_degree": 3})
        self._kinetic = jit.form(0.5 * self.rho * ufl.inner(u, u) * dx)

    def update_properties(self, phi_values: np.ndarray) -> None:
        """ρ, μ from φ (eqs 12–13, clipped) at the nodes."""
        fl = self.case.fluid
        self.rho.x.array[:] = property_map(phi_values, fl.density, fl.gas_density)
        self.mu.x.array[:] = property_map(phi_values, fl.viscosity, fl.gas_viscosity)
        if self.cut is not None:
            self.cut.fluid_part_density(self.rho, self.rho_cell, *sorted((fl.density, fl.gas_density)))
        else:
            self.rho_cell.interpolate(self.rho)   # cell mean of the P1 ρ (midpoint value)
        # μ and ρ are both affine in the clipped φ, so the cell's μ follows from its ρ̄
        share = (self.rho_cell.x.array - fl.gas_density) / (fl.density - fl.gas_density)
        self.mu_cell.x.array[:] = property_map(share, fl.viscosity, fl.gas_viscosity)
        if self.static is not None:
            self.static.update()

    def follow_cut(self, cut, extra_cells: np.ndarray | None = None) -> None:
        """The flow lives on the fluid part of ``cut`` (a ``fluid.cut_walls.CutDomain``; a coupled
        run calls this after every new cut): φ is transported in advective form on the cells at
        and inside the bodies (and ``extra_cells``, e.g. sealed pockets); φ inside the bodies
        moves with them; the cell density ρ̄ is the mean over each cell's fluid part; the
        phase field's volume is the fluid part's, held at its value at the first call."""
        if self._advective_dofs is None:
            dofmap = self.pf.advective_cells.function_space.dofmap
            self._advective_dofs = dofmap.list.array.reshape(len(cut.geom_cells), -1)[:, 0]
        cells = cut.body_cells if extra_cells is None else cut.body_cells | extra_cells
        self.pf.advective_cells.x.array[self._advective_dofs] = cells
        if self.cut is None:
            self.cut = cut
            self.pf.use_cut(cut)

    # -------------------------------------------------------------- time step
    def advance(self, t: float, dt: float, timer: StageTimer, retake: bool = False) -> None:
        """One step of φ, then of the flow. ``retake``: the step is taken again from the same start
        on the same cut (an implicit coupling's later pass, whose wall velocity alone differs): φ
        moves inside the bodies with their motion at the start of the step
        (``CutDomain.rigid_inside``), so it is the last take's, which is kept, and so are ρ, μ
        and the flow's matrix (``NavierStokes.step``)."""
        ns, pf = self.ns, self.pf
        vm = ns.V_map
        key = (ns.step_count, ns.t, dt)
        kept = self._taken if retake and self._taken is not None and self._taken[0] == key else None
        with timer("phase field"):
            phi_old = pf.phi.x.array.copy()
            if kept is None:
                first = ns.step_count == 0
                u_n = ns.U.x.array[vm]
                self.u_adv.x.array[:] = u_n if first else 1.5 * u_n - 0.5 * ns.U_n.x.array[vm]
                if self.cut is not None:
                    self.cut.rigid_inside(self.u_adv.x.array, self.ns.V)
                self.pf_iterations = pf.advance(dt)
                self._taken = (key, phase_field_state(pf), self.pf_iterations)
            else:
                set_phase_field_state(pf, kept[1])
                self.pf_iterations = kept[2]
            if self.rho_rate is not None:
                fl = self.case.fluid
                self.rho_rate.x.array[:] = (property_map(pf.phi.x.array, fl.density, fl.gas_density)
                                            - property_map(phi_old, fl.density, fl.gas_density)) / dt
        with timer("properties"):
            self.update_properties(0.5 * (phi_old + pf.phi.x.array))
        with timer("navier-stokes"):
            ns.dt.value = dt
            try:
                info = ns.step(same_operator=kept is not None)
            except NonlinearSolveError as err:
                raise SimulationDiverged(str(err)) from err
            self.ns_iterations = info.iterations
        self.set_output()
        self.last_dt = dt

    def speed_max(self, nodes: np.ndarray | None = None) -> float:
        """max |u| [m/s] over the velocity nodes (those where ``nodes`` is True, if given)."""
        u = self.ns.U.x.array[self.ns.V_map].reshape(-1, self.gdim)
        speed = np.sqrt((u ** 2).sum(axis=1))
        local = float((speed if nodes is None else speed[nodes]).max(initial=0.0))
        return self.mesh.comm.allreduce(local, op=MPI.MAX)

    def phi_at_velocity_nodes(self) -> np.ndarray:
        """φ at each velocity node (both spaces are P1 on the same mesh; this rank incl. ghosts)."""
        if self._v_to_phi is None:
            cells_v = self.ns.V.dofmap.list.array.reshape(-1, self.gdim + 1)
            cells_phi = self.pf.V.dofmap.list.array.reshape(-1, self.gdim + 1)
            self._v_to_phi = np.empty(len(self.ns.V_map) // self.gdim, np.int64)
            self._v_to_phi[cells_v.ravel()] = cells_phi.ravel()
        return self.pf.phi.x.array[self._v_to_phi]

    def stable_dt(self, cfl: float, nodes: np.ndarray | None = None) -> float:
        """Δt = C·h_min/max|u| (inf at rest; the loop caps it with run.dt_max). With
        ``run.cfl_gas``: min(C·h_min/max_liquid|u|, C_gas·h_min/max_gas|u|), the liquid being
        the nodes with φ ≥ :data:`GAS_PHI` (interface included). ``nodes``: only these count."""
        cfl_gas = self.case.run.cfl_gas
        if cfl_gas is None:
            umax = self.speed_max(nodes)
            return cfl * self.h_min / umax if umax > 0 else np.inf
        liquid = self.phi_at_velocity_nodes() >= GAS_PHI
        gas = ~liquid
        if nodes is not None:
            liquid, gas = liquid & nodes, gas & nodes
        dt = np.inf
        for courant, umax in ((cfl, self.speed_max(liquid)), (cfl_gas, self.speed_max(gas))):
            if umax > 0:
                dt = min(dt, courant * self.h_min / umax)
        return dt

    # ------------------------------------------------------------ diagnostics
    def diagnostics(self) -> dict[str, float]:
        comm = self.mesh.comm
        pf = self.pf
        volume, _ = pf.volume()
        mass = pf.mass()
        umax = self.speed_max()
        phi = pf.phi.x.array
        diag = {"volume": volume, "volume_error": (volume - pf.volume0) / pf.volume0,
                "mass_drift": (mass - pf.mass0) / pf.mass0, "u_max": umax,
                "cfl": umax * self.last_dt / self.h_min}
        for key, (form, divisor) in self._phi_forms.items():
            diag[key] = comm.allreduce(fem.assemble_scalar(form), op=MPI.SUM) / divisor
        form, length = self._p_bottom
        diag["p_bottom"] = comm.allreduce(fem.assemble_scalar(form), op=MPI.SUM) / length
        diag["kinetic_energy"] = comm.allreduce(fem.assemble_scalar(self._kinetic), op=MPI.SUM)
        diag["phi_min"] = comm.allreduce(float(phi.min(initial=np.inf)), op=MPI.MIN)
        diag["phi_max"] = comm.allreduce(float(phi.max(initial=-np.inf)), op=MPI.MAX)
        diag["ns_iterations"] = float(self.ns_iterations)
        diag["pf_iterations"] = float(self.pf_iterations)
        return diag

    def health(self, diag: dict[str, float]) -> str | None:
        return phase_field_health(diag)

    # ------------------------------------------------------------- checkpoint
    def probe_fields(self) -> dict:
        """The fields probes record (simulation/probes.py): total pressure, velocity, φ."""
        return {"p": self.p_out, "u": self.u_out, "phi": self.pf.phi}

    def halves(self, dt: float) -> bool:
        """Any step may be retaken as two half steps (the loop's retaken steps)."""
        return True

    def snapshot(self) -> tuple:
        """What a step changes (flow, φ with its history and outflow), to take it again."""
        return ns_snapshot(self.ns), self.last_dt, phase_field_state(self.pf)

    def restore(self, snap: tuple) -> None:
        """Inverse of :meth:`snapshot` (ρ, μ from the restored φ)."""
        ns, self.last_dt, phase = snap
        ns_restore(self.ns, ns)
        set_phase_field_state(self.pf, phase)
        self.update_properties(self.pf.phi.x.array)

    def state(self):
        fields, globals_ = self.pf.state()
        ns_fields, ns_globals = ns_state(self.ns, self.gdim)
        fields.update(ns_fields)
        globals_.update(ns_globals)
        globals_["two_phase_scalars"] = np.array([self.ns.t, float(self.ns.step_count)])
        return fields, globals_

    def load_state(self, checkpoint) -> None:
        self.pf.load_state(checkpoint)
        ns_load_state(self.ns, checkpoint)
        ns = self.ns
        t, steps = checkpoint.globals["two_phase_scalars"]
        ns.t, ns.step_count = float(t), int(steps)
        self.update_properties(self.pf.phi.x.array)
        self.set_output()

    def set_output(self) -> None:
        """u and the total pressure p = p' + Π into the output functions."""
        ns = self.ns
        self.u_out.x.array[:] = ns.U.x.array[ns.V_map]
        p = ns.U.x.array[ns.Q_map]
        self.p_out.x.array[:] = p if self.static is None else self.static.total_pressure(p)
