"""Sub-cycled fluid ⇄ DEM coupling on one fixed mesh (SPEC §3 (a)–(f); issue #8).

One fluid step tⁿ → tⁿ⁺¹ runs the stages of ``fcm_fsi.coupling`` in order (the names of the
timing table in brackets):

(a) [cut rebuild] ``CutStage``: the level set of the blocks at their poses at tⁿ, the
    moment-fitted cut weights and the wall velocity ū = v + ω × (x − x_c) of the owning
    block at every node;
(b) [phase field, navier-stokes] the fluid (two-phase or single-phase) on the cut domain, the
    wall condition the penalty term on ū (explicit in the block motion);
(c) [exchange] ``ExchangeStage``: force and torque of the fluid on each block from the wall
    traction on its cut surface (2D fluids: per unit depth × ``coupling.depth``), the static
    load moved to the true surfaces, the added-mass stabilisation;
(d) [dem sub-steps] ``DEMSubcycler``: whole DEM steps filling Δt_f with that load held (or
    ramped, ``coupling.force_mode``), gravity, contacts and cohesive bonds as in a pure DEM
    run; the new block velocities become the next step's ū;
(e) the exchange check, the blocks' check (finite, moved less than the band), the body output;
(f) [diagnostics] ``CoupledDiagnostics``: the series row and the health check.

With ``coupling.iterations`` > 1 ``ImplicitIteration`` repeats (a)–(d) from the step's
snapshot on the guessed block velocities at tⁿ⁺¹ until they agree with the DEM's.

The DEM is replicated: every rank runs the same DEM on the same allreduced loads, and the
states are compared by hash every ``coupling.check_every`` steps (coupling/dem_side.py).

Added mass: the coupling is explicit (staggered), which is unstable once the added mass
of a block exceeds about its own mass (a floating box: m_a ≈ 1.6 m). ``coupling.added_mass``
= C_a raises the DEM inertia of every block by m̃ = C_a ρ̄_b V_b (coupling/added_mass.py) and
adds m̃ a of the previous fluid step to the load, minus m̃ g so the weight is unchanged:
(m + m̃) aⁿ⁺¹ = F_fluid + m g + m̃ aⁿ. At a converged or steady motion this is exact; in a
transient it lags by one fluid step, O(Δt ȧ).
"""
from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
from dolfinx import fem
from mpi4py import MPI

from ..config.case import Case
from ..coupling.added_mass import AddedMassStage
from ..coupling.body_output import BodyOutput
from ..coupling.cut_stage import CutStage
from ..coupling.dem_side import (
    DEMSubcycler,
    fluid_gyration_ratio,
    fluid_thickness,
    fluid_volume_ratio,
    shapes_of_blocks,
)
from ..coupling.diagnostics import CoupledDiagnostics
from ..coupling.exchange import ExchangeStage
from ..coupling.implicit import ImplicitIteration, StepSnapshot, dem_arrays, load_dem_arrays
from ..coupling.unresolved import UnresolvedBlocks
from ..dem.model import build_system
from ..fcm.levelset import FaceDistance, StructureLevelSet
from ..fluid.cut_walls import CutDomain
from ..fluid.ns_forms import quadrature_degree
from ..io.logging import get_logger
from ..io.timing import StageTimer
from ..mesh.build import build_mesh, cell_sizes
from .loop import SimulationDiverged

log = get_logger("coupled")


