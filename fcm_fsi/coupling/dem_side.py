"""The DEM side of the sub-cycled fluid–DEM coupling (SPEC §3 steps a, d, e; issue #8).

Per fluid step Δt_f the coupling loop

1. asks :func:`shapes_of_blocks` once (at set-up) for the level-set primitives of every
   block in its body frame, and :meth:`DEMSubcycler.pose` each step for where the bodies
   are, so the fluid side can build the structure level set (step a);
2. hands the fluid force and torque on every block to :meth:`DEMSubcycler.advance`, which
   runs the fluid step in whole DEM steps (:meth:`DEMSubcycler.substeps`) with that load held or
   linearly interpolated and records what it delivered (step d);
3. reads :meth:`DEMSubcycler.rigid_velocity` at the fluid's interface points as the
   moving-wall velocity ū of the penalty term (step e).

Parallel runs: the DEM is replicated
------------------------------------
Every rank holds the whole DEM and advances it identically. The fluid force on a block is
a sum over the fluid partition, so every rank must pass the same, allreduced, force and
torque; the DEM kernels are deterministic (independent of the Numba thread count), so the
states then stay bit-identical. :meth:`DEMSubcycler.check_replicated` verifies it
(collective; call it e.g. at every output) and stops every rank with the names of the
arrays that differ.

When the DEM outgrows one rank (the plan, not implemented): decompose the blocks by the
fluid partition — a block belongs to the rank whose fluid subdomain holds its centre of
mass; each rank also keeps *ghost* copies of the blocks within the contact range (largest
block radius + Verlet skin) of its subdomain boundary, so its contacts and cohesive bonds
are complete; owners integrate their blocks and send the new poses and velocities to the
ranks that ghost them after every DEM step (migrating blocks whose centre crossed over);
at each fluid step every owner broadcasts its blocks' poses (a small (nb, 7) allgather)
so that every rank can evaluate the level set of every block near its own cells, and the
fluid force on a block is reduced to its owner only.
"""
from __future__ import annotations

import hashlib
import time
from dataclasses import dataclass
from typing import Literal

import numpy as np

from ..config.dem import DEMConfig
from ..dem.grid_fill import piece_grid
from ..dem.mesh_block import MeshBlock, mesh_block
from ..dem.model import build_structure, described_blocks, grid_fill_of, template_of
from ..dem.state import DEMState
from ..dem.system import DEMSystem, substep_count
from ..fcm.levelset import BOX, MESH, SPHERE, Shapes
from ..geometry import quat_to_matrix_np
from ..geometry.surface_distance import DistanceGrid, distance_grid

__all__ = ["DEMSubcycler", "Exchange", "block_volume", "bonded_clusters", "cluster_rigid_motion", "fluid_gyration_ratio",
           "fluid_thickness", "fluid_volume_ratio", "rigid_body_velocity", "shapes_of_blocks", "state_digests", "substep_count"]

REPLICATED = ("pos", "quat", "vel", "angmom", "ext_force", "ext_torque")   # compared across ranks


