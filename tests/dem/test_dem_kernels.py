"""Numba DEM kernels against their plain-NumPy references (STYLE rule 4)."""
import numpy as np
import pytest

from fcm_fsi.dem.bodies import box_template, clump_template, update_sphere_positions
from fcm_fsi.dem.contact import HIST, gather_pair_forces, history_held, material_table, pair_forces
from fcm_fsi.dem.contact_reference import pair_forces_ref, wall_forces_ref
from fcm_fsi.dem.integrate import drift, drift_ref, kick
from fcm_fsi.dem.neighbours import build_pairs, build_pairs_ref, carry_history, sphere_pair_map
from fcm_fsi.dem.state import DEMState
from fcm_fsi.dem.wall_contact import closest_point_triangle, wall_forces


def random_state(nb=40, per=3, seed=1, box=0.08):
    rng = np.random.default_rng(seed)
    pos = rng.uniform(0, box, (nb, 3))
    q = rng.normal(size=(nb, 4))
    q /= np.linalg.norm(q, axis=1)[:, None]
    sb = np.repeat(np.arange(nb), per)
    sl = rng.uniform(-0.006, 0.006, (nb * per, 3))
    sr = rng.uniform(0.004, 0.007, nb * per)
    mat = rng.integers(0, 2, nb * per)
    st = DEMState.from_blocks(pos, q, rng.uniform(0.5, 2, nb), rng.uniform(1e-4, 1e-3, (nb, 3)), sb, sl, sr, mat,
                              vel=rng.normal(size=(nb, 3)), omega=rng.normal(size=(nb, 3)) * 10,
                              fixed=rng.uniform(size=nb) < 0.1)
    return st, rng


MAT = (np.array([1e5, 3e5]), np.array([0.8e5, 2e5]), np.array([0.1, 0.3]), np.array([0.5, 0.2]))


def test_sphere_positions_kernel_matches_numpy():
    st, _ = random_state()
    ref = st.sph_pos.copy()
    out = np.zeros_like(ref)
    update_sphere_positions(st.pos, st.quat, st.sph_block, st.sph_local, out)
    np.testing.assert_allclose(out, ref, rtol=0, atol=1e-15)


@pytest.mark.parametrize("skin", [0.0, 0.002])
def test_cell_list_pairs_match_kdtree(skin):
    st, _ = random_state(nb=300, box=0.15)
    p = build_pairs(st.sph_pos, st.sph_radius, st.sph_block, skin)
    r = build_pairs_ref(st.sph_pos, st.sph_radius, st.sph_block, skin)
    assert len(r) > 50
    np.testing.assert_array_equal(p, r)


@pytest.mark.parametrize("zero_rows", [False, True])
def test_pair_forces_match_numpy_reference(zero_rows):
    """zero_rows: a random half of the pairs start with an all-zero history (held = 0), the
    others with a random one — both the skip and the full path, and the held/act flags."""
    st, rng = random_state()
    pairs = build_pairs(st.sph_pos, st.sph_radius, st.sph_block, 0.001)
    hist = rng.normal(scale=1e-4, size=(len(pairs), HIST))
    if zero_rows:
        hist[rng.uniform(size=len(pairs)) < 0.5] = 0.0
    for clip in (True, False):
        h1 = hist.copy()
        held = history_held(h1)
        np.testing.assert_array_equal(held, np.any(hist != 0, axis=1))
        act = rng.integers(0, 2, len(pairs)).astype(np.uint8)      # stale flags must not matter
        pf, px = rng.normal(size=(len(pairs), 3)), rng.normal(size=(len(pairs), 3))   # nor stale forces
        es, dd, df, nc = pair_forces(pairs, h1, held, act, st.sph_pos, st.sph_radius, st.sph_block, st.sph_material,
                                     st.pos, st.vel, st.omega, st.mass, st.fixed, *MAT, clip, 1e-5, pf, px)
        F, T = np.zeros_like(st.pos), np.zeros_like(st.pos)
        s0, sp, sg = sphere_pair_map(pairs, st.ns)
        gather_pair_forces(st.blk_sph_start, st.pos, s0, sp, sg, act, pf, px, F, T)
        Fr, Tr, hr, (er, dr, fr) = pair_forces_ref(pairs, hist, st.sph_pos, st.sph_radius, st.sph_block,
                                                   st.sph_material, st.pos, st.vel, st.omega, st.mass, st.fixed,
                                                   *MAT, clip, 1e-5)
        assert nc > 10
        np.testing.assert_allclose(F, Fr, rtol=1e-10, atol=1e-9)
        np.testing.assert_allclose(T, Tr, rtol=1e-10, atol=1e-11)
        np.testing.assert_allclose(h1, hr, rtol=1e-10, atol=1e-16)
        np.testing.assert_allclose([es, dd, df], [er, dr, fr], rtol=1e-9, atol=1e-15)
        # held ⇔ the new history is non-zero; in contact ⇒ act
        np.testing.assert_array_equal(held.astype(bool), np.any(hr != 0, axis=1))
        d = np.linalg.norm(st.sph_pos[pairs[:, 1]] - st.sph_pos[pairs[:, 0]], axis=1)
        on = d < st.sph_radius[pairs[:, 0]] + st.sph_radius[pairs[:, 1]]
        assert np.all(act[on] == 1) and np.all(act[~on & (np.abs(hist).sum(1) == 0)] == 0)
        if zero_rows:
            assert np.count_nonzero(on & (np.abs(hist).sum(1) == 0)) > 3    # onsets from a zero history


