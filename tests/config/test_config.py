"""Strict case loading: every kind of bad input gives one clear line, never a traceback."""
from __future__ import annotations

import pytest

from fcm_fsi.config import ConfigError, case_from_dict, load_case
from fcm_fsi.config.docs import reference_markdown
from fcm_fsi.preflight import CHECKS
from tests.conftest import ROOT, run_cli

GOOD = {"name": "t", "run": {"t_end": 1.0, "dt": 0.1},
        "mesh": {"kind": "rectangle", "lower": [0, 0], "upper": [1, 1], "cells": [4, 4]},
        "phase_field": {"initial": {"shape": "circle", "center": [0.5, 0.5], "radius": 0.2},
                        "velocity": {"kind": "rotation", "center": [0.5, 0.5]}}}


def with_change(path: str, value) -> dict:
    import copy
    data = copy.deepcopy(GOOD)
    node = data
    keys = path.split(".")
    for k in keys[:-1]:
        node = node[k]
    node[keys[-1]] = value
    return data


def test_good_case_loads_with_defaults():
    case = case_from_dict(GOOD)
    assert case.physics == "phase_field"
    assert case.phase_field.form == "conservative"
    assert case.run.log_every == 10


@pytest.mark.parametrize("path, value, expected", [
    ("run.dt", -0.1, "key 'run.dt': = -0.1 is out of range: allowed > 0 (s)"),
    ("run.dt", "fast", "key 'run.dt': = 'fast' must be a number"),
    ("mesh.kind", "rectangel", "did you mean 'rectangle'?"),
    ("mesh.cells", [4, 0], "key 'mesh.cells[1]': = 0 is out of range: allowed >= 1"),
    ("phase_field.width_factor", 0, "key 'phase_field.width_factor': = 0.0 is out of range: allowed (0, 10]"),
    ("phase_field.supg", "yes", "key 'phase_field.supg': = 'yes' must be true or false"),
])
def test_bad_values_name_key_value_and_range(path, value, expected):
    with pytest.raises(ConfigError) as err:
        case_from_dict(with_change(path, value))
    assert expected in str(err.value)


def test_unknown_key_suggests_closest():
    data = with_change("run.dtt", 0.1)
    with pytest.raises(ConfigError, match=r"key 'run.dtt': is not a known key; did you mean 'run.dt'\?"):
        case_from_dict(data)


def test_cross_field_checks():
    with pytest.raises(ConfigError, match="must not exceed run.t_end"):
        case_from_dict(with_change("run.dt", 2.0))
    with pytest.raises(ConfigError, match="must exceed mesh.lower"):
        case_from_dict(with_change("mesh.upper", [1, -1]))
    with pytest.raises(ConfigError, match="'run.cfl_gas' needs run.cfl"):
        case_from_dict(with_change("run.cfl_gas", 1.0))
    data = with_change("run.cfl", 0.5)
    data["run"]["cfl_gas"] = 0.2
    with pytest.raises(ConfigError, match="'run.cfl_gas' = 0.2 must be at least run.cfl = 0.5"):
        case_from_dict(data)
    data["run"]["cfl_gas"] = 1.0     # GOOD has no fluid: the gas bound means nothing there
    with pytest.raises(ConfigError, match="'run.cfl_gas' applies to two-phase flow"):
        case_from_dict(data)


def test_missing_file_is_one_line(tmp_path):
    with pytest.raises(ConfigError, match="case file not found"):
        load_case(tmp_path / "nope.yaml")


def test_override_applies_and_is_checked(tmp_path):
    import yaml
    f = tmp_path / "c.yaml"
    f.write_text(yaml.safe_dump(GOOD))
    assert load_case(f, ["run.dt=0.05"]).run.dt == 0.05
    with pytest.raises(ConfigError, match="run.dt"):
        load_case(f, ["run.dt=-1"])


@pytest.mark.parametrize("edit, expected", [
    (("run.dtt", 0.1), "did you mean 'run.dt'"),
    (("run.dt", "abc"), "must be a number"),
    (("run.dt", -1.0), "out of range"),
])
def test_cli_bad_input_exits_2_without_traceback(tmp_path, edit, expected):
    import yaml
    f = tmp_path / "bad.yaml"
    f.write_text(yaml.safe_dump(with_change(*edit)))
    res = run_cli([str(f), "--validate"])
    assert res.returncode == 2
    assert expected in res.stderr
    assert "Traceback" not in res.stderr + res.stdout
    assert len(res.stderr.strip().splitlines()) == 1


