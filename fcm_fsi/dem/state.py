"""DEM state as plain float64/int64 arrays (struct of arrays), SI units throughout.

Blocks (rigid bodies, ``nb`` of them), all world frame unless stated:

===================  ==========  ======  ==================================================
array                shape       unit    meaning
===================  ==========  ======  ==================================================
``pos``              (nb, 3)     m       centre of mass
``quat``             (nb, 4)     -       orientation, unit quaternion (w, x, y, z);
                                         body→world rotation ``x_w = R(q) x_b``
``vel``              (nb, 3)     m/s     centre-of-mass velocity
``omega``            (nb, 3)     rad/s   angular velocity, world frame
``angmom``           (nb, 3)     kg m²/s angular momentum about the centre of mass, world
                                         frame. The integrator's primary rotational
                                         variable; ``omega`` is derived from it after every
                                         step (``omega = R diag(1/I) Rᵀ angmom``). Use
                                         :meth:`DEMState.set_omega` to set spins.
``mass``             (nb,)       kg      block mass
``inertia``          (nb, 3)     kg m²   principal moments; the body frame IS the
                                         principal frame
``ext_force``        (nb, 3)     N       external force input (the fluid's), held
                                         constant over a DEM step
``ext_torque``       (nb, 3)     N m     external torque about the centre of mass
``fixed``            (nb,)       bool    block never moves (walls built of spheres)
===================  ==========  ======  ==================================================

Spheres (``ns`` of them), each rigidly attached to one block. Spheres are stored
**sorted by block**: the spheres of block ``b`` are ``blk_sph_start[b]:blk_sph_start[b+1]``.

===================  ==========  ======  ==================================================
``sph_block``        (ns,)       int64   owning block
``sph_local``        (ns, 3)     m       centre offset from the block's centre of mass,
                                         body (principal) frame
``sph_radius``       (ns,)       m       radius
``sph_material``     (ns,)       int64   index into the material table
``sph_pos``          (ns, 3)     m       world centre, refreshed by :meth:`update_spheres`
                                         (derived, but kept so kernels need not rebuild it)
``blk_sph_start``    (nb + 1,)   int64   CSR offsets of each block's spheres
===================  ==========  ======  ==================================================

Time ``t`` [s] and ``step`` (int) complete the state. Velocities are those of the
leapfrog half step ``n - 1/2`` between steps (see ``integrate.py``); positions and
orientations are at step ``n``.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..geometry import quat_to_matrix_np


@dataclass
class DEMState:
    """All per-block and per-sphere arrays of a DEM model (see module docstring)."""

    pos: np.ndarray
    quat: np.ndarray
    vel: np.ndarray
    omega: np.ndarray
    angmom: np.ndarray
    mass: np.ndarray
    inertia: np.ndarray
    ext_force: np.ndarray
    ext_torque: np.ndarray
    fixed: np.ndarray
    sph_block: np.ndarray
    sph_local: np.ndarray
    sph_radius: np.ndarray
    sph_material: np.ndarray
    sph_pos: np.ndarray
    blk_sph_start: np.ndarray
    t: float = 0.0
    step: int = 0
    extra: dict = field(default_factory=dict)

    @property
    def nb(self) -> int:
        return self.pos.shape[0]

    @property
    def ns(self) -> int:
        return self.sph_block.shape[0]

    @classmethod
    def from_blocks(cls, pos, quat, mass, inertia, sph_block, sph_local, sph_radius,
                    sph_material=None, vel=None, omega=None, fixed=None) -> DEMState:
        """Assemble a state; spheres are re-ordered by block (stable) if needed."""
        pos = np.array(pos, dtype=np.float64).reshape(-1, 3)
        nb = pos.shape[0]
        sph_block = np.asarray(sph_block, dtype=np.int64)
        order = np.argsort(sph_block, kind="stable")
        sph_block = sph_block[order]
        sph_local = np.array(sph_local, dtype=np.float64).reshape(-1, 3)[order]
        sph_radius = np.array(sph_radius, dtype=np.float64).reshape(-1)[order]
        ns = sph_block.shape[0]
        mat = np.zeros(ns, np.int64) if sph_material is None else \
            np.asarray(sph_material, dtype=np.int64).reshape(-1)[order]
        counts = np.bincount(sph_block, minlength=nb)
        if counts.shape[0] != nb or np.any(counts == 0):
            raise ValueError("every block needs at least one sphere and sph_block must be < nb")
        start = np.zeros(nb + 1, np.int64)
        np.cumsum(counts, out=start[1:])
        z = np.zeros((nb, 3))
        st = cls(pos=pos, quat=np.array(quat, dtype=np.float64).reshape(nb, 4),
                 vel=z.copy() if vel is None else np.array(vel, dtype=np.float64).reshape(nb, 3),
                 omega=z.copy(), angmom=z.copy(),
                 mass=np.array(mass, dtype=np.float64).reshape(nb),
                 inertia=np.array(inertia, dtype=np.float64).reshape(nb, 3),
                 ext_force=z.copy(), ext_torque=z.copy(),
                 fixed=np.zeros(nb, bool) if fixed is None else np.asarray(fixed, bool).reshape(nb),
                 sph_block=sph_block, sph_local=sph_local, sph_radius=sph_radius,
                 sph_material=mat, sph_pos=np.zeros((ns, 3)), blk_sph_start=start)
        st.quat /= np.linalg.norm(st.quat, axis=1)[:, None]
        if omega is not None:
            st.set_omega(np.array(omega, dtype=np.float64).reshape(nb, 3))
        st.update_spheres()
        return st

    def rotation_matrices(self) -> np.ndarray:
        """(nb, 3, 3) body→world rotation matrices R(q)."""
        return quat_to_matrix_np(self.quat)

    def set_omega(self, omega: np.ndarray) -> None:
        """Set world angular velocities and the matching angular momenta L = R I Rᵀ ω."""
        R = self.rotation_matrices()
        w_b = np.einsum("bji,bj->bi", R, omega)
        self.angmom[:] = np.einsum("bij,bj->bi", R, self.inertia * w_b)
        self.omega[:] = omega

    def update_spheres(self) -> None:
        """Refresh ``sph_pos`` = pos[block] + R(q[block]) sph_local."""
        R = self.rotation_matrices()
        self.sph_pos[:] = self.pos[self.sph_block] + np.einsum(
            "sij,sj->si", R[self.sph_block], self.sph_local)

    def arrays(self) -> dict[str, np.ndarray]:
        """Name → array of every stored array (for checkpoints)."""
        names = ("pos", "quat", "vel", "omega", "angmom", "mass", "inertia", "ext_force",
                 "ext_torque", "fixed", "sph_block", "sph_local", "sph_radius", "sph_material",
                 "sph_pos", "blk_sph_start")
        return {n: getattr(self, n) for n in names}


def kinetic_energy(state: DEMState, mass: np.ndarray, inertia: np.ndarray) -> float:
    """Translational + rotational kinetic energy [J] of the blocks that are not fixed, with the
    masses ``mass`` (nb,) [kg] and principal inertias ``inertia`` (nb, 3) [kg m²] given (a coupled
    run passes the blocks' own, without the added mass)."""
    w_body = np.einsum("bji,bj->bi", state.rotation_matrices(), state.omega)
    e = 0.5 * (mass * (state.vel ** 2).sum(axis=1) + (inertia * w_body ** 2).sum(axis=1))
    return float(e[~state.fixed].sum())