@pytest.mark.parametrize("zero_rows", [False, True])
def test_wall_forces_match_numpy_reference(zero_rows):
    """zero_rows: a random half of the sphere–wall histories start all zero (held = 0)."""
    st, rng = random_state()
    planes = np.array([[0, 0, 1, 0.01], [1, 0, 0, 0.02], [0, -1, 0, -0.07]], float)
    hist = rng.normal(scale=1e-4, size=(st.ns, 3, HIST))
    if zero_rows:
        hist[rng.uniform(size=(st.ns, 3)) < 0.5] = 0.0
    pm = np.array([0, 1, 1])
    for clip in (True, False):
        h1 = hist.copy()
        held = np.any(h1 != 0, axis=2).astype(np.uint8)
        F, T = np.zeros_like(st.pos), np.zeros_like(st.pos)
        e = wall_forces(st.blk_sph_start, st.sph_pos, st.sph_radius, st.sph_material, st.pos, st.vel, st.omega,
                        st.mass, st.fixed, planes, pm, np.zeros((0, 3, 3)), np.zeros(0, np.int64),
                        np.zeros(0, np.int64), 0, np.ones(3, bool), h1, held, *MAT, clip, 1e-5, F, T)
        Fr, Tr, hr, er = wall_forces_ref(st.blk_sph_start, st.sph_pos, st.sph_radius, st.sph_material, st.sph_block,
                                         st.pos, st.vel, st.omega, st.mass, st.fixed, planes, pm, hist, *MAT, clip, 1e-5)
        assert np.count_nonzero(np.any(Fr != 0, axis=1)) > 5
        np.testing.assert_allclose(F, Fr, rtol=1e-10, atol=1e-9)
        np.testing.assert_allclose(T, Tr, rtol=1e-10, atol=1e-11)
        np.testing.assert_allclose(h1, hr, rtol=1e-10, atol=1e-16)
        np.testing.assert_allclose(e, er, rtol=1e-9, atol=1e-15)
        live = ~st.fixed[st.sph_block]
        np.testing.assert_array_equal(held[live].astype(bool), np.any(hr[live] != 0, axis=2))


def test_closest_point_on_triangle_matches_brute_force():
    rng = np.random.default_rng(3)
    tri = rng.normal(size=(3, 3))
    uv = np.array([(u, v) for u in np.linspace(0, 1, 401) for v in np.linspace(0, 1, 401) if u + v <= 1])
    pts = tri[0] + uv[:, :1] * (tri[1] - tri[0]) + uv[:, 1:] * (tri[2] - tri[0])
    for p in rng.normal(scale=2, size=(30, 3)):
        c = np.array(closest_point_triangle(p[0], p[1], p[2], tri[0], tri[1], tri[2]))
        brute = np.min(np.linalg.norm(pts - p, axis=1))
        assert np.linalg.norm(c - p) <= brute + 1e-12
        assert np.linalg.norm(c - p) >= brute - 5e-3


