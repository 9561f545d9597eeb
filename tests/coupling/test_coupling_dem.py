"""DEM side of the fluid–DEM coupling: sub-step count, impulse delivered per fluid step,
interface velocity, level-set primitives of the blocks, replicated DEM under MPI."""
from __future__ import annotations

import json
import shutil
import subprocess
import sys

import numpy as np
import pytest

from fcm_fsi.config.dem import DEMConfig
from fcm_fsi.config.loader import build
from fcm_fsi.coupling.dem_side import (
    DEMSubcycler,
    fluid_gyration_ratio,
    fluid_thickness,
    fluid_volume_ratio,
    shapes_of_blocks,
    substep_count,
)
from fcm_fsi.dem.model import build_state, build_structure, build_system
from fcm_fsi.fcm.levelset import BOX, SPHERE
from fcm_fsi.geometry import quat_to_matrix_np
from tests.conftest import ROOT, mpi_env

MAT = {"name": "m", "stiffness": 1e5, "restitution": 0.5, "friction_angle": 20.0, "density": 2000.0}


def dem_config(blocks, gravity=(0.0, 0.0, -9.81), dt=1e-5, **extra) -> DEMConfig:
    return build(DEMConfig, {"dt": dt, "gravity": list(gravity), "materials": [MAT], "blocks": blocks, **extra},
                 source="t.yaml", prefix="dem")


def free_sphere(**over):
    return {"shape": "sphere", "material": "m", "radius": 0.01, "position": [0.0, 0.0, 0.0], **over}


def box_block(**over):
    return {"shape": "box", "material": "m", "size": [0.2, 0.12, 0.08], "radius": 0.02,
            "position": [0.0, 0.0, 0.0], **over}


# ------------------------------------------------------------------ substep_count
def test_substep_count_accepts_whole_multiples_within_round_off():
    assert substep_count(1e-3, 2.5e-7) == 4000
    assert substep_count(2e-2, 1e-5) == 2000
    assert substep_count(0.1, 0.1) == 1


@pytest.mark.parametrize("fluid_dt, dem_dt, nearest", [(1e-3, 3e-7, 3.000300030003e-07), (1e-3, 3e-3, 1e-3)])
def test_substep_count_names_both_steps_and_the_nearest_valid_dem_dt(fluid_dt, dem_dt, nearest):
    with pytest.raises(ValueError) as err:
        substep_count(fluid_dt, dem_dt)
    msg = str(err.value)
    assert f"{fluid_dt:.10g}" in msg and f"{dem_dt:.10g}" in msg
    assert f"nearest valid DEM dt = {nearest:.10g} s" in msg
    assert substep_count(fluid_dt, nearest) >= 1


# ------------------------------------------------------------------ impulse delivered
def test_held_force_gives_closed_form_velocity_and_impulse():
    """Free block, constant F over one fluid step: v = (F/m + g)Δt, impulse F·Δt, L = T·Δt."""
    g = np.array([0.0, 0.0, -9.81])
    sub = DEMSubcycler(build_system(dem_config([free_sphere()], g)))
    st = sub.system.state
    F, T = np.array([[0.3, -0.2, 0.5]]), np.array([[1e-4, 2e-4, -3e-4]])
    fluid_dt = 1e-3
    sub.advance(fluid_dt, F, T)
    ex = sub.last
    assert ex.n_sub == 100
    np.testing.assert_allclose(st.vel[0], (F[0] / st.mass[0] + g) * fluid_dt, rtol=1e-12)
    np.testing.assert_allclose(ex.impulse, F * fluid_dt, rtol=1e-12)
    np.testing.assert_allclose(ex.angular_impulse, T * fluid_dt, rtol=1e-12)
    np.testing.assert_allclose(st.angmom, T * fluid_dt, rtol=1e-12)
    assert 0 < ex.dt_over_dt_cr < 0.2 and ex.wall_seconds > 0


