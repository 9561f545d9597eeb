"""DEM case schema: strict errors that name the key, the value and the allowed range."""
import pytest

from fcm_fsi.config.dem import DEMConfig
from fcm_fsi.config.loader import ConfigError, build
from fcm_fsi.dem.model import build_system


def base(**over):
    d = {"dt": 1e-6, "materials": [{"name": "m", "stiffness": 1e5, "restitution": 0.5, "friction_angle": 20.0}],
         "blocks": [{"shape": "sphere", "material": "m", "radius": 0.01, "position": [0, 0, 0.02]}],
         "walls": [{"kind": "plane", "material": "m"}]}
    d.update(over)
    return d


def make(d):
    return build(DEMConfig, d, source="t.yaml", prefix="dem")


def test_valid_case_builds_and_reports_margin():
    s = build_system(make(base()))
    assert 0 < s.dt < 0.2 * s.critical_time_step()


def test_dt_above_safety_fraction_is_refused_with_dt_cr():
    s = build_system(make(base()))
    dtc = s.critical_time_step()
    with pytest.raises(ConfigError) as err:
        build_system(make(base(dt=0.5 * dtc)))
    msg = str(err.value)
    assert "dem.dt" in msg and f"{dtc:.4g}" in msg
    build_system(make(base(dt=0.19 * dtc)))            # just under the default 0.2 is accepted
    with pytest.raises(ConfigError):
        build_system(make(base(dt=0.19 * dtc, dt_safety=0.1)))


@pytest.mark.parametrize("e", [0.0, -0.1, 1.2])
def test_restitution_outside_0_1_is_refused(e):
    d = base()
    d["materials"][0]["restitution"] = e
    with pytest.raises(ConfigError, match=r"dem\.materials\[0\]\.restitution.*\(0, 1\]"):
        make(d)


def test_unknown_key_and_undefined_material():
    with pytest.raises(ConfigError, match="dem.blocks\\[0\\].radus"):
        d = base()
        d["blocks"][0]["radus"] = 0.01
        make(d)
    d = base()
    d["walls"][0]["material"] = "steel"
    with pytest.raises(ConfigError, match="dem.walls\\[0\\].material"):
        make(d)


def test_box_needs_size_and_generator_must_fit():
    with pytest.raises(ConfigError, match="size"):
        make(base(blocks=[{"shape": "box", "material": "m", "radius": 0.01, "position": [0, 0, 0]}]))
    gen = [{"block": {"shape": "sphere", "material": "m", "radius": 0.01, "position": [0, 0, 0]},
            "count": 1000, "region_min": [0, 0, 0], "region_max": [0.1, 0.1, 0.1]}]
    with pytest.raises(ConfigError, match="do not fit"):
        build_system(make(base(blocks=[], generators=gen)))
