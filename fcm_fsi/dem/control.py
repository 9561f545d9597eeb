"""Controlled blocks (DEM tutorial §3): per block and world DOF (x, y, z, rx, ry, rz)

- ``free``          nothing imposed
- ``force``         constant force [N] (or torque [N m]) added every step
- ``velocity``      velocity [m/s] (or angular velocity [rad/s]) imposed every step
- ``displacement``  displacement [m] (or rotation [rad]) u(t) = value·min(t/ramp, 1)
                    imposed by setting the step's velocity to (u(t+Δt) − u(t))/Δt

The reaction that enforces an imposed velocity is R = m (v_imposed − v_kicked)/Δt
(for rotation (L_imposed − L_kicked)/Δt); it enters the ledger as control work and the
force–displacement series.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..geometry import quat_to_matrix_np
from .integrate import omega_from_angmom

MODES = ("free", "force", "velocity", "displacement")


@dataclass
class Control:
    block: int
    modes: tuple[str, ...]        # 6 entries
    values: tuple[float, ...]     # 6 entries
    ramp: float = 0.0


class Controls:
    """All controlled blocks; ``pos0`` is each block's position at t = 0 (for u)."""

    def __init__(self, controls: list[Control], state):
        self.items = list(controls)
        self.pos0 = np.array([state.pos[c.block] for c in self.items]).reshape(-1, 3)
        self.F = np.zeros_like(state.pos)    # control force on each block this step
        self.T = np.zeros_like(state.pos)

    def _target(self, c: Control, d: int, t: float, dt: float) -> float:
        if c.modes[d] == "velocity":
            return c.values[d]
        def frac(s: float) -> float:
            return min(s / c.ramp, 1.0) if c.ramp > 0 else 1.0
        return c.values[d] * (frac(t + dt) - frac(t)) / dt

    def add_forces(self, force, torque) -> None:
        """Prescribed forces/torques (before the kick)."""
        self.F[:] = 0.0
        self.T[:] = 0.0
        for c in self.items:
            for d in range(6):
                if c.modes[d] == "force":
                    (self.F if d < 3 else self.T)[c.block, d % 3] += c.values[d]
        force += self.F
        torque += self.T

    def enforce(self, state, dt: float) -> None:
        """Impose velocity/displacement DOFs after the kick; record reactions."""
        t = state.t
        for c in self.items:
            b = c.block
            m = state.mass[b]
            for d in range(3):
                if c.modes[d] in ("velocity", "displacement"):
                    v = self._target(c, d, t, dt)
                    self.F[b, d] += m * (v - state.vel[b, d]) / dt
                    state.vel[b, d] = v
            if any(c.modes[d] in ("velocity", "displacement") for d in range(3, 6)):
                w = np.zeros((1, 3))
                omega_from_angmom(state.quat[b:b + 1], state.angmom[b:b + 1], state.inertia[b:b + 1], w)
                for d in range(3, 6):
                    if c.modes[d] in ("velocity", "displacement"):
                        w[0, d - 3] = self._target(c, d, t, dt)
                R = quat_to_matrix_np(state.quat[b])
                L_new = R @ (state.inertia[b] * (R.T @ w[0]))
                self.T[b] += (L_new - state.angmom[b]) / dt
                state.angmom[b] = L_new

    def displacement(self, state) -> np.ndarray:
        return np.array([state.pos[c.block] for c in self.items]).reshape(-1, 3) - self.pos0