# ------------------------------------------------------------------ level-set primitives
def shapes_of_blocks(cfg: DEMConfig, state: DEMState, min_thickness: float = 0.0, structure=None) -> Shapes:
    """Level-set primitives of every block of ``build_state(cfg)`` in its body (principal)
    frame: a box block is one solid box of its size [m], sphere and clump blocks are the union
    of their spheres, a mesh block its surface (:func:`_mesh_shape`; never widened), structure
    blocks are the boxes lo..hi of the builder (its fixed foundation
    has none: it lies under the ground, the fluid never sees it). The world shape of block b is
    ``pos[b] + R(quat[b]) (offset + rot x_shape)``. Box edges shorter than ``min_thickness``
    [m] are widened to it about the box centre (``coupling.min_thickness``:
    a wall thinner than a cell would otherwise fall between the mesh nodes and leak).
    ``structure``: the built ``dem.structure`` when the caller has it (built here otherwise)."""
    parts, first = [], 0
    for key, b, count in described_blocks(cfg):
        blocks = np.arange(first, first + count)
        if b.fill == "bonded_grid":
            parts.extend(_grid_piece_shapes(b, grid_fill_of(cfg, key), first))
        elif b.shape == "mesh":
            density = cfg.materials[cfg.material_index(b.material)].density
            parts.extend(_mesh_shape(b, mesh_block(b, density, key), k) for k in blocks)
        elif b.shape == "box":
            density = cfg.materials[cfg.material_index(b.material)].density
            # R_body: principal → description frame, so the box axes in the body frame are its
            # transpose; the solid box's centre is its centre of mass (offset 0).
            parts.append(_boxes(blocks, np.maximum(0.5 * np.asarray(b.size), 0.5 * min_thickness),
                                template_of(b, density).R_body.T))
        else:
            parts.append(_spheres(state, blocks))
        first += count
    if structure is None:
        structure = build_structure(cfg)
    if structure is not None:   # builder blocks: axis-aligned boxes at identity orientation; the
        seen = ~structure.fixed  # foundation lies under the ground: no shape (the fluid never sees it)
        parts.append(_boxes(first + np.flatnonzero(seen),
                            np.maximum(0.5 * (structure.hi - structure.lo)[seen], 0.5 * min_thickness), np.eye(3)))
        first += structure.nb
    if first != state.nb:
        raise ValueError(f"the DEM config describes {first} blocks but the state has {state.nb}")
    return Shapes.concat(parts)


def block_volume(cfg: DEMConfig, state: DEMState) -> np.ndarray:
    """Per block (nb,): its own volume [m³], mass / its material's density (the material of its
    first sphere)."""
    density = np.array([m.density for m in cfg.materials])
    return state.mass / density[state.sph_material[state.blk_sph_start[:-1]]]


def fluid_volume_ratio(cfg: DEMConfig, state: DEMState, min_thickness: float, gdim: int) -> np.ndarray:
    """Per block (nb,): volume of the shape the fluid sees / the block's own volume, ≥ 1.

    Box and structure blocks thinner than ``min_thickness`` are widened in the fluid's level
    set (:func:`shapes_of_blocks`), so the fluid the wall penalty drags along with such a block
    — its numerical added mass — belongs to the widened shape, not to the true one (a 0.2 m
    wall widened to 0.8 m: ×4). In a 2D fluid the box axis along z is the depth, not seen by
    the fluid, and does not count. 1 for sphere and clump blocks and without widening."""
    ratio = np.ones(state.nb)
    if min_thickness <= 0.0:
        return ratio
    true, wide = shapes_of_blocks(cfg, state), shapes_of_blocks(cfg, state, min_thickness)
    boxes = np.flatnonzero(true.kind == BOX)
    factor = np.where(_depth_axes(true, boxes, state, gdim), 1.0, wide.half[boxes] / true.half[boxes])
    np.multiply.at(ratio, true.body[boxes], np.prod(factor, axis=1))
    return ratio


def fluid_gyration_ratio(cfg: DEMConfig, state: DEMState, min_thickness: float, gdim: int) -> np.ndarray:
    """Per block and principal axis (nb, 3): squared radius of gyration of the shape the fluid
    sees / that of the block's own box, ≥ 1.

    The rotational added inertia of a widened block belongs to the widened shape as much as
    its added mass does (:func:`fluid_volume_ratio`), and it grows faster: a 0.4 m column block
    widened to 0.8 m drags 4× the fluid volume along, at twice the lever arm about its long
    axis — 16× the rotational added inertia, not 4×. For a box of half extents h the squared
    gyration radius about body axis i is (h_j² + h_k²)/3; in a 2D fluid the depth axis is left
    at its own extent (the fluid does not see it). 1 for sphere and clump blocks and without
    widening."""
    ratio = np.ones((state.nb, 3))
    if min_thickness <= 0.0:
        return ratio
    true, wide = shapes_of_blocks(cfg, state), shapes_of_blocks(cfg, state, min_thickness)
    boxes = np.flatnonzero(true.kind == BOX)
    h_true = true.half[boxes]
    h_wide = np.where(_depth_axes(true, boxes, state, gdim), h_true, wide.half[boxes])

    def gyration_body(h):   # (n, 3) squared gyration radii about the body axes
        local = (h[:, [1, 2, 0]] ** 2 + h[:, [2, 0, 1]] ** 2) / 3.0          # about the shape axes
        rot = true.rot[boxes]                                               # shape → body
        return np.einsum("nij,nj,nij->ni", rot, local, rot)                 # diag(rot diag(k²) rotᵀ)

    ratio[true.body[boxes]] = gyration_body(h_wide) / gyration_body(h_true)
    return ratio


