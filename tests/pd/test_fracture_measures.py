"""The measures of the fracture validation cases (fcm_fsi/verify/cases/pd_fracture.py) on
synthetic damage fields whose answers are known: the crushed zone and radial cracks of a blast,
the crack tip and branch point of a running crack, the wave speeds."""
import math

import numpy as np
import pytest

from fcm_fsi.pd.lattice import lattice_points
from fcm_fsi.verify.cases import pd_fracture as pf
from fcm_fsi.verify.cases.pd import lattice_moduli


def test_rayleigh_speed_matches_the_classical_ratios():
    """ν = 1/4 plane strain (Poisson solid): c_R/c_s = √(2 − 2/√3) = 0.91940; plane stress ν = 1/3
    is the plane-strain root at ν' = ν/(1 + ν) = 1/4, the same ratio."""
    e, rho = 50e9, 2660.0
    cs = math.sqrt(e / 2.5 / rho)
    assert pf.rayleigh_speed(e, rho, "plane_strain") / cs == pytest.approx(math.sqrt(2 - 2 / math.sqrt(3)), rel=1e-9)
    cs = math.sqrt(4.55e9 / (2 * (4 / 3)) / 1230.0)
    assert pf.rayleigh_speed(4.55e9, 1230.0, "plane_stress") / cs == pytest.approx(0.919402, rel=1e-5)


def test_lattice_c11_is_the_stencil_of_pd_elastic_wave():
    c11, _ = lattice_moduli(3.015)
    assert pf.lattice_c11("plane_stress", 3.015) == pytest.approx(c11, rel=1e-12)
    assert pf.classical_c11("plane_strain") == pytest.approx(1.2, rel=1e-12)        # (1−ν)/((1+ν)(1−2ν))


def blast_field(n_cracks: int, crack_len: float, ring: float):
    """A lattice around a hole of radius R = 1 mm (Δx = 0.25 mm): every point within ``ring`` of
    the centre cracked, plus ``n_cracks`` straight radial lines of cracked points out to ``ring`` +
    ``crack_len``."""
    dx = 0.25e-3
    x = lattice_points([-0.01, -0.01], [0.01, 0.01], dx)
    r = np.hypot(x[:, 0], x[:, 1])
    keep = r >= 1e-3
    x, r = x[keep], r[keep]
    ang = np.arctan2(x[:, 1], x[:, 0])
    d = np.zeros(len(x))
    d[r < ring] = 0.6
    for k in range(n_cracks):
        a = 2 * math.pi * k / n_cracks + 0.3
        across = np.abs(r * np.sin(ang - a))
        along = r * np.cos(ang - a)
        d[(across < 0.6 * dx) & (along > 0) & (r < ring + crack_len)] = 0.5
    return x, r, d, dx


@pytest.mark.parametrize("n", [0, 3, 5])
def test_crushed_zone_and_radial_cracks_are_counted_and_measured(n):
    x, r, d, dx = blast_field(n, 4e-3, 2e-3)
    cracked = d >= pf.CRACKED
    rc = pf.crushed_radius(r, cracked, dx)
    assert rc == pytest.approx(2e-3, abs=dx)
    lengths = pf.radial_cracks(x, r, cracked, rc, dx, 3.015 * dx)
    assert len(lengths) == n
    assert all(abs(L - 4e-3) <= 2 * dx for L in lengths)


def test_no_crushed_zone_when_the_wall_ring_is_intact():
    x, r, d, dx = blast_field(0, 0.0, 0.0)
    assert pf.crushed_radius(r, d >= pf.CRACKED, dx) == pytest.approx(r.min())


def test_arrival_times_of_a_ramp_moving_at_a_known_speed():
    """A front v = clip((t − r/c)/τ, 0, 1) at three radii: half the peak arrives at r/c + τ/2."""
    t = np.linspace(0, 10e-6, 2001)
    radii = np.array([0.005, 0.01, 0.02])
    v = np.clip((t[:, None] - radii[None] / 4000.0) / 1e-6, 0.0, 1.0)
    arr = pf.arrival_times(t, v)
    assert np.allclose(arr, radii / 4000.0 + 0.5e-6, atol=1e-12)
    assert np.polyfit(arr, radii, 1)[0] == pytest.approx(4000.0, rel=1e-9)


def y_crack(branch_x: float, angle: float, dx: float = 1e-3):
    """The Homalite plate's points with a straight crack along y = H/2 from the notch tip to
    ``branch_x``, then two branches at ±``angle`` out to x = 0.35 m."""
    x = lattice_points([0, 0], list(pf.PLATE), dx)
    y0 = 0.5 * pf.PLATE[1]
    d = np.zeros(len(x))
    stem = (x[:, 0] >= pf.NOTCH) & (x[:, 0] <= branch_x) & (np.abs(x[:, 1] - y0) < dx)
    d[stem] = 0.5
    for sign in (1, -1):
        yb = y0 + sign * np.tan(angle) * (x[:, 0] - branch_x)
        d[(x[:, 0] > branch_x) & (x[:, 0] <= 0.35) & (np.abs(x[:, 1] - yb) < dx)] = 0.5
    d[(x[:, 0] > 0.39) & (x[:, 1] > 0.195)] = 0.9          # a damaged loaded corner: not the crack
    return x, d, dx


def test_crack_tip_and_branch_point_of_a_y_shaped_crack():
    x, d, dx = y_crack(0.28, math.radians(15))
    assert pf.crack_tip(x, d) == pytest.approx(0.35, abs=dx)
    xb = pf.branch_point(x, d, dx, 4.015 * dx)
    # two groups once the gap between the branches (each 2Δx thick) passes 2Δx: the centrelines
    # 2 (x − x_b) tan 15° > 4Δx apart, i.e. 7.5 mm past the split (one column more at most)
    assert xb is not None and 0.28 + 2 * dx / math.tan(math.radians(15)) - dx <= xb
    assert xb <= 0.28 + 2 * dx / math.tan(math.radians(15)) + dx


def test_a_straight_crack_has_no_branch_point():
    x, d, dx = y_crack(0.36, math.radians(15))
    assert pf.branch_point(x, d, dx, 4.015 * dx) is None
