"""The flight-safety config fields: drone.control_port / verify_config / config_ids / hull and
safety.start_tolerance_m / heading_tolerance_rad, validated with one line each."""

import pytest

from ardrone_nmpc.config.schema import ConfigError

from ardrone_nmpc.config.io import load_config


def test_defaults():
    cfg = load_config(None)
    d, s = cfg.drone, cfg.safety
    assert (d.control_port, d.verify_config, d.config_ids, d.hull) == (5559, True, None,
                                                                      "indoor")
    assert (s.start_tolerance_m, s.heading_tolerance_rad) == (0.5, 0.2)


@pytest.mark.parametrize("value, ids", [
    ("[d2e081a3,be27e2e4,d87f7e0c]", ("d2e081a3", "be27e2e4", "d87f7e0c")),
    ('["00000001",BE27E2E4,d87f7e0c]', ("00000001", "BE27E2E4", "d87f7e0c")),
])
def test_config_ids_accepted(value, ids):
    assert load_config(None, [f"drone.config_ids={value}"]).drone.config_ids == ids


@pytest.mark.parametrize("setting, message", [
    ("drone.config_ids=[00000001,be27e2e4,d87f7e0c]", "quote ids made of digits only"),
    ("drone.config_ids=[d2e081a,be27e2e4,d87f7e0c]", "each id must be 8 hex digits"),
    ("drone.config_ids=[d2e081ag,be27e2e4,d87f7e0c]", "each id must be 8 hex digits"),
    ("drone.config_ids=[d2e081a3,be27e2e4]", "drone.config_ids"),
    ("drone.control_port=0", "drone.control_port"),
    ("drone.control_port=65536", "drone.control_port"),
    ("drone.hull=carbon", "drone.hull"),
    ("safety.start_tolerance_m=0", "safety.start_tolerance_m"),
    ("safety.heading_tolerance_rad=-1", "safety.heading_tolerance_rad"),
])
def test_bad_values_are_one_line_naming_the_field(setting, message):
    with pytest.raises(ConfigError) as err:
        load_config(None, [setting])
    assert len(err.value.messages) == 1 and message in err.value.messages[0]
