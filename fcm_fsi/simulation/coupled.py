"""Sub-cycled fluid ⇄ DEM coupling on one fixed mesh (SPEC §3 (a)–(f); issue #8).

One fluid step tⁿ → tⁿ⁺¹ (stages as in the timing table):

(a) **cut rebuild**: the level set of the blocks at their poses at tⁿ (``fcm.levelset``),
    the moment-fitted cut weights and the wall velocity ū = v + ω × (x − x_c) of the
    owning block at every node (``fluid.cut_walls.CutDomain.update``);
(b) **fluid**: phase field (two-phase cases) and Navier–Stokes on the cut domain, the
    wall condition the penalty term on ū (explicit in the block motion);
(c) **exchange**: force and torque of the fluid on each block from the wall traction on
    its cut surface (2D fluids: per unit depth × ``coupling.depth``);
(d) **dem sub-steps**: Δt_f/Δt_DEM explicit DEM steps with that load held (or ramped,
    ``coupling.force_mode``), gravity, contacts and cohesive bonds as in a pure DEM run;
(e) the new block velocities become the next step's ū.

The DEM is replicated: every rank runs the same DEM on the same allreduced loads, and the
states are compared by hash every ``coupling.check_every`` steps (plan for larger DEMs:
``coupling/dem_side.py``).

Momentum exchange (issue #8 item 3): ``exchange_error`` compares, per step, the impulse the
DEM integrated over its sub-steps with the momentum the fluid's discrete equations received
from the wall term (the assembled wall residual summed over all velocity dofs, i.e. tested
with the constant unit vectors), relative to the larger of the two. It checks the whole
chain (cell-to-body split, depth scaling, DEM load application) to round-off.

Added mass: the coupling is explicit (staggered), which is unstable once the added mass
of a block exceeds about its own mass (a floating box: m_a ≈ 1.6 m). ``coupling.added_mass``
= C_a raises the DEM inertia of every block by m̃ = C_a ρ̄_b V_b (rotational inertia by
Ĩ = C_a ρ̄_b V_b k_b², k_b the radius of gyration of that shape about each principal axis),
ρ̄_b the mean fluid density on the block's wetted (cut) surface at this step, V_b
the volume of the shape the fluid sees (a block widened by ``coupling.min_thickness`` drags the
fluid of its widened shape along, at its larger lever arms), and adds m̃ a (and Ĩ α) of the previous fluid step to the
load, minus m̃ g so the weight is unchanged:  (m + m̃) aⁿ⁺¹ = F_fluid + m g + m̃ aⁿ. At a converged or steady motion
this is exact; in a transient it lags by one fluid step, O(Δt ȧ). aⁿ is the change, over a fluid step, of
the wall velocity the fluid is given (``coupling.wall_velocity``: end-of-step or mean velocities), since the
fluid's added-mass reaction answers that change: with ``mean``, an impact in the middle of a step shows in
the fluid as two half-changes over two steps, and the end-of-step difference (the whole change in the first
step, none in the second) left ±½ m̃ Δv/Δt uncancelled — a spurious bounce (docs/design-notes.md).
"""
from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import ufl
from dolfinx import fem
from mpi4py import MPI
from petsc4py import PETSc

from ..config.case import Case
from ..config.loader import ConfigError
from ..coupling.added_mass import AddedMassStage
from ..coupling.body_output import BodyOutput
from ..coupling.dem_side import (
    DEMSubcycler,
    fluid_gyration_ratio,
    fluid_thickness,
    fluid_volume_ratio,
    shapes_of_blocks,
)
from ..coupling.fixed_point import accelerator
from ..coupling.hidden_load import HiddenLoad
from ..coupling.sealed_pockets import SealedPockets
from ..coupling.wall_motion import WallMotion
from ..dem.model import build_system
from ..dem.walls import gap_walls
from ..fcm.levelset import FaceDistance, StructureLevelSet
from ..fluid.cut_walls import CutDomain
from ..fluid.navier_stokes import quadrature_degree
from ..fluid.solvers import LinearSolveError
from ..fluid.tagged_form import TaggedForm
from ..io.logging import get_logger
from ..io.timing import StageTimer
from ..mesh.build import build_mesh, cell_sizes
from .loop import SimulationDiverged
from .two_phase import property_map

#: blocks thinner than this × h_min (the smallest cell diameter) in the fluid get a warning
THIN_WALL = 1.25

log = get_logger("coupled")

#: blocks whose pose/velocity/load columns go into series.csv (all blocks: bodies.csv)
SERIES_BLOCKS = 4


