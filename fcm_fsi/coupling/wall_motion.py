"""The wall velocity the fluid gets from the blocks: a stage of the coupled step that owns its
choices (``coupling.wall_velocity``, ``coupling.wall_motion``, ``coupling.load_split``).

Each block's wall nodes get the rigid motion ū = V + Ω × (x − X) of

* the block itself, with the DEM's end-of-step or sub-step-mean v, ω (``wall_velocity``), or
  the iterated unknown of the implicit coupling;
* its bonded cluster (``wall_motion: bonded_cluster``): the blocks joined by intact bonds move
  for the fluid as one rigid body, so the fluid sees the structure's motion, not the bonds'
  ringing (dem_side.cluster_rigid_motion);

blended continuously where two blocks' shapes overlap or nearly touch (``load_split:
shared``) and in the gap fill between blocks (the fill's own weights, fcm/levelset.py).
"""
from __future__ import annotations

import numpy as np

from ..fcm.levelset import NO_SHAPE
from .dem_side import blended_rigid_velocity, bonded_clusters, cluster_rigid_motion, rigid_body_velocity


class WallMotion:
    """The blocks' rigid motion as the fluid sees it. ``coupling`` the case's coupling
    section; ``dem`` the DEMSubcycler; ``bonds`` the cohesive bonds or None; ``levelset`` the
    StructureLevelSet; ``points`` (n, 3) the cut's nodes [m]; ``gyration`` (nb,) [m] the radii
    that scale Ω in the iterated unknown; ``mass`` (nb,) [kg] and ``inertia`` (nb, 3) [kg m²]
    the blocks' own (body frame); ``h_min`` [m] the smallest cell diameter."""

    def __init__(self, coupling, dem, bonds, levelset, points: np.ndarray, gyration: np.ndarray,
                 mass: np.ndarray, inertia: np.ndarray, h_min: float, gdim: int) -> None:
        self.coupling, self.dem, self.bonds, self.levelset = coupling, dem, bonds, levelset
        self.points, self.gyration, self.mass, self.inertia = points, gyration, mass, inertia
        self.h_min, self.gdim = h_min, gdim
        self.nb = len(mass)

    @property
    def by_cluster(self) -> bool:
        """Whether the fluid sees bonded clusters (``coupling.wall_motion: bonded_cluster``)."""
        return self.coupling.wall_motion == "bonded_cluster" and self.bonds is not None

    def bonded_labels(self) -> np.ndarray:
        """(nb,) label of each block's bonded cluster: blocks joined by intact bonds."""
        if self.bonds is None:
            return np.arange(self.nb)
        first = np.unique(self.bonds.pt_bond, return_index=True)[1]      # one point per bond
        intact = ~self.bonds.broken_bonds()[self.bonds.pt_bond[first]]
        return bonded_clusters(self.nb, self.bonds.pt_a[first], self.bonds.pt_b[first], intact)

    def cluster_labels(self) -> np.ndarray:
        """(nb,) label of each block's moving group for the fluid: its bonded cluster with
        ``wall_motion: bonded_cluster``, else the block itself."""
        return self.bonded_labels() if self.by_cluster else np.arange(self.nb)

    def cluster_rigid(self, X: np.ndarray, V: np.ndarray, W: np.ndarray):
        """Per block, the rigid motion (or rigid acceleration: V, W = a, α) of its group
        (:meth:`cluster_labels`; dem_side.cluster_rigid_motion)."""
        st = self.dem.system.state
        R = st.rotation_matrices()
        inertia_world = np.einsum("bij,bj,bkj->bik", R, self.inertia, R)
        return cluster_rigid_motion(X, V, W, self.mass, inertia_world, self.cluster_labels(), st.fixed)

    def motion(self, velocities: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(X, V, Ω) (nb, 3) per block, the rigid motion ū = V + Ω × (x − X) its wall nodes get:
        the DEM's x_c, v, ω (``coupling.wall_velocity``) or ``velocities``, the iterated unknown
        (per block V then Ω × its gyration radius); with ``wall_motion: bonded_cluster`` the
        rigid motion of its bonded cluster."""
        if velocities is None:
            X, V, W = self.dem.motion(mean=self.coupling.wall_velocity == "mean")
        else:
            v = velocities.reshape(2 * self.nb, 3)
            X, V, W = self.dem.system.state.pos, v[: self.nb], v[self.nb:] / self.gyration[:, None]
        if self.by_cluster:
            X, V, W = self.cluster_rigid(X, V, W)
        return X, V, W

    def at_nodes(self, owner: np.ndarray, velocities: np.ndarray | None = None):
        """ū (n, gdim) [m/s] at the cut's nodes owned by the blocks ``owner`` (n,), blended where
        shapes overlap (``load_split: shared``) and in the gap fill; and the shared ownership
        (second owner, weight) or None."""
        motion = self.motion(velocities)
        ubar = self._rigid_velocity(self.points, owner, motion)
        share = None
        if self.coupling.load_split == "shared":
            share = self._shared_ownership(owner, motion, ubar)
        fill = self.levelset.fill_other[:, 0] != NO_SHAPE     # the gap fill: its own blend (continuous ū)
        if fill.any():
            ubar[fill] = self._rigid_velocity(self.points[fill], owner[fill], motion,
                                              self.levelset.fill_other[fill], self.levelset.fill_weight[fill])
        return ubar, share

    def fill_free_to_part(self, owner: np.ndarray) -> np.ndarray:
        """Per node: fill between owners free to part — one a moving block, not both blocks of
        one bonded cluster (the nodes where a pocket's seal may open)."""
        fixed, other = self.dem.system.state.fixed, self.levelset.fill_other[:, 0]
        cluster = self.bonded_labels()
        bonded = (owner >= 0) & (other >= 0)
        bonded[bonded] = cluster[owner[bonded]] == cluster[other[bonded]]
        free = np.append(~fixed, False)          # moving blocks; index −1: static, wall, none
        moving = free[np.where(owner >= 0, owner, -1)] | free[np.where(other >= 0, other, -1)]
        return moving & ~bonded

    def _shared_ownership(self, owner: np.ndarray, motion, ubar: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``load_split: shared``: at each node the nearest other block (second owner) and its
        weight w = max(0, ½ − (d₂ − d₁)/(2 h)), h = h_min, d₁, d₂ the two blocks' signed
        distances; blends ū in place to (1 − w) ū₁ + w ū₂, so load and wall velocity are
        continuous where two blocks' shapes overlap or nearly touch."""
        second = self.levelset.second_owner
        w = np.clip(0.5 - self.levelset.owner_margin / (2.0 * self.h_min), 0.0, 0.5)
        w = np.where((second >= 0) & (owner >= 0), w, 0.0)
        blend = w > 0
        if blend.any():
            ubar[blend] = self._rigid_velocity(self.points[blend], owner[blend], motion, second[blend], w[blend])
        return second, w

    def _rigid_velocity(self, points: np.ndarray, owner: np.ndarray, motion, other=None, weight=None) -> np.ndarray:
        """Wall velocity (n, gdim) [m/s] at ``points`` of the blocks ``owner`` (0 where < 0) from
        the per-block rigid ``motion`` (X, V, Ω); with ``other`` and ``weight`` w, (1 − w)
        times it plus w times that of the blocks ``other``."""
        if other is None:
            return rigid_body_velocity(*motion, points, owner)[:, : self.gdim]
        return blended_rigid_velocity(*motion, points, owner, other, weight)[:, : self.gdim]
