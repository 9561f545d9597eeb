"""Accelerators of the implicit coupling's fixed-point iteration (``coupling.iterations`` > 1).

One pass maps the guessed block velocities x (the fluid's wall velocity) to the velocities
x̃ = H(x) the DEM sub-steps give under the fluid's load; the step is converged when
r = x̃ − x is small. Each pass costs a fluid step, so the number of passes is the cost.

- ``Aitken``: x ← x + ω r with Aitken's Δ² factor ω (Küttler & Wall 2008, Comput. Mech. 43):
  one scalar for all blocks.
- ``InterfaceQuasiNewton``: IQN-ILS (Degroote, Bathe & Vierendeels 2009, Comput. Struct. 87):
  from the passes of this step, the least-squares combination c of the residual differences
  V = [Δr] that cancels r, and x ← x̃ + W c with W = [Δx̃]. It is exact for a linear H once
  the differences span the active directions, so it needs few passes when only a few blocks
  (the loose debris) move, whatever their number.

Both take x and x̃ as flat float arrays of one size and return the next guess; all ranks call
them with the same (replicated) arrays, so they return the same guess.
"""
from __future__ import annotations

import numpy as np


class Aitken:
    """x ← x + ω r, ω from Aitken's Δ² rule, first ω = ``omega``, clipped to [0.05, 1]."""

    def __init__(self, omega: float) -> None:
        self.omega = omega
        self._r_old: np.ndarray | None = None

    def next_guess(self, x: np.ndarray, x_tilde: np.ndarray) -> np.ndarray:
        r = x_tilde - x
        if self._r_old is not None:
            dr = r - self._r_old
            denom = float(dr @ dr)
            if denom > 0:
                self.omega = float(np.clip(-self.omega * (self._r_old @ dr) / denom, 0.05, 1.0))
        self._r_old = r
        return x + self.omega * r


class InterfaceQuasiNewton:
    """IQN-ILS: the first pass relaxed by ``omega``, later ones x ← x̃ + W c with
    c = argmin ‖V c + r‖ over this step's differences (columns whose singular values fall
    below ``rcond`` × the largest are dropped: nearly dependent differences)."""

    def __init__(self, omega: float, rcond: float = 1e-10) -> None:
        self.omega = omega
        self.rcond = rcond
        self._r_prev: np.ndarray | None = None
        self._xt_prev: np.ndarray | None = None
        self._dr: list[np.ndarray] = []
        self._dxt: list[np.ndarray] = []

    def next_guess(self, x: np.ndarray, x_tilde: np.ndarray) -> np.ndarray:
        r = x_tilde - x
        if self._r_prev is not None:
            self._dr.append(r - self._r_prev)
            self._dxt.append(x_tilde - self._xt_prev)
        self._r_prev, self._xt_prev = r, x_tilde.copy()
        if not self._dr:
            return x + self.omega * r
        V = np.column_stack(self._dr)
        W = np.column_stack(self._dxt)
        c = np.linalg.lstsq(V, -r, rcond=self.rcond)[0]
        return x_tilde + W @ c


def accelerator(method: str, omega: float):
    """The accelerator of ``coupling.iteration_method``."""
    if method == "aitken":
        return Aitken(omega)
    if method == "iqn_ils":
        return InterfaceQuasiNewton(omega)
    raise ValueError(f"unknown coupling.iteration_method {method!r}")
