"""Face bonds: forces are the gradient of the stored energy, momentum is conserved,
bending and torsion are resisted, and a DEM step through the interaction hook works."""
from pathlib import Path

import numpy as np
import pytest

from fcm_fsi.dem.builder import assemble
from fcm_fsi.dem.cohesive import CohesiveBonds, CohesiveLaw
from fcm_fsi.geometry import quat_to_matrix_np

SC, DF = 1.0e7, 0.02


def pair(mode="reversible", ppe=3, delta_tc=0.7 * DF):
    s = assemble([[0, 0, 0], [1, 0, 0]], [[1, 0.6, 0.4], [2, 0.6, 0.4]], density=2000.0,
                 sphere_radius=0.1)
    law = CohesiveLaw(sigma_c=SC, delta_f=DF, delta_tc=delta_tc, penalty_factor=1.0, mode=mode)
    return s, s.bonds(law, ppe)


def small_quat(rng, angle):
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    return np.r_[np.cos(angle / 2), np.sin(angle / 2) * axis]


def evaluate(bonds, pos, quat):
    f = np.zeros_like(pos)
    t = np.zeros_like(pos)
    bonds.lam_max[:] = 0.0
    bonds.broken[:] = False
    bonds.compute(pos, quat, f, t)
    return f, t, bonds.stored


def test_force_on_b_is_minus_gradient_of_energy_and_momentum_is_conserved():
    rng = np.random.default_rng(0)
    s, bonds = pair()
    pos = s.pos.copy()
    pos[1] += rng.normal(0, 0.002, 3) + [0.003, 0, 0]
    quat = s.quat.copy()
    quat[1] = small_quat(rng, 0.004)
    f, t, _ = evaluate(bonds, pos, quat)
    h = 1e-8
    grad = np.zeros(3)
    for k in range(3):
        p1, p2 = pos.copy(), pos.copy()
        p1[1, k] += h
        p2[1, k] -= h
        grad[k] = (evaluate(bonds, p1, quat)[2] - evaluate(bonds, p2, quat)[2]) / (2 * h)
    np.testing.assert_allclose(f[1], -grad, rtol=1e-5, atol=1e-6 * np.abs(grad).max())
    # torques are minus the derivative of the energy under small rotations of each block
    from fcm_fsi.dem.integrate import _quat_mul_np
    for blk in (0, 1):
        dgrad = np.zeros(3)
        for k in range(3):
            e = np.zeros(3)
            e[k] = 1.0
            ea = []
            for sgn in (1, -1):
                q = quat.copy()
                q[blk] = _quat_mul_np(np.r_[np.cos(sgn * h / 2), np.sin(sgn * h / 2) * e], quat[blk])
                ea.append(evaluate(bonds, pos, q)[2])
            dgrad[k] = (ea[0] - ea[1]) / (2 * h)
        np.testing.assert_allclose(t[blk], -dgrad, rtol=1e-4, atol=1e-5 * np.abs(t).max())
    np.testing.assert_allclose(f.sum(axis=0), 0.0, atol=1e-9 * np.abs(f).max())
    moment = t.sum(axis=0) + np.cross(pos, f).sum(axis=0)
    np.testing.assert_allclose(moment, 0.0, atol=1e-9 * np.abs(t).max())


def test_bending_and_torsion_stiffness_match_the_face_integrals():
    """Small rotation θ of block b about the face centre: moment k0·I·θ (bending, I of the
    0.6 × 0.4 face) and k_t·J·θ (torsion, J = polar moment), exact with Gauss points."""
    s, bonds = pair(ppe=2, delta_tc=DF)
    k0 = 6.75 * SC / DF
    theta = 1e-7
    c = np.array([1.0, 0.3, 0.2])  # face centre
    for axis, inertia in ((2, 0.4 * 0.6 ** 3 / 12), (1, 0.6 * 0.4 ** 3 / 12),
                          (0, 0.6 * 0.4 * (0.6 ** 2 + 0.4 ** 2) / 12)):
        e = np.eye(3)[axis]
        q = np.r_[np.cos(theta / 2), np.sin(theta / 2) * e]
        R = quat_to_matrix_np(q)
        pos = s.pos.copy()
        pos[1] = c + R @ (s.pos[1] - c)
        quat = s.quat.copy()
        quat[1] = q
        f, t, _ = evaluate(bonds, pos, quat)
        moment_about_c = t[1] + np.cross(pos[1] - c, f[1])
        assert -moment_about_c[axis] == pytest.approx(k0 * inertia * theta, rel=1e-5)


