"""σ_c identified as in the paper (``python -m fcm_fsi strength``): a joint's bending
strength per σ_c, concrete's flexural strength from fib Model Code 2010, the CLI."""
import numpy as np
import pytest

from fcm_fsi.cli import main
from fcm_fsi.config.loader import ConfigError
from fcm_fsi.dem.cohesive import CohesiveLaw
from fcm_fsi.dem.strength import (
    identify,
    joint_bending_factor,
    mc2010_flexural_strength,
    mc2010_tensile_strength,
    section_capacity,
)
from tests.conftest import ROOT


def _law(sigma_c=1.0e7, delta_f=0.02, penalty=1.0):
    return CohesiveLaw(sigma_c=sigma_c, delta_f=delta_f, delta_tc=delta_f, penalty_factor=penalty,
                       mode="reversible")


def test_joint_bending_strength_is_a_multiple_of_sigma_c_w_whatever_the_section_and_scale():
    """M_u/(σ_c W) depends on the law only through penalty_factor (θh/δ_f is scanned), so the
    0.4 × 0.4 m column, a 0.2 m wall strip, another σ_c and another δ_f give the same factor.
    It lies between the first-crack value 1 (linear stress up to σ_c at the extreme fibre) and
    the rigid-plastic value 3/2·2 = 3 (σ_c over the whole tension half, compression a line
    at the face); with a stiffer compression side the neutral axis moves towards the
    compressed face and the factor grows."""
    c = joint_bending_factor(_law())
    for b, h, law in ((0.4, 0.4, _law()), (1.0, 0.2, _law(2.5e6)), (0.3, 0.5, _law(1e7, 0.005))):
        assert section_capacity(b, h, law) / (law.sigma_c * b * h ** 2 / 6) == pytest.approx(c, rel=2e-4)
    assert 1.0 < c < 3.0
    assert c == pytest.approx(1.716, abs=2e-3)      # docs/cohesive.md, beam_bending reaches it to 1.3 %
    assert joint_bending_factor(_law(penalty=10.0)) > c


def test_model_code_tensile_strength_matches_the_code_tables():
    """f_ctm of fib MC2010 eq 5.1-3a against the tabulated values (MC2010 Table 5.1-2, the
    same as Eurocode 2 Table 3.1): C20 2.2, C30 2.9, C50 4.1 MPa (rounded to 0.1 MPa)."""
    for fck, table in ((20e6, 2.2e6), (30e6, 2.9e6), (50e6, 4.1e6)):
        assert mc2010_tensile_strength(fck) == pytest.approx(table, abs=0.05e6)
    with pytest.raises(ConfigError, match="12–50 MPa"):
        mc2010_tensile_strength(60e6)


def test_model_code_flexural_strength_has_the_size_effect_of_eurocode_2():
    """MC2010's f_ctm,fl/f_ctm against Eurocode 2 eq 3.23, max(1.6 − h/1000, 1) with h in mm,
    an independent formula for the same effect: within 5 % from 200 to 400 mm (the building's
    walls and columns; deeper, EC2's straight line runs out at 600 mm while MC2010 keeps a size
    effect: 1.22 against 1.10 at 500 mm), decreasing with depth and tending to 1 for deep members."""
    ft = mc2010_tensile_strength(30e6)
    depths = (0.2, 0.3, 0.4)
    ratios = [mc2010_flexural_strength(30e6, h) / ft for h in depths]
    for h, r in zip(depths, ratios):
        assert r == pytest.approx(max(1.6 - h, 1.0), rel=0.05)
    assert np.all(np.diff(ratios) < 0)
    assert mc2010_flexural_strength(30e6, 50.0) / ft == pytest.approx(1.0, abs=0.01)


def test_identified_sigma_c_gives_the_target_strength():
    """The identified σ_c, put back into the law, gives a joint the target flexural strength;
    the paper's σ_c gives a 0.4 m column 4.7 × C30's."""
    r = identify(_law(), mc2010_flexural_strength(30e6, 0.4))
    back = joint_bending_factor(_law(r.sigma_c_identified)) * r.sigma_c_identified
    assert back == pytest.approx(r.flexural_target, rel=1e-4)
    assert r.strength_ratio == pytest.approx(4.74, abs=0.01)
    with pytest.raises(ConfigError, match="must be > 0"):
        identify(_law(), 0.0)


def test_cli_reports_the_identification_and_refuses_a_case_without_bonds(capsys):
    assert main(["strength", "cases/tsunami_building.yaml", "--fck", "30"]) == 0
    out = capsys.readouterr().out              # the case carries the identified σ_c
    assert "identified sigma_c = 2.112e+06 Pa" in out and "1.00 x stronger" in out
    assert main(["strength", "cases/tsunami_building.yaml", "--flexural-strength", "3.625"]) == 0
    assert "1.00 x stronger" in capsys.readouterr().out
    assert main(["strength", "cases/tsunami_building.yaml", "--set", "dem.cohesive.sigma_c=1e7", "--fck", "30"]) == 0
    assert "4.74 x stronger" in capsys.readouterr().out       # the paper's σ_c with our joints
    assert main(["strength", "cases/cavity_re100.yaml", "--fck", "30"]) == 2
    err = capsys.readouterr().err
    assert "cases/cavity_re100.yaml" in err and "dem.cohesive" in err


def test_the_shipped_tsunami_case_carries_the_sigma_c_identified_for_c30():
    """``cases/tsunami_building.yaml`` carries σ_c identified as the paper did (its column in
    three-point bending as strong as plain C30 concrete 0.4 m deep, fib MC2010) for our joints;
    ``verify tsunami_building_paper_sigma`` puts back the paper's 1e7, 4.74 x that."""
    from fcm_fsi.config.case import load_case
    from fcm_fsi.dem.strength import identify_concrete
    from fcm_fsi.verify.cases.tsunami import PAPER_SIGMA_C
    from fcm_fsi.verify.registry import REGISTRY
    case = load_case(ROOT / "cases" / "tsunami_building.yaml")
    identified = identify_concrete(case, 30.0e6)[0].sigma_c_identified
    assert case.dem.cohesive.sigma_c == pytest.approx(identified, rel=5e-4)
    assert PAPER_SIGMA_C / identified == pytest.approx(4.74, abs=0.01)
    assert {"tsunami_building", "tsunami_building_paper_sigma"} <= set(REGISTRY)
