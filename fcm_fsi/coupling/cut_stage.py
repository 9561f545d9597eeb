"""Stage (a) of the coupled step: the cut of the fluid mesh by the blocks at their poses.

From the blocks' poses at tⁿ: the structure level set with the gap fill (fcm/levelset.py) at
the mesh vertices, the sealed pockets' vents and drains (``coupling.vent_pockets``,
``drain_pockets``), the moment-fitted cut weights and the wall velocity ū of the owning block
at every vertex (fluid/cut_walls.CutDomain, ū from :class:`~.wall_motion.WallMotion`), the
hidden parts of the blocks' surfaces (``coupling.hidden_pressure``), and, in a two-phase
flow, the cells where φ moves with the blocks (``TwoPhaseModel.follow_cut``).
"""
from __future__ import annotations

import numpy as np
from mpi4py import MPI

from ..config.loader import ConfigError
from ..dem.walls import gap_walls
from ..fcm.levelset import StructureLevelSet, grid_margin
from ..fluid.phase_field import property_map
from ..io.logging import get_logger
from .dem_side import fluid_thickness
from .hidden_load import HiddenLoad
from .sealed_pockets import SealedPockets
from .wall_motion import WallMotion

#: blocks thinner than this × h_min (the smallest cell diameter) in the fluid get a warning
THIN_WALL = 1.25

log = get_logger("coupled")


