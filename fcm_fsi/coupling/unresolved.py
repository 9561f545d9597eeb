"""Blocks the fluid mesh cannot resolve (``coupling.unresolved_cells``): taken out of the cut
and loaded as point particles.

Why: a block thinner than about a cell has no mesh node inside it; the continuous P1 pressure
cannot jump across it, its cut cells keep tiny fluid fractions, and its cut-surface load is
spurious — large and erratic while it tumbles through the cells (a front-wall block of the
tsunami case carried into the tank's 1.2 m cells, docs/coupling.md 'Unresolved blocks').

Rule: at every new pose (the cut's full rebuild) a moving block b that the fluid sees is
*unresolved* when

    t_b < unresolved_cells × h(x_b),

t_b its thinnest extent as the fluid sees it (dem_side.fluid_thickness) and h(x_b) the mean
edge length of the cell holding its centre x_b, or when no cell holds x_b (it left the fluid
mesh).
From then on — one way: its shape appearing again inside the flow would be an impulse — the
level set leaves it out (``StructureLevelSet.unseen``) and its load is

    F_b = −ρ V_b g + ½ ρ C_d A_b(ê) |u − v_b| (u − v_b),     T_b = 0,

u and ρ = ρ(φ) the fluid's velocity and density at x_b after the fluid step (none outside the
mesh), v_b the block's velocity, V_b = m_b/ρ_material, C_d ``coupling.unresolved_drag``,
ê = (u − v_b)/|u − v_b| and A_b(ê) = Σ_k |ê·a_k| 4 h_i h_j the projected area of a box block
of half extents h along its axes a_k ({i, j, k} a permutation), π r_V² for other blocks (the
sphere of volume V_b). The fluid does not feel the particle: the momentum it takes from the
water is not given back, so the exchange check leaves these blocks out.
"""
from __future__ import annotations

import numpy as np
from mpi4py import MPI

from ..fcm.levelset import BOX
from ..fluid.phase_field import property_map
from ..fluid.probes import PointValues
from ..io.logging import get_logger
from ..mesh.build import cell_mean_edges
from .dem_side import block_volume

log = get_logger("coupled")


