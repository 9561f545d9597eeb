"""Pre-run checks (fcm_fsi/preflight.py): geometry the schema cannot see and the memory estimate."""
from __future__ import annotations

import copy

import pytest
import yaml

from fcm_fsi.config import ConfigError, case_from_dict, load_case
from fcm_fsi.preflight import check_case, estimate_mesh
from tests.conftest import ROOT

PLENTY = 1.0e15          # bytes: no memory limit


def shipped(name: str) -> dict:
    return yaml.safe_load((ROOT / "cases" / f"{name}.yaml").read_text())


def findings(data: dict, available: float = PLENTY, ranks: int = 1):
    found, est = check_case(case_from_dict(data), ranks, available=available)
    return found, est


def errors(found):
    return [f for f in found if f.level == "error"]


@pytest.mark.parametrize("path", sorted((ROOT / "cases").glob("*.yaml")), ids=lambda p: p.stem)
def test_shipped_cases_pass_every_check(path):
    found, _ = check_case(load_case(path), 1, available=PLENTY)
    assert found == [], [f.text() for f in found]


def test_structured_mesh_estimate_is_exact():
    case = load_case(ROOT / "cases" / "block_overturn.yaml")
    est = estimate_mesh(case)
    assert est.cells == 2 * 400 * 120 and est.vertices == 401 * 121
    assert est.unknowns == est.vertices * (3 + 1)           # u, p and φ on P1


@pytest.mark.parametrize("overrides, measured", [
    (["mesh.size=0.5"], 11328),                               # impact_box_3d at 0.5 m (measured)
    (["mesh.size=0.35"], 33788),                              # and at 0.35 m
])
def test_gmsh_estimate_within_15_percent_of_measured_meshes(overrides, measured):
    est = estimate_mesh(load_case(ROOT / "cases" / "impact_box_3d.yaml", overrides))
    assert abs(est.cells / measured - 1.0) < 0.15, est.cells


def test_tsunami_band_estimate_near_the_measured_band_meshes():
    """docs/performance.md: the paper level with a 0.02 m band has 9,999,950 tetrahedra (meshed);
    0.01 m was extrapolated to 3.7e7."""
    case = load_case(ROOT / "cases" / "tsunami_building.yaml", ["resolution=paper", "mesh.structure_band.size=0.02"])
    found, est = check_case(case, 1, available=PLENTY)
    assert found == [] and abs(est.cells / 9_999_950 - 1.0) < 0.25, est.cells


def test_memory_refused_with_numbers_and_a_hint():
    data = shipped("floating_box")
    data["mesh"]["cells"] = [20000, 20000]
    found, est = findings(data, available=16e9)
    assert est.cells == 8e8
    [err] = errors(found)
    assert err.key == "mesh.cells" and "8e+08 cells" in err.text() and "16 GB are available" in err.text()
    assert "machines" in err.text()
    assert errors(findings(shipped("floating_box"), available=16e9)[0]) == []


def test_memory_per_rank_falls_with_ranks_but_not_on_one_machine():
    data = shipped("floating_box")
    data["mesh"]["cells"] = [2000, 2000]                    # 8e6 triangles ≈ 48 GB
    case = case_from_dict(data)
    one, est = check_case(case, 1, available=30e9)
    many, _ = check_case(case, 8, ranks_on_node=1, available=30e9)   # 8 machines, one rank each
    assert errors(one) and not errors(many)
    assert est.bytes_per_rank(8) < est.bytes_per_rank(1) / 7


def test_block_outside_the_fluid_is_an_error_partly_outside_a_warning():
    data = shipped("floating_box")
    data["dem"]["blocks"][0]["position"] = [50.0, 0.275, 0.0]
    [err] = errors(findings(data)[0])
    assert err.key == "dem.blocks[0].position" and "wholly outside the fluid mesh" in err.text()
    data["dem"]["blocks"][0]["position"] = [1.95, 0.275, 0.0]      # half through the right end
    found, _ = findings(data)
    assert [f.level for f in found] == ["warning"] and "outside the fluid mesh" in found[0].text()