def test_mean_velocity_is_the_displacement_over_the_fluid_step():
    """``coupling.wall_velocity: mean``: the sub-steps' mean v equals (x_end − x_start)/Δt_f
    (leapfrog), i.e. half the end velocity for a block starting from rest under a constant
    load, and the mean ω likewise; ``rigid_velocity(mean=True)`` uses them."""
    g = np.array([0.0, 0.0, -9.81])
    sub = DEMSubcycler(build_system(dem_config([free_sphere()], g)))
    st = sub.system.state
    x0 = st.pos.copy()
    fluid_dt = 1e-3
    sub.advance(fluid_dt, np.array([[0.3, -0.2, 0.5]]), np.array([[1e-4, 2e-4, -3e-4]]))
    ex = sub.last
    np.testing.assert_allclose(sub.mean_velocity, (st.pos - x0) / fluid_dt, rtol=1e-10)
    np.testing.assert_allclose(sub.mean_velocity, 0.5 * st.vel * (1 + 1 / ex.n_sub), rtol=1e-10)
    np.testing.assert_allclose(sub.mean_omega, 0.5 * st.omega * (1 + 1 / ex.n_sub), rtol=1e-10)
    point, owner = st.pos + np.array([[0.0, 0.0, 0.0]]), np.array([0])
    np.testing.assert_allclose(sub.rigid_velocity(point, owner, mean=True), sub.mean_velocity, rtol=1e-12)
    np.testing.assert_allclose(sub.rigid_velocity(point, owner), st.vel, rtol=1e-12)


def test_linear_mode_delivers_the_trapezoid_impulse():
    """Ramp from the previous exchange's load to the new one: Δt (F0 + F1)/2, and the block's
    momentum change is exactly that impulse (no gravity, no contact)."""
    sub = DEMSubcycler(build_system(dem_config([free_sphere()], (0.0, 0.0, 0.0))))
    st = sub.system.state
    F0, F1 = np.array([[1.0, 0.0, -2.0]]), np.array([[3.0, 0.5, 0.0]])
    T0, T1 = np.array([[0.0, 1e-3, 0.0]]), np.array([[2e-3, 0.0, 0.0]])
    fluid_dt = 1e-3
    sub.advance(fluid_dt, F0, T0, mode="hold")
    p0, L0 = st.mass[0] * st.vel[0].copy(), st.angmom[0].copy()
    sub.advance(fluid_dt, F1, T1, mode="linear")
    trapezoid = 0.5 * fluid_dt * (F0 + F1)
    np.testing.assert_allclose(sub.last.impulse, trapezoid, rtol=1e-12, atol=1e-18)
    np.testing.assert_allclose(sub.last.angular_impulse, 0.5 * fluid_dt * (T0 + T1), rtol=1e-12, atol=1e-18)
    np.testing.assert_allclose(st.mass[0] * st.vel[0] - p0, trapezoid[0], rtol=1e-12, atol=1e-16)
    np.testing.assert_allclose(st.angmom[0] - L0, 0.5 * fluid_dt * (T0 + T1)[0], rtol=1e-12, atol=1e-18)
    np.testing.assert_array_equal(st.ext_force, F1)     # the state carries the latest exchange
    assert not np.allclose(sub.last.impulse, F1 * fluid_dt)   # differs from holding F1


def test_advance_refuses_a_wrong_load_shape_and_mode():
    sub = DEMSubcycler(build_system(dem_config([free_sphere()])))
    with pytest.raises(ValueError, match=r"\(1, 3\)"):
        sub.advance(1e-3, np.zeros((2, 3)), np.zeros((1, 3)))
    with pytest.raises(ValueError, match="hold"):
        sub.advance(1e-3, np.zeros((1, 3)), np.zeros((1, 3)), mode="cubic")


def test_a_diverging_load_stops_the_sub_steps_instead_of_crashing_the_neighbour_search():
    """A non-finite load makes the state non-finite in one DEM step; the sub-steps stop there
    (the coupled model's check then names the block) instead of the next step's neighbour
    search failing on a NaN grid with a traceback."""
    sub = DEMSubcycler(build_system(dem_config([free_sphere(), free_sphere(position=[0.05, 0.0, 0.0])])))
    force = np.zeros((2, 3))
    force[0, 0] = np.inf
    with np.errstate(all="ignore"):                  # inf − inf in the energy ledger is expected here
        sub.advance(1e-3, force, np.zeros((2, 3)))
    assert not np.isfinite(sub.system.state.pos[0]).all()