def test_cli_missing_file_and_bad_yaml(tmp_path):
    res = run_cli([str(tmp_path / "missing.yaml")])
    assert res.returncode == 2 and "case file not found" in res.stderr and "Traceback" not in res.stderr
    bad = tmp_path / "broken.yaml"
    bad.write_text("run: {t_end: 1\n")
    res = run_cli([str(bad)])
    assert res.returncode == 2 and "not valid YAML" in res.stderr and "Traceback" not in res.stderr


def test_shipped_cases_validate():
    for case in sorted((ROOT / "cases").glob("*.yaml")):
        load_case(case)


def test_case_reference_is_current():
    current = (ROOT / "docs" / "case-reference.md").read_text()
    assert current == reference_markdown(CHECKS), \
        "docs/case-reference.md is stale: run python -m fcm_fsi.config.docs > docs/case-reference.md"


def test_resolution_levels_merge_and_name_the_allowed_levels():
    import copy
    data = copy.deepcopy(GOOD)
    data["resolutions"] = {"coarse": {"mesh": {"cells": [8, 8]}}, "fine": {"mesh": {"cells": [64, 64]}, "run": {"dt": 0.01}}}
    data["resolution"] = "fine"
    case = case_from_dict(data)
    assert case.mesh.cells == (64, 64) and case.run.dt == 0.01 and case.mesh.upper == (1, 1)
    data["resolution"] = "paper"
    with pytest.raises(ConfigError, match="resolution.*'paper'.*allowed 'coarse', 'fine'"):
        case_from_dict(data)
    data["resolutions"]["fine"]["mesh"]["cells"] = [0, 4]          # a level's values are checked as usual
    data["resolution"] = "fine"
    with pytest.raises(ConfigError, match="mesh.cells"):
        case_from_dict(data)
    del data["resolutions"]
    with pytest.raises(ConfigError, match="resolutions"):
        case_from_dict(data)
    paper = load_case(ROOT / "cases" / "tsunami_building.yaml", ["resolution=paper"])
    assert paper.dem.dt == 1.0e-5 and paper.mesh.structure_band.size == 0.01


def test_command_line_overrides_win_over_the_resolution_level():
    """Precedence case file < resolution level < --set: the coarse tsunami level sets dem.dt
    and fluid.nonlinear, and a --set of either must not be silently replaced by the level's
    value (a regression once seen); --set can still pick and edit the level itself."""
    path = ROOT / "cases" / "tsunami_building.yaml"
    coarse = load_case(path)
    assert coarse.dem.dt == 1.0e-4 and coarse.fluid.nonlinear == "linearised"
    case = load_case(path, ["dem.dt=2.0e-5", "fluid.nonlinear=newton",
                            "fluid.petsc={ksp_type: gmres, pc_type: bjacobi}"])
    assert case.dem.dt == 2.0e-5 and case.fluid.nonlinear == "newton"
    assert case.fluid.petsc == {"ksp_type": "gmres", "pc_type": "bjacobi"}
    edited = load_case(path, ["resolutions.coarse.dem.dt=4.0e-5"])
    assert edited.dem.dt == 4.0e-5
    paper = load_case(path, ["resolution=paper", "dem.dt=2.0e-5"])
    assert paper.dem.dt == 2.0e-5 and paper.mesh.structure_band.size == 0.01


def test_cli_phase_field_without_liquid_names_file_and_key(tmp_path):
    """A liquid region outside the mesh is bad input (it used to end in a ZeroDivisionError in
    the diagnostics): exit 2, one line naming the case file and phase_field.initial."""
    import yaml
    data = {"name": "dry", "run": {"t_end": 0.01, "dt": 0.005},
            "mesh": {"kind": "rectangle", "lower": [0, 0], "upper": [1, 1], "cells": [4, 4]},
            "phase_field": {"initial": {"shape": "box", "lower": [2.0, 2.0], "upper": [3.0, 3.0]}},
            "fluid": {"density": 1000.0, "viscosity": 1e-3, "gas_density": 1.2, "gas_viscosity": 1.8e-5,
                      "gravity": [0.0, -9.81], "pressure_reference": [1.0, 1.0],
                      "boundaries": [{"boundary": b, "kind": "slip"} for b in ("xmin", "xmax", "ymin", "ymax")]}}
    f = tmp_path / "dry.yaml"
    f.write_text(yaml.safe_dump(data))
    res = run_cli([str(f), "--output", str(tmp_path / "out")])
    assert res.returncode == 2
    assert str(f) in res.stderr and "phase_field.initial" in res.stderr and "no liquid" in res.stderr
    assert "Traceback" not in res.stderr + res.stdout


