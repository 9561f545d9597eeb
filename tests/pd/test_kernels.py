"""The Numba kernels of fcm_fsi/pd against their NumPy twins (fcm_fsi/pd/reference.py), and the
bond lists against all pairs."""
import numpy as np
import pytest

from fcm_fsi.pd import forces, neighbours
from fcm_fsi.pd import reference as ref
from fcm_fsi.pd.lattice import lattice_points
from fcm_fsi.pd.neighbours import compress, notch_array, transpose


def same_lists(a, b):
    (oa, na), (ob, nb) = a, b
    assert np.array_equal(oa, ob)
    for p in range(len(oa) - 1):
        assert np.array_equal(np.sort(na[oa[p]:oa[p + 1]]), nb[ob[p]:ob[p + 1]])


@pytest.mark.parametrize("dim", [2, 3])
def test_cell_binned_bonds_are_all_pairs_within_each_points_horizon(dim):
    rng = np.random.default_rng(3)
    x = lattice_points([0.0] * dim, [1.0, 0.7, 0.5][:dim], 0.1 if dim == 2 else 0.125)
    x[:, :dim] += rng.uniform(-0.02, 0.02, (len(x), dim))
    horizon = rng.uniform(0.15, 0.35, len(x))          # a horizon per point: the dual form's H_p
    got = neighbours.bond_lists(x, horizon)
    same_lists(got, ref.bond_lists(x, horizon))
    offsets, nbr = got
    owner = np.repeat(np.arange(len(x)), np.diff(offsets))
    assert (np.linalg.norm(x[nbr] - x[owner], axis=1) <= horizon[owner] * (1 + 1e-12)).all()
    assert len(nbr) > 5 * len(x)


def test_notch_filter_matches_the_twin_and_cuts_only_crossing_bonds():
    x = lattice_points([0, 0], [1, 1], 0.05)
    offsets, nbr = neighbours.bond_lists(x, np.full(len(x), 0.16))
    notches = notch_array([((0.5, 0.0), (0.5, 0.5))], 2)
    keep = neighbours.notch_keep(x, offsets, nbr, notches)
    assert np.array_equal(keep, ref.notch_keep(x, offsets, nbr, notches))
    owner = np.repeat(np.arange(len(x)), np.diff(offsets))
    side = np.sign(x[:, 0] - 0.5)
    cross_low = (side[owner] != side[nbr]) & (np.maximum(x[owner, 1], x[nbr, 1]) < 0.5)
    assert not keep[cross_low].any() and keep[side[owner] == side[nbr]].all()
    x3 = lattice_points([0, 0, 0], [0.5, 0.5, 0.5], 0.05)
    o3, n3 = neighbours.bond_lists(x3, np.full(len(x3), 0.11))
    rect = notch_array([((0.25, 0.0, 0.0), (0.25, 0.3, 0.0), (0.25, 0.0, 0.5))], 3)
    k3 = neighbours.notch_keep(x3, o3, n3, rect)
    assert np.array_equal(k3, ref.notch_keep(x3, o3, n3, rect)) and 0 < (~k3).sum() < len(k3)


def body(seed=0, broken=0.1):
    """A perturbed 2D lattice body with some bonds broken: the kernels' arguments."""
    rng = np.random.default_rng(seed)
    x = lattice_points([0, 0], [0.3, 0.2], 0.01)
    horizon = rng.uniform(0.025, 0.04, len(x))
    offsets, nbr = neighbours.bond_lists(x, horizon)
    offsets, nbr = compress(offsets, nbr, np.ones(len(nbr), bool))
    owner = np.repeat(np.arange(len(x)), np.diff(offsets))
    dual_offsets, dual_bond = transpose(offsets, nbr)
    length = np.linalg.norm(x[nbr] - x[owner], axis=1)
    beta = rng.uniform(0.5, 1.0, len(nbr))
    intact = (rng.uniform(size=len(nbr)) > broken).astype(np.uint8)
    y = x + rng.normal(0.0, 1e-4, x.shape)
    modulus, vol = rng.uniform(1e12, 2e12, len(x)), rng.uniform(0.9e-4, 1.1e-4, len(x))
    s0 = rng.uniform(0.0, 0.03, len(nbr))
    return dict(y=y, offsets=offsets, nbr=nbr, owner=owner, dual_offsets=dual_offsets, dual_bond=dual_bond,
                length=length, beta=beta, intact=intact, modulus=modulus, vol=vol, s0=s0)


def test_force_density_matches_the_twin_and_conserves_momentum():
    b = body()
    args = [b[k] for k in ("y", "offsets", "nbr", "dual_offsets", "dual_bond", "owner", "length", "beta", "intact",
                           "modulus", "vol")]
    f, g = np.zeros_like(b["y"]), np.zeros_like(b["y"])
    forces.force_density(*args, f)
    ref.force_density(*args, g)
    scale = np.abs(g).max()
    assert scale > 0 and np.abs(f - g).max() <= 1e-12 * scale
    total = (f * b["vol"][:, None]).sum(axis=0)                 # Newton's third law per bond
    assert np.abs(total).max() <= 1e-12 * (np.abs(f) * b["vol"][:, None]).sum()


def test_bond_breaking_and_damage_match_the_twins():
    b = body(seed=1)
    args = lambda intact: [b["y"], b["offsets"], b["nbr"], b["length"], b["beta"], b["s0"], intact,  # noqa: E731
                           b["modulus"], b["vol"]]
    i1, i2 = b["intact"].copy(), b["intact"].copy()
    e1, r1 = forces.break_bonds(*args(i1))
    e2, r2 = ref.break_bonds(*args(i2))
    assert np.array_equal(i1, i2) and (i1 <= b["intact"]).all() and (i1 < b["intact"]).any()
    assert np.allclose(e1, e2, rtol=1e-12, atol=0) and np.allclose(r1, r2, rtol=1e-12, atol=0)
    d1 = forces.damage(b["offsets"], b["nbr"], b["beta"], i1, b["vol"])
    d2 = ref.damage(b["offsets"], b["nbr"], b["beta"], i1, b["vol"])
    assert np.allclose(d1, d2, rtol=0, atol=1e-14) and 0 < d1.mean() < 1
