"""The safety limits are bounded by the drone (issue 21, item 7): what the firmware and the
airframe can do (docs/protocol.md §3.1: control:euler_angle_max ≤ 0.52 rad; the AR.Drone 2.0's
top speed; the firmware's own take-off threshold of 20 %), the kit's command convention in its
own port units and only in simulation, and a tune space that never searches them."""

from __future__ import annotations

import pytest

from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.config.limits import FIRMWARE_TILT_MAX_RAD
from ardrone_nmpc.config.schema import ConfigError
from ardrone_nmpc.protocol.config_text import EULER_ANGLE_MAX_LIMIT_RAD


def test_the_schemas_tilt_cap_is_the_protocols():
    assert FIRMWARE_TILT_MAX_RAD == EULER_ANGLE_MAX_LIMIT_RAD == 0.52


@pytest.mark.parametrize("setting, message", [
    ("safety.max_tilt_rad=54.9", "max_tilt_rad"),
    ("safety.max_tilt_rad=0.53", "beyond the firmware's euler_angle_max cap 0.52 rad"),
    ("safety.max_tilt_rad=0", "max_tilt_rad"),
    ("safety.max_speed_mps=1e9", "max_speed_mps"),
    ("safety.max_speed_mps=5.01", "max_speed_mps"),
    ("safety.battery_floor_pct=0", "battery_floor_pct"),
    ("safety.battery_floor_pct=19.9", "battery_floor_pct"),
    ("safety.navdata_land_ms=2001", "navdata_land_ms"),
])
def test_check_refuses_a_safety_limit_beyond_the_drone(setting, message):
    with pytest.raises(ConfigError, match=message):
        load_config(None, [setting])


def test_the_limits_at_the_drones_bounds_are_accepted():
    cfg = load_config(None, ["safety.max_tilt_rad=0.52", "safety.max_speed_mps=5",
                             "safety.battery_floor_pct=20", "safety.navdata_land_ms=2000"])
    assert (cfg.safety.max_tilt_rad, cfg.safety.max_speed_mps) == (0.52, 5.0)


def test_the_kit_convention_measures_the_tilt_limit_in_its_port_units():
    kit = load_config(None, ["drone.command_convention=kit", "safety.max_tilt_rad=1.0"])
    assert kit.safety.max_tilt_rad == 1.0
    with pytest.raises(ConfigError, match="max_tilt_rad"):  # the port saturates at ±1
        load_config(None, ["drone.command_convention=kit", "safety.max_tilt_rad=1.01"])
    # the thesis_kit profile's 1.0 belongs to its convention: under the SDK's the default stays
    assert load_config(None, ["sim.plant.profile=thesis_kit"]).safety.max_tilt_rad == 1.0
    sdk = load_config(None, ["sim.plant.profile=thesis_kit", "drone.command_convention=sdk"])
    assert sdk.safety.max_tilt_rad == load_config(None, []).safety.max_tilt_rad
    with pytest.raises(ConfigError, match="cap 0.52 rad"):  # … unless asked for explicitly
        load_config(None, ["sim.plant.profile=thesis_kit", "drone.command_convention=sdk",
                           "safety.max_tilt_rad=1.0"])


@pytest.mark.parametrize("drone", ["192.168.1.1", "udp://10.0.0.7"])
def test_a_real_drone_refuses_the_kit_convention_before_anything_opens(tmp_path, drone):
    from ardrone_nmpc.experiments.flight import KitConventionNotSimulated, run_flight

    cfg = load_config(None, ["sim.plant.profile=thesis_kit"])
    with pytest.raises(KitConventionNotSimulated, match=r"^drone.command_convention 'kit' .*"
                                                        r"flies only a simulated drone"):
        run_flight(cfg=cfg, drone_host=drone, log_dir=tmp_path, seed=None)
    assert list(tmp_path.iterdir()) == []  # no run directory, no datagram (no socket opened)


@pytest.mark.parametrize("name", ["safety.max_tilt_rad", "safety.geofence_max_m[0]",
                                  "safety.battery_floor_pct"])
def test_tune_refuses_to_search_a_safety_limit(name):
    from ardrone_nmpc.experiments.tune.space import parse_space

    cfg = load_config(None, [])
    with pytest.raises(ConfigError) as err:
        parse_space({"default": False, "params": {name: {"low": 0.1, "high": 0.5}}}, cfg)
    assert str(err.value) == (f"--space: params.{name}: the safety limits are not searched "
                              "(set them with --set; tune the controller, not the supervisor)")
