"""The coupling's fixed-point accelerators (coupling/fixed_point.py) on linear maps, where the
answers are known: Aitken is the Δ² rule the coupled step used before, and IQN-ILS solves a
map whose active part has rank n in n + 2 passes, however many inactive unknowns there are."""
import numpy as np
import pytest

from fcm_fsi.coupling.fixed_point import Aitken, InterfaceQuasiNewton, accelerator


def _linear_map(n_total: int, n_active: int, seed: int = 0):
    """H(x) = A x + b acting on the first n_active unknowns only (the others are mapped to b):
    the loose debris among the resting blocks. A has eigenvalues down to −1.8, which plain
    iteration (x ← H(x)) cannot converge: the added-mass instability of a light block."""
    rng = np.random.default_rng(seed)
    Q, _ = np.linalg.qr(rng.normal(size=(n_active, n_active)))
    A = np.zeros((n_total, n_total))
    A[:n_active, :n_active] = Q @ np.diag(np.linspace(-1.8, 0.6, n_active)) @ Q.T
    b = rng.normal(size=n_total)
    x_star = np.linalg.solve(np.eye(n_total) - A, b)
    return (lambda x: A @ x + b), x_star


def _passes(acc, H, x_star, tol=1e-10, max_passes=60):
    x = np.zeros_like(x_star)
    for k in range(1, max_passes + 1):
        xt = H(x)
        if np.abs(xt - x).max() <= tol * np.abs(xt).max():
            return k, xt
        x = acc.next_guess(x, xt)
    return max_passes + 1, x


def test_iqn_ils_solves_a_rank_n_linear_map_in_n_plus_two_passes():
    H, x_star = _linear_map(n_total=600, n_active=5)
    passes, x = _passes(InterfaceQuasiNewton(0.5), H, x_star)
    assert passes <= 5 + 2
    np.testing.assert_allclose(x, x_star, rtol=0, atol=1e-8 * np.abs(x_star).max())


def test_iqn_ils_needs_fewer_passes_than_aitken_on_the_unstable_map():
    H, x_star = _linear_map(n_total=600, n_active=5, seed=3)
    iqn, _ = _passes(InterfaceQuasiNewton(0.5), H, x_star)
    ait, _ = _passes(Aitken(0.5), H, x_star)
    assert iqn < ait


def test_aitken_is_the_delta_squared_rule():
    """Two updates by hand: ω₁ = −ω₀ r₀·(r₁ − r₀)/|r₁ − r₀|², clipped to [0.05, 1]."""
    acc = Aitken(0.5)
    x0, xt0 = np.array([0.0, 0.0]), np.array([1.0, 2.0])
    x1 = acc.next_guess(x0, xt0)
    np.testing.assert_allclose(x1, [0.5, 1.0])
    xt1 = np.array([0.8, 1.4])
    r0, r1 = xt0 - x0, xt1 - x1
    omega = -0.5 * (r0 @ (r1 - r0)) / ((r1 - r0) @ (r1 - r0))
    np.testing.assert_allclose(acc.next_guess(x1, xt1), x1 + np.clip(omega, 0.05, 1.0) * r1)


def test_unknown_method_is_refused():
    with pytest.raises(ValueError, match="iteration_method"):
        accelerator("newton", 0.5)


def _steps(acc, A, rhs, tol=1e-10, max_passes=60):
    """Passes per step of a sequence of steps x = A x + b_s (the same map, new data each step),
    each step from the last one's answer, with start_step / end_step as the coupled step calls them."""
    x, passes = np.zeros(A.shape[0]), []
    for b in rhs:
        acc.start_step()
        done = 0
        while done < max_passes:
            done += 1
            xt = A @ x + b
            if np.abs(xt - x).max() <= tol * np.abs(xt).max():
                break
            x = acc.next_guess(x, xt)
        acc.end_step(x, xt)
        passes.append(done)
        x = xt
    return passes


def _unstable_map(n_total, n_active, seed):
    rng = np.random.default_rng(seed)
    Q, _ = np.linalg.qr(rng.normal(size=(n_active, n_active)))
    A = np.zeros((n_total, n_total))
    A[:n_active, :n_active] = Q @ np.diag(np.linspace(-1.8, 0.6, n_active)) @ Q.T
    rhs = rng.normal(size=(8, n_total))
    return A, rhs


def test_iqn_mvj_carries_the_jacobian_so_later_steps_need_one_update():
    """On a map that stays the same from step to step, the Jacobian IQN-MVJ learned in the first
    steps is exact on the active directions: a later step converges after its first update
    (two passes), while IQN-ILS learns it again in every step."""
    A, rhs = _unstable_map(600, 5, seed=1)
    mvj = _steps(accelerator("iqn_mvj", 0.5, steps=100), A, rhs)
    ils = _steps(InterfaceQuasiNewton(0.5), A, rhs)
    assert ils[0] == mvj[0]                  # no Jacobian carried yet: the same first step
    assert max(mvj[3:]) <= 2 < min(ils[3:])


def test_iqn_mvj_starts_again_from_the_identity_after_its_steps():
    """``steps`` = 1: each step's Jacobian is dropped at the end of the next, so it holds one step's passes."""
    A, rhs = _unstable_map(200, 4, seed=2)
    acc = accelerator("iqn_mvj", 0.5, steps=1)
    _steps(acc, A, rhs[:3])
    assert acc.carried == 1 and acc.arrays()["coupling__mvj_u"].shape[1] <= 6


def test_iqn_mvj_state_round_trips_through_its_arrays():
    """A checkpoint or a retaken step puts the carried Jacobian back: the same guesses follow."""
    A, rhs = _unstable_map(100, 5, seed=4)
    acc = accelerator("iqn_mvj", 0.5, steps=10)
    _steps(acc, A, rhs[:2])
    saved = acc.arrays()
    fresh = accelerator("iqn_mvj", 0.5, steps=10)
    fresh.load_arrays(saved)
    assert fresh.carried == acc.carried
    x = np.ones(100)
    for a in (acc, fresh):
        a.start_step()
    np.testing.assert_array_equal(acc.next_guess(x, A @ x + rhs[2]), fresh.next_guess(x, A @ x + rhs[2]))