# ------------------------------------------------------------------ interface velocity
def test_rigid_velocity_is_v_plus_omega_cross_r_on_a_spinning_block():
    """Box spinning about its principal z axis while translating, no gravity: ω and v stay
    constant, ū(pos + r) = v + ω × r; a resting block and static points give zero."""
    w, v = 3.0, np.array([0.2, -0.1, 0.0])
    cfg = dem_config([box_block(omega=[0.0, 0.0, w], velocity=v.tolist()),
                      free_sphere(position=[1.0, 0.0, 0.0])], (0.0, 0.0, 0.0))
    sub = DEMSubcycler(build_system(cfg))
    sub.advance(1e-2, np.zeros((2, 3)), np.zeros((2, 3)))
    pos, quat = sub.pose()
    np.testing.assert_allclose(pos[0], v * 1e-2, rtol=1e-12)
    np.testing.assert_allclose(quat[0], [np.cos(w * 1e-2 / 2), 0, 0, np.sin(w * 1e-2 / 2)], atol=1e-12)
    r = np.array([[0.1, 0.0, 0.0], [0.0, 0.05, 0.03], [-0.02, 0.0, -0.04]])
    points = np.vstack([pos[0] + r, pos[1] + r[:1], [[5.0, 5.0, 5.0], [6.0, 6.0, 6.0]]])
    u = sub.rigid_velocity(points, np.array([0, 0, 0, 1, -1, -2]))
    expect = [v + [0.0, w * 0.1, 0.0], v + [-w * 0.05, 0.0, 0.0], v + [0.0, -w * 0.02, 0.0]]
    np.testing.assert_allclose(u[:3], expect, rtol=1e-12, atol=1e-14)
    np.testing.assert_array_equal(u[3:], 0.0)


# ------------------------------------------------------------------ level-set primitives
def _world_box_corners(shapes, i, pos, quat):
    b = shapes.body[i]
    R = quat_to_matrix_np(quat[b]) @ shapes.rot[i]
    signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], float)
    centre = pos[b] + quat_to_matrix_np(quat[b]) @ shapes.offset[i]
    return centre + (signs * shapes.half[i]) @ R.T, signs, R


def test_rotated_box_block_corners_lie_on_its_extreme_sphere_surfaces():
    """The box from the config size, placed by the block's pose, has each world corner on the
    surface of the corner sphere (the spheres are inset by one radius from the faces)."""
    cfg = dem_config([box_block(axis=[1.0, 2.0, 3.0], angle=37.0, position=[0.3, -0.2, 0.5])])
    st = build_state(cfg)
    shapes = shapes_of_blocks(cfg, st)
    assert list(shapes.kind) == [BOX] and list(shapes.body) == [0]
    np.testing.assert_allclose(shapes.half[0], [0.1, 0.06, 0.04])
    corners, signs, R = _world_box_corners(shapes, 0, st.pos, st.quat)
    r = st.sph_radius[0]
    for c, s in zip(corners, signs):
        inner = c - R @ (s * r)             # centre of the sphere that touches this corner's 3 faces
        assert np.min(np.linalg.norm(st.sph_pos - inner, axis=1)) < 1e-12
    local = (st.sph_pos - st.pos[0]) @ R     # sphere centres in box axes: none pokes out
    assert np.all(np.abs(local) + r <= shapes.half[0] + 1e-12)


def test_min_thickness_widens_thin_boxes_in_the_level_set_only():
    """coupling.min_thickness: edges below it are widened about the centre; the DEM state is untouched."""
    cfg = dem_config([box_block(axis=[1.0, 2.0, 3.0], angle=37.0, position=[0.3, -0.2, 0.5])])
    st = build_state(cfg)
    wide = shapes_of_blocks(cfg, st, min_thickness=0.15)
    np.testing.assert_allclose(wide.half[0], [0.1, 0.075, 0.075])
    np.testing.assert_allclose(shapes_of_blocks(cfg, st).half[0], [0.1, 0.06, 0.04])