def test_hook_adds_ledger_terms_and_dissipation_increments():
    from fcm_fsi.dem import L_BOND, L_BOND_LOSS, LEDGER_SLOTS
    s, bonds = pair(mode="damage", ppe=2)
    st = s.to_state()
    ledger = np.zeros(LEDGER_SLOTS)
    f = np.zeros((2, 3))
    t = np.zeros((2, 3))
    st.pos[1, 0] += 0.5 * DF
    bonds.add_forces(st, f, t, ledger, 1e-5)
    area = 0.6 * 0.4
    g = 6.75 * 0.5 * 0.25
    assert -f[1, 0] == pytest.approx(area * SC * g, rel=1e-12)
    psi = 6.75 * (0.5 ** 2 / 2 - 2 * 0.5 ** 3 / 3 + 0.5 ** 4 / 4)
    # damage: stored = secant energy ½·g(λ)·λ, the rest of ψ(λ) is lost; they sum to ψ
    assert ledger[L_BOND] == pytest.approx(area * SC * DF * 0.5 * g * 0.5, rel=1e-12)
    assert ledger[L_BOND_LOSS] == pytest.approx(area * SC * DF * (psi - 0.5 * g * 0.5), rel=1e-12)
    ledger[:] = 0.0
    bonds.add_forces(st, f, t, ledger, 1e-5)  # same opening: nothing new dissipated
    assert ledger[L_BOND_LOSS] == 0.0
    st.pos[1, 0] += 0.6 * DF  # beyond δ_f: broken for good, everything dissipated
    ledger[:] = 0.0
    bonds.add_forces(st, f, t, ledger, 1e-5)
    assert bonds.broken_bonds().all() and ledger[L_BOND] == 0.0
    assert bonds.dissipated == pytest.approx(area * 9 / 16 * SC * DF, rel=1e-12)
    st.pos[1, 0] -= 1.1 * DF  # back to the bonded position: no force any more
    f[:] = 0.0
    bonds.add_forces(st, f, t, ledger, 1e-5)
    assert np.all(f == 0.0)


def test_checkpoint_restore_continues_identically():
    s, bonds = pair(mode="damage", ppe=2)
    law = bonds.law
    pos1, pos2 = s.pos.copy(), s.pos.copy()
    pos1[1, 0] += 0.4 * DF
    pos2[1, 0] += 0.2 * DF
    f = np.zeros((2, 3))
    t = np.zeros((2, 3))
    bonds.compute(pos1, s.quat, f, t)
    saved = bonds.checkpoint_arrays()
    f[:] = 0.0
    bonds.compute(pos2, s.quat, f, t)
    fresh = s.bonds(law, 2)
    fresh.restore(saved)
    f2 = np.zeros((2, 3))
    fresh.compute(pos2, s.quat, f2, np.zeros((2, 3)))
    np.testing.assert_array_equal(f, f2)
    assert fresh.energies() == bonds.energies()


