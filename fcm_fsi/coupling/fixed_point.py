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
- ``MultiVectorQuasiNewton``: IQN-MVJ (Bogaers, Kok, Reddy & Franz 2014, Comput. Methods Appl.
  Mech. Eng. 279): the inverse Jacobian J of the residual that IQN-ILS builds from a step's
  passes, J = J₀ + (X − J₀ V) V⁺ (X = [Δx], V = [Δr]), is carried into the next step as its
  J₀; IQN-ILS is J₀ = −I every step. The next step's first update is then a quasi-Newton
  one: the map changes little from step to step (the same blocks in nearly the same water).

All take x and x̃ as flat float arrays of one size and return the next guess; all ranks call
them with the same (replicated) arrays, so they return the same guess. The coupled step calls
``start_step()`` before a step's first pass and ``end_step(x, x̃)`` with its last pass; only
the multi-vector method carries anything from one step to the next (``arrays()``).
"""
from __future__ import annotations

import numpy as np


class WithinStep:
    """An accelerator whose state lives within a step: nothing to end, carry or restore."""

    def end_step(self, x: np.ndarray, x_tilde: np.ndarray) -> None:
        pass

    def arrays(self) -> dict[str, np.ndarray]:
        """Nothing carries over from one step to the next."""
        return {}

    def load_arrays(self, g: dict[str, np.ndarray]) -> None:
        pass


class Aitken(WithinStep):
    """x ← x + ω r, ω from Aitken's Δ² rule, first ω = ``omega``, clipped to [0.05, 1]."""

    def __init__(self, omega: float) -> None:
        self.omega0 = self.omega = omega
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

    def start_step(self) -> None:
        """A new step: the rule starts again from ``omega``."""
        self.omega, self._r_old = self.omega0, None


class InterfaceQuasiNewton(WithinStep):
    """IQN-ILS: the first pass relaxed by ``omega``, later ones x ← x̃ + W c with
    c = argmin ‖V c + r‖ over this step's differences (columns whose singular values fall
    below ``rcond`` × the largest are dropped: nearly dependent differences)."""

    def __init__(self, omega: float, rcond: float = 1e-10) -> None:
        self.omega = omega
        self.rcond = rcond
        self.start_step()

    def start_step(self) -> None:
        """A new step: this step's differences only."""
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


class MultiVectorQuasiNewton:
    """IQN-MVJ (module docstring): x ← x − J r with J = J₀ + (X − J₀ V) V⁺ from this step's
    differences, J₀ the last step's J (−I at first, when the first update is x + ``omega`` r
    as in IQN-ILS). J₀ + I is held as a low-rank product U Wᵀ (n × k each), so memory and cost
    grow with the passes carried, not with n²; after ``steps`` steps it starts again from −I
    (information from far back, of blocks since set in other contacts, is dropped). V⁺ drops
    the directions whose singular values fall below ``rcond`` × the largest."""

    def __init__(self, omega: float, steps: int, rcond: float = 1e-10) -> None:
        self.omega, self.steps, self.rcond = omega, int(steps), rcond
        self._U = self._W = None        # J₀ = −I + U Wᵀ; None: J₀ = −I
        self.carried = 0                # steps whose differences J₀ holds
        self.start_step()

    def start_step(self) -> None:
        """A new step: no differences of its own yet; J₀ the last step's J."""
        self._x_prev: np.ndarray | None = None
        self._r_prev: np.ndarray | None = None
        self._dx: list[np.ndarray] = []
        self._dr: list[np.ndarray] = []

    def _record(self, x: np.ndarray, r: np.ndarray) -> None:
        if self._r_prev is not None:
            self._dx.append(x - self._x_prev)
            self._dr.append(r - self._r_prev)
        self._x_prev, self._r_prev = x.copy(), r.copy()

    def _apply_j0(self, v: np.ndarray) -> np.ndarray:
        """J₀ v for a vector or the columns of a matrix ``v``."""
        out = -v
        if self._U is not None:
            out = out + self._U @ (self._W.T @ v)
        return out

    def _update(self) -> tuple[np.ndarray, np.ndarray] | None:
        """J − J₀ = (X − J₀ V) V⁺ as factors (n × k, k × n), or None without differences."""
        if not self._dr:
            return None
        V, X = np.column_stack(self._dr), np.column_stack(self._dx)
        return X - self._apply_j0(V), np.linalg.pinv(V, rcond=self.rcond)

    def next_guess(self, x: np.ndarray, x_tilde: np.ndarray) -> np.ndarray:
        r = x_tilde - x
        self._record(x, r)
        if self._U is None and not self._dr:
            return x + self.omega * r
        step = self._apply_j0(r)
        update = self._update()
        if update is not None:
            step = step + update[0] @ (update[1] @ r)
        return x - step

    def end_step(self, x: np.ndarray, x_tilde: np.ndarray) -> None:
        """The step's last pass (``x``, ``x̃``): its J becomes the next step's J₀."""
        self._record(x, x_tilde - x)
        update = self._update()
        if update is None:
            return
        if self.carried >= self.steps:
            self._U = self._W = None
            self.carried = 0
        A, B = update
        if self._U is not None:
            A, B = np.hstack([self._U, A]), np.vstack([self._W.T, B])
        # C order, as arrays() copies them: a restart then repeats the products to the bit
        self._U, self._W = np.ascontiguousarray(A), np.ascontiguousarray(B.T)
        self.carried += 1

    def arrays(self) -> dict[str, np.ndarray]:
        """J₀ (its factors and the steps it holds): checkpoints and retaken steps."""
        if self._U is None:
            return {"coupling__mvj_steps": np.zeros(1)}
        return {"coupling__mvj_u": self._U.copy(), "coupling__mvj_w": self._W.copy(),
                "coupling__mvj_steps": np.array([float(self.carried)])}

    def load_arrays(self, g: dict[str, np.ndarray]) -> None:
        """Inverse of :meth:`arrays` (absent: J₀ = −I)."""
        if "coupling__mvj_u" in g:
            self._U, self._W = (np.ascontiguousarray(g[k]) for k in ("coupling__mvj_u", "coupling__mvj_w"))
            self.carried = int(g["coupling__mvj_steps"][0])
        else:
            self._U = self._W = None
            self.carried = 0


def accelerator(method: str, omega: float, steps: int = 1):
    """The accelerator of ``coupling.iteration_method`` (``steps``: ``coupling.iteration_reuse``,
    the steps IQN-MVJ carries)."""
    if method == "aitken":
        return Aitken(omega)
    if method == "iqn_ils":
        return InterfaceQuasiNewton(omega)
    if method == "iqn_mvj":
        return MultiVectorQuasiNewton(omega, steps)
    raise ValueError(f"unknown coupling.iteration_method {method!r}")