class CoupledModel:
    """Fluid (single- or two-phase) on a cut mesh + replicated DEM; model protocol of :mod:`.loop`.
    The step runs the stages of coupling/ in order (module docstring): :attr:`cuts`
    (CutStage), the fluid, :attr:`exchange` (ExchangeStage), the DEM sub-steps (:attr:`dem`,
    DEMSubcycler), :attr:`report` (CoupledDiagnostics), :attr:`output` (BodyOutput); with
    ``coupling.iterations`` > 1 :attr:`implicit` (ImplicitIteration) repeats the first four."""

    # the later passes of an implicit step reuse what the guessed block velocities do not change (the
    # cut, the flow's added mass) and start Newton from the last pass's flow; False computes every pass
    # from scratch (the reference the tests compare with)
    retake_passes = True

    def __init__(self, case: Case, comm: MPI.Comm, case_dir: Path | None = None, out_dir: Path | None = None):
        self.case, self.comm = case, comm
        cp = case.coupling
        # no energy ledger: a coupled run writes none (the DEM-only runs' dem_energy.csv), and without
        # it an unbonded DEM takes the fused step (bit-identical, tests/dem/test_dem_fused.py)
        self.system = build_system(case.dem, with_ledger=False)
        st = self.system.state
        shapes = shapes_of_blocks(case.dem, st, cp.min_thickness)     # the blocks as the fluid sees them
        block_faces = None
        if case.mesh.structure_band is not None:     # cells graded away from the blocks' faces
            block_faces = FaceDistance(shapes, st.pos, st.quat)
        self.mesh = build_mesh(case.mesh, comm, case_dir, face_distance=block_faces)
        self.gdim = self.mesh.geometry.dim
        self.system.planar = self.gdim == 2          # a 2D fluid sees the blocks as prisms moving in its plane
        self.fluid, cut = self._fluid_on_cut_mesh(case, comm, case_dir)
        self.ns, self.h_min = self.fluid.ns, self.fluid.h_min
        self.dem = DEMSubcycler(self.system)
        self.nb = st.nb
        self.bonds = next((it for it in self.system.interactions if hasattr(it, "broken_bonds")), None)
        # radius of gyration [m] (rotations enter the iteration residual as ω × it)
        with np.errstate(divide="ignore", invalid="ignore"):
            g = np.sqrt(st.inertia.sum(axis=1) / (2.0 * st.mass))
        gyration = np.where(np.isfinite(g) & (g > 0), g, 1.0)
        self.depth = 1.0 if self.gdim == 3 else float(cp.depth)
        rho = self.fluid.rho if hasattr(self.fluid, "rho") else fem.Constant(self.mesh, float(case.fluid.density))
        self.added = AddedMassStage(case, self.system, cut, rho, self.ns.bc_set.natural_facets, self.gdim,
                                    self.depth, fluid_volume_ratio(case.dem, st, cp.min_thickness, self.gdim),
                                    fluid_gyration_ratio(case.dem, st, cp.min_thickness, self.gdim), out_dir,
                                    comm.rank)
        mass, inertia = self.added.mass0, self.added.inertia0   # the blocks' own
        h_max = comm.allreduce(float(cell_sizes(self.mesh).max(initial=0.0)), op=MPI.MAX)
        own_shapes = shapes_of_blocks(case.dem, st) if cp.min_thickness > 0 else shapes   # unwidened
        true_half = own_shapes.half if cp.min_thickness > 0 else None
        self.unresolved = None                       # coupling.unresolved_cells: blocks loaded as point particles
        if cp.unresolved_cells > 0:
            self.unresolved = UnresolvedBlocks(case, self.mesh, st, own_shapes,
                                               fluid_thickness(case.dem, st, cp.min_thickness, self.gdim),
                                               self.fluid.probe_fields)
        self.cuts = CutStage(case, comm, self.dem, self.bonds, shapes, cut, self.fluid, self.h_min, h_max,
                             gyration, mass, inertia, self.depth, true_half, self.unresolved)
        self.exchange = ExchangeStage(case, comm, self.dem, cut, self.ns, self.cuts.walls, self.cuts.hidden,
                                      self.added, self.depth, self.unresolved)
        self.implicit = ImplicitIteration(cp, self.cuts.walls, gyration)
        self.report = CoupledDiagnostics(case, comm, self.fluid, self.cuts, self.exchange, self.dem, self.implicit,
                                         self.bonds, mass, inertia, rho, self.depth, self.h_min, h_max)
        self.output = BodyOutput(case, self.nb, self.bonds, out_dir, comm.rank)   # bodies.csv, bond breaks, VTP
        self.cuts.warn_vertices_on_surfaces()
        self.cuts.warn_thin_blocks()
        self.output_functions = list(self.fluid.output_functions) + [cut.level_set]
        self.series_units = self.report.units
        log.info("coupled: %d blocks, %d spheres; DEM dt %.4g s; level-set band %.4g m, gap fill %.4g m "
                 "(%d walls); cut cells %d, smallest cut fraction %.2e", self.nb, st.ns, self.system.dt,
                 self.cuts.band, self.cuts.gap, len(self.cuts.levelset.walls), self.cuts.stats.cut_cells,
                 self.cuts.stats.min_cut_fraction)

    def _fluid_on_cut_mesh(self, case: Case, comm: MPI.Comm, case_dir: Path | None):
        """The fluid model on the cut domain of :attr:`mesh` (the wall term of the blocks in its
        equations; uncut cells by the Navier–Stokes forms' own rule), and the CutDomain."""
        cp = case.coupling
        plain_degree = quadrature_degree(case.fluid, field_properties=case.phase_field is not None)
        cut = CutDomain(self.mesh, alpha=cp.fictitious_factor, penalty=cp.penalty, wall=cp.wall,
                        extension=cp.cut_extension, slip=cp.wall_slip, plain_degree=plain_degree)
        ns_options = {"dx": cut.dx, "extra_terms": [cut.penalty_term()], "retaken_steps": cp.iterations > 1,
                      "retake_tolerance": cp.iteration_tol if cp.iterations > 1 else None}
        fluid_case = dataclasses.replace(case, fluid=dataclasses.replace(case.fluid, quadrature_degree=cut.degree))
        if case.phase_field is not None:
            from .two_phase import TwoPhaseModel
            return TwoPhaseModel(fluid_case, comm, case_dir, mesh=self.mesh, ns_options=ns_options), cut
        from .fluid import FluidModel
        return FluidModel(fluid_case, comm, case_dir, mesh=self.mesh, ns_options=ns_options), cut

    # ----------------------------------------------------------------- the step
    def snapshot(self) -> StepSnapshot:
        """The step's start state, to take it again (the loop's retaken steps)."""
        return StepSnapshot(self.fluid, self.dem, self.added, self.exchange, self.implicit)

    def restore(self, start: StepSnapshot) -> None:
        start.restore()

    def halves(self, dt: float) -> bool:
        """Whether a step of ``dt`` [s] splits into two of whole DEM steps."""
        return self.dem.halves(dt)

    def advance(self, t: float, dt: float, timer: StageTimer) -> None:
        """cut → fluid → exchange → DEM sub-steps, once or as the passes of the implicit
        coupling; then the exchange check, the blocks' check and the body output."""
        if self.case.coupling.iterations == 1:
            with timer("cut rebuild"):
                self.cuts.rebuild()
            load = self._fluid_then_dem(t, dt, timer)
        else:
            def one_pass(guess: np.ndarray, retake: bool) -> np.ndarray:
                with timer("cut rebuild"):
                    self.cuts.rebuild(velocities=guess, same_poses=retake)
                load = self._fluid_then_dem(t, dt, timer, retake=retake)
                self._check_dem(t + dt, only_not_finite=True)     # a diverged pass stops the run, naming the block
                return load
            start = StepSnapshot(self.fluid, self.dem, self.added, self.exchange)
            load = self.implicit.run(t, start, one_pass, self.ns.warm_start, lambda: self.ns.U.x.array.copy(),
                                     retake=self.retake_passes)
        self.exchange.check(dt, load)
        self._check_dem(t + dt)
        if self.ns.step_count % self.case.coupling.check_every == 0:
            self.dem.check_replicated(self.comm)
        self.output.step(t + dt, self.system.state, self.exchange.force, self.exchange.torque)

    def _fluid_then_dem(self, t: float, dt: float, timer: StageTimer, retake: bool = False) -> np.ndarray:
        """Fluid step on the current cut, the exchange and the DEM sub-steps; returns the force
        the DEM got. ``retake``: a later pass of the step (same poses and bonds)."""
        self.fluid.advance(t, dt, timer, retake=retake)
        with timer("exchange"):
            self.exchange.collect(self.ns.t, self.fluid.p_out, self.cuts.node_density, same_poses=retake)
        with timer("dem sub-steps"):
            mean = self.case.coupling.wall_velocity == "mean"
            _, v0, w0 = (a.copy() for a in self.dem.motion(mean=mean))
            force, torque = self.exchange.load()
            self.dem.advance(dt, force, torque, self.case.coupling.force_mode)
            # the change of the wall velocity the fluid gets next step against the one it got
            # this step: what the fluid's added-mass reaction answers, so m̃ aⁿ cancels it
            _, v1, w1 = self.dem.motion(mean=mean)
            self.added.record(v0, w0, v1, w1, dt)
        return force

    def _check_dem(self, t: float, only_not_finite: bool = False) -> None:
        """Stop with the body, its load and velocity when the DEM state is not finite or (unless
        ``only_not_finite``) a block moved more than a band width in one fluid step (the cut could
        not follow)."""
        st = self.system.state
        bad = ~np.isfinite(st.pos).all(axis=1) | ~np.isfinite(st.vel).all(axis=1)
        if only_not_finite and not bad.any():
            return
        speed = np.linalg.norm(st.vel, axis=1)
        band = self.cuts.band
        fast = speed * self.fluid.last_dt > band
        for b in np.flatnonzero(bad | fast):
            raise SimulationDiverged(
                f"t = {t:.6g} s: block {b} {'is not finite' if bad[b] else 'moved more than the level-set band'}"
                f": fluid force {np.array2string(self.exchange.force[b], precision=4)} N, velocity "
                f"{np.array2string(st.vel[b], precision=4)} m/s, DEM dt/Δt_cr {self.dem.last.dt_over_dt_cr:.3f}, "
                f"fluid dt {self.fluid.last_dt:.4g} s (band {band:.4g} m)")

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
            dt = self.fluid.stable_dt(cfl, self.cuts.fluid_nodes())
        else:
            umax = self.cuts.fluid_speed_max()
            dt = cfl * self.h_min / umax if umax > 0 else np.inf
        if vmax > 0:
            dt = min(dt, 0.25 * self.cuts.band / vmax)
        return self.dem.whole_steps(dt)

    def diagnostics(self) -> dict[str, float]:
        return self.report.values()

    def probe_fields(self) -> dict:
        return self.fluid.probe_fields()

    def block_poses(self) -> tuple[np.ndarray, np.ndarray]:
        """The blocks' centres (nb, 3) [m] and orientations (nb, 4) now (sensors move with them)."""
        st = self.system.state
        return st.pos, st.quat

    def solid_at(self, points: np.ndarray) -> np.ndarray:
        """Whether ``points`` (n, gdim) [m] lie inside a block now (its own shape, no gap fill)."""
        x = np.zeros((len(points), 3))
        x[:, : self.gdim] = points
        ls = self.cuts.levelset
        shapes = StructureLevelSet(ls.shapes, self.nb, self.cuts.band, walls=ls.walls, true_half=ls.true_half)
        st = self.system.state
        return shapes.evaluate(x, st.pos, st.quat)[0] < 0

    def health(self, diag: dict[str, float]) -> str | None:
        return self.report.health(diag)

    def state(self):
        fields, globals_ = self.fluid.state()
        globals_.update(dem_arrays(self.system, self.dem, self.added))
        globals_.update(self.implicit.arrays())
        if self.unresolved is not None:
            globals_["unresolved_blocks"] = self.unresolved.unseen.astype(np.int8)
        return fields, globals_

    def write_output(self, t: float) -> None:
        """The blocks at a field output (coupling/body_output.py)."""
        self.output.fields(t, self.system.state)

    def load_state(self, checkpoint) -> None:
        self.fluid.load_state(checkpoint)
        load_dem_arrays(self.system, self.dem, self.added, checkpoint.globals)
        self.implicit.load_arrays(checkpoint.globals)
        self.output.resume(checkpoint.time)                # continue the earlier run's files
        self.added.resume(checkpoint.time)
        if self.unresolved is not None and "unresolved_blocks" in checkpoint.globals:
            self.cuts.take_out(np.flatnonzero(checkpoint.globals["unresolved_blocks"]))
        self.cuts.rebuild()
