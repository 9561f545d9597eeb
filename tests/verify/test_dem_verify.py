"""The DEM verification cases at quick level: every metric meets its criterion.

Known misses (reported, not hidden) go in KNOWN_MISS as strict xfails: if one ever passes,
the test says so. None at present (bounce's ``energy_balance_error`` was one until the
onset/release correction of the contact spring, see docs/dem.md §3).
"""
import pytest
from mpi4py import MPI

from fcm_fsi.verify.registry import load_all

KNOWN_MISS: set = set()


@pytest.mark.parametrize("name", ["bounce", "incline", "free_rotation", "chain_wave", "repose"])
def test_quick_case(name, tmp_path):
    metrics = load_all()[name].run("quick", tmp_path, MPI.COMM_SELF)
    assert (tmp_path / f"{name}.png").exists()
    keys = {m.key for m in metrics}
    expected = {"bounce": {"restitution_rel_error", "energy_balance_error"}, "incline": {"accel_rel_error"},
                "free_rotation": {"angmom_drift", "energy_drift"}, "chain_wave": {"wave_speed_rel_error"},
                "repose": {"repose_angle"}}[name]
    assert expected <= keys
    failed = [m for m in metrics if not m.passed and (name, m.key) not in KNOWN_MISS]
    assert not failed, [(m.key, m.value, m.criterion) for m in failed]
    for m in metrics:
        if (name, m.key) in KNOWN_MISS:
            if m.passed:
                pytest.fail(f"{name}.{m.key} now passes ({m.value:.3g}): remove it from KNOWN_MISS")
            pytest.xfail(f"{name}.{m.key} = {m.value:.3g} misses {m.criterion} (documented in docs/dem.md)")