def fluid_thickness(cfg: DEMConfig, state: DEMState, min_thickness: float, gdim: int) -> np.ndarray:
    """Per block (nb,): its thinnest extent [m] as the fluid sees it — the shortest edge of a
    box block after the ``min_thickness`` widening (in 2D not the depth along z), the smallest
    sphere diameter of a sphere or clump block, twice the deepest point's depth of a mesh block
    (of the whole solid for the pieces of a bonded grid).
    A wall must be about two cells thick to hold a pressure difference (docs/coupling.md, 'Thin
    walls')."""
    shapes = shapes_of_blocks(cfg, state, min_thickness)
    extent = np.where(shapes.kind[:, None] == BOX, 2.0 * shapes.half, np.inf)
    extent[:, 0] = np.where(shapes.kind == SPHERE, 2.0 * shapes.half[:, 0], extent[:, 0])
    for s in np.flatnonzero(shapes.kind == MESH):           # the deepest point's depth × 2 (a box: its
        start, nx, ny, nz = shapes.grid[s]                  # thinnest edge), to the grid's resolution
        extent[s, 0] = -2.0 * shapes.values[start:start + nx * ny * nz].min()
    boxes = np.flatnonzero(shapes.kind == BOX)
    extent[boxes] = np.where(_depth_axes(shapes, boxes, state, gdim), np.inf, extent[boxes])
    thin = np.full(state.nb, np.inf)
    np.minimum.at(thin, shapes.body, extent.min(axis=1))
    first = 0
    for key, b, count in described_blocks(cfg):     # a bonded grid stands as its whole solid
        if b.fill == "bonded_grid":
            thin[first:first + count] = _whole_solid_thickness(b, grid_fill_of(cfg, key))
        first += count
    return thin


def _whole_solid_thickness(b, fill) -> float:
    """Twice the deepest point's depth [m] of the solid a bonded grid was cut from (its distance
    grid): while bonded, its pieces hold the water as that solid does."""
    return -2.0 * float(_solid_grid(b, fill.surface)[0].values.min())


def _depth_axes(shapes: Shapes, boxes: np.ndarray, state: DEMState, gdim: int) -> np.ndarray:
    """(len(boxes), 3) bool: in a 2D fluid, the box axis that points along z (the depth)."""
    if gdim == 3:
        return np.zeros((len(boxes), 3), bool)
    axes = quat_to_matrix_np(state.quat[shapes.body[boxes]]) @ shapes.rot[boxes]   # columns: axes in world
    return np.abs(axes[:, 2, :]) > 0.5


def _mesh_shape(b, block: MeshBlock, k: int) -> Shapes:
    """Block ``k`` of shape mesh as the fluid sees it: its surface's signed-distance grid
    (node spacing ``sdf_spacing``, default radius/2; reaching ``sdf_margin`` beyond the
    surface, default a quarter of its largest extent), in the body (principal) frame: the
    file's point x is at R_bodyᵀ (x − com)."""
    grid, _ = _solid_grid(b, block.surface)
    to_body = block.template.R_body.T
    return Shapes.mesh(grid, block.surface.corners, origin=-to_body @ block.properties.centre, rot=to_body, body=k)


