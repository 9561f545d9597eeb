"""The convergence check of the coarse verification levels (registry.error_order)."""
from __future__ import annotations

import math

from fcm_fsi.verify.registry import error_order

REF = 6.185333          # Schäfer–Turek 3D-1Z c_D


def test_observed_order_of_the_quick_meshes():
    """cylinder_3d1z quick: c_D 7.76324 at h_cyl 0.03, 7.19530 at 0.02: order 1.10 ≥ 1."""
    assert math.isclose(math.log(1.577907 / 1.009967) / math.log(1.5), 1.1004, rel_tol=1e-3)
    m = error_order("c_D_order", 7.76324, 7.19530, REF, 1.5, 1.0)
    assert m.passed and math.isclose(m.value, math.log(1.577907 / 1.009967) / math.log(1.5), rel_tol=1e-3)


def test_a_shift_away_from_the_reference_fails_first_order():
    shift = 0.03 * REF
    assert not error_order("c_D_order", 7.76324 + shift, 7.19530 + shift, REF, 1.5, 1.0).passed


def test_direction_only_and_reversed_trend():
    assert error_order("c", 7.566, 7.364, REF, 1.5, 0.0).passed            # cut c_D: order 0.39 > 0
    assert not error_order("c", 7.364, 7.566, REF, 1.5, 0.0).passed        # moving away
    assert not error_order("c", 7.0, 7.0, REF, 1.5, 0.0).passed            # no change
