"""The static load of the water on the parts of a block's surface the cut fluid does not reach
(``coupling.hidden_pressure``): a stage of the coupled step that owns its state.

The fluid sees a block through its cut surface Γ; where the gap fill hides the block's
underside (a block resting on the floor, on a stopper or on another block), Γ runs along the
fill and the water under the block is missing from the load. With ``hidden_pressure`` on, the
block gets

    F = F_Γ(p − P) + Σ_samples (−P n w)

the flow's part of the load on Γ (the fluid's pressure p minus its static part P) plus the
static pressure on every sample of the block's *true* surface (fcm/hidden.py), the hidden
samples taking P from the wetted surface around them as through a thin gap. P is the local
column pressure (``hydrostatic``, fluid/column_pressure.py) or the whole pressure
(``linear``). In still water this is Archimedes' buoyancy on the true shape, whatever the
fill hides.

Per cut rebuild (:meth:`HiddenLoad.rebuild`): the share χ of the hidden surface, the cells
the fill sets, the owners of the cut cells, the solid cells, and (``hydrostatic``) the nodes
at which P is needed and the open-fluid points they read it from. Per exchange
(:meth:`HiddenLoad.exchange`): P at those nodes from this step's pressure and density, and the
two loads (a later pass of an implicit step keeps the first pass's: exchange.py).
"""
from __future__ import annotations

import numpy as np
from dolfinx import fem, la
from mpi4py import MPI
from petsc4py import PETSc

from ..config.loader import ConfigError
from ..fcm.domain import cut_cells
from ..fcm.hidden import NOT_CUT, HiddenSurface
from ..fluid.column_pressure import ColumnPressure

#: sample spacing of the hidden-surface pressure (fcm/hidden.py) × h_min, by fluid dimension: a
#: hidden patch's edge is placed to one sample, so its load is off by ≈ p × (perimeter × spacing)
HIDDEN_SPACING = {2: 1.0 / 16, 3: 1.0 / 4}

#: how far out [× h_min] a hidden sample looks for open fluid (fcm/hidden.py), and how far out
#: the static pressure of a cut cell's node is read: beyond the gap fill, whose width is h_min
HIDDEN_PROBE = 1.5

#: rings of cells round the cells with a vertex in a body at whose nodes P is set: every cell
#: that holds a surface sample, a share of Γ or a hidden sample's probe
COLUMN_RINGS = 3


def or_over_ranks(work: fem.Function, dofs: np.ndarray, flags: np.ndarray) -> np.ndarray:
    """Per-node ``flags`` (mesh vertex order; ``dofs`` their P1 dofs in ``work``'s space)
    or-ed over the ranks that hold each node. Collective."""
    x = work.x
    x.array[:] = 0.0
    x.array[dofs] = flags
    x.scatter_reverse(la.ScatterMode.add)
    x.scatter_forward()
    return x.array[dofs] > 0


