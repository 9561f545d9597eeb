"""The fused DEM step (pair kernel + one pass over the blocks, fcm_fsi/dem/fused.py) against
the stage-by-stage step (compute_forces, kick, drift, update_sphere_positions): bit for bit."""
import numpy as np
import pytest

from fcm_fsi.dem.contact import SphereContact
from fcm_fsi.dem.laws import LAWS, ContactLaw, register
from fcm_fsi.dem.model import build_system
from fcm_fsi.dem.wall_contact import WallContact
from fcm_fsi.verify.cases.dem import _cfg, repose_config

FUSED_LAWS = [name for name, law in LAWS.items() if law.fused]


def pour(fuse: bool, steps: int = 2400, t_gate=None, tensor: bool = False, law: str = "spring_dashpot",
         planar: bool = False):
    cfg = repose_config(40, 5, 2.5e-5) if t_gate is None else repose_config(40, 5, 2.5e-5, t_gate=t_gate)
    s = build_system(_cfg(cfg), with_ledger=False, law=law)
    s.fuse = fuse
    if planar:      # motion in planes z = const, gravity in them
        s.planar, s.gravity = True, np.array([0.0, -9.81, 0.0])
    if tensor:     # an anisotropic added inertia (as coupled runs with added_mass_model: tensor set)
        m = s.state.mass
        s.inv_mass = np.linalg.inv(m[:, None, None] * np.diag([1.5, 1.2, 2.0])[None])
    calls = []
    import fcm_fsi.dem.system as system_mod
    orig = system_mod.advance_blocks

    def spy(*a):
        calls.append(1)
        return orig(*a)

    system_mod.advance_blocks = spy
    try:
        s.run(steps)
    finally:
        system_mod.advance_blocks = orig
    return s, len(calls)


@pytest.mark.parametrize("law", FUSED_LAWS)
@pytest.mark.parametrize("t_gate, tensor, planar", [(None, False, False), (0.03, False, False), (None, True, False),
                                                    (None, False, True)])
def test_fused_step_is_bit_identical_to_stage_by_stage(t_gate, tensor, planar, law):
    """A pour into a box (walls, one of them a gate removed at t_gate: released wall contacts;
    with ``tensor``, an inverse inertia tensor per block in the kick; ``planar``, the motion
    held in planes z = const), for every contact law registered as fused."""
    a, na = pour(True, t_gate=t_gate, tensor=tensor, law=law, planar=planar)
    b, nb_ = pour(False, t_gate=t_gate, tensor=tensor, law=law, planar=planar)
    if planar:
        assert np.all(a.state.vel[:, 2] == 0.0) and np.all(a.state.angmom[:, :2] == 0.0)
    assert na == 2400 and nb_ == 0
    assert a.interactions[0].n_contacts > 0 and np.any(a.interactions[1].hist != 0)
    for name in ("pos", "quat", "vel", "omega", "angmom", "sph_pos"):
        np.testing.assert_array_equal(getattr(a.state, name), getattr(b.state, name), err_msg=name)
    np.testing.assert_array_equal(a.force, b.force)
    np.testing.assert_array_equal(a.torque, b.torque)
    for k in (0, 1):
        np.testing.assert_array_equal(a.interactions[k].hist, b.interactions[k].hist)
        np.testing.assert_array_equal(a.interactions[k].held, b.interactions[k].held)
    # ledger energies: the same terms, summed per block range instead of block by block
    np.testing.assert_allclose(a.led, b.led, rtol=1e-12, atol=0)
    assert a.led[0] > 0


def test_fused_path_only_without_ledger_and_controls():
    s = build_system(_cfg(repose_config(10, 5, 2.5e-5)), with_ledger=True)
    assert s._fusable() is None
    s = build_system(_cfg(repose_config(10, 5, 2.5e-5)), with_ledger=False)
    assert s._fusable() is not None
    s.interactions.append(object())
    assert s._fusable() is None


def test_a_law_not_registered_as_fused_runs_stage_by_stage():
    """A new law must say whether the fused step implements it; one registered with
    fused=False (here the same law in subclasses) never takes the fused path."""
    class Spheres(SphereContact):
        pass

    class Walls(WallContact):
        pass

    def walls(w, mats, ns, clip):
        return Walls(mats, w.planes, w.plane_mat, w.tris, w.tri_mesh, w.mesh_mat, ns, clip, until=w.until)

    with pytest.raises(TypeError):
        ContactLaw(name="no_flag", sphere_type=Spheres, wall_type=Walls, spheres=Spheres, walls=walls)
    with pytest.raises(TypeError):
        ContactLaw(name="bad_flag", sphere_type=Spheres, wall_type=Walls, spheres=Spheres, walls=walls, fused=None)
    with pytest.raises(ValueError):
        register(LAWS["spring_dashpot"])
    register(ContactLaw(name="unfused_copy", sphere_type=Spheres, wall_type=Walls, spheres=Spheres, walls=walls,
                        fused=False))
    try:
        s = build_system(_cfg(repose_config(10, 5, 2.5e-5)), with_ledger=False, law="unfused_copy")
        assert type(s.interactions[0]) is Spheres and type(s.interactions[1]) is Walls
        assert s._fusable() is None
        assert build_system(_cfg(repose_config(10, 5, 2.5e-5)), with_ledger=False)._fusable() is not None
    finally:
        del LAWS["unfused_copy"]