def _grid_piece_shapes(b, fill, first: int) -> list[Shapes]:
    """The pieces of a bonded grid (blocks ``first`` …) as the fluid sees them: each its signed
    distance max(d_S, d_U) on a grid (dem/grid_fill.py; spacing and margin as a mesh block's), in
    its body (principal) frame."""
    whole, margin = _solid_grid(b, fill.surface)
    key = (b.file, b.scale, b.grid_size, margin, tuple(whole.dims))
    if key not in _PIECE_GRIDS:
        _PIECE_GRIDS.clear()
        _PIECE_GRIDS[key] = [piece_grid(whole, p, fill.origin, fill.size, margin) for p in fill.pieces]
    out = []
    for k, (p, grid) in enumerate(zip(fill.pieces, _PIECE_GRIDS[key])):
        to_body = p.template.R_body.T
        out.append(Shapes.mesh(grid, p.corners, origin=-to_body @ p.properties.centre, rot=to_body, body=first + k))
    return out


def _solid_grid(b, surface) -> tuple[DistanceGrid, float]:
    """The signed-distance grid of the solid of block ``b`` (shape mesh) bounded by ``surface``
    and its margin [m]: node spacing ``sdf_spacing`` (default radius/2), reaching ``sdf_margin``
    (default a quarter of the solid's largest extent) beyond the surface."""
    spacing = b.sdf_spacing if b.sdf_spacing is not None else 0.5 * b.radius
    margin = b.sdf_margin if b.sdf_margin is not None else 0.25 * float(np.ptp(surface.vertices, axis=0).max())
    return _distance_grid(b.file, b.scale, float(spacing), float(margin), surface), float(margin)


_PIECE_GRIDS: dict = {}
_GRIDS: dict = {}


def _distance_grid(file: str, scale: float, spacing: float, margin: float, surface) -> DistanceGrid:
    """:func:`~fcm_fsi.geometry.surface_distance.distance_grid`, kept per (file, scale,
    spacing, margin): the case asks for the blocks' shapes more than once."""
    key = (file, scale, spacing, margin)
    if key not in _GRIDS:
        if len(_GRIDS) > 16:
            _GRIDS.clear()
        _GRIDS[key] = distance_grid(surface, spacing, margin)
    return _GRIDS[key]


def _boxes(blocks: np.ndarray, half, rot) -> Shapes:
    """One box per block: half extents [m] (3,) or (n, 3), shape → body rotation (3, 3)."""
    n = len(blocks)
    return Shapes(kind=np.full(n, BOX), body=blocks, offset=np.zeros((n, 3)),
                  rot=np.broadcast_to(rot, (n, 3, 3)), half=np.broadcast_to(half, (n, 3)))


def _spheres(state: DEMState, blocks: np.ndarray) -> Shapes:
    """The spheres of consecutive ``blocks`` as they are in the state (body frame)."""
    s = slice(state.blk_sph_start[blocks[0]], state.blk_sph_start[blocks[-1] + 1])
    n = s.stop - s.start
    half = np.zeros((n, 3))
    half[:, 0] = state.sph_radius[s]
    return Shapes(kind=np.full(n, SPHERE), body=state.sph_block[s], offset=state.sph_local[s],
                  rot=np.broadcast_to(np.eye(3), (n, 3, 3)), half=half)


# ------------------------------------------------------------------ interface velocity
def rigid_body_velocity(pos: np.ndarray, vel: np.ndarray, omega: np.ndarray, points: np.ndarray,
                        owner: np.ndarray) -> np.ndarray:
    """ū = v_b + ω_b × (x − x_b) [m/s] at ``points`` x (n, 3) [m] of block b = ``owner``;
    points with a negative owner (levelset STATIC −1, NO_SHAPE −2) get ū = 0."""
    points = np.asarray(points, np.float64)
    owner = np.asarray(owner, np.int64)
    u = np.zeros_like(points)
    on = owner >= 0
    b = owner[on]
    u[on] = vel[b] + np.cross(omega[b], points[on] - pos[b])
    return u