def projected_area(half: np.ndarray, axes: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """Area [m²] (n,) of boxes of half extents ``half`` (n, 3) [m] along their world ``axes``
    (n, 3, 3) (columns) seen along the unit ``direction`` (n, 3): Σ_k |d·a_k| × the face area
    4 h_i h_j normal to a_k."""
    faces = 4.0 * np.stack([half[:, 1] * half[:, 2], half[:, 2] * half[:, 0], half[:, 0] * half[:, 1]], axis=1)
    return (np.abs(np.einsum("nd,ndk->nk", direction, axes)) * faces).sum(axis=1)


def particle_force(u_fluid: np.ndarray, density: np.ndarray, v_block: np.ndarray, volume: np.ndarray,
                   half: np.ndarray, axes: np.ndarray, drag: float, gravity: np.ndarray) -> np.ndarray:
    """Buoyancy and drag [N] (n, 3) on point particles (module docstring): fluid velocity
    ``u_fluid`` (n, 3) [m/s] and ``density`` (n,) [kg/m³] at their centres, their velocity
    ``v_block`` (n, 3), ``volume`` (n,) [m³], box ``half`` extents (n, 3) [m] (NaN rows: not a
    box, the sphere of their volume) along world ``axes`` (n, 3, 3), drag coefficient ``drag``,
    ``gravity`` (3,) [m/s²]."""
    relative = u_fluid - v_block
    speed = np.linalg.norm(relative, axis=1)
    direction = np.divide(relative, speed[:, None], out=np.zeros_like(relative), where=speed[:, None] > 0)
    box = np.isfinite(half).all(axis=1)
    area = np.pi * (3.0 * volume / (4.0 * np.pi)) ** (2.0 / 3.0)
    if box.any():
        area[box] = projected_area(half[box], axes[box], direction[box])
    buoyancy = -(density * volume)[:, None] * gravity[None, :]
    return buoyancy + (0.5 * density * drag * area * speed)[:, None] * relative


class UnresolvedBlocks:
    """Which blocks the fluid leaves out, and their point-particle load (module docstring).
    ``case`` the case; ``mesh`` the fluid mesh; ``state`` the DEM state; ``shapes`` the blocks'
    own level-set primitives (dem_side.shapes_of_blocks without widening); ``thickness`` (nb,)
    [m] their thinnest extent as the fluid sees it; ``fields`` a callable giving the fluid's
    probe fields (``u``, and ``phi`` in a two-phase flow)."""

    def __init__(self, case, mesh, state, shapes, thickness: np.ndarray, fields) -> None:
        cp, fl = case.coupling, case.fluid
        self.factor, self.drag = float(cp.unresolved_cells), float(cp.unresolved_drag)
        self.gdim = mesh.geometry.dim
        self.comm = mesh.comm
        self.gravity = np.zeros(3)
        self.gravity[: len(fl.gravity)] = fl.gravity
        self.density = (fl.density, fl.gas_density if case.phase_field is not None else fl.density)
        seen = np.zeros(state.nb, bool)
        seen[shapes.body[shapes.body >= 0]] = True
        self.candidates = seen & ~state.fixed
        self.thickness = np.asarray(thickness, float)
        # single-box blocks: half extents and box → body axes (the others: NaN, the sphere of their volume)
        count = np.bincount(shapes.body[shapes.body >= 0], minlength=state.nb)
        single = np.flatnonzero((shapes.body >= 0) & (shapes.kind == BOX) & (count[np.maximum(shapes.body, 0)] == 1))
        self.half = np.full((state.nb, 3), np.nan)
        self.box_axes = np.tile(np.eye(3), (state.nb, 1, 1))
        self.half[shapes.body[single]] = shapes.half[single]
        self.box_axes[shapes.body[single]] = shapes.rot[single]
        self.volume = block_volume(case.dem, state)
        self.fields = fields
        self.unseen = np.zeros(state.nb, bool)
        self.points = PointValues(mesh, state.nb) if self.active else None
        self.h_cell = cell_mean_edges(mesh) if self.active else None

    @property
    def active(self) -> bool:
        """Whether ``coupling.unresolved_cells`` > 0."""
        return self.factor > 0 and bool(self.candidates.any())

    def update(self, t: float, pos: np.ndarray) -> np.ndarray:
        """Blocks (indices) newly unresolved at the poses ``pos`` (nb, 3) [m] at ``t`` [s]; they
        join :attr:`unseen`. Collective; the same on every rank."""
        if not self.active:
            return np.zeros(0, np.int64)
        index, cell, found = self.points.cells(pos[:, : self.gdim])
        h = np.zeros(len(pos))
        h[index] = self.h_cell[cell]
        self.comm.Allreduce(MPI.IN_PLACE, h, op=MPI.SUM)
        new = np.flatnonzero(self.candidates & ~self.unseen & (~found | (self.thickness < self.factor * h)))
        for b in new:
            where = (f"in a cell of {h[b]:.3g} m" if found[b] else "outside the fluid mesh")
            log.info("t = %.6g s: block %d (%.3g m thick in the fluid, centre %s m) is %s: out of the cut, loaded "
                     "as a point particle from now on (coupling.unresolved_cells %.3g)", t, b, self.thickness[b],
                     np.array2string(pos[b], precision=3), where, self.factor)
        self.unseen[new] = True
        return new

    def load(self, pos: np.ndarray, vel: np.ndarray, rotation: np.ndarray) -> np.ndarray:
        """The particle force (nb, 3) [N] on the unresolved blocks (0 on the others) with the
        fluid's fields now, at centres ``pos`` (nb, 3) [m], velocities ``vel`` (nb, 3) [m/s] and
        body → world ``rotation`` (nb, 3, 3). Collective."""
        force = np.zeros((len(pos), 3))
        if not self.unseen.any():
            return force
        fields = self.fields()
        names = ["u"] + (["phi"] if "phi" in fields else [])
        values, found = self.points.values([fields[n] for n in names], pos[:, : self.gdim])
        b = np.flatnonzero(self.unseen & found)
        if not b.size:
            return force
        u = np.zeros((b.size, 3))
        u[:, : self.gdim] = values[0][b, : self.gdim]
        rho = property_map(values[1][b, 0], *self.density) if "phi" in fields else np.full(b.size, self.density[0])
        axes = rotation[b] @ self.box_axes[b]
        force[b] = particle_force(u, rho, vel[b], self.volume[b], self.half[b], axes, self.drag, self.gravity)
        return force