def test_fluid_volume_ratio_is_the_widened_box_over_the_true_one():
    """The added mass of a widened block uses the volume the fluid sees: edges 0.12 and 0.08 m
    widened to 0.15 m give (0.15/0.12)(0.15/0.08) in 3D; in 2D the edge along z (here the
    unrotated box's 0.08 m depth) does not count; a sphere block and no widening give 1."""
    cfg = dem_config([box_block(), free_sphere(position=[0.5, 0.0, 0.0])])
    st = build_state(cfg)
    np.testing.assert_allclose(fluid_volume_ratio(cfg, st, 0.15, 3), [(0.15 / 0.12) * (0.15 / 0.08), 1.0])
    np.testing.assert_allclose(fluid_volume_ratio(cfg, st, 0.15, 2), [0.15 / 0.12, 1.0])
    np.testing.assert_allclose(fluid_volume_ratio(cfg, st, 0.0, 3), [1.0, 1.0])


def test_fluid_gyration_ratio_is_the_widened_box_over_the_true_one_about_each_principal_axis():
    """Box 0.2 × 0.12 × 0.08 (its body axes x, y, z here: I/m = (b² + c²)/12, …) widened to
    0.15: squared gyration radii (0.15² + 0.15²)/(0.12² + 0.08²) about x, (0.2² + 0.15²)/
    (0.2² + 0.08²) about y, (0.2² + 0.15²)/(0.2² + 0.12²) about z; in 2D the 0.08 m depth
    stays; a sphere block and no widening give 1."""
    cfg = dem_config([box_block(), free_sphere(position=[0.5, 0.0, 0.0])])
    st = build_state(cfg)
    np.testing.assert_allclose(st.inertia[0] / st.mass[0] * 12.0, [0.12**2 + 0.08**2, 0.2**2 + 0.08**2, 0.2**2 + 0.12**2])
    np.testing.assert_allclose(fluid_gyration_ratio(cfg, st, 0.15, 3),
                               [[2 * 0.15**2 / (0.12**2 + 0.08**2), (0.2**2 + 0.15**2) / (0.2**2 + 0.08**2),
                                 (0.2**2 + 0.15**2) / (0.2**2 + 0.12**2)], [1.0, 1.0, 1.0]])
    np.testing.assert_allclose(fluid_gyration_ratio(cfg, st, 0.15, 2),
                               [[(0.15**2 + 0.08**2) / (0.12**2 + 0.08**2), 1.0, (0.2**2 + 0.15**2) / (0.2**2 + 0.12**2)],
                                [1.0, 1.0, 1.0]])
    np.testing.assert_allclose(fluid_gyration_ratio(cfg, st, 0.0, 3), np.ones((2, 3)))


def test_fluid_thickness_is_the_thinnest_widened_extent():
    """Box 0.2 × 0.12 × 0.08: 0.08 in 3D, 0.12 in 2D (the z edge is the depth), 0.15 once
    widened to 0.15; a sphere block: its diameter."""
    cfg = dem_config([box_block(), free_sphere(position=[0.5, 0.0, 0.0])])
    st = build_state(cfg)
    d = 2 * st.sph_radius[st.blk_sph_start[1]]
    np.testing.assert_allclose(fluid_thickness(cfg, st, 0.0, 3), [0.08, d])
    np.testing.assert_allclose(fluid_thickness(cfg, st, 0.0, 2), [0.12, d])
    np.testing.assert_allclose(fluid_thickness(cfg, st, 0.15, 3), [0.15, max(d, 0.0)])