def blended_rigid_velocity(pos, vel, omega, points, owner, other, weight) -> np.ndarray:
    """ū = (1 − Σ_k w_k) ū_owner + Σ_k w_k ū_other_k [m/s] at ``points`` (n, 3) [m]: blocks'
    rigid velocities (:func:`rigid_body_velocity`; a negative index — static, wall, none —
    moves with 0) mixed by ``weight`` (n,) or (n, k) over the blocks ``other`` of the same
    shape: the wall velocity where owners meet (the gap fill, ``coupling.load_split: shared``)."""
    other = np.asarray(other, np.int64).reshape(len(points), -1)
    weight = np.asarray(weight, np.float64).reshape(len(points), -1)
    u = (1.0 - weight.sum(axis=1))[:, None] * rigid_body_velocity(pos, vel, omega, points, owner)
    for k in range(other.shape[1]):
        u += weight[:, k, None] * rigid_body_velocity(pos, vel, omega, points, other[:, k])
    return u


def bonded_clusters(nb: int, bond_a: np.ndarray, bond_b: np.ndarray, intact: np.ndarray) -> np.ndarray:
    """Label (nb,) of the cluster each block belongs to: the connected components of the
    blocks over the bonds a–b that are still ``intact`` (an unbonded block is its own cluster)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    a, b = np.asarray(bond_a)[intact], np.asarray(bond_b)[intact]
    graph = coo_matrix((np.ones(len(a)), (a, b)), shape=(nb, nb))
    return connected_components(graph, directed=False)[1]


def cluster_rigid_motion(pos: np.ndarray, vel: np.ndarray, omega: np.ndarray, mass: np.ndarray,
                         inertia_world: np.ndarray, labels: np.ndarray,
                         fixed: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The rigid motion of each block's cluster, per block: (X, V, Ω) (nb, 3) such that
    ū(x) = V + Ω × (x − X) for a point x of the block.

    X, V: the cluster's centre of mass [m] and its velocity [m/s] (momentum / mass);
    Ω = J⁻¹ L [rad/s], L the cluster's angular momentum about X and J its inertia tensor about
    X (``inertia_world`` (nb, 3, 3) the blocks' own tensors in the world frame [kg m²], plus
    the parallel-axis terms of ``mass`` [kg]). So the rigid part of the blocks' motion keeps
    the cluster's momentum and angular momentum, and blocks that move as one rigid body get
    exactly their own velocities back. A cluster holding a ``fixed`` block is at rest
    (V = Ω = 0); a block alone in its cluster keeps its own pos, v, ω exactly."""
    X, V, W = pos.copy(), vel.copy(), omega.copy()
    counts = np.bincount(labels, minlength=labels.max(initial=-1) + 1)
    multi = counts[labels] > 1
    if multi.any():
        lab = labels[multi]
        m = mass[multi]
        nc = counts.size
        M = np.bincount(lab, weights=m, minlength=nc)
        Mg = np.where(M > 0, M, 1.0)
        Xc = np.stack([np.bincount(lab, weights=m * pos[multi, k], minlength=nc) for k in range(3)], 1) / Mg[:, None]
        Vc = np.stack([np.bincount(lab, weights=m * vel[multi, k], minlength=nc) for k in range(3)], 1) / Mg[:, None]
        r = pos[multi] - Xc[lab]
        Iw = inertia_world[multi]
        L_b = np.einsum("bij,bj->bi", Iw, omega[multi]) + m[:, None] * np.cross(r, vel[multi])
        J_b = Iw + m[:, None, None] * (np.einsum("bk,bk->b", r, r)[:, None, None] * np.eye(3)
                                       - np.einsum("bi,bj->bij", r, r))
        Lc = np.zeros((nc, 3))
        Jc = np.zeros((nc, 3, 3))
        np.add.at(Lc, lab, L_b)
        np.add.at(Jc, lab, J_b)
        used = np.unique(lab)
        Wc = np.zeros((nc, 3))
        Wc[used] = np.linalg.solve(Jc[used], Lc[used][..., None])[..., 0]
        anchored = np.zeros(nc, bool)
        anchored[lab[fixed[multi]]] = True
        Vc[anchored] = 0.0
        Wc[anchored] = 0.0
        X[multi], V[multi], W[multi] = Xc[lab], Vc[lab], Wc[lab]
    return X, V, W


