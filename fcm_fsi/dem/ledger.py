"""Energy ledger (DEM tutorial §2): how a DEM proves itself.

Evaluated at step n (after the kick, before the drift), in J:

- ``potential``   −Σ m g·x_n over free blocks (datum: the origin)
- ``kinetic_trans`` Σ ½ m v_{n−1/2}·v_{n+1/2} — the leapfrog's own kinetic energy: with it,
  free flight and a linear spring conserve the ledger exactly, so what remains in the
  balance is the error of contacts opening/closing and of the rotation splitting
- ``kinetic_rot`` Σ ½ L_{n−1/2}·I_w(q_n)⁻¹ L_{n+1/2}, the rotational analogue
- ``spring``      stored elastic energy of contact springs and cohesive bonds (interactions)
- ``dashpot_loss``, ``friction_loss``, ``bond_loss``  accumulated dissipation (interactions)
- ``work_external``  Σ_k Δt [F_ext·(v₋+v₊)/2 + T_ext·(ω₋+ω₊)/2] over steps k ≤ n, minus the
  second half of step n, ½Δt F_n·v_{n+1/2}: the work done up to t_n
- ``work_control``   the same with the control forces (prescribed-force DOFs and the
  reactions that enforce prescribed velocity/displacement)
- ``balance_error`` = (potential + kinetic + spring + losses) − (E₀ + work_external +
  work_control), E₀ the first evaluated total; ``balance_rel`` = |balance_error| / E_scale,
  E_scale = max(|E₀|, largest kinetic + spring energy seen so far).
"""
from __future__ import annotations

import numpy as np

from . import L_BOND, L_BOND_LOSS, L_DASHPOT, L_FRICTION, L_SPRING

COLUMNS = {"t": "s", "step": "-", "potential": "J", "kinetic_trans": "J", "kinetic_rot": "J",
           "spring": "J", "dashpot_loss": "J", "friction_loss": "J", "bond_loss": "J",
           "work_external": "J", "work_control": "J", "total": "J", "balance_error": "J",
           "balance_rel": "-"}


class Ledger:
    """Accumulates the dissipation and work integrals and evaluates the balance."""

    def __init__(self):
        self.acc = {"dashpot_loss": 0.0, "friction_loss": 0.0, "bond_loss": 0.0,
                    "work_external": 0.0, "work_control": 0.0}
        self.E0 = None
        self.scale = 0.0
        self.last: dict[str, float] = {}

    def update(self, state, gravity, led, vm, vp, Lm, Lp, wm, wp, F_ctrl, T_ctrl, dt) -> dict:
        """One step's bookkeeping; vm/vp, Lm/Lp are the n∓1/2 velocities and angular momenta,
        wm/wp = I_w(q_n)⁻¹ Lm/Lp."""
        free = ~state.fixed
        m = state.mass[free]
        vbar = 0.5 * (vm + vp)[free]
        wbar = 0.5 * (wm + wp)[free]
        pot = -float(np.sum(m * (state.pos[free] @ np.asarray(gravity))))
        kt = float(0.5 * np.sum(m * np.sum(vm[free] * vp[free], axis=1)))
        kr = float(0.5 * np.sum(Lm[free] * wp[free]))
        a = self.acc
        a["dashpot_loss"] += float(led[L_DASHPOT])
        a["friction_loss"] += float(led[L_FRICTION])
        a["bond_loss"] += float(led[L_BOND_LOSS])
        a["work_external"] += dt * float(np.sum(state.ext_force[free] * vbar) + np.sum(state.ext_torque[free] * wbar))
        a["work_control"] += dt * float(np.sum(F_ctrl[free] * vbar) + np.sum(T_ctrl[free] * wbar))
        # work up to t_n: the step's midpoint work minus its second half ½Δt F_n·v_{n+1/2}
        w_ext = a["work_external"] - 0.5 * dt * float(np.sum(state.ext_force[free] * vp[free])
                                                      + np.sum(state.ext_torque[free] * wp[free]))
        w_ctl = a["work_control"] - 0.5 * dt * float(np.sum(F_ctrl[free] * vp[free]) + np.sum(T_ctrl[free] * wp[free]))
        spring = float(led[L_SPRING] + led[L_BOND])
        total = pot + kt + kr + spring + a["dashpot_loss"] + a["friction_loss"] + a["bond_loss"]
        if self.E0 is None:
            self.E0 = total - w_ext - w_ctl
        self.scale = max(self.scale, abs(self.E0), kt + kr + spring)
        bal = total - (self.E0 + w_ext + w_ctl)
        self.last = {"t": state.t, "step": state.step, "potential": pot, "kinetic_trans": kt,
                     "kinetic_rot": kr, "spring": spring, **a, "work_external": w_ext, "work_control": w_ctl,
                     "total": total,
                     "balance_error": bal, "balance_rel": abs(bal) / self.scale if self.scale > 0 else 0.0}
        return self.last

    def checkpoint_arrays(self) -> dict:
        vals = [self.acc[k] for k in sorted(self.acc)] + [np.nan if self.E0 is None else self.E0, self.scale]
        return {"ledger": np.array(vals)}

    def restore(self, arrays) -> None:
        v = np.asarray(arrays["ledger"])
        for i, k in enumerate(sorted(self.acc)):
            self.acc[k] = float(v[i])
        self.E0 = None if np.isnan(v[-2]) else float(v[-2])
        self.scale = float(v[-1])