def test_every_block_kind_is_covered_in_state_order():
    """Box, sphere, clump, generated clumps and builder blocks: one box per box block, the
    clump's own spheres (same world centres as the DEM's), builder boxes matching lo..hi."""
    clump = {"shape": "clump", "material": "m", "position": [1.0, 0.0, 0.0],
             "spheres": [[0.0, 0.0, 0.0, 0.02], [0.03, 0.0, 0.0, 0.015], [0.0, 0.025, 0.01, 0.01]],
             "axis": [0.0, 1.0, 1.0], "angle": 50.0}
    gen = {"block": {**clump, "position": [0.0, 0.0, 0.0]}, "count": 3, "region_min": [2.0, 0.0, 0.0],
           "region_max": [2.5, 0.5, 0.5], "seed": 4}
    structure = {"origin": [5.0, 0.0, 0.0], "storeys": 1, "storey_height": 1.0, "bays_x": [1.0], "bays_y": [1.0],
                 "column": [0.2, 0.2], "wall_thickness": 0.2, "walls": [], "slab_thickness": 0.2,
                 "openings": [], "block_size": 1.0, "sphere_radius": 0.05, "material": "m", "density": 2000.0}
    cohesive = {"sigma_c": 1e5, "delta_f": 0.01}
    cfg = dem_config([box_block(), free_sphere(position=[0.5, 0.0, 0.0]), clump], generators=[gen],
                     structure=structure, cohesive=cohesive)
    st = build_state(cfg, build_structure(cfg))
    shapes = shapes_of_blocks(cfg, st)
    assert np.array_equal(np.unique(shapes.body), np.arange(st.nb))
    spheres = shapes.kind == SPHERE
    sph = np.flatnonzero(np.isin(st.sph_block, shapes.body[spheres]))
    R = quat_to_matrix_np(st.quat[shapes.body[spheres]])
    world = st.pos[shapes.body[spheres]] + np.einsum("sij,sj->si", R, shapes.offset[spheres])
    np.testing.assert_allclose(world, st.sph_pos[sph], atol=1e-14)
    np.testing.assert_allclose(shapes.half[spheres, 0], st.sph_radius[sph])
    assert np.count_nonzero(spheres) == 1 + 3 + 3 * 3
    built = np.flatnonzero(shapes.body >= 6)
    assert np.all(shapes.kind[built] == BOX) and len(built) == st.nb - 6
    lo = st.pos[shapes.body[built]] - shapes.half[built]
    hi = st.pos[shapes.body[built]] + shapes.half[built]
    assert lo.min(axis=0)[0] == pytest.approx(4.9) and hi.max(axis=0)[2] == pytest.approx(1.0)


# ------------------------------------------------------------------ replicated DEM under MPI
MPI_SCRIPT = """
import json
import numpy as np
from mpi4py import MPI
from fcm_fsi.config.dem import DEMConfig
from fcm_fsi.config.loader import build
from fcm_fsi.coupling.dem_side import DEMSubcycler
from fcm_fsi.dem.model import build_system

comm = MPI.COMM_WORLD
mat = {"name": "m", "stiffness": 1e5, "restitution": 0.5, "friction_angle": 20.0}
blocks = [{"shape": "sphere", "material": "m", "radius": 0.01, "position": [0.03 * i, 0.0, 0.0101]}
          for i in range(3)]
cfg = build(DEMConfig, {"dt": 1e-5, "materials": [mat], "blocks": blocks,
                        "walls": [{"kind": "plane", "material": "m"}]}, source="t.yaml", prefix="dem")
sub = DEMSubcycler(build_system(cfg))
share = np.full((3, 3), 0.1 * (comm.rank + 1) / 3.0)   # this rank's part of the fluid force
force, torque = np.empty((3, 3)), np.zeros((3, 3))
comm.Allreduce(share, force, op=MPI.SUM)
for _ in range(3):
    sub.advance(1e-3, force, torque, mode="linear")
sub.check_replicated(comm)
if comm.rank == 1:                                    # one rank drifts by one ulp
    sub.system.state.vel[1, 2] = np.nextafter(sub.system.state.vel[1, 2], 1.0)
try:
    sub.check_replicated(comm)
    msg = None
except RuntimeError as err:
    msg = str(err)
res = comm.gather({"rank": comm.rank, "msg": msg, "z": sub.system.state.pos[:, 2].tolist()})
if comm.rank == 0:
    print("RESULT" + json.dumps(res))
"""