def test_kick_with_an_inverse_mass_tensor_matches_numpy():
    """``kick`` with per-block inverse inertia tensors (a block plus its fluid's added-mass
    tensor): v += Δt (m I + M)⁻¹ F; L += Δt T as with the scalar mass; fixed blocks untouched."""
    st, rng = random_state()
    L = rng.normal(size=(st.nb, 3)) * 1e-3
    A = rng.normal(size=(st.nb, 3, 3))
    M = np.einsum("bij,bkj->bik", A, A)                         # symmetric positive semi-definite
    inv = np.linalg.inv(st.mass[:, None, None] * np.eye(3)[None] + M)
    vel, ang = st.vel.copy(), L.copy()
    F, T = rng.normal(size=st.pos.shape), rng.normal(size=st.pos.shape)
    kick(vel, ang, st.mass, inv, F, T, st.fixed, False, 1e-3)
    free = ~st.fixed
    ref = st.vel + 1e-3 * np.einsum("bij,bj->bi", inv, F)
    np.testing.assert_allclose(vel[free], ref[free], rtol=1e-13, atol=1e-16)
    np.testing.assert_allclose(ang[free], (L + 1e-3 * T)[free], rtol=1e-14)
    np.testing.assert_array_equal(vel[~free], st.vel[~free])
    assert np.abs(vel - (st.vel + 1e-3 * F / st.mass[:, None]))[free].max() > 1e-6   # not the scalar kick


def test_planar_kick_holds_the_motion_in_the_plane():
    """``planar`` (blocks coupled to a 2D fluid): the in-plane kick is the plain one, and v_z,
    L_x, L_y are 0 afterwards whatever the load (no out-of-plane mode can grow from round-off)."""
    st, rng = random_state()
    L = rng.normal(size=(st.nb, 3)) * 1e-3
    F, T = rng.normal(size=st.pos.shape), rng.normal(size=st.pos.shape)
    inv = np.zeros((0, 3, 3))
    v_plain, L_plain = st.vel.copy(), L.copy()
    kick(v_plain, L_plain, st.mass, inv, F, T, st.fixed, False, 1e-3)
    v_plane, L_plane = st.vel.copy(), L.copy()
    kick(v_plane, L_plane, st.mass, inv, F, T, st.fixed, True, 1e-3)
    free = ~st.fixed
    np.testing.assert_array_equal(v_plane[free, :2], v_plain[free, :2])
    np.testing.assert_array_equal(L_plane[free, 2], L_plain[free, 2])
    assert np.all(v_plane[free, 2] == 0.0) and np.all(L_plane[free, :2] == 0.0)
    assert np.abs(v_plain[free, 2]).min() > 0 and np.abs(L_plain[free, :2]).min() > 0
    np.testing.assert_array_equal(v_plane[~free], st.vel[~free])