class CoupledModel:
    """Fluid (single- or two-phase) on a cut mesh + replicated DEM; model protocol of :mod:`.loop`."""

    # the later passes of an implicit step reuse what the guessed block velocities do not change (the
    # cut, the flow's added mass) and start Newton from the last pass's flow; False computes every pass
    # from scratch (the reference the tests compare with)
    retake_passes = True

    def __init__(self, case: Case, comm: MPI.Comm, case_dir: Path | None = None, out_dir: Path | None = None):
        self.case, self.comm = case, comm
        cp = case.coupling
        self.system = build_system(case.dem)
        st = self.system.state
        shapes = shapes_of_blocks(case.dem, st, cp.min_thickness)     # the blocks as the fluid sees them
        block_faces = None
        if case.mesh.structure_band is not None:     # cells graded away from the blocks' faces
            block_faces = FaceDistance(shapes, st.pos, st.quat)
        self.mesh = build_mesh(case.mesh, comm, case_dir, face_distance=block_faces)
        self.gdim = self.mesh.geometry.dim
        self.system.planar = self.gdim == 2          # a 2D fluid sees the blocks as prisms moving in its plane
        # uncut cells: the Navier–Stokes forms' own rule (exact for their polynomial parts)
        plain_degree = quadrature_degree(case.fluid, field_properties=case.phase_field is not None)
        self.cut = CutDomain(self.mesh, alpha=cp.fictitious_factor, penalty=cp.penalty, wall=cp.wall,
                             extension=cp.cut_extension, slip=cp.wall_slip, plain_degree=plain_degree)
        ns_options = {"dx": self.cut.dx, "extra_terms": [self.cut.penalty_term()]}
        fluid_case = dataclasses.replace(case, fluid=dataclasses.replace(case.fluid, quadrature_degree=self.cut.degree))
        if case.phase_field is not None:
            from .two_phase import TwoPhaseModel
            self.fluid = TwoPhaseModel(fluid_case, comm, case_dir, mesh=self.mesh, ns_options=ns_options)
        else:
            from .fluid import FluidModel
            self.fluid = FluidModel(fluid_case, comm, case_dir, mesh=self.mesh, ns_options=ns_options)
        self.ns = self.fluid.ns
        self.h_min = self.fluid.h_min

        self.dem = DEMSubcycler(self.system)
        self.nb = st.nb
        self.bonds = next((it for it in self.system.interactions if hasattr(it, "broken_bonds")), None)
        self._energy_limit = None                    # health(): set at the first check
        # radius of gyration [m] (rotations enter the iteration residual as ω × it)
        with np.errstate(divide="ignore", invalid="ignore"):
            g = np.sqrt(st.inertia.sum(axis=1) / (2.0 * st.mass))
        self.gyration = np.where(np.isfinite(g) & (g > 0), g, 1.0)
        self.iterations_done, self.iteration_residual = 1, 0.0
        self.depth = 1.0 if self.gdim == 3 else float(cp.depth)
        rho = self.fluid.rho if hasattr(self.fluid, "rho") else fem.Constant(self.mesh, float(case.fluid.density))
        self._rho_field = rho                        # the fluid's density field
        self.added = AddedMassStage(case, self.system, self.cut, rho, self.ns.bc_set.natural_facets, self.gdim,
                                    self.depth, fluid_volume_ratio(case.dem, st, cp.min_thickness, self.gdim),
                                    fluid_gyration_ratio(case.dem, st, cp.min_thickness, self.gdim), out_dir,
                                    comm.rank)
        self.mass0, self.inertia0 = self.added.mass0, self.added.inertia0   # the blocks' own
        h_max = comm.allreduce(float(cell_sizes(self.mesh).max(initial=0.0)), op=MPI.MAX)
        self.band = cp.band if cp.band is not None else 2.0 * h_max
        self.gap = self.h_min if cp.gap_fill is None else float(cp.gap_fill)
        if self.gap >= self.band:
            raise ConfigError(f"key 'coupling.gap_fill' = {self.gap:.4g} m: allowed 0 ≤ gap_fill < the level-set "
                              f"band {self.band:.4g} m (coupling.band, default 2 × the largest cell)")
        self.levelset = StructureLevelSet(shapes, self.nb, self.band,
                                          gap=self.gap,
                                          walls=gap_walls(case.dem, self.gdim))
        self.points = np.zeros((self.cut.nodes.shape[0], 3))
        self.points[:, : self.gdim] = self.cut.nodes[:, : self.gdim]
        self.walls = WallMotion(cp, self.dem, self.bonds, self.levelset, self.points, self.gyration, self.mass0,
                                self.inertia0, self.h_min, self.gdim)
        self.pockets = None                # coupling.vent_pockets / drain_pockets (coupling/sealed_pockets.py)
        self._phi_of_node = None           # phase-field dof at each mesh vertex (built on first use)
        self._plain_levelset = None        # the level set without the fill (vents, hidden pressure)
        self._pass_cut = None              # (node owners, statistics) of the last full cut rebuild
        if self.gap > 0 and (cp.vent_pockets or cp.drain_pockets):
            self._plain_levelset = StructureLevelSet(self.levelset.shapes, self.nb, self.band)
            self.pockets = SealedPockets(case, comm, self.cut, self.ns, self._plain_levelset, self.points,
                                         getattr(self.fluid, "static", None))
        self.hidden = None                 # coupling.hidden_pressure (coupling/hidden_load.py)
        if cp.hidden_pressure != "none":
            if self._plain_levelset is None:
                self._plain_levelset = StructureLevelSet(self.levelset.shapes, self.nb, self.band)
            self.hidden = HiddenLoad(cp.hidden_pressure, self.cut, self._plain_levelset, self.levelset.shapes,
                                     self.nb, self.fluid.p_out.function_space, self.points,
                                     np.asarray(case.fluid.gravity, float), self.h_min, self.depth)
        self.v_of_node = self.cut.node_map(self.ns.V)     # mesh vertex → NS velocity node
        nv = self.ns.V.dofmap.index_map.size_local + self.ns.V.dofmap.index_map.num_ghosts
        self.v_fluid = np.ones(nv, bool)
        self.v_rigid = np.zeros((nv, self.gdim))
        self._advective_dofs = None   # DG0 dof of each cell of the phase field's advective_cells
        if case.phase_field is not None:
            self.fluid.advection_filter = self.rigid_inside
            self.fluid.cell_density = self.fluid_part_density
            dofmap = self.fluid.pf.advective_cells.function_space.dofmap
            self._advective_dofs = dofmap.list.array.reshape(len(self.cut.geom_cells), -1)[:, 0]

        self._wall_form = None
        self.force = np.zeros((self.nb, 3))
        self.torque = np.zeros((self.nb, 3))
        self.exchange_error = 0.0
        self.retried = 0          # steps retaken as two half steps after a failed fluid solve
        self.stats = self.rebuild_cut()
        self._warn_vertices_on_surfaces(case)
        self._warn_thin_blocks(case)
        self.output_functions = list(self.fluid.output_functions) + [self.cut.level_set]
        self.series_units = {**self.fluid.series_units, "cut_cells": "-", "min_cut_fraction": "-",
                             "dem_substeps": "-", "dem_dt_margin": "-", "exchange_error": "-", "retried_steps": "-",
                             "coupling_iterations": "-", "coupling_residual": "-", "pocket_nodes": "-",
                             "vented_nodes": "-", "drained_nodes": "-", "force_x": "N", "force_y": "N", "force_z": "N"}
        for b in range(min(self.nb, SERIES_BLOCKS)):
            for key, unit in (("x", "m"), ("y", "m"), ("z", "m"), ("vx", "m/s"), ("vy", "m/s"), ("vz", "m/s"),
                              ("wx", "rad/s"), ("wy", "rad/s"), ("wz", "rad/s")):
                self.series_units[f"b{b}_{key}"] = unit
        if self.hidden is not None:
            self.series_units.update({f"hidden_force_{c}": "N" for c in "xyz"[: self.gdim]})
            self.series_units.update({"hidden_length": "m"} if self.gdim == 2 else {"hidden_area": "m^2"})
        self._water_forms = None
        if case.phase_field is not None:
            # liquid volume [m^d] in the fluid part and inside the blocks (fitted weights): the
            # phase field is solved on the whole mesh, so water can diffuse into a block
            cf = self.cut.fluid_fraction
            phi = self.fluid.pf.phi
            # and the liquid {φ ≥ ½} inside the blocks (indicator at the quadrature points): the
            # liquid volume of the fluid part is the exact whole-mesh {φ ≥ ½} volume minus it
            liquid = ufl.conditional(ufl.ge(phi, 0.5), 1.0, 0.0)
            self._water_forms = (fem.form(phi * cf * self.cut.dx_q), fem.form(phi * (1 - cf) * self.cut.dx_q),
                                 fem.form(liquid * (1 - cf) * self.cut.dx_q))
            self.series_units.update({"water_fluid_part": "m^d", "water_in_blocks": "m^d",
                                      "water_fluid_error": "-", "liquid_volume_fluid": "m^d",
                                      "liquid_volume_error": "-"})
            self._gauge_half_width = None
            if self.gdim == 2 and self.nb > 0:
                # water level on vertical mesh lines just outside block 0 (left, right): the
                # local waterline for its draft, away from the walls' standing waves
                b0 = case.dem.blocks[0]
                half = 0.5 * b0.size[0] if b0.shape == "box" else b0.radius
                self._gauge_half_width = half + 1.5 * h_max
                self._pf_x = self.fluid.pf.V.tabulate_dof_coordinates()[:, :2]
                self._y_bottom = float(case.mesh.lower[1])
                self.series_units.update({"b0_level_left": "m", "b0_level_right": "m"})
            self.fluid.pf.liquid_inside_bodies = self._liquid_in_blocks
            self.fluid.pf.volume0 = self.fluid.pf.volume()[0]
            self.water0 = self.comm.allreduce(fem.assemble_scalar(self._water_forms[0]), op=MPI.SUM)
            self.liquid0 = self._liquid_volume_fluid()
        if self.bonds is not None:
            self.series_units["broken_bonds"] = "-"
        self.output = BodyOutput(case, self.nb, self.bonds, out_dir, comm.rank)   # bodies.csv, bond breaks, VTP
        log.info("coupled: %d blocks, %d spheres; DEM dt %.4g s; level-set band %.4g m, gap fill %.4g m "
                 "(%d walls); cut cells %d, smallest cut fraction %.2e", self.nb, st.ns, self.system.dt, self.band,
                 self.gap, len(self.levelset.walls), self.stats.cut_cells, self.stats.min_cut_fraction)

    def _stabilised_load(self) -> tuple[np.ndarray, np.ndarray]:
        """The DEM's load (coupling/added_mass.AddedMassStage.load): the fluid's, relaxed, plus
        the lagged added-mass terms on the accelerations the fluid answers — with the flow's
        added mass of bonded clusters, the cluster's rigid acceleration, not the bonds' ringing."""
        st = self.system.state
        accel, alpha = self.added.accel, self.added.alpha
        if self.added.from_flow and self.walls.by_cluster:
            X, A, Al = self.walls.cluster_rigid(st.pos, accel, alpha)
            accel, alpha = A + np.cross(Al, st.pos - X), Al
        return self.added.load(self.force, self.torque, accel, alpha)

    # -------------------------------------------------------------- stages
    def _warn_thin_blocks(self, case: Case) -> None:
        """Warn when a block, as the fluid sees it, is thinner than about two mesh spacings
        (``THIN_WALL`` × the smallest cell diameter h_min; a right triangle of legs h has
        diameter √2 h): a wall one cell thick has no node inside, so the continuous P1 pressure
        cannot jump across it and water passes through (measured: a fixed 2D wall holding a
        0.4 m head leaks at 1 and 1.5 spacings, holds at 2 and more, docs/coupling.md 'Thin walls')."""
        thin = fluid_thickness(case.dem, self.system.state, case.coupling.min_thickness, self.gdim)
        bad = np.flatnonzero(thin < THIN_WALL * self.h_min)
        if bad.size:
            log.warning("%d block(s) are thinner than two cells in the fluid (thinnest %.3g m, smallest cell "
                        "diameter %.3g m; blocks %s): walls thinner than about two cells let water through and "
                        "their loads are spurious (docs/coupling.md, 'Thin walls'); refine the mesh there or raise "
                        "coupling.min_thickness", bad.size, float(thin[bad].min()), self.h_min,
                        ", ".join(map(str, bad[:8])) + (" ..." if bad.size > 8 else ""))

    def _warn_vertices_on_surfaces(self, case: Case) -> None:
        """Warn when interior mesh vertices lie exactly on a block surface (a face on a mesh
        line). The cells on the body side of such a face are cut with no fluid part yet carry
        the whole face; where the free surface runs along it this broke the Newton solve
        (block_overturn at 0.48 s, floating_box; docs/coupling.md). Faces on the mesh boundary
        (a block standing on the floor) are left out: the gap fill handles them."""
        lo, hi = np.array(case.mesh.lower), np.array(case.mesh.upper)
        x = self.points[:, : self.gdim]
        tol = 1e-9 * self.h_min
        interior = np.all((x > lo + tol) & (x < hi - tol), axis=1)
        level = self.cut.level_set.x.array[self.cut.level_dofs]     # at self.points, as last built
        count = self.comm.allreduce(int(np.count_nonzero(interior & (np.abs(level) <= tol))), op=MPI.SUM)
        if count:
            log.warning("%d mesh vertices lie exactly on a block surface (faces on mesh lines): where the free "
                        "surface runs along such a face the fluid solve is known to fail (docs/coupling.md); "
                        "shift the blocks or the mesh by a fraction of a cell", count)

    def rebuild_cut(self, velocities: np.ndarray | None = None, same_poses: bool = False):
        """(a): level set, cut weights and wall velocity from the current block poses; the
        wall velocity from the blocks' current v, ω, or from ``velocities`` (the iterated
        unknown of :meth:`_block_velocities`). ``same_poses``: the blocks stand where the last
        rebuild found them (a later pass of the implicit coupling), so only the wall velocity is
        set again, unless ``drain_pockets`` (the drain also resets the restored flow's pressure)."""
        if same_poses and self._pass_cut is not None and not self.case.coupling.drain_pockets:
            owner, stats = self._pass_cut
            ubar = self.walls.at_nodes(owner, velocities)[0]
            self.v_rigid[self.v_of_node] = ubar
            self.cut.set_wall_velocity(ubar)
            return stats
        st = self.system.state
        level, owner = self.levelset.evaluate(self.points, st.pos, st.quat)
        if self.pockets is not None:
            self.pockets.apply(level, owner, self.levelset, self.walls.fill_free_to_part(owner), st.pos, st.quat,
                               self._node_density)
        ubar, share = self.walls.at_nodes(owner, velocities)
        self.v_fluid[self.v_of_node] = level > 0
        self.v_rigid[self.v_of_node] = ubar
        stats = self.cut.update(level, owner, ubar, share)
        self._pass_cut = (owner, stats)
        if self.hidden is not None:
            self.hidden.rebuild(level, st.pos, st.quat)
        if self._advective_dofs is not None:
            # φ in advective form on the cells at and inside the blocks (phase_field_residual)
            pockets = None if self.pockets is None else self.pockets.cells
            cells = self.cut.body_cells if pockets is None else self.cut.body_cells | pockets
            self.fluid.pf.advective_cells.x.array[self._advective_dofs] = cells
            # the volume correction holds the liquid of the fluid part
            self.fluid.pf.interface_cell_weights = self.cut.fluid_fractions()
        return stats

    def _node_density(self) -> np.ndarray:
        """Fluid density [kg/m³] at the mesh vertices: from φ with a phase field, else the fluid's."""
        fl = self.case.fluid
        if self.case.phase_field is None:
            return np.full(len(self.points), fl.density)
        if self._phi_of_node is None:
            self._phi_of_node = self.cut.node_map(self.fluid.pf.phi.function_space)
        return property_map(self.fluid.pf.phi.x.array[self._phi_of_node], fl.density, fl.gas_density)

    def fluid_part_density(self, rho, rho_cell) -> None:
        """Cell-mean ρ of the PSPG test function over the cell's (weighted) fluid part, not
        its midpoint: a cut cell whose fluid part is air must not take the water carried in
        its fictitious part, nor the reverse."""
        if not hasattr(self, "_rho_forms"):
            v0 = ufl.TestFunction(rho_cell.function_space)
            self._rho_forms = (TaggedForm(rho * v0 * self.cut.dx), TaggedForm(v0 * self.cut.dx))
        num = fem.petsc.assemble_vector(self._rho_forms[0].form)
        den = fem.petsc.assemble_vector(self._rho_forms[1].form)
        # the fitted weights may be negative at some points: keep the mean within the phases'
        # densities (it sets the wall penalty p̄ and the PSPG scaling, which must stay positive)
        fl = self.case.fluid
        lo, hi = sorted((fl.density, fl.gas_density))
        rho_cell.x.array[: len(num.array)] = np.clip(num.array / den.array, lo, hi)
        rho_cell.x.scatter_forward()
        num.destroy(), den.destroy()

    def rigid_inside(self, u_adv: np.ndarray) -> None:
        """The phase field inside the blocks moves with them: u_adv = ū at the velocity nodes
        inside (level set < 0), not the fictitious flow there."""
        u = u_adv.reshape(-1, self.gdim)
        u[~self.v_fluid] = self.v_rigid[~self.v_fluid]

    def fluid_speed_max(self) -> float:
        """max |u| over the velocity nodes in the fluid (level set > 0) [m/s]: the
        fictitious flow inside the blocks limits neither the CFL step nor the report."""
        u = self.ns.U.x.array[self.ns.V_map].reshape(-1, self.gdim)[self.v_fluid]
        local = float(np.sqrt((u ** 2).sum(axis=1)).max(initial=0.0))
        return self.comm.allreduce(local, op=MPI.MAX)

    def _wall_momentum(self) -> np.ndarray:
        """Momentum per unit time the fluid's equations receive from the wall term: the
        assembled wall residual summed over the velocity dofs of each component (N)."""
        if self._wall_form is None:
            term = self.cut.penalty_term()(self.ns.parts)
            self._wall_form = TaggedForm(term)
        vec = fem.petsc.assemble_vector(self._wall_form.form)
        vec.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        owned = self.ns.V.dofmap.index_map.size_local
        w_dofs = np.asarray(self.ns.V_map).reshape(-1, self.gdim)[:owned]
        out = np.zeros(3)
        out[: self.gdim] = vec.array[w_dofs].sum(axis=0)
        vec.destroy()
        return -self.comm.allreduce(out, op=MPI.SUM) * self.depth

    def advance(self, t: float, dt: float, timer: StageTimer, retries: int = 2) -> None:
        """One coupled step; when its fluid solve fails, the step is restored and retaken as two
        half steps (at most ``retries`` halvings, then the failure stops the run)."""
        snap = self._snapshot()
        try:
            self._advance(t, dt, timer)
        except (SimulationDiverged, LinearSolveError, FloatingPointError) as err:
            n_sub = dt / self.case.dem.dt
            if retries == 0 or n_sub < 2 - 1e-9 or abs(n_sub / 2 - round(n_sub / 2)) > 1e-9:
                raise
            log.warning("t = %.6g s: %s — retrying as two steps of %.4g s", t, str(err).split(";")[0], dt / 2)
            self._restore(snap)
            self.retried += 1
            self.advance(t, dt / 2, timer, retries - 1)
            self.advance(t + dt / 2, dt / 2, timer, retries - 1)

    def _snapshot(self) -> dict:
        """Everything one step changes, as local copies (ghosts included)."""
        ns = self.ns
        snap = {"ns": (ns.U.x.array.copy(), ns.U_n.x.array.copy(), ns.u_nm1.x.array.copy(), ns.t, ns.step_count,
                       len(ns.history)),
                "dem": self.dem_arrays(),
                "coupling": (getattr(self, "_prev_exchange", None), self.fluid.last_dt)}
        if hasattr(self.fluid, "pf"):
            pf = self.fluid.pf
            snap["pf"] = (pf.phi.x.array.copy(), pf.phi_n.x.array.copy(), pf.phi_nm1.x.array.copy(),
                          pf.steps_done, pf.outflow_total)
        return snap

    def _restore(self, snap: dict) -> None:
        ns = self.ns
        U, U_n, u_nm1, ns.t, ns.step_count, nhist = snap["ns"]
        ns.U.x.array[:], ns.U_n.x.array[:], ns.u_nm1.x.array[:] = U, U_n, u_nm1
        del ns.history[nhist:]
        self.load_dem_arrays(snap["dem"])
        prev, self.fluid.last_dt = snap["coupling"]
        if prev is not None:
            self._prev_exchange = prev
        if "pf" in snap:
            pf = self.fluid.pf
            phi, phi_n, phi_nm1, pf.steps_done, pf.outflow_total = snap["pf"]
            pf.phi.x.array[:], pf.phi_n.x.array[:], pf.phi_nm1.x.array[:] = phi, phi_n, phi_nm1
            self.fluid.update_properties(phi)

    def _advance(self, t: float, dt: float, timer: StageTimer) -> None:
        """One step; with ``coupling.iterations`` > 1 a fixed-point iteration on the block
        velocities at tⁿ⁺¹ (wall velocity ū of the fluid ⇄ result of the DEM sub-steps),
        updated between passes as ``coupling.iteration_method`` says (coupling/fixed_point.py),
        every pass from the same start state (fluid, phase field, DEM); a later pass keeps the
        first's cut and flow added mass and starts Newton from the last pass's flow
        (``retake_passes``, ``NavierStokes.warm_start``)."""
        cp = self.case.coupling
        st = self.system.state
        if cp.iterations == 1:
            with timer("cut rebuild"):
                self.stats = self.rebuild_cut()
            F, fluid_side = self._fluid_then_dem(t, dt, timer)
        else:
            start = self._snapshot()
            guess = self._block_velocities()
            fixed_point = accelerator(cp.iteration_method, cp.iteration_relaxation)
            for k in range(cp.iterations):
                retake = k > 0 and self.retake_passes
                if k:
                    last = self.ns.U.x.array.copy()
                    self._restore(start)
                if retake:
                    # a later pass differs from the last only in the wall velocity: its flow starts this
                    # pass's Newton iteration (on the kept factorisation), and the poses, so the cut, are
                    # the last pass's (φ is not: inside the blocks it moves with the wall velocity)
                    self.ns.warm_start(last)
                with timer("cut rebuild"):
                    self.stats = self.rebuild_cut(velocities=guess, same_poses=retake)
                F, fluid_side = self._fluid_then_dem(t, dt, timer, retake=retake)
                if not (np.isfinite(st.pos).all() and np.isfinite(st.vel).all()):
                    self._check_dem(t + dt)              # a diverged pass stops the run, naming the block
                result = self._block_velocities()
                r = result - guess
                scale = max(float(np.abs(result).max(initial=0.0)), cp.iteration_velocity)
                self.iteration_residual = float(np.abs(r).max(initial=0.0)) / scale
                self.iterations_done = k + 1
                if self.iteration_residual <= cp.iteration_tol:
                    break
                guess = fixed_point.next_guess(guess, result)
            else:
                log.debug("t = %.6g s: coupling iteration not converged after %d passes (residual %.2e)",
                          t, cp.iterations, self.iteration_residual)
        # coupling.hidden_pressure: the hidden-surface load is not the fluid's (its reaction is the floor's)
        # and the fill's surface load (the fluid's) is not the block's: the check compares the fluid's own
        fluid_load = self.force if self.hidden is None else \
            self.force - self.hidden.surface_force + self.hidden.cut_force
        self.exchange_error = self._exchange_error(dt, F - fluid_load, fluid_side)
        self._check_dem(t + dt)
        if self.ns.step_count % self.case.coupling.check_every == 0:
            self.dem.check_replicated(self.comm)
        self.output.step(t + dt, self.system.state, self.force, self.torque)

    def _fluid_then_dem(self, t: float, dt: float, timer: StageTimer, retake: bool = False):
        """Fluid step on the current cut, the exchange, and the DEM sub-steps; returns the
        load the DEM got and the momentum the fluid received from the wall term. ``retake``: a
        later pass of the step (same poses and bonds: the flow's added mass is the first
        pass's)."""
        st = self.system.state
        self.fluid.advance(t, dt, timer)
        with timer("exchange"):
            centres = st.pos[:, : self.gdim] if self.gdim == 2 else st.pos
            force, torque = self.cut.body_forces(self.nb, centres)
            self.force[:] = 0.0
            self.force[:, : self.gdim] = force * self.depth
            self.torque[:] = torque * self.depth
            if self.hidden is not None:
                self._hidden_load(centres)
            fluid_side = self._wall_momentum()
            labels = self.walls.cluster_labels() if self.added.from_flow else None   # the flow's groups only
            self.added.update(self.ns.t, labels, same_poses=retake)
        with timer("dem sub-steps"):
            # the last step before t_end may be a fraction of run.dt: take whole DEM steps no
            # longer than dem.dt that fill it exactly
            n_sub = int(np.ceil(dt / self.case.dem.dt * (1 - 1e-9)))
            self.system.dt = dt / n_sub
            mean = self.case.coupling.wall_velocity == "mean"
            _, v0, w0 = (a.copy() for a in self.dem.motion(mean=mean))
            F, T = self._stabilised_load()
            try:
                self.dem.advance(dt, F, T, self.case.coupling.force_mode)
            finally:
                self.system.dt = self.case.dem.dt
            # the change of the wall velocity the fluid gets next step against the one it got
            # this step: what the fluid's added-mass reaction answers, so m̃ aⁿ cancels it
            _, v1, w1 = self.dem.motion(mean=mean)
            self.added.record(v0, w0, v1, w1, dt)
        return F, fluid_side

    def _hidden_load(self, centres: np.ndarray) -> None:
        """``coupling.hidden_pressure``: the block's load becomes the fluid's on Γ minus the
        static pressure's on Γ plus the static pressure's on the true surface (coupling/hidden_load.py)."""
        st = self.system.state
        density = self.case.fluid.density if self.case.phase_field is None else self._node_density()
        h = self.hidden
        h.exchange(self.fluid.p_out, density, st.pos, st.rotation_matrices(), centres)
        self.force += h.surface_force - h.cut_force
        self.torque += h.surface_torque - h.cut_torque
        if h.unreached:
            log.debug("hidden pressure: %d block(s) hidden all round (no wetted mouth): no hidden load", h.unreached)

    def _block_velocities(self) -> np.ndarray:
        """The iterated unknown [m/s], flattened: per block the V and Ω × radius of gyration of
        the rigid motion its wall nodes get (coupling/wall_motion.WallMotion.motion: with ``wall_velocity: mean``
        the sub-steps' mean, with ``wall_motion: bonded_cluster`` its cluster's motion).

        Why not the end-of-step v, ω: the fluid never sees them in those modes, so iterating on
        them fed the fluid a velocity the explicit step does not (the end-of-step one) and
        measured the bonds' ringing, which no pass can converge (in the tsunami case with σ_c/4
        every step took the 6 passes allowed, residual 1e-4…3e-2)."""
        _, V, W = self.walls.motion()
        return np.concatenate([V, W * self.gyration[:, None]]).ravel()

    def _exchange_error(self, dt: float, stabilisation: np.ndarray, fluid_side: np.ndarray) -> float:
        """|fluid impulse the DEM integrated + momentum the fluid received| / scale, the
        added-mass stabilisation taken out; the linear force mode compares trapezoids."""
        ex = self.dem.last
        linear = self.case.coupling.force_mode == "linear"
        prev_stab, prev_fluid = getattr(self, "_prev_exchange", (np.zeros_like(stabilisation), fluid_side))
        stab = 0.5 * (prev_stab + stabilisation) if linear else stabilisation
        fluid = 0.5 * (prev_fluid + fluid_side) if linear else fluid_side
        self._prev_exchange = (stabilisation.copy(), fluid_side.copy())
        dem_side = (ex.impulse - dt * stab).sum(axis=0) / dt
        scale = max(np.abs(dem_side).max(), np.abs(fluid).max(), 1e-300)
        return float(np.abs(dem_side + fluid).max() / scale)

    def _check_dem(self, t: float) -> None:
        """Stop with the body, its load and velocity when the DEM state is not finite or a
        block moved more than a band width in one fluid step (the cut could not follow)."""
        st = self.system.state
        speed = np.linalg.norm(st.vel, axis=1)
        bad = ~np.isfinite(st.pos).all(axis=1) | ~np.isfinite(st.vel).all(axis=1)
        fast = speed * self.fluid.last_dt > self.band
        for b in np.flatnonzero(bad | fast):
            raise SimulationDiverged(
                f"t = {t:.6g} s: block {b} {'is not finite' if bad[b] else 'moved more than the level-set band'}"
                f": fluid force {np.array2string(self.force[b], precision=4)} N, velocity "
                f"{np.array2string(st.vel[b], precision=4)} m/s, DEM dt/Δt_cr {self.dem.last.dt_over_dt_cr:.3f}, "
                f"fluid dt {self.fluid.last_dt:.4g} s (band {self.band:.4g} m)")

    # ------------------------------------------------------- loop protocol
    @property
    def last_dt(self) -> float:
        return self.fluid.last_dt

    def stable_dt(self, cfl: float) -> float:
        """The fluid's CFL step (over the fluid nodes; with run.cfl_gas as in
        :meth:`TwoPhaseModel.stable_dt`), also limited so no block moves more than ¼ of the band,
        rounded down to a whole number of DEM steps."""
        st = self.system.state
        vmax = float(np.linalg.norm(st.vel, axis=1).max(initial=0.0))
        if self.case.run.cfl_gas is not None:      # two-phase: a looser Courant number in the gas
            dt = self.fluid.stable_dt(cfl, self.v_fluid)
        else:
            umax = self.fluid_speed_max()
            dt = cfl * self.h_min / umax if umax > 0 else np.inf
        if vmax > 0:
            dt = min(dt, 0.25 * self.band / vmax)
        dem_dt = self.case.dem.dt
        return max(np.floor(dt / dem_dt * (1 + 1e-9)), 1.0) * dem_dt if np.isfinite(dt) else dt

    def diagnostics(self) -> dict[str, float]:
        diag = self.fluid.diagnostics()
        umax = self.fluid_speed_max()
        diag["u_max"], diag["cfl"] = umax, umax * self.last_dt / self.h_min
        st = self.system.state
        ex = self.dem.last
        diag.update({"cut_cells": float(self.stats.cut_cells), "min_cut_fraction": self.stats.min_cut_fraction,
                     "dem_substeps": float(ex.n_sub if ex else 0), "dem_dt_margin": float(ex.dt_over_dt_cr if ex else 0),
                     "exchange_error": self.exchange_error, "retried_steps": float(self.retried),
                     "coupling_iterations": float(self.iterations_done),
                     "coupling_residual": self.iteration_residual,
                     **(self.pockets.counts() if self.pockets else
                        {"pocket_nodes": 0.0, "vented_nodes": 0.0, "drained_nodes": 0.0})})
        if self.hidden is not None:
            diag.update({f"hidden_force_{c}": float(self.hidden.surface_force[:, k].sum())
                         for k, c in enumerate("xyz"[: self.gdim])})
            diag["hidden_length" if self.gdim == 2 else "hidden_area"] = float(self.hidden.hidden_measure.sum())
        total = self.force.sum(axis=0)
        diag.update({"force_x": total[0], "force_y": total[1], "force_z": total[2]})
        for b in range(min(self.nb, SERIES_BLOCKS)):
            for k, key in enumerate("xyz"):
                diag[f"b{b}_{key}"] = st.pos[b, k]
                diag[f"b{b}_v{key}"] = st.vel[b, k]
                diag[f"b{b}_w{key}"] = st.omega[b, k]
        if self._water_forms is not None:
            wf, wb = (self.comm.allreduce(fem.assemble_scalar(f), op=MPI.SUM) for f in self._water_forms[:2])
            lv = self._liquid_volume_fluid()
            diag.update({"water_fluid_part": wf, "water_in_blocks": wb,
                         "water_fluid_error": (wf - self.water0) / self.water0,
                         "liquid_volume_fluid": lv, "liquid_volume_error": (lv - self.liquid0) / self.liquid0})
            if self._gauge_half_width is not None:
                x0 = st.pos[0, 0]
                diag["b0_level_left"] = self.water_level_at(x0 - self._gauge_half_width)
                diag["b0_level_right"] = self.water_level_at(x0 + self._gauge_half_width)
        if self.bonds is not None:
            diag["broken_bonds"] = float(np.count_nonzero(self.bonds.broken_bonds()))
        return diag

    def water_level_at(self, x_target: float) -> float:
        """Water level [m] on the vertical line of P1 nodes nearest to ``x_target`` (2D):
        bottom + ∫φ dy along it (trapezoid over the nodes; collective)."""
        x = self._pf_x
        n = self.fluid.pf.V.dofmap.index_map.size_local
        d = np.abs(x[:n, 0] - x_target)
        i = int(np.argmin(d)) if n else -1
        cands = self.comm.allgather((float(d[i]), float(x[i, 0])) if n else (np.inf, np.nan))
        x_line = min(cands)[1]
        on = np.abs(x[:n, 0] - x_line) <= 1e-9 * max(1.0, abs(x_line))
        pts = np.concatenate(self.comm.allgather(np.c_[x[:n][on, 1], self.fluid.pf.phi.x.array[:n][on]]))
        pts = pts[np.argsort(pts[:, 0])]
        return self._y_bottom + float(np.sum(0.5 * (pts[1:, 1] + pts[:-1, 1]) * np.diff(pts[:, 0])))

    def _liquid_volume_fluid(self) -> float:
        """|{φ ≥ ½}| of the fluid part [m^d], the volume the correction holds: the exact
        whole-mesh volume minus :meth:`_liquid_in_blocks` (collective)."""
        return self.fluid.pf.volume()[0]

    def _liquid_in_blocks(self) -> float:
        """|{φ ≥ ½}| inside the blocks [m^d]: the indicator at the cut quadrature points
        weighted by the solid fraction (collective)."""
        return self.comm.allreduce(fem.assemble_scalar(self._water_forms[2]), op=MPI.SUM)

    def health(self, diag: dict[str, float]) -> str | None:
        """The fluid's checks, then the energy bound (:meth:`_energy_bound`)."""
        problem = self.fluid.health(diag)
        if problem is None and "kinetic_energy" in diag:
            if self._energy_limit is None:
                self._energy_limit = self._energy_bound(diag["kinetic_energy"])
            total = diag["kinetic_energy"] + self._block_kinetic_energy()
            if self._energy_limit is not None and total > self._energy_limit:
                unit = "J" if self.gdim == 3 else "J/m"
                problem = (f"kinetic energy of fluid and blocks {total:.4g} {unit} exceeds all the energy the system "
                           f"has, {self._energy_limit:.4g} {unit} (kinetic energy at the start + g × its mass × the "
                           "domain's height): the coupling has diverged")
        return problem

    def _block_kinetic_energy(self) -> float:
        """Kinetic energy of the blocks [J; per unit depth in 2D, like the fluid's]."""
        st = self.system.state
        R = st.rotation_matrices()
        w_body = np.einsum("bji,bj->bi", R, st.omega)
        e = 0.5 * (self.mass0 * (st.vel ** 2).sum(axis=1) + (self.inertia0 * w_body ** 2).sum(axis=1))
        return float(e[~st.fixed].sum()) / self.depth

    def _energy_bound(self, fluid_kinetic: float) -> float | None:
        """An upper bound of the kinetic energy of fluid and blocks: what they have now plus g ×
        their mass × the mesh's height along g (nothing can fall further). Without inflow
        boundaries no energy enters (slip, no-slip and do-nothing walls; damping zones only
        take it out), so exceeding it means the run has diverged — the check that stops a run
        whose loads and speeds have run away while φ and the block steps stay in range
        (docs/coupling.md). None (no check) with inflow boundaries."""
        fl = self.case.fluid
        if any(bc.kind in ("velocity", "parabolic_inflow") for bc in fl.boundaries):
            return None
        g = np.asarray(fl.gravity, float)
        gn = float(np.linalg.norm(g))
        x = self.mesh.geometry.x[:, : self.gdim]
        along = x @ (g / gn) if gn > 0 else np.zeros(len(x))
        lo = self.comm.allreduce(float(along.min(initial=np.inf)), op=MPI.MIN)
        hi = self.comm.allreduce(float(along.max(initial=-np.inf)), op=MPI.MAX)
        rho = self._rho_field
        mass = self.comm.allreduce(fem.assemble_scalar(fem.form(rho * ufl.dx(domain=self.mesh))), op=MPI.SUM)
        moving = ~self.system.state.fixed
        mass += float(self.mass0[moving].sum()) / self.depth
        return fluid_kinetic + self._block_kinetic_energy() + gn * mass * (hi - lo)

    def dem_arrays(self) -> dict[str, np.ndarray]:
        """Copies of everything the DEM side carries between steps (state, contact histories,
        bonds, ledger, the last accelerations), by flat names: checkpoint globals and the
        retry snapshot."""
        st = self.system.state
        out = {f"dem__{name}": a.copy() for name, a in st.arrays().items()}
        out["dem__time"] = np.array([st.t, float(st.step)])
        for k, it in enumerate(self.system.interactions):
            if hasattr(it, "checkpoint_arrays"):
                for name, a in it.checkpoint_arrays().items():
                    out[f"dem_int{k}__{name}"] = np.copy(a)
        out.update(self.added.arrays())
        if self.dem.mean_velocity is not None:
            out["coupling__mean_velocity"] = np.concatenate([self.dem.mean_velocity, self.dem.mean_omega])
        if self.system.ledger is not None:
            out["dem__ledger"] = np.copy(self.system.ledger.checkpoint_arrays()["ledger"])
        return out

    def load_dem_arrays(self, g: dict[str, np.ndarray]) -> None:
        """Inverse of :meth:`dem_arrays`."""
        st = self.system.state
        for name, a in st.arrays().items():
            a[...] = g[f"dem__{name}"]
        st.t, st.step = float(g["dem__time"][0]), int(g["dem__time"][1])
        self.added.load_arrays(g)
        if "coupling__mean_velocity" in g:
            m = g["coupling__mean_velocity"]
            self.dem.mean_velocity, self.dem.mean_omega = m[: self.nb].copy(), m[self.nb:].copy()
        for k, it in enumerate(self.system.interactions):
            if hasattr(it, "restore"):
                prefix = f"dem_int{k}__"
                it.restore({n[len(prefix):]: np.copy(a) for n, a in g.items() if n.startswith(prefix)})
        if self.system.ledger is not None and "dem__ledger" in g:
            self.system.ledger.restore({"ledger": np.copy(g["dem__ledger"])})

    def state(self):
        fields, globals_ = self.fluid.state()
        globals_.update(self.dem_arrays())
        return fields, globals_

    def write_output(self, t: float) -> None:
        """The blocks at a field output (coupling/body_output.py)."""
        self.output.fields(t, self.system.state)

    def load_state(self, checkpoint) -> None:
        self.fluid.load_state(checkpoint)
        self.load_dem_arrays(checkpoint.globals)
        self.output.resume(checkpoint.time)                # continue the earlier run's files
        self.added.resume(checkpoint.time)
        self.stats = self.rebuild_cut()