def test_free_vibration_on_the_dem_stepper_conserves_the_ledger():
    """Four bonded blocks spinning and vibrating freely (reversible, anisotropic bonds: shear
    stiffer than tension, compression stiffer still): the DEM ledger's balance stays at
    integration level — only if the bond forces derive from the stored energy."""
    from fcm_fsi.dem.system import DEMSystem
    s = assemble([[i * 0.5, 0, 0] for i in range(4)], [[(i + 1) * 0.5, 0.4, 0.4] for i in range(4)],
                 density=2400.0, sphere_radius=0.1)
    law = CohesiveLaw(sigma_c=SC, delta_f=DF, delta_tc=0.5 * DF, penalty_factor=2.0, mode="reversible")
    bonds = s.bonds(law, 3)
    st = s.to_state()
    rng = np.random.default_rng(1)
    st.vel[:] = rng.normal(0, 2.0, (4, 3))
    st.set_omega(rng.normal(0, 2.0, (4, 3)))
    system = DEMSystem(st, [bonds], 2e-6, gravity=(0.0, 0.0, 0.0))
    system.run(3000)
    led = system.ledger.last
    assert led["spring"] > 0.05 * led["kinetic_trans"]  # the bonds do work
    assert bonds.lam_max.max() > 0.05 and not bonds.broken.any()
    assert led["balance_rel"] < 1e-5


def test_block_damage_is_the_fraction_of_a_blocks_bonds_that_broke():
    """Blocks 0–1–2 in a row, bond 0 (0, 1) and bond 1 (1, 2) of two points each, block 3
    unbonded: break both points of bond 1 → damage 0, ½, 1, 0; one point of bond 0 broken
    leaves that bond (and the damage) intact."""
    law = CohesiveLaw(sigma_c=SC, delta_f=DF, delta_tc=DF, penalty_factor=1.0, mode="reversible")
    z = np.zeros((4, 3))
    bonds = CohesiveBonds(law, pt_bond=[0, 0, 1, 1], pt_a=[0, 0, 1, 1], pt_b=[1, 1, 2, 2], pt_ra=z, pt_rb=z,
                          pt_na=z, pt_area=np.ones(4), bond_area=np.full(2, 2.0))
    np.testing.assert_array_equal(bonds.block_damage(4), [0.0, 0.0, 0.0, 0.0])
    bonds.broken[[0, 2, 3]] = True
    np.testing.assert_allclose(bonds.block_damage(4), [0.0, 0.5, 1.0, 0.0])


def test_bond_report_ranks_points_by_the_largest_traction_they_carried(tmp_path, capsys):
    """``python -m fcm_fsi bond-report``: λ_max from a checkpoint → σ/σ_c = 27/4 λ(1−λ)²
    (capped at the peak 1 once past λ = 1/3; 0 once broken), most loaded first, located on
    the structure as built; a checkpoint of another structure is refused."""
    import h5py

    from fcm_fsi.cli import main
    from fcm_fsi.config import load_case
    from fcm_fsi.dem.cohesive import shape_g
    from fcm_fsi.dem.model import build_system
    case_path = Path(__file__).resolve().parents[2] / "cases" / "bonded_wall_surge.yaml"
    system = build_system(load_case(case_path).dem)
    bonds = next(it for it in system.interactions if hasattr(it, "broken_bonds"))
    lam = np.zeros(bonds.n_points)
    lam[3], lam[5], lam[7] = 0.2, 0.5, 0.05
    broken = np.zeros(bonds.n_points, bool)
    broken[7] = True
    ck = tmp_path / "checkpoint.h5"
    with h5py.File(ck, "w") as f:
        f["globals/dem_int1__bond_lam_max"] = lam
        f["globals/dem_int1__bond_broken"] = broken
    assert main(["bond-report", str(case_path), str(ck), "--top", "3"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith(f"{bonds.n_points} bond points, 1 broken, 1 past the peak")
    rows = [line.split() for line in out[2:]]
    assert [int(r[0]) for r in rows[:2]] == [5, 3]
    assert float(rows[0][-1]) == pytest.approx(1.0) and float(rows[1][-1]) == pytest.approx(shape_g(0.2), abs=1e-3)
    x = system.state.pos[bonds.pt_a[3]] + bonds.pt_ra[3]
    assert [float(v) for v in rows[1][3:6]] == pytest.approx(list(x), abs=0.006)
    with h5py.File(ck, "w") as f:
        f["globals/dem_int1__bond_lam_max"] = np.zeros(bonds.n_points + 1)
    assert main(["bond-report", str(case_path), str(ck)]) == 2
    assert "not this case's checkpoint" in capsys.readouterr().err