class HiddenLoad:
    """``coupling.hidden_pressure`` for the ``nb`` bodies of a cut domain ``cut``
    (fluid/cut_walls.CutDomain): ``plain`` the bodies' level set without the gap fill (a
    StructureLevelSet), ``pressure_space`` the fluid's P1 pressure space, ``points`` (n, 3) the
    mesh vertices, ``gravity`` (gdim,) [m/s²], ``h_min`` [m] the smallest cell diameter,
    ``depth`` [m] the span of a 2D fluid (1 in 3D)."""

    def __init__(self, mode: str, cut, plain, shapes, nb: int, pressure_space, points: np.ndarray,
                 gravity: np.ndarray, h_min: float, depth: float) -> None:
        self.mode, self.cut, self.plain, self.nb = mode, cut, plain, nb
        self.points, self.h_min, self.depth = points, h_min, depth
        self.gdim = cut.mesh.topology.dim
        self.gravity = np.asarray(gravity, float)[: self.gdim]
        try:
            # every body, fixed ones too: the static load on Γ comes off all of them
            self.surface = HiddenSurface(cut.mesh, shapes, nb, h_min * HIDDEN_SPACING[self.gdim], bridge=h_min,
                                         probe=HIDDEN_PROBE * h_min)
        except ValueError as err:
            raise ConfigError(f"key 'coupling.hidden_pressure' = {mode}: {err}") from None
        self._unit_weight = fem.Constant(cut.mesh, PETSc.ScalarType(1.0))
        self._flags = fem.Function(cut.S1)
        self.rho_node = fem.Function(cut.S1, name="rho_node")
        #: χ (P1): 1 at every vertex of a cut cell in which the fill (or a neighbour) sets the
        #: level set, 0 elsewhere: where the body's surface samples are hidden
        self.share = fem.Function(cut.S1, name="hidden_share")
        self._fill_eps = 1e-6 * h_min       # [m] above round-off of the two level sets' difference
        self.column = None
        if mode == "hydrostatic":
            self.column = ColumnPressure(cut.mesh, self.gravity, h_min)
            self.p_column = fem.Function(pressure_space, name="p_column")
            self._column_of_node = cut.node_map(pressure_space)
        #: the static pressure's load on the true surface (all samples) and on Γ [N, N m]
        self.surface_force, self.surface_torque = np.zeros((nb, 3)), np.zeros((nb, 3))
        self.cut_force, self.cut_torque = np.zeros((nb, 3)), np.zeros((nb, 3))

    # ------------------------------------------------------------------ per cut rebuild
    def rebuild(self, level: np.ndarray, pos: np.ndarray, quat: np.ndarray) -> None:
        """From the level set at the mesh vertices with the fill (``level``, as the cut was
        just updated with) and the poses: what is hidden, the cut cells' owners, the solid
        cells, and where P is read."""
        self.surface.forget()                                       # the samples are classified anew
        geo = self.cut.geom_cells
        plain, _ = self.plain.evaluate(self.points, pos, quat)    # [m] the bodies' level set without the fill
        filled = plain - level > self._fill_eps                     # where the fill (or a neighbour) sets it
        self._set_share(level, filled)
        self.filled_cell = filled[geo].any(axis=1)
        cut = cut_cells(level[geo])
        self.cut_owner = np.column_stack([np.where(cut, self.cut.cell_owner, NOT_CUT),
                                          np.where(cut & (self.cut.cell_share > 0), self.cut.cell_second, NOT_CUT)])
        self.solid_cell = level[geo].max(axis=1) < 0
        if self.column is not None:
            self._column_nodes(level, plain, pos, quat)

    def _set_share(self, level: np.ndarray, filled: np.ndarray) -> None:
        """χ: 1 at every vertex of a cut cell with a vertex the fill sets (assembled over the
        ranks, so that a vertex sees all its cells), P1 between: a surface sample where χ = 1
        is hidden (fcm/hidden.py)."""
        geo = self.cut.geom_cells
        cells = geo[cut_cells(level[geo]) & filled[geo].any(axis=1)]
        touched = np.zeros(len(filled))
        touched[cells.ravel()] = 1.0
        chi = self.share
        chi.x.array[self.cut.level_dofs] = touched
        chi.vector.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        chi.x.array[:] = chi.x.array > 0
        chi.vector.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)

    def _column_nodes(self, level: np.ndarray, plain: np.ndarray, pos: np.ndarray, quat: np.ndarray) -> None:
        """The nodes of the cells with a vertex in a body or the fill (``level`` < 0) and :data:`COLUMN_RINGS` rings of
        cells round them, and for each the point :data:`HIDDEN_PROBE` h_min out in the open
        fluid whose static pressure it takes (:meth:`_off_the_bodies`)."""
        geo = self.cut.geom_cells
        near = np.zeros(len(self.points), bool)
        near[geo[level[geo].min(axis=1) < 0]] = True
        near = or_over_ranks(self._flags, self.cut.level_dofs, near)
        for _ in range(COLUMN_RINGS):
            near[geo[near[geo].any(axis=1)]] = True
            near = or_over_ranks(self._flags, self.cut.level_dofs, near)
        self._nodes = np.flatnonzero(near)
        x = self.points[self._nodes]
        self._probes = self._off_the_bodies(x, plain[self._nodes], HIDDEN_PROBE * self.h_min, pos, quat)

    def _off_the_bodies(self, x: np.ndarray, d: np.ndarray, distance: float, pos: np.ndarray,
                        quat: np.ndarray) -> np.ndarray:
        """Points ``x`` (n, 3), at ``d`` [m] in the bodies' level set without the fill, moved
        along its gradient to ``distance`` [m] from the nearest body, where they are closer:
        the open fluid next to a surface, whose static pressure the nodes of its cut cells
        take (next to a wall the phase field hugs the wall and the columns through it carry
        its contents)."""
        eps = 1e-3 * self.h_min
        near = np.flatnonzero(d < distance)                 # the points that move
        xn = x[near]
        grad = np.zeros_like(xn)
        for i in range(self.gdim):
            e = np.zeros(3)
            e[i] = eps
            grad[:, i] = (self.plain.evaluate(xn + e, pos, quat)[0] - self.plain.evaluate(xn - e, pos, quat)[0]) / (2 * eps)
        norm = np.linalg.norm(grad, axis=1)
        n = np.where(norm[:, None] > 0.5, grad / np.maximum(norm, 1e-300)[:, None], 0.0)
        out = x.copy()
        out[near] += (distance - d[near])[:, None] * n
        return out

    # ------------------------------------------------------------------ per exchange
    def static_pressure(self, p, density):
        """P (P1, in the gauge of the fluid's pressure ``p``): ``hydrostatic`` the column
        pressure read at the open-fluid points of :meth:`rebuild` and moved hydrostatically back
        to their nodes (the fluid's pressure elsewhere, never used); ``linear`` ``p`` itself.
        ``density`` a P1 Function [kg/m³] or a number."""
        if self.column is None:
            return p
        out = self.p_column
        out.x.array[:] = p.x.array
        x, y = self.points[self._nodes], self._probes
        P, rho = self.column.values(y, p, density, self.cut.level_set, with_density=True)
        g = np.zeros(3)
        g[: self.gdim] = self.gravity
        moved = P + rho * ((x - y) @ g)                           # hydrostatically back to the node
        bad = ~np.isfinite(moved)
        if self.cut.comm.allreduce(bool(bad.any()), op=MPI.LOR):    # an offset point left the mesh (collective)
            moved[bad] = self.column.values(x[bad], p, density, self.cut.level_set)
        out.x.array[self._column_of_node[self._nodes]] = np.nan_to_num(moved)
        return out

    def exchange(self, p, node_density: np.ndarray | float, pos: np.ndarray, rot: np.ndarray,
                 centres: np.ndarray) -> None:
        """The static pressure's load on the true surface (hidden samples by the gap's
        interpolation) and on Γ per block, from this step's pressure ``p`` (P1) and the
        density at the mesh vertices ``node_density`` [kg/m³] (a number for one fluid):
        :attr:`surface_force`, :attr:`surface_torque`, :attr:`cut_force`, :attr:`cut_torque`.
        The block's load is the fluid's on Γ minus the one on Γ plus the one on the surface.
        Collective."""
        density = node_density
        if not np.isscalar(node_density):
            self.rho_node.x.array[self.cut.level_dofs] = node_density
            density = self.rho_node
        pressure = self.static_pressure(p, density)
        self.surface_force, self.surface_torque = self.surface.load(
            self.share, pressure, density, self.gravity, self.cut_owner, self.solid_cell, self.filled_cell, pos,
            rot, self.depth)
        force, torque = self.cut.pressure_load(self.nb, centres, pressure, self._unit_weight)
        self.cut_force[:] = 0.0
        self.cut_force[:, : self.gdim] = force * self.depth
        self.cut_torque[:] = torque * self.depth

    @property
    def hidden_measure(self) -> np.ndarray:
        """Length (2D) or area (3D) [m, m²] of each block's hidden surface at the last exchange."""
        return self.surface.hidden_measure

    @property
    def unreached(self) -> int:
        """Blocks hidden all round (no wetted mouth) at the last exchange: no hidden load."""
        return self.surface.unreached

    @property
    def last(self) -> dict:
        """The samples of the last exchange (positions, normals, weights, hidden flags, pressures)."""
        return self.surface.last
