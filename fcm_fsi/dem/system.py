"""The DEM system: state + interactions + gravity + controls + ledger, advanced one step.

One step n → n+1 (between steps ``sph_pos`` matches ``pos``/``quat``):

1. ``forces``     zero force/torque/ledger slots; every interaction adds (hook contract in
                  ``fcm_fsi/dem/__init__.py``); then gravity m g, ext_force/ext_torque
                  (the fluid's) and prescribed control forces
2. ``kick``       v += Δt F/m, L += Δt T; control imposes velocity/displacement DOFs
3. ``ledger``     energy bookkeeping (optional, every step when enabled)
4. ``drift``      x += Δt v, q by the split free-rotor flow, ω refreshed; spheres moved

Without controls and ledger and with only the sphere–sphere and wall interactions of a contact
law registered as fused (``laws.py``), the same step runs as two Numba kernels (``fused.py``: the pair kernel, then one pass over
the blocks for the rest), with bit-identical results.
"""
from __future__ import annotations

import math

import numpy as np

from ..io.threads import serial_below
from . import L_DASHPOT, L_FRICTION, L_SPRING, LEDGER_SLOTS
from .bodies import update_sphere_positions
from .contact import HIST, SphereContact
from .control import Controls
from .fused import advance_blocks
from .integrate import drift, kick, omega_from_angmom
from .laws import fused_parts
from .ledger import Ledger
from .state import DEMState
from .wall_contact import WallContact


def critical_time_step(m: float, k: float, h: float) -> float:
    """Δt_cr = 2√(m/k)(√(h²+1) − h) of the leapfrog spring–dashpot (tutorial §6)."""
    return 2.0 * math.sqrt(m / k) * (math.sqrt(h * h + 1.0) - h)


def substep_count(fluid_dt: float, dem_dt: float) -> int:
    """Whole number of DEM steps ``dem_dt`` [s] in one outer step ``fluid_dt`` [s] (the fluid
    step of a coupled run, ``run.dt`` of a pure-DEM run), to 1e-9 relative.

    Raises ValueError naming both steps and the nearest DEM step that divides ``fluid_dt``."""
    if not (fluid_dt > 0 and dem_dt > 0):
        raise ValueError(f"time steps must be > 0: fluid dt = {fluid_dt} s, DEM dt = {dem_dt} s")
    n = max(round(fluid_dt / dem_dt), 1)
    if abs(n * dem_dt - fluid_dt) > 1e-9 * fluid_dt:
        raise ValueError(f"fluid dt = {fluid_dt:.10g} s is not a whole multiple of DEM dt = {dem_dt:.10g} s "
                         f"(ratio {fluid_dt / dem_dt:.10g}); nearest valid DEM dt = {fluid_dt / n:.10g} s "
                         f"({n} sub-steps)")
    return n


def effective_contact_mass(state: DEMState) -> float:
    """Smallest mass a contact can see: per sphere 1/m_eff = 1/m + |r|²/I_min (the block's
    translation plus its softest rotation about the centre of mass), halved (reduced mass of
    two such blocks) when more than one block is free."""
    free = ~state.fixed
    if not np.any(free):
        return math.inf
    b = state.sph_block
    r2 = np.sum(state.sph_local ** 2, axis=1)
    meff = 1.0 / (1.0 / state.mass[b] + r2 / state.inertia[b].min(axis=1))
    m = float(meff[free[b]].min())
    return 0.5 * m if np.count_nonzero(free) > 1 else m