def test_reference_blas_is_detected_from_the_loaded_libraries():
    """The CLI warns on Debian's reference BLAS (MUMPS ≈ 3× slower) unless an optimised BLAS
    is loaded too; the check reads the process's mapped libraries."""
    from fcm_fsi.tools.run import reference_blas_loaded
    ref = "7f00-7f10 r-xp 0 08:01 1 /usr/lib/x86_64-linux-gnu/blas/libblas.so.3.11.0\n"
    openblas = "7f20-7f30 r-xp 0 08:01 2 /usr/lib/x86_64-linux-gnu/openblas-serial/libblas.so.3\n"
    assert reference_blas_loaded(ref)
    assert not reference_blas_loaded(openblas)
    assert not reference_blas_loaded(ref + openblas)
    assert not reference_blas_loaded("")


@pytest.mark.parametrize("content, expected", [
    (b"\x00\x01\x02\x03binary", "is not a text file"),
    ("name: Größe\n".encode("latin-1"), "line 1 is not UTF-8 text (byte 0xf6"),
    (b"", "is empty"),
    (b"   \n# only a comment\n", "is empty"),
    (b"- run\n- mesh\n", "is a list, not a mapping"),
    (b"42\n", "is a number, not a mapping"),
    (b"name: a\nname: b\n", "key 'name' appears twice"),
])
def test_files_that_are_not_a_yaml_mapping_of_text_are_one_line(tmp_path, content, expected):
    f = tmp_path / "case.yaml"
    f.write_bytes(content)
    with pytest.raises(ConfigError) as err:
        load_case(f)
    assert str(err.value).startswith(str(f)) and expected in str(err.value) and "\n" not in str(err.value)


def test_every_resolution_level_is_validated_and_named():
    path = ROOT / "cases" / "tsunami_impact_2d.yaml"
    with pytest.raises(ConfigError, match=r"\[resolution 'medium'\]: key 'resolutions.medium.mesh.size': = inf"):
        load_case(path, ["resolutions.medium.mesh.size=.inf"])
    with pytest.raises(ConfigError, match=r"\[resolution 'paper'\]: key 'resolutions.paper.dem.dt': = nan"):
        load_case(ROOT / "cases" / "tsunami_building.yaml", ["resolutions.paper.dem.dt=.nan"])
    # a key of the base case that only one level breaks is named as the base key, in that level
    with pytest.raises(ConfigError, match=r"\[resolution 'fine'\]: .*mesh.structure_band"):
        load_case(path, ["resolutions.fine.mesh.structure_band={size: 0.5}"])
    import yaml
    with pytest.raises(ConfigError, match=r"key 'resolutionx': is not a known key; did you mean 'resolution'"):
        data = yaml.safe_load(path.read_text())
        data["resolutionx"] = data.pop("resolution")
        case_from_dict(data)


@pytest.mark.parametrize("option, expected", [
    ("ksp_gmres_restart=.nan", "'fluid.petsc.ksp_gmres_restart': = nan must be a finite number"),
    ("ksp_rtol=.inf", "must be a finite number"),
    ("ksp_rtol=-1.0e-6", "'fluid.petsc.ksp_rtol' = -1e-06: must be a number > 0"),
    ("ksp_max_it=2.5", "'fluid.petsc.ksp_max_it' = 2.5: must be an integer >= 1"),
    ("ksp_type=gmress", "is not a ksp type of this PETSc (did you mean 'gmres'?)"),
    ("sub_pc_type=iluu", "'fluid.petsc.sub_pc_type' = 'iluu' is not a pc type"),
    ("pc_factor_mat_solver_type=mumsp", "did you mean 'mumps'?"),
    ("ksp_rtoll=1e-6", "did you mean 'fluid.petsc.ksp_rtol'?"),
    ("-ksp_rtol=1e-6", "without the prefix and the leading '-'"),
])
def test_petsc_options_are_checked_before_a_solver_exists(option, expected):
    with pytest.raises(ConfigError) as err:
        load_case(ROOT / "cases" / "impact_box_3d.yaml", [f"fluid.petsc.{option}"])
    assert expected in str(err.value)


def test_petsc_options_unknown_to_us_but_not_near_a_common_one_pass():
    case = load_case(ROOT / "cases" / "impact_box_3d.yaml", ["fluid.petsc.mat_mumps_icntl_7=5",
                                                             "phase_field.petsc.ksp_monitor_true_residual=true"])
    assert case.fluid.petsc["mat_mumps_icntl_7"] == 5
