"""The start of the linearised step's Krylov solve (fcm_fsi/fluid/krylov_guess.py)."""
from __future__ import annotations

import numpy as np

from fcm_fsi.fluid.krylov_guess import Increment, IncrementHistory, extrapolated_increment


def _increment(rate, t0: float, t1: float, step: int) -> Increment:
    """The update over [t0, t1] of a quantity whose rate is ``rate(t)`` (exact for a linear rate
    by the midpoint rule)."""
    return Increment(step, t1 - t0, (t1 - t0) * rate(0.5 * (t0 + t1)))


def test_the_extrapolation_is_exact_for_a_rate_linear_in_time_on_unequal_steps():
    rate = lambda t: np.array([2.0 + 3.0 * t, -1.0 + 0.5 * t])      # noqa: E731
    before, last = _increment(rate, 0.0, 0.1, 7), _increment(rate, 0.1, 0.25, 8)
    guess = extrapolated_increment(last, before, 9, 0.3)
    assert np.allclose(guess, 0.3 * rate(0.25 + 0.15), rtol=1e-14)


def test_first_order_with_one_update_a_retaken_step_and_none_when_stale():
    last = Increment(4, 0.2, np.array([1.0, -2.0]))
    assert np.allclose(extrapolated_increment(last, None, 5, 0.1), [0.5, -1.0])   # scaled to the new Δt
    assert np.allclose(extrapolated_increment(last, Increment(1, 0.2, np.zeros(2)), 5, 0.2), [1.0, -2.0])
    assert np.allclose(extrapolated_increment(last, None, 4, 0.1), [0.5, -1.0])   # the same step again
    assert extrapolated_increment(last, None, 6, 0.1) is None                      # steps were skipped
    assert extrapolated_increment(None, None, 1, 0.1) is None


def test_the_history_keeps_two_steps_and_a_retaken_step_replaces_its_own():
    h = IncrementHistory()
    h.record(1, 0.1, np.array([1.0]))
    h.record(2, 0.1, np.array([2.0]))
    h.record(2, 0.05, np.array([0.9]))             # step 2 taken again with half the step
    assert h.last.step == 2 and h.last.dt == 0.05 and h.before.step == 1
    values = np.array([3.0])
    h.record(3, 0.1, values)
    values[:] = 0.0                                 # the history holds a copy
    assert h.last.values[0] == 3.0 and h.before.step == 2