# ------------------------------------------------------------------ sub-cycling
@dataclass(frozen=True)
class Exchange:
    """What one fluid step's DEM advance delivered (issue #8 item 3: the DEM half of the
    momentum-exchange check)."""

    n_sub: int                     # DEM steps taken
    impulse: np.ndarray            # (nb, 3) Σ ext_force·dt over the steps [N s] (a fixed
                                   # block passes its share on to the ground)
    angular_impulse: np.ndarray    # (nb, 3) Σ ext_torque·dt, about the centres of mass [N m s]
    wall_seconds: float            # wall time of the DEM steps [s]
    dt_over_dt_cr: float           # DEM dt / Δt_cr, the stability margin (< dem.dt_safety) [-]


class DEMSubcycler:
    """Advance a :class:`DEMSystem` by whole fluid steps under the fluid's load.

    The load of the latest exchange lives in ``state.ext_force`` / ``state.ext_torque``
    (world frame, torque about the centre of mass), so a checkpoint of the state carries
    it; in a fresh state it is zero unless the caller sets it."""

    def __init__(self, system: DEMSystem):
        self.system = system
        self.dem_dt = system.dt        # the case's DEM step [s]; a fluid step takes whole steps no longer
        self.last: Exchange | None = None
        # means of v, ω over the last advance's sub-steps (nb, 3): the displacement / Δt_f [m/s],
        # and [rad/s]; None before the first advance (state that a checkpoint must carry)
        self.mean_velocity: np.ndarray | None = None
        self.mean_omega: np.ndarray | None = None

    def substeps(self, fluid_dt: float) -> int:
        """DEM steps in a fluid step of ``fluid_dt`` [s]: the fewest whole steps no longer than
        the DEM step that fill it exactly (the last fluid step before t_end may be a fraction
        of the others)."""
        return int(np.ceil(fluid_dt / self.dem_dt * (1 - 1e-9)))

    def whole_steps(self, dt: float) -> float:
        """``dt`` [s] rounded down to a whole number (at least one) of DEM steps."""
        return max(np.floor(dt / self.dem_dt * (1 + 1e-9)), 1.0) * self.dem_dt if np.isfinite(dt) else dt

    def halves(self, fluid_dt: float) -> bool:
        """Whether a fluid step of ``fluid_dt`` [s] splits into two of whole DEM steps."""
        n = fluid_dt / self.dem_dt
        return n >= 2 - 1e-9 and abs(n / 2 - round(n / 2)) <= 1e-9

    def advance(self, fluid_dt: float, force: np.ndarray, torque: np.ndarray,
                mode: Literal["hold", "linear"] = "hold") -> None:
        """Run :meth:`substeps` DEM steps of Δt_f / n with the fluid ``force`` (nb, 3) [N] and
        ``torque`` (nb, 3) [N m] on every block, and record the :class:`Exchange` in ``self.last``.

        ``hold``: the new load acts over the whole interval (impulse F·Δt_f).
        ``linear``: the load ramps from the previous exchange's to the new one, sampled at
        the middle (k + ½)/n of each DEM step, so the impulse is the trapezoid
        Δt_f (F_prev + F)/2 — the impulse of a Crank–Nicolson fluid step."""
        if mode not in ("hold", "linear"):
            raise ValueError(f"mode = {mode!r}; allowed: 'hold', 'linear'")
        n = self.substeps(fluid_dt)
        self.system.dt = fluid_dt / n
        try:
            self._advance(n, force, torque, mode)
        finally:
            self.system.dt = self.dem_dt

    def _advance(self, n: int, force: np.ndarray, torque: np.ndarray, mode: str) -> None:
        st, dt = self.system.state, self.system.dt
        F0, T0 = st.ext_force.copy(), st.ext_torque.copy()
        F1, T1 = _per_block(force, st.nb, "force"), _per_block(torque, st.nb, "torque")
        impulse, angular = np.zeros((st.nb, 3)), np.zeros((st.nb, 3))
        v_sum, w_sum = np.zeros((st.nb, 3)), np.zeros((st.nb, 3))
        st.ext_force[:], st.ext_torque[:] = F1, T1
        wall0 = time.perf_counter()
        for k in range(n):
            if mode == "linear":
                s = (k + 0.5) / n
                st.ext_force[:] = (1.0 - s) * F0 + s * F1
                st.ext_torque[:] = (1.0 - s) * T0 + s * T1
            impulse += dt * st.ext_force
            angular += dt * st.ext_torque
            self.system.step()
            v_sum += st.vel      # leapfrog: x_{k+1} = x_k + dt v_{k+1/2}, so Σ v dt is the displacement
            w_sum += st.omega
            if not np.isfinite(st.pos).all():
                break            # diverged: the next step's neighbour search cannot grid NaN; the caller names the block
        wall = time.perf_counter() - wall0
        st.ext_force[:], st.ext_torque[:] = F1, T1
        self.last = Exchange(n, impulse, angular, wall, dt / self.system.critical_time_step())
        self.mean_velocity, self.mean_omega = v_sum / max(n, 1), w_sum / max(n, 1)

    def pose(self) -> tuple[np.ndarray, np.ndarray]:
        """Copies of the centres of mass (nb, 3) [m] and orientations (nb, 4) (w, x, y, z)."""
        st = self.system.state
        return st.pos.copy(), st.quat.copy()

    def motion(self, mean: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(x_c, v, ω) (nb, 3) of every block: centres, and the leapfrog velocities of the last
        half step or, with ``mean``, their means over the last fluid step's sub-steps."""
        st = self.system.state
        if mean and self.mean_velocity is not None:
            return st.pos, self.mean_velocity, self.mean_omega
        return st.pos, st.vel, st.omega

    def rigid_velocity(self, points: np.ndarray, owner: np.ndarray, mean: bool = False) -> np.ndarray:
        """Rigid-body velocity ū [m/s] at ``points`` (n, 3) of block ``owner`` (n,), zero
        where owner < 0. Uses the leapfrog velocities v, ω of the last half step (within
        O(Δt_DEM) of the end of the fluid step), or with ``mean`` their means over the last
        fluid step's sub-steps (``coupling.wall_velocity: mean``)."""
        st = self.system.state
        if mean and self.mean_velocity is not None:
            return rigid_body_velocity(st.pos, self.mean_velocity, self.mean_omega, points, owner)
        return rigid_body_velocity(st.pos, st.vel, st.omega, points, owner)

    def check_replicated(self, comm) -> None:
        """Collective: raise RuntimeError on every rank when the replicated DEM state differs
        between ranks, naming the arrays that differ and the ranks that differ from rank 0."""
        st = self.system.state
        every = comm.allgather(state_digests(st))
        differ = [name for name in every[0] if len({d[name] for d in every}) > 1]
        if differ:
            ranks = [r for r, d in enumerate(every) if d != every[0]]
            raise RuntimeError(
                f"replicated DEM differs between ranks at DEM step {st.step} (t = {st.t:.9g} s): "
                f"{', '.join(differ)} of rank(s) {ranks} differ from rank 0. Every rank must pass "
                f"bit-identical (allreduced) fluid forces and torques to DEMSubcycler.advance")


def state_digests(state: DEMState) -> dict[str, str]:
    """SHA-256 of the bytes of each replicated array, and of (t, step) as ``time``."""
    arrays = {name: getattr(state, name) for name in REPLICATED}
    arrays["time"] = np.array([state.t, state.step], np.float64)
    return {name: hashlib.sha256(np.ascontiguousarray(a).tobytes()).hexdigest() for name, a in arrays.items()}


def _per_block(a, nb: int, what: str) -> np.ndarray:
    a = np.asarray(a, np.float64)
    if a.shape != (nb, 3):
        raise ValueError(f"fluid {what} must have shape ({nb}, 3) (one vector per block), got {a.shape}")
    return a