@pytest.mark.mpi
def test_check_replicated_passes_for_identical_ranks_and_names_the_drifting_array():
    cmd = [shutil.which("mpirun"), "-n", "2", sys.executable, "-c", MPI_SCRIPT]
    out = subprocess.run(cmd, cwd=ROOT, env=mpi_env(), stdin=subprocess.DEVNULL, capture_output=True,
                         text=True, timeout=600)
    assert out.returncode == 0, out.stderr[-3000:]
    res = json.loads([ln for ln in out.stdout.splitlines() if ln.startswith("RESULT")][0][6:])
    assert sorted(r["rank"] for r in res) == [0, 1]
    assert res[0]["z"] == res[1]["z"]
    for r in res:   # every rank stops, and the message names the array and the rank
        assert r["msg"] is not None and "): vel of rank(s) [1] differ from rank 0" in r["msg"]


# ------------------------------------------------------------------ bonded clusters
def _random_blocks(n, seed):
    rng = np.random.default_rng(seed)
    pos = rng.normal(size=(n, 3))
    mass = rng.uniform(1.0, 5.0, n)
    R = np.array([np.linalg.qr(rng.normal(size=(3, 3)))[0] for _ in range(n)])
    inertia_world = np.einsum("bij,bj,bkj->bik", R, rng.uniform(0.1, 1.0, (n, 3)), R)
    return rng, pos, mass, inertia_world


def test_bonded_clusters_are_the_components_over_intact_bonds():
    from fcm_fsi.coupling.dem_side import bonded_clusters
    a, b = np.array([0, 1, 3, 4]), np.array([1, 2, 4, 5])
    lab = bonded_clusters(7, a, b, np.array([True, True, False, True]))
    assert lab[0] == lab[1] == lab[2] and lab[4] == lab[5]
    assert len({lab[0], lab[3], lab[4], lab[6]}) == 4


def test_cluster_motion_of_a_rigidly_moving_cluster_is_each_blocks_own():
    """Blocks moving as one rigid body (v_b = V + Ω × (x_b − X), ω_b = Ω) get their own
    velocity back at every point; a single block keeps its own x, v, ω exactly."""
    from fcm_fsi.coupling.dem_side import cluster_rigid_motion, rigid_body_velocity
    rng, pos, mass, Iw = _random_blocks(6, 1)
    V, W, X0 = rng.normal(size=3), rng.normal(size=3), rng.normal(size=3)
    vel = V + np.cross(W, pos - X0)
    omega = np.tile(W, (6, 1))
    vel[5], omega[5] = rng.normal(size=3), rng.normal(size=3)         # block 5 alone
    labels = np.array([0, 0, 0, 0, 0, 1])
    X, Vc, Wc = cluster_rigid_motion(pos, vel, omega, mass, Iw, labels, np.zeros(6, bool))
    pts = pos[:5] + rng.normal(size=(5, 3))
    own = rigid_body_velocity(pos, vel, omega, pts, np.arange(5))
    np.testing.assert_allclose(rigid_body_velocity(X, Vc, Wc, pts, np.arange(5)), own, rtol=1e-11, atol=1e-12)
    np.testing.assert_array_equal(np.vstack([X[5], Vc[5], Wc[5]]), np.vstack([pos[5], vel[5], omega[5]]))


def test_cluster_motion_keeps_momentum_and_angular_momentum_and_a_fixed_block_anchors():
    """For arbitrary (non-rigid) block velocities the cluster's rigid motion carries the same
    momentum Σ m v and angular momentum Σ (I ω + m r × v) as the blocks; with a fixed block in
    it the cluster is at rest."""
    from fcm_fsi.coupling.dem_side import cluster_rigid_motion
    rng, pos, mass, Iw = _random_blocks(5, 2)
    vel, omega = rng.normal(size=(5, 3)), rng.normal(size=(5, 3))
    labels = np.zeros(5, int)
    X, V, W = cluster_rigid_motion(pos, vel, omega, mass, Iw, labels, np.zeros(5, bool))
    np.testing.assert_allclose(X[0], (mass[:, None] * pos).sum(0) / mass.sum(), rtol=1e-13)
    v_rigid = V + np.cross(W, pos - X)
    np.testing.assert_allclose((mass[:, None] * v_rigid).sum(0), (mass[:, None] * vel).sum(0), rtol=1e-12, atol=1e-12)
    r = pos - X

    def ang(v, w):
        return (np.einsum("bij,bj->bi", Iw, w) + mass[:, None] * np.cross(r, v)).sum(0)
    np.testing.assert_allclose(ang(v_rigid, W), ang(vel, omega), rtol=1e-11, atol=1e-12)
    fixed = np.zeros(5, bool)
    fixed[3] = True
    _, V, W = cluster_rigid_motion(pos, vel, omega, mass, Iw, labels, fixed)
    np.testing.assert_array_equal(V, 0.0)
    np.testing.assert_array_equal(W, 0.0)