class DEMSystem:
    """Advance a :class:`DEMState` under a list of interactions (see package docstring)."""

    def __init__(self, state: DEMState, interactions: list, dt: float, gravity=(0.0, 0.0, -9.81),
                 controls: Controls | None = None, with_ledger: bool = True):
        self.state = state
        #: the blocks move in the plane z = const (the prisms of a 2D fluid; set by the coupled
        #: model once it knows the mesh's dimension): v_z, ω_x, ω_y held at 0
        self.planar = False
        self.interactions = list(interactions)
        self.dt = float(dt)
        self.gravity = np.asarray(gravity, np.float64)
        self.controls = controls
        self.ledger = Ledger() if with_ledger else None
        self.force = np.zeros((state.nb, 3))
        self.torque = np.zeros((state.nb, 3))
        self.led = np.zeros(LEDGER_SLOTS)
        self.interaction_force = np.zeros((state.nb, 3))
        self._w = np.zeros((state.nb, 3))
        self._wm = np.zeros((state.nb, 3))
        self.vel_prev = state.vel.copy()        # v_{n−1/2} kept for the ledger
        self.angmom_prev = state.angmom.copy()
        self.fuse = True                        # False: always the stage-by-stage step (tests)
        # translational inverse inertia tensors (nb, 3, 3) the kick uses instead of 1/mass when
        # not empty: a block's own mass with its fluid's added-mass tensor (coupled runs with
        # ``coupling.added_mass_model: tensor`` set it every fluid step); not part of the state
        self.inv_mass = np.zeros((0, 3, 3))

    # ------------------------------------------------------------------ stages
    def compute_forces(self) -> None:
        st, f, t = self.state, self.force, self.torque
        f[:] = 0.0
        t[:] = 0.0
        self.led[:] = 0.0
        for it in self.interactions:
            it.add_forces(st, f, t, self.led, self.dt)
        if self.controls is not None:
            self.interaction_force[:] = f
        f += st.mass[:, None] * self.gravity[None, :]
        f += st.ext_force
        t += st.ext_torque
        if self.controls is not None:
            self.controls.add_forces(f, t)

    def _fusable(self):
        """(sphere contact, walls or None) when the step can run fused (module docstring): the
        interactions are those of a contact law registered as fused (``laws.py``)."""
        if not self.fuse or self.ledger is not None or self.controls is not None:
            return None
        return fused_parts(self.interactions)

    def _fused_step(self, contact: SphereContact, walls: WallContact | None) -> None:
        st, dt, led = self.state, self.dt, self.led
        led[:] = 0.0
        es, dd, df = contact.pair_stage(st, dt)
        led[L_SPRING] += es
        led[L_DASHPOT] += dd
        led[L_FRICTION] += df
        nl = contact.neighbours
        if walls is None or walls.hist.shape[1] == 0:
            if getattr(self, "_nowall", None) is None or self._nowall[7].shape[0] != st.ns:
                self._nowall = (np.zeros((0, 4)), np.zeros(0, np.int64), np.zeros((0, 3, 3)), np.zeros(0, np.int64),
                                np.zeros(0, np.int64), 0, np.zeros(0, np.bool_), np.zeros((st.ns, 0, HIST)),
                                np.zeros((st.ns, 0), np.uint8), np.zeros((1, 1, 4)))
            wargs = self._nowall
            clip = contact.clip
        else:
            wargs = (walls.planes, walls.plane_mat, walls.tris, walls.tri_mesh, walls.mesh_mat, len(walls.mesh_mat),
                     walls.until > st.t, walls.hist, walls.held, walls.material_table())
            clip = walls.clip
        es, dd, df = advance_blocks(st.blk_sph_start, st.sph_pos, st.sph_radius, st.sph_material, st.sph_local,
                                    st.pos, st.quat, st.vel, st.omega, st.angmom, st.mass, self.inv_mass, st.inertia, st.fixed,
                                    st.ext_force, st.ext_torque, self.gravity,
                                    nl.sp_start, nl.sp_pair, nl.sp_sign, contact.act, contact.pair_f, contact.pair_x,
                                    *wargs, clip, self.planar, dt, self.force, self.torque)
        led[L_SPRING] += es
        led[L_DASHPOT] += dd
        led[L_FRICTION] += df
        st.t += dt
        st.step += 1

    def step(self) -> None:
        """One DEM step; a small model (``io.threads.serial_below``) runs its kernels on one thread."""
        with serial_below(self.state.sph_pos.shape[0]):
            parts = self._fusable()
            if parts is not None:
                self._fused_step(*parts)
            else:
                self._staged_step()

    def _staged_step(self) -> None:
        st, dt = self.state, self.dt
        self.compute_forces()
        if self.ledger is not None:
            self.vel_prev[:] = st.vel
            self.angmom_prev[:] = st.angmom
            vm, Lm = self.vel_prev, self.angmom_prev
        kick(st.vel, st.angmom, st.mass, self.inv_mass, self.force, self.torque, st.fixed, self.planar, dt)
        if self.controls is not None:
            self.controls.enforce(st, dt)
        if self.ledger is not None:
            omega_from_angmom(st.quat, st.angmom, st.inertia, self._w)      # I(q_n)⁻¹ L_{n+1/2}
            omega_from_angmom(st.quat, Lm, st.inertia, self._wm)             # I(q_n)⁻¹ L_{n−1/2}
            wm = self._wm
            Fc = self.controls.F if self.controls is not None else self._zero()
            Tc = self.controls.T if self.controls is not None else self._zero()
            self.ledger.update(st, self.gravity, self.led, vm, st.vel, Lm, st.angmom, wm, self._w, Fc, Tc, dt)
        drift(st.pos, st.quat, st.vel, st.angmom, st.omega, st.inertia, st.fixed, dt)
        update_sphere_positions(st.pos, st.quat, st.sph_block, st.sph_local, st.sph_pos)
        st.t += dt
        st.step += 1

    def run(self, nsteps: int) -> None:
        for _ in range(int(nsteps)):
            self.step()

    def _zero(self) -> np.ndarray:
        return np.zeros_like(self.force)

    # ------------------------------------------------------------------ checkpoint
    def arrays(self) -> dict[str, np.ndarray]:
        """Copies of everything the DEM carries from step to step (state, contact histories,
        bonds, ledger, controls), by flat names: checkpoint globals and step snapshots."""
        st = self.state
        out = {f"dem__{name}": a.copy() for name, a in st.arrays().items()}
        out["dem__time"] = np.array([st.t, float(st.step)])
        for k, it in enumerate(self.interactions):
            if hasattr(it, "checkpoint_arrays"):
                out.update({f"dem_int{k}__{name}": np.copy(a) for name, a in it.checkpoint_arrays().items()})
        if self.ledger is not None:
            out["dem__ledger"] = np.copy(self.ledger.checkpoint_arrays()["ledger"])
        if self.controls is not None:
            out["dem__controls_pos0"] = np.copy(self.controls.pos0)
        return out

    def load_arrays(self, g: dict[str, np.ndarray]) -> None:
        """Inverse of :meth:`arrays`."""
        st = self.state
        for name, a in st.arrays().items():
            a[...] = g[f"dem__{name}"]
        st.t, st.step = float(g["dem__time"][0]), int(g["dem__time"][1])
        for k, it in enumerate(self.interactions):
            if hasattr(it, "restore"):
                prefix = f"dem_int{k}__"
                it.restore({n[len(prefix):]: np.copy(a) for n, a in g.items() if n.startswith(prefix)})
        if self.ledger is not None and "dem__ledger" in g:
            self.ledger.restore({"ledger": np.copy(g["dem__ledger"])})
        if self.controls is not None and "dem__controls_pos0" in g:
            self.controls.pos0[...] = g["dem__controls_pos0"]

    # ------------------------------------------------------------------ time step
    def critical_time_step(self) -> float:
        """Δt_cr over the stiffest interaction and the lightest effective contact mass."""
        bounds = [it.stiffness_bound() for it in self.interactions if hasattr(it, "stiffness_bound")]
        if not bounds:
            return math.inf
        k = max(b[0] for b in bounds)
        h = max(b[1] for b in bounds)
        return critical_time_step(effective_contact_mass(self.state), k, h)
