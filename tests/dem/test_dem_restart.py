"""A restarted pure-DEM run continues bit-identically (checkpoint → restart == uninterrupted)."""
import h5py
import numpy as np
import pytest
from mpi4py import MPI

from fcm_fsi.api import run
from fcm_fsi.config.case import case_from_dict
from fcm_fsi.simulation.dem_model import DEMModel
from fcm_fsi.verify.cases.dem import repose_config


def case(t_end):
    dem = repose_config(24, 3, t_gate=0.01)
    dem.update(ledger_every=50, controls=[{"block": 0, "modes": ["free", "velocity", "free", "free", "free", "free"],
                                           "values": [0, 0.05, 0, 0, 0, 0]}])
    return case_from_dict({"name": "r", "run": {"t_end": t_end, "dt": 0.0025, "output_every": 4,
                                               "checkpoint_every": 4, "log_every": 100}, "dem": dem})


def test_restart_is_bit_identical(tmp_path):
    run(case(0.12), tmp_path / "a", comm=MPI.COMM_SELF)
    run(case(0.06), tmp_path / "b", comm=MPI.COMM_SELF)
    run(case(0.12), tmp_path / "b", comm=MPI.COMM_SELF, restart=tmp_path / "b" / "checkpoint.h5")
    with h5py.File(tmp_path / "a" / "checkpoint.h5") as fa, h5py.File(tmp_path / "b" / "checkpoint.h5") as fb:
        assert fa.attrs["step"] == fb.attrs["step"] == 48
        ga, gb = fa["globals"], fb["globals"]
        assert ga["dem__time"][1] == 4800
        assert sorted(ga) == sorted(gb)
        for name in ga:
            np.testing.assert_array_equal(ga[name][...], gb[name][...], err_msg=name)
        assert np.any(ga["dem_int1__hist"][...] != 0)            # wall contacts were active
        assert ga["dem_int0__pairs"].shape[0] > 0
    ea = (tmp_path / "a" / "dem_energy.csv").read_text()
    eb = (tmp_path / "b" / "dem_energy.csv").read_text()
    assert ea == eb
    fa = (tmp_path / "a" / "dem_force_displacement.csv").read_text()
    assert fa == (tmp_path / "b" / "dem_force_displacement.csv").read_text()
    assert "spheres_00012.vtp" in (tmp_path / "b" / "spheres.pvd").read_text()
    # the DEM's columns bit-identical, the loop's clock to round-off; not the neighbour-list builds
    # (a restart builds the list afresh)
    sa, sb = (np.genfromtxt(tmp_path / r / "series.csv", delimiter=",", names=True) for r in "ab")
    assert sa.dtype.names == sb.dtype.names and len(sa) == len(sb) == 49
    for name in sa.dtype.names:
        if name in ("t_s", "dt_s"):
            np.testing.assert_allclose(sa[name], sb[name], rtol=0, atol=1e-15)
        elif name != "neighbour_builds_":
            np.testing.assert_array_equal(sa[name], sb[name], err_msg=name)


def test_a_dem_case_refuses_an_end_time_off_its_step(tmp_path):
    from fcm_fsi.config import ConfigError
    with pytest.raises(ConfigError, match="run.t_end.*whole multiple"):
        DEMModel(case(0.1213), MPI.COMM_SELF, tmp_path)


def test_result_does_not_depend_on_thread_count():
    """Forces are gathered per block in a fixed order, so 1 and 2 threads agree bit for bit."""
    import numba

    from fcm_fsi.verify.cases.dem import _pour
    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("needs NUMBA_NUM_THREADS >= 2")
    numba.set_num_threads(1)
    a = _pour(40, 5, 0.06)
    numba.set_num_threads(2)
    b = _pour(40, 5, 0.06)
    assert a.interactions[0].n_contacts > 0
    np.testing.assert_array_equal(a.state.pos, b.state.pos)
    np.testing.assert_array_equal(a.state.quat, b.state.quat)
