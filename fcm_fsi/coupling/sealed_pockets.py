"""Fluid pockets the gap fill seals, a stage of the coupled step's cut rebuild
(``coupling.vent_pockets``, ``coupling.drain_pockets``; fcm/pockets.py finds them):

- **vents**: the fill is removed (the node gets the plain level set back) where it seals a
  pocket between owners free to part — one a moving block, not both of one bonded cluster;
- **drains**: the pressure at the inner nodes of every pocket the fill sealed is held at the
  ambient one, P₀ + ρ_k g·x, with P₀ the mean of p − ρ_k g·x over the pocket's rim (the
  main fluid's nodes nearest to it, from the last solved step) and ρ_k the mean density of
  its nodes — as if its water could leave and enter past the block's sides, as around a block
  of finite depth in 3D — from the first solved step on (at t = 0 the pressure is not solved
  yet: a target taken from it drove a flow inside the block whose Brinkman reaction kept
  loading the block). Its cells take φ in advective form (its flow need not be solenoidal).
"""
from __future__ import annotations

import numpy as np
from dolfinx import fem
from mpi4py import MPI

from ..fcm.levelset import NO_SHAPE
from ..fcm.pockets import PocketVents
from ..io.logging import get_logger
from .hidden_load import or_over_ranks

log = get_logger("coupled")


class SealedPockets:
    """Vents and drains of the pockets on the cut domain ``cut`` (fluid/cut_walls.CutDomain) for
    the Navier–Stokes solver ``ns`` (its pressure held in drained pockets by
    ``ns.set_step_bcs``): ``plain`` the bodies' level set without the fill (a
    StructureLevelSet), ``points`` (n, 3) the mesh vertices, ``static`` the two-phase
    model's static pressure part Π or None (then p is the unknown itself)."""

    def __init__(self, case, comm: MPI.Comm, cut, ns, plain, points: np.ndarray, static=None) -> None:
        cp = case.coupling
        self.comm, self.cut, self.ns, self.plain, self.points, self.static = comm, cut, ns, plain, points, static
        self.vent_on, self.drain_on = cp.vent_pockets, cp.drain_pockets
        self.gdim = cut.mesh.topology.dim
        self.gravity = np.zeros(3)
        self.gravity[: self.gdim] = np.asarray(case.fluid.gravity, float)[: self.gdim]
        imap, dofs = cut.S1.dofmap.index_map, cut.level_dofs
        self.vents = PocketVents(comm, cut.geom_cells, imap.local_to_global(dofs.astype(np.int32)),
                                 dofs < imap.size_local, cut.n_owned)
        self._flags = fem.Function(cut.S1)
        #: the cells of the drained pockets (None: none)
        self.cells = None
        if self.drain_on:
            self._q_of_node = cut.node_map(ns.Q)          # mesh vertex → pressure node
            self._p_pocket = fem.Function(ns.Q, name="p_pocket")

    def _any_rank(self, flags: np.ndarray) -> np.ndarray:
        return or_over_ranks(self._flags, self.cut.level_dofs, flags)

    def apply(self, level: np.ndarray, owner: np.ndarray, levelset, free_to_part: np.ndarray, pos: np.ndarray,
              quat: np.ndarray, node_density) -> None:
        """At a cut rebuild, before the cut is updated: the pockets as the fill seals them
        (``level``, ``owner`` at the mesh vertices from ``levelset``, the fill's), drained
        (their pressure held), then vented (``level``, ``owner`` and the fill's velocity
        blend in ``levelset`` get the plain level set's, in place, where ``free_to_part``).
        ``node_density`` () → the density at the mesh vertices [kg/m³]."""
        drained = self.vents.drainable(level, free_to_part, self._any_rank) if self.drain_on else None
        if self.vent_on:
            self._vent(level, owner, levelset, free_to_part, pos, quat)
        if drained is not None:
            self._drain(*drained, node_density)

    def _vent(self, level, owner, levelset, free_to_part, pos, quat) -> None:
        """Remove the fill where it seals a pocket; the plain level set is evaluated only when
        some fill next to a pocket may go."""
        plain = {}

        def plain_level():
            if not plain:
                plain["level"], plain["owner"] = self.plain.evaluate(self.points, pos, quat)
            return plain["level"]

        reverted = self.vents.vent(level, plain_level, free_to_part, self._any_rank)
        if reverted.any():
            owner[reverted] = plain["owner"][reverted]
            levelset.fill_other[reverted] = NO_SHAPE
            levelset.fill_weight[reverted] = 0.0

    def _drain(self, pocket: np.ndarray, rim: np.ndarray, node_density) -> None:
        """Hold the pressure of the pockets (``pocket``, ``rim`` of
        :meth:`PocketVents.drainable`) at the ambient one by a Dirichlet condition on the
        pressure at their inner nodes (no cut cell touches them)."""
        ns, static = self.ns, self.static
        npockets = self.comm.allreduce(int(pocket.max(initial=-1)) + 1, op=MPI.MAX)
        if npockets == 0 or ns.step_count == 0:      # no solved pressure yet to take the ambient from
            self.cells = None
            ns.set_step_bcs(())
            return
        p = ns.U.x.array[ns.Q_map]
        p = (p if static is None else static.total_pressure(p))[self._q_of_node]
        rho = node_density()
        gx = self.points @ self.gravity
        owned = self.vents.owned
        sums = np.zeros((npockets, 4))    # Σ ρ, count over the pocket; Σ (p − ρ_k g·x), count over the rim
        for k in range(npockets):
            mine = (pocket == k) & owned
            sums[k, 0], sums[k, 1] = rho[mine].sum(), np.count_nonzero(mine)
        self.comm.Allreduce(MPI.IN_PLACE, sums[:, :2], op=MPI.SUM)
        rho_k = sums[:, 0] / np.maximum(sums[:, 1], 1)
        for k in range(npockets):
            ring = (rim == k) & owned
            sums[k, 2], sums[k, 3] = (p[ring] - rho_k[k] * gx[ring]).sum(), np.count_nonzero(ring)
        self.comm.Allreduce(MPI.IN_PLACE, sums[:, 2:], op=MPI.SUM)
        p0 = sums[:, 2] / np.maximum(sums[:, 3], 1)
        log.debug("drained pockets: density %s kg/m³, rim nodes %s, P₀ %s Pa", rho_k, sums[:, 3], p0)
        inner = self.vents.inner_nodes(pocket, self._any_rank)
        nodes = np.flatnonzero(inner & (sums[np.maximum(pocket, 0), 3] > 0))   # a pocket with no rim keeps its own
        k = pocket[nodes]
        target = p0[k] + rho_k[k] * gx[nodes]
        if static is not None:
            target -= static.p1.x.array[self._q_of_node[nodes]]
        q = self._q_of_node[nodes]
        self._p_pocket.x.array[q] = target
        w = np.asarray(ns.Q_map)[q]
        ns.set_step_bcs([fem.dirichletbc(self._p_pocket, [w.astype(np.int32), q.astype(np.int32)], ns.pressure_subspace)])
        self.cells = (pocket[self.cut.geom_cells] >= 0).any(axis=1)

    def counts(self) -> dict[str, float]:
        """Nodes in pockets, vented and drained at the last rebuild (diagnostics)."""
        return {"pocket_nodes": float(self.vents.pocket_nodes), "vented_nodes": float(self.vents.vented_nodes),
                "drained_nodes": float(self.vents.drained_nodes)}
