"""output.probes, output.gauges, output.sensors: closed forms in still water, 1 = 2 ranks, and
the refusals that name the probe."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tests.conftest import run_cli

ROOT = Path(__file__).resolve().parents[2]
G, RHO_W, RHO_A = 9.81, 998.2, 1.204          # cases/still_water.yaml
PROBES = ("output.probes=[{name: deep, point: [0.5, 0.1], fields: [p, u, phi]}, {name: mid, point: [0.5, 0.3]}, "
          "{name: air, point: [0.4875, 0.9], fields: [p, phi]}]")
GAUGES = "output.gauges=[{name: centre, position: [0.5]}, {name: off_node, position: [0.21]}]"


def still_water(out: Path, np_: int = 1, *extra: str):
    args = [str(ROOT / "cases" / "still_water.yaml"), "--output", str(out), "--set", "run.t_end=0.01",
            "--set", "output.xdmf=false", "--set", PROBES, "--set", GAUGES]
    for e in extra:
        args += ["--set", e]
    return run_cli(args, np_)


def hydrostatic(z: float) -> float:
    """p [Pa] at height z [m] in the tank of still_water (water to 0.5 m, air above, p = 0 at the lid y = 1)."""
    if z >= 0.5:
        return RHO_A * G * (1.0 - z)
    return RHO_A * G * 0.5 + RHO_W * G * (0.5 - z)


@pytest.fixture(scope="module")
def one_rank(tmp_path_factory):
    out = tmp_path_factory.mktemp("probes1")
    done = still_water(out)
    assert done.returncode == 0, done.stderr[-2000:]
    return out


def test_probes_record_the_hydrostatic_pressure_and_gauges_the_still_water_level(one_rank):
    """At rest the total pressure is hydrostatic: the well-balanced static part is exact for the P1
    density, and the diffuse interface's density integrates to the sharp one (1e-5 measured, 1e-4
    allowed); the gauges read the 0.5 m depth (∫φ dz of the symmetric profile)."""
    p = np.genfromtxt(one_rank / "probes.csv", delimiter=",", names=True)
    g = np.genfromtxt(one_rank / "gauges.csv", delimiter=",", names=True)
    assert len(p) == len(g) == 6                                     # t = 0 and 5 steps
    for name, z in (("deep_p_Pa", 0.1), ("mid_p_Pa", 0.3), ("air_p_Pa", 0.9)):
        np.testing.assert_allclose(p[name], hydrostatic(z), rtol=1e-4, err_msg=name)
    assert np.abs(p["deep_ux_ms"]).max() < 1e-9 and np.abs(p["deep_uy_ms"]).max() < 1e-9
    assert p["deep_phi_"].min() > 0.999 and p["air_phi_"].max() < 1e-3
    for name in ("centre_m", "off_node_m"):
        np.testing.assert_allclose(g[name], 0.5, atol=1e-6, err_msg=name)
    header = (one_rank / "probes.csv").read_text().splitlines()[0]
    assert "deep_p [Pa]" in header and "deep_ux [m/s]" in header and "air_phi [-]" in header


def test_probes_and_gauges_are_the_same_on_one_and_two_ranks(one_rank, tmp_path):
    done = still_water(tmp_path, 2)
    assert done.returncode == 0, done.stderr[-2000:]
    for name in ("probes.csv", "gauges.csv"):
        a = np.genfromtxt(one_rank / name, delimiter=",", skip_header=1)
        b = np.genfromtxt(tmp_path / name, delimiter=",", skip_header=1)
        assert a.shape == b.shape
        # the flow solve agrees to its tolerance (a partition-dependent block-Jacobi preconditioner)
        np.testing.assert_allclose(a, b, rtol=1e-7, atol=1e-9, err_msg=name)


@pytest.mark.parametrize("setting, message", [
    ("output.probes=[{name: far, point: [2.0, 0.5]}]", "probe 'far'.*outside the mesh"),
    ("output.probes=[{name: flat, point: [0.5, 0.5, 0.5]}]", "probe 'flat'.*give 2 coordinates"),
    ("output.gauges=[{name: g, position: [0.5, 0.5]}]", "gauge 'g'.*give 1 coordinate"),
    ("output.sensors=[{name: s, block: 0, point: [0.5, 0.5]}]", "sensor 's'.*coupled case"),
    ("output.probes=[{name: a, point: [0.5, 0.5]}, {name: a, point: [0.2, 0.5]}]", "name 'a' is used twice"),
])
def test_a_misplaced_probe_is_refused_with_its_name(tmp_path, setting, message):
    done = run_cli([str(ROOT / "cases" / "still_water.yaml"), "--output", str(tmp_path), "--set", "run.t_end=0.002",
                    "--set", "output.xdmf=false", "--set", setting])
    assert done.returncode == 2, done.stderr[-2000:]
    assert "Traceback" not in done.stderr
    import re
    assert re.search(message, done.stderr), done.stderr[-2000:]