def test_fixed_block_sunk_in_the_floor_is_allowed_a_free_one_is_not():
    data = shipped("block_overturn")
    assert findings(data)[0] == []                          # the fixed stopper stands on the floor
    data["dem"]["blocks"][0]["position"][1] = 0.03           # the free block 2 cm into the floor
    [err] = errors(findings(data)[0])
    assert err.key == "dem.blocks[0].position" and "dem.walls[0]" in err.text()


def test_liquid_region_outside_the_mesh():
    data = shipped("dam_break")
    data["phase_field"]["initial"] = {"shape": "box", "lower": [2.0, 2.0], "upper": [3.0, 3.0]}
    [err] = errors(findings(data)[0])
    assert err.key == "phase_field.initial" and "does not overlap the mesh" in err.text()
    data["phase_field"]["initial"] = {"shape": "box", "lower": [-1.0, -1.0], "upper": [2.0, 2.0]}
    found, _ = findings(data)
    assert [f.level for f in found] == ["warning"] and "whole mesh" in found[0].text()
    data["phase_field"]["initial"] = {"shape": "box", "lower": [-1.0, -1.0, -1.0], "upper": [0.05, 0.1, 1.0]}
    [err] = errors(findings(data)[0])
    assert err.key == "phase_field.initial.lower" and "needs 2 coordinates" in err.text()


def test_points_and_zones_outside_the_mesh():
    data = shipped("dam_break")
    data["fluid"]["pressure_reference"] = [0.5, 0.142875]
    [err] = errors(findings(data)[0])
    assert err.key == "fluid.pressure_reference"
    data = shipped("sloshing")
    data["mesh"]["refine"][0]["lower"] = [2.0, 0.97]
    data["mesh"]["refine"][0]["upper"] = [3.0, 1.03]
    [err] = errors(findings(data)[0])
    assert err.key == "mesh.refine[0]" and "does not overlap" in err.text()
    data = shipped("floating_box")
    data["fluid"]["damping_zones"][1].update(start=2.5, end=3.0)
    [err] = errors(findings(data)[0])
    assert err.key == "fluid.damping_zones[1]"


def test_courant_number_of_the_initial_velocity():
    data = shipped("rotating_cylinder")              # |u| ≤ √2 m/s at the corners, h = 2/96
    data["run"]["dt"] = 0.5
    [err] = errors(findings(data)[0])
    assert err.key == "phase_field.velocity.omega" and "Courant number" in err.text()
    data["run"]["dt"] = 0.05
    found, _ = findings(data)
    assert [f.level for f in found] == ["warning"]
    cavity = shipped("cavity_re100")                 # pseudo-time: Navier–Stokes alone may take any step
    assert findings(cavity)[0] == []


def test_dem_time_step_is_checked_before_the_run():
    data = shipped("block_overturn")
    data["dem"]["dt"] = 1.0e-3
    [err] = errors(findings(data)[0])
    assert "dem.dt" in err.text() and "Δt_cr" in err.text()


def test_every_resolution_level_meets_the_schema_but_checks_take_the_chosen_one():
    data = copy.deepcopy(shipped("tsunami_impact_2d"))
    data["resolutions"]["fine"]["mesh"]["refine"][0]["size"] = -0.1
    with pytest.raises(ConfigError, match=r"\[resolution 'fine'\]: key 'resolutions\.fine\.mesh\.refine\[0\]\.size': = -0\.1"):
        case_from_dict(data)
    path = ROOT / "cases" / "tsunami_building.yaml"
    assert errors(check_case(load_case(path), 2, available=16e9)[0]) == []
    [err] = errors(check_case(load_case(path, ["resolution=paper"]), 2, available=16e9)[0])
    assert err.key == "mesh.structure_band.size" and "gmsh_file" in err.text()
