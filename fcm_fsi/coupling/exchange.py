"""Stage (c) of the coupled step: the fluid's load on the blocks, and the check that the
momentum the DEM received is the momentum the fluid gave.

Load: the wall traction on each block's cut surface (fluid/cut_walls.CutDomain.body_forces;
2D fluids: per unit depth × ``coupling.depth``), with ``coupling.hidden_pressure`` the static
pressure's load moved from the gap fill's surface to the block's true one (hidden_load.py),
and the added-mass stabilisation (added_mass.py) on the accelerations the fluid answers.

Momentum exchange: ``error`` compares, per step, the impulse the DEM integrated over its
sub-steps with the momentum the fluid's discrete equations received from the wall term (the
assembled wall residual summed over all velocity dofs, i.e. tested with the constant unit
vectors), relative to the larger of the two. It checks the whole chain (cell-to-body split,
depth scaling, DEM load application) to round-off.
"""
from __future__ import annotations

import numpy as np
from dolfinx import fem
from mpi4py import MPI
from petsc4py import PETSc

from ..fluid.tagged_form import TaggedForm
from ..io.logging import get_logger

log = get_logger("coupled")


class ExchangeStage:
    """The load on the blocks and the exchange check (module docstring). ``case`` the case;
    ``comm`` the fluid's communicator; ``dem`` the DEMSubcycler; ``cut`` the CutDomain; ``ns``
    the NavierStokes solver; ``walls`` the WallMotion; ``hidden`` the HiddenLoad or None;
    ``added`` the AddedMassStage; ``depth`` [m] the span of a 2D fluid; ``unresolved`` the
    UnresolvedBlocks (their load replaces the cut's, unresolved.py)."""

    def __init__(self, case, comm: MPI.Comm, dem, cut, ns, walls, hidden, added, depth: float,
                 unresolved=None) -> None:
        self.case, self.comm, self.dem, self.cut, self.ns = case, comm, dem, cut, ns
        self.walls, self.hidden, self.added, self.depth = walls, hidden, added, depth
        self.unresolved = unresolved
        self.gdim = cut.gdim
        nb = dem.system.state.nb
        self.force = np.zeros((nb, 3))      # on each block [N]: the fluid's, with the static load's move
        self.torque = np.zeros((nb, 3))     # about its centre of mass [N m]
        self.fluid_side = np.zeros(3)       # momentum per unit time the fluid's equations received [N]
        self.error = 0.0                    # the exchange check of the last step
        self._previous = None               # (stabilisation, fluid side) of the last step (force_mode linear)
        self._wall_form = None

    def collect(self, t: float, pressure, node_density, same_poses: bool = False) -> None:
        """The fluid's load on every block after the fluid step to ``t`` [s]; ``pressure`` the
        total pressure field, ``node_density`` a callable giving ρ at the mesh vertices (the
        static load); ``same_poses`` a later pass of the implicit coupling (the flow's added
        mass and the static load are the first pass's)."""
        st = self.dem.system.state
        centres = st.pos[:, : self.gdim] if self.gdim == 2 else st.pos
        force, torque = self.cut.body_forces(st.nb, centres)
        self.force[:] = 0.0
        self.force[:, : self.gdim] = force * self.depth
        self.torque[:] = torque * self.depth
        if self.hidden is not None:
            self._move_static_load(pressure, node_density, centres, same_poses)
        if self.unresolved is not None and self.unresolved.unseen.any():
            out = self.unresolved.unseen
            self.force[out] = self.unresolved.load(st.pos, st.vel, st.rotation_matrices())[out]
            self.torque[out] = 0.0
        labels = self.walls.cluster_labels() if self.added.from_flow else None   # the flow's groups only
        self.added.update(t, labels, same_poses=same_poses)

    def _move_static_load(self, pressure, node_density, centres: np.ndarray, later_pass: bool) -> None:
        """``coupling.hidden_pressure``: the block's load becomes the fluid's on Γ minus the
        static pressure's on Γ plus the static pressure's on the true surface (hidden_load.py).
        A ``later_pass`` of an implicit step keeps its first pass's static loads: it has the same
        density (φ), poses and cut, so the column pressure differs only by the change of the
        pressure at the top of the columns (on the tsunami building 1e-4 N of the blocks' 2e4 N
        static loads, where their loads change by 2–30 N from pass to pass)."""
        h = self.hidden
        if not later_pass:
            st = self.dem.system.state
            density = self.case.fluid.density if self.case.phase_field is None else node_density()
            h.exchange(pressure, density, st.pos, st.rotation_matrices(), centres)
        self.force += h.surface_force - h.cut_force
        self.torque += h.surface_torque - h.cut_torque
        if h.unreached:
            log.debug("hidden pressure: %d block(s) hidden all round (no wetted mouth): no hidden load", h.unreached)

    def _wall_momentum(self) -> np.ndarray:
        """Momentum per unit time the fluid's equations receive from the wall term: the
        assembled wall residual summed over the velocity dofs of each component (N)."""
        if self._wall_form is None:
            self._wall_form = TaggedForm(self.cut.penalty_term()(self.ns.parts))
        vec = fem.petsc.assemble_vector(self._wall_form.form)
        vec.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        owned = self.ns.V.dofmap.index_map.size_local
        w_dofs = np.asarray(self.ns.V_map).reshape(-1, self.gdim)[:owned]
        out = np.zeros(3)
        out[: self.gdim] = vec.array[w_dofs].sum(axis=0)
        vec.destroy()
        return -self.comm.allreduce(out, op=MPI.SUM) * self.depth

    def load(self) -> tuple[np.ndarray, np.ndarray]:
        """The DEM's load (added_mass.AddedMassStage.load): the fluid's, relaxed, plus the lagged
        added-mass terms on the accelerations the fluid answers — with the flow's added mass of
        bonded clusters, the cluster's rigid acceleration, not the bonds' ringing."""
        st = self.dem.system.state
        accel, alpha = self.added.accel, self.added.alpha
        if self.added.from_flow and self.walls.by_cluster:
            X, A, Al = self.walls.cluster_rigid(st.pos, accel, alpha)
            accel, alpha = A + np.cross(Al, st.pos - X), Al
        return self.added.load(self.force, self.torque, accel, alpha)

    def check(self, dt: float, dem_load: np.ndarray) -> None:
        """:attr:`error` of the step just taken: |fluid impulse the DEM integrated + momentum
        the fluid received| / scale, the added-mass stabilisation taken out; the linear force
        mode compares trapezoids. ``dem_load`` the force (nb, 3) [N] the DEM got."""
        self.fluid_side = self._wall_momentum()       # of the flow the step ends with (its last pass)
        # with the static load moved, the hidden-surface load is not the fluid's (its reaction is the
        # floor's) and the fill's surface load (the fluid's) is not the block's: compare the fluid's own
        fluid_load = self.force if self.hidden is None else \
            self.force - self.hidden.surface_force + self.hidden.cut_force
        if self.unresolved is not None and self.unresolved.unseen.any():   # the particles' load: not the fluid's
            fluid_load = np.where(self.unresolved.unseen[:, None], 0.0, fluid_load)
        stabilisation = dem_load - fluid_load
        linear = self.case.coupling.force_mode == "linear"
        prev_stab, prev_fluid = self._previous or (np.zeros_like(stabilisation), self.fluid_side)
        stab = 0.5 * (prev_stab + stabilisation) if linear else stabilisation
        fluid = 0.5 * (prev_fluid + self.fluid_side) if linear else self.fluid_side
        self._previous = (stabilisation.copy(), self.fluid_side.copy())
        dem_side = (self.dem.last.impulse - dt * stab).sum(axis=0) / dt
        scale = max(np.abs(dem_side).max(), np.abs(fluid).max(), 1e-300)
        self.error = float(np.abs(dem_side + fluid).max() / scale)

    def snapshot(self):
        """What :meth:`check` carries from step to step (a retried step restores it)."""
        return self._previous

    def restore(self, previous) -> None:
        if previous is not None:
            self._previous = previous