def test_drift_and_kick_match_numpy_reference():
    st, rng = random_state()
    L = rng.normal(size=(st.nb, 3)) * 1e-3
    L[0] = 0.0
    pos, quat, vel, ang = st.pos.copy(), st.quat.copy(), st.vel.copy(), L.copy()
    omega = np.zeros_like(pos)
    F, T = rng.normal(size=pos.shape), rng.normal(size=pos.shape)
    kick(vel, ang, st.mass, np.zeros((0, 3, 3)), F, T, st.fixed, False, 1e-3)
    free = ~st.fixed
    np.testing.assert_allclose(vel[free], (st.vel + 1e-3 * F / st.mass[:, None])[free], rtol=1e-14)
    np.testing.assert_allclose(ang[free], (L + 1e-3 * T)[free], rtol=1e-14)
    np.testing.assert_array_equal(vel[~free], st.vel[~free])
    pr, qr, wr = drift_ref(pos, quat, vel, ang, st.inertia, st.fixed, 1e-3)
    drift(pos, quat, vel, ang, omega, st.inertia, st.fixed, 1e-3)
    np.testing.assert_allclose(pos, pr, rtol=1e-14, atol=1e-16)
    np.testing.assert_allclose(quat, qr, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(omega[free], wr[free], rtol=1e-10, atol=1e-12)


def test_material_table_matches_mixing_rules():
    k, kt, h, mu = MAT
    tab = material_table(*MAT)
    for a in range(2):
        for b in range(2):
            np.testing.assert_array_equal(tab[a, b], [2 * k[a] * k[b] / (k[a] + k[b]),
                                                      2 * kt[a] * kt[b] / (kt[a] + kt[b]),
                                                      0.5 * (h[a] + h[b]), min(mu[a], mu[b])])


def test_cos_sin_series_matches_library_to_rounding():
    import numba as nb

    from fcm_fsi.dem.integrate import _cos_sin

    @nb.njit
    def many(a):
        c = np.empty_like(a)
        s = np.empty_like(a)
        for i in range(a.shape[0]):
            c[i], s[i] = _cos_sin(a[i])
        return c, s

    rng = np.random.default_rng(5)
    a = np.concatenate([rng.uniform(-0.0625, 0.0625, 20000), 10.0 ** rng.uniform(-12, -1.2, 5000),
                        rng.uniform(-3, 3, 1000), [0.0, 0.0624999, -0.0625, 0.0625]])
    c, s = many(a)
    import math
    cr = np.array([math.cos(x) for x in a])      # the C library (np.cos may use a SIMD version)
    sr = np.array([math.sin(x) for x in a])
    assert np.all(np.abs(c - cr) <= np.spacing(np.abs(cr)))     # within one ulp
    assert np.all(np.abs(s - sr) <= np.spacing(np.abs(sr)))


def test_history_carried_over_on_rebuild():
    old = np.array([[0, 3], [1, 2], [2, 5]], np.int64)
    hist = np.arange(3 * HIST, dtype=float).reshape(3, HIST) + 1
    new = np.array([[0, 3], [0, 4], [2, 5]], np.int64)
    h = carry_history(old, hist, new, 6)
    np.testing.assert_array_equal(h[0], hist[0])
    np.testing.assert_array_equal(h[1], 0.0)
    np.testing.assert_array_equal(h[2], hist[2])


def test_history_carry_over_matches_dict_reference():
    rng = np.random.default_rng(4)
    ns = 500

    def random_pairs(n):
        i = rng.integers(0, ns - 1, n)
        j = i + 1 + rng.integers(0, 30, n)
        p = np.unique(np.stack([i, np.minimum(j, ns - 1)], axis=1), axis=0)
        return p[p[:, 0] < p[:, 1]].astype(np.int64)

    old, new = random_pairs(3000), random_pairs(3000)
    hist = rng.normal(size=(len(old), HIST))
    hist[rng.uniform(size=len(old)) < 0.5] = 0.0
    ref = {tuple(p): h for p, h in zip(old.tolist(), hist)}
    h = carry_history(old, hist, new, ns)
    expect = np.array([ref.get(tuple(p), np.zeros(HIST)) for p in new.tolist()])
    assert np.count_nonzero(np.any(expect != 0, axis=1)) > 100
    np.testing.assert_array_equal(h, expect)
    assert carry_history(np.zeros((0, 2), np.int64), np.zeros((0, HIST)), new, ns).shape == (len(new), HIST)


def test_box_and_clump_mass_properties():
    t = box_template((0.3, 0.2, 0.1), 1000.0, 0.02)
    m = 1000.0 * 0.006
    np.testing.assert_allclose(t.mass, m)
    np.testing.assert_allclose(t.inertia, m / 12 * np.array([0.05, 0.10, 0.13]))
    # spheres sit on the surface: every outer extent is the box face
    ext = np.abs(t.sph_local).max(axis=0) + 0.02
    np.testing.assert_allclose(ext, [0.15, 0.1, 0.05])
    # a two-sphere dumbbell along (1,1,0): principal moments 2·(2/5 m r²) and 2·(2/5 m r²) + 2 m d²
    r, d = 0.01, 0.03
    c = clump_template([[0, 0, 0], [2 * d / np.sqrt(2), 2 * d / np.sqrt(2), 0]], [r, r], 2000.0)
    ms = 2000.0 * 4 / 3 * np.pi * r ** 3
    np.testing.assert_allclose(np.sort(c.inertia), np.sort([0.8 * ms * r * r, 0.8 * ms * r * r + 2 * ms * d * d,
                                                            0.8 * ms * r * r + 2 * ms * d * d]), rtol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(c.sph_local, axis=1), [d, d], rtol=1e-12)