def test_coupled_wall_motion_uses_the_intact_bonds_clusters():
    """``WallMotion.motion`` with ``wall_motion: bonded_cluster``: blocks 0–1 joined by an
    intact bond share their cluster's motion, block 2 (its bond to 1 broken) keeps its own;
    with ``block`` every block keeps its own."""
    from types import SimpleNamespace

    from fcm_fsi.coupling.wall_motion import WallMotion
    cfg = dem_config([box_block(velocity=[1.0, 0.0, 0.0]), box_block(position=[0.3, 0.0, 0.0]),
                      box_block(position=[0.6, 0.0, 0.0], velocity=[0.0, 2.0, 0.0])], (0.0, 0.0, 0.0))
    system = build_system(cfg)
    st = system.state
    bonds = SimpleNamespace(pt_bond=np.array([0, 0, 1]), pt_a=np.array([0, 0, 1]), pt_b=np.array([1, 1, 2]),
                            broken_bonds=lambda: np.array([False, True]))
    coupling = SimpleNamespace(wall_velocity="end", wall_motion="bonded_cluster", load_split="owner")
    walls = WallMotion(coupling, DEMSubcycler(system), bonds, None, np.zeros((0, 3)), np.ones(3), st.mass.copy(),
                       st.inertia.copy(), 0.01, 3)
    X, V, W = walls.motion()
    np.testing.assert_allclose(V[0], [0.5, 0.0, 0.0])
    np.testing.assert_allclose(V[1], V[0])
    np.testing.assert_allclose(X[0], 0.5 * (st.pos[0] + st.pos[1]))
    np.testing.assert_array_equal(V[2], st.vel[2])
    np.testing.assert_array_equal(walls.cluster_labels(), [0, 0, 1])
    coupling.wall_motion = "block"
    X, V, W = walls.motion()
    np.testing.assert_array_equal(V, st.vel)
    np.testing.assert_array_equal(walls.cluster_labels(), [0, 1, 2])


def test_a_coupled_run_whose_kinetic_energy_exceeds_what_the_system_has_stops():
    """``CoupledDiagnostics.health``: kinetic energy of fluid and blocks above the bound (start +
    g × mass × height; no inflow) is a divergence with a message; below it, or without a bound
    (inflow boundaries), the fluid's own verdict stands. The bonded wall with added_mass 2 ×
    the potential estimate ran on for 0.07 s at 100–250 m/s with φ in range before this
    check (docs/design-notes.md)."""
    from types import SimpleNamespace

    from fcm_fsi.coupling.diagnostics import CoupledDiagnostics
    fake = SimpleNamespace(fluid=SimpleNamespace(health=lambda diag: None), _energy_limit=100.0, gdim=2,
                           block_kinetic_energy=lambda: 10.0)
    assert CoupledDiagnostics.health(fake, {"kinetic_energy": 80.0}) is None
    message = CoupledDiagnostics.health(fake, {"kinetic_energy": 95.0})
    assert "exceeds all the energy" in message and "105 J/m" in message
    fake.fluid = SimpleNamespace(health=lambda diag: "φ left [-0.5, 1.5]")
    assert CoupledDiagnostics.health(fake, {"kinetic_energy": 95.0}) == "φ left [-0.5, 1.5]"
