"""Where the linearised step's Krylov solve starts: the coming update dU = Uⁿ − Uⁿ⁺¹ of the
(u, p) unknowns extrapolated in time from the updates of the last steps.

The update of a smooth flow changes slowly from step to step, so its extrapolation leaves a small
part of ‖b‖ for the Krylov method to remove (the 2D dam break at a/20: 22 GMRES iterations per
step instead of 26). The stopping rule, ‖b − A dU‖ ≤ rtol ‖b‖, does not depend on the start, so
neither does the accuracy of the solve. A step taken again with the same Δt (an implicit
coupling's later pass) starts from its own last update and solves for that start's correction
(:meth:`fcm_fsi.fluid.navier_stokes.NavierStokes._krylov_system`): the pass then resolves the
response of the flow to the changed wall velocity.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Increment:
    """One step's update dU (this rank's array, ghosts included) over the step Δt (s)."""

    step: int
    dt: float
    values: np.ndarray


def extrapolated_increment(last: Increment | None, before: Increment | None, step: int, dt: float
                           ) -> np.ndarray | None:
    """Estimate of the update of ``step`` (length Δt = ``dt``) from the newest update ``last`` and
    the one ``before`` it: the rate dU/Δt extrapolated linearly to the middle of the new step when
    they are the two steps just before (second order), ``last`` scaled to Δt when it is the step
    before or this same step taken again (an implicit pass, a retry; first order); None without one."""
    if last is None or not 0 <= step - last.step <= 1:
        return None
    rate = last.values / last.dt
    if last.step == step - 1 and before is not None and before.step == step - 2:
        slope = (rate - before.values / before.dt) / (0.5 * (last.dt + before.dt))
        rate = rate + slope * 0.5 * (last.dt + dt)
    return dt * rate


class IncrementHistory:
    """The last two updates of the linearised step (newest last) and the start they give."""

    def __init__(self) -> None:
        self.last: Increment | None = None
        self.before: Increment | None = None

    def record(self, step: int, dt: float, values: np.ndarray) -> None:
        """Keep this update; a step taken again replaces its own earlier update."""
        if self.last is not None and self.last.step != step:
            self.before = self.last
        self.last = Increment(step, dt, values.copy())

    def guess(self, step: int, dt: float) -> np.ndarray | None:
        return extrapolated_increment(self.last, self.before, step, dt)

    def clear(self) -> None:
        self.last = self.before = None