class CutStage:
    """The cut of the fluid mesh by the blocks (module docstring). ``case`` the case; ``comm``
    the fluid's communicator; ``dem`` the DEMSubcycler; ``bonds`` the cohesive bonds or None;
    ``shapes`` the blocks as the fluid sees them; ``cut`` the fluid's CutDomain; ``fluid`` the
    fluid model (FluidModel or TwoPhaseModel); ``h_min``, ``h_max`` the smallest and largest
    cell diameters [m]; ``gyration``, ``mass``, ``inertia`` as :class:`WallMotion`'s;
    ``depth`` [m] the span of a 2D fluid; ``true_half`` the blocks' own half extents where
    ``shapes`` widens them (``coupling.min_thickness``; the widening is narrowed near the tank's
    walls, fcm/levelset.narrowed_at_walls); ``unresolved`` the UnresolvedBlocks, whose blocks
    the level sets leave out."""

    def __init__(self, case, comm: MPI.Comm, dem, bonds, shapes, cut, fluid, h_min: float, h_max: float,
                 gyration: np.ndarray, mass: np.ndarray, inertia: np.ndarray, depth: float,
                 true_half: np.ndarray | None = None, unresolved=None) -> None:
        cp = case.coupling
        self.case, self.comm, self.dem, self.cut, self.fluid = case, comm, dem, cut, fluid
        self.gdim = cut.gdim
        nb = dem.system.state.nb
        self.band = cp.band if cp.band is not None else 2.0 * h_max
        self.gap = h_min if cp.gap_fill is None else float(cp.gap_fill)
        if self.gap >= self.band:
            raise ConfigError(f"key 'coupling.gap_fill' = {self.gap:.4g} m: allowed 0 ≤ gap_fill < the level-set "
                              f"band {self.band:.4g} m (coupling.band, default 2 × the largest cell)")
        short = np.flatnonzero(grid_margin(shapes) < self.band)
        if short.size:
            raise ConfigError(f"key 'dem.blocks[].sdf_margin': the signed-distance grid of block {shapes.body[short[0]]} "
                              f"reaches {grid_margin(shapes)[short[0]]:.4g} m beyond its surface, less than the "
                              f"level-set band {self.band:.4g} m (coupling.band, default 2 × the largest cell): "
                              "raise sdf_margin")
        walls = gap_walls(case.dem, self.gdim)
        self.levelset = StructureLevelSet(shapes, nb, self.band, gap=self.gap, walls=walls, true_half=true_half)
        self.points = np.zeros((cut.nodes.shape[0], 3))
        self.points[:, : self.gdim] = cut.nodes[:, : self.gdim]
        self.walls = WallMotion(cp, dem, bonds, self.levelset, self.points, gyration, mass, inertia, h_min, self.gdim)
        self.h_min = h_min
        self.unresolved = unresolved
        plain = None                       # the level set without the fill (vents, hidden pressure)
        if self.gap > 0 and (cp.vent_pockets or cp.drain_pockets) or cp.hidden_pressure != "none":
            plain = StructureLevelSet(self.levelset.shapes, nb, self.band, walls=walls, true_half=true_half)
        self.plain = plain
        self.pockets = None                # coupling.vent_pockets / drain_pockets
        if self.gap > 0 and (cp.vent_pockets or cp.drain_pockets):
            self.pockets = SealedPockets(case, comm, cut, fluid.ns, plain, self.points, getattr(fluid, "static", None))
        self.hidden = None                 # coupling.hidden_pressure
        if cp.hidden_pressure != "none":
            self.hidden = HiddenLoad(cp.hidden_pressure, cut, plain, self.levelset.shapes, nb,
                                     fluid.p_out.function_space, self.points, np.asarray(case.fluid.gravity, float),
                                     h_min, depth)
        self._phi_of_node = None           # phase-field dof at each mesh vertex (built on first use)
        self._pass_cut = None              # (node owners, statistics) of the last full rebuild
        self._poses = None                 # the blocks' (positions, quaternions) at the last full rebuild
        self.stats = self.rebuild()

    def rebuild(self, velocities: np.ndarray | None = None, same_poses: bool = False):
        """The cut and the wall velocity from the current block poses; the wall velocity from
        the blocks' current v, ω, or from ``velocities`` (the implicit coupling's iterated
        unknown). ``same_poses``: the blocks stand where the last rebuild found them (a later
        pass of the implicit coupling), so only the wall velocity is set again, unless
        ``drain_pockets`` (the drain also resets the restored flow's pressure). The same holds
        whenever every pose equals, to the bit, the last full rebuild's (fixed or resting
        blocks): the level set, the cut and the hidden surfaces are functions of the poses.
        The phase field inside the bodies moves with the blocks' current v, ω (their motion at the
        start of the step, explicit as their poses are), whatever ``velocities`` says: a later
        pass keeps its φ and the flow's matrix (``TwoPhaseModel.advance``). Returns the cut's
        statistics."""
        st = self.dem.system.state
        later = same_poses
        same_poses = same_poses or (self._poses is not None and np.array_equal(st.pos, self._poses[0])
                                    and np.array_equal(st.quat, self._poses[1]))
        if same_poses and self._pass_cut is not None and not self.case.coupling.drain_pockets:
            owner, self.stats = self._pass_cut
            ubar = self.walls.at_nodes(owner, velocities)[0]
            self.cut.set_wall_velocity(ubar, self._inside_velocity(owner, ubar, velocities, later))
            return self.stats
        self._poses = (st.pos.copy(), st.quat.copy())
        if self.unresolved is not None:
            self.take_out(self.unresolved.update(self.fluid.ns.t, st.pos))
        level, owner = self.levelset.evaluate(self.points, st.pos, st.quat)
        if self.pockets is not None:
            self.pockets.apply(level, owner, self.levelset, self.walls.fill_free_to_part(owner), st.pos, st.quat,
                               self.node_density)
        ubar, share = self.walls.at_nodes(owner, velocities)
        self.stats = self.cut.update(level, owner, ubar, share, self._inside_velocity(owner, ubar, velocities, later))
        self._pass_cut = (owner, self.stats)
        if self.hidden is not None:
            self.hidden.rebuild(level, st.pos, st.quat)
        if hasattr(self.fluid, "follow_cut"):
            self.fluid.follow_cut(self.cut, None if self.pockets is None else self.pockets.cells)
        return self.stats

    def _inside_velocity(self, owner: np.ndarray, ubar: np.ndarray, velocities: np.ndarray | None,
                         later: bool) -> np.ndarray:
        """The velocity (n, gdim) [m/s] the phase field moves with inside the bodies: the wall
        velocity of the blocks' current v, ω (``ubar`` when no ``velocities`` were given), kept
        from the step's first pass in a ``later`` one."""
        if later:
            return self.cut.node_inside_velocity
        return ubar if velocities is None else self.walls.at_nodes(owner)[0]

    def take_out(self, blocks: np.ndarray) -> None:
        """Leave ``blocks`` out of the level sets from now on (unresolved, point particles)."""
        if self.unresolved is not None:
            self.unresolved.unseen[blocks] = True
        for levelset in (self.levelset, self.plain):
            if levelset is not None:
                levelset.unseen[blocks] = True

    def node_density(self) -> np.ndarray:
        """Fluid density [kg/m³] at the mesh vertices: from φ with a phase field, else the fluid's."""
        fl = self.case.fluid
        if self.case.phase_field is None:
            return np.full(len(self.points), fl.density)
        if self._phi_of_node is None:
            self._phi_of_node = self.cut.node_map(self.fluid.pf.phi.function_space)
        return property_map(self.fluid.pf.phi.x.array[self._phi_of_node], fl.density, fl.gas_density)

    def fluid_nodes(self) -> np.ndarray:
        """True at the Navier–Stokes velocity nodes in the fluid (level set > 0)."""
        return self.cut.fluid_nodes(self.fluid.ns.V)

    def fluid_speed_max(self) -> float:
        """max |u| over the velocity nodes in the fluid [m/s]: the fictitious flow inside the
        blocks limits neither the CFL step nor the report."""
        ns = self.fluid.ns
        u = ns.U.x.array[ns.V_map].reshape(-1, self.gdim)[self.fluid_nodes()]
        local = float(np.sqrt((u ** 2).sum(axis=1)).max(initial=0.0))
        return self.comm.allreduce(local, op=MPI.MAX)

    def warn_thin_blocks(self) -> None:
        """Warn when a block, as the fluid sees it, is thinner than about two mesh spacings
        (``THIN_WALL`` × the smallest cell diameter h_min; a right triangle of legs h has
        diameter √2 h): a wall one cell thick has no node inside, so the continuous P1 pressure
        cannot jump across it and water passes through (a fixed 2D wall holding a 0.4 m head
        leaks at 1 and 1.5 spacings, holds at 2 and more; docs/coupling.md 'Thin walls')."""
        case = self.case
        thin = fluid_thickness(case.dem, self.dem.system.state, case.coupling.min_thickness, self.gdim)
        bad = np.flatnonzero(thin < THIN_WALL * self.h_min)
        if bad.size:
            log.warning("%d block(s) are thinner than two cells in the fluid (thinnest %.3g m, smallest cell "
                        "diameter %.3g m; blocks %s): walls thinner than about two cells let water through and "
                        "their loads are spurious (docs/coupling.md, 'Thin walls'); refine the mesh there or raise "
                        "coupling.min_thickness", bad.size, float(thin[bad].min()), self.h_min,
                        ", ".join(map(str, bad[:8])) + (" ..." if bad.size > 8 else ""))

    def warn_vertices_on_surfaces(self) -> None:
        """Warn when interior mesh vertices lie exactly on a block surface (a face on a mesh
        line). The cells on the body side of such a face are cut with no fluid part yet carry
        the whole face; where the free surface runs along it the Newton solve can fail
        (docs/coupling.md). Faces on the mesh boundary (a block standing on the floor) are left
        out: the gap fill handles them."""
        lo, hi = np.array(self.case.mesh.lower), np.array(self.case.mesh.upper)
        x = self.points[:, : self.gdim]
        tol = 1e-9 * self.h_min
        interior = np.all((x > lo + tol) & (x < hi - tol), axis=1)
        level = self.cut.level_set.x.array[self.cut.level_dofs]     # at self.points, as last built
        count = self.comm.allreduce(int(np.count_nonzero(interior & (np.abs(level) <= tol))), op=MPI.SUM)
        if count:
            log.warning("%d mesh vertices lie exactly on a block surface (faces on mesh lines): where the free "
                        "surface runs along such a face the fluid solve is known to fail (docs/coupling.md); "
                        "shift the blocks or the mesh by a fraction of a cell", count)
