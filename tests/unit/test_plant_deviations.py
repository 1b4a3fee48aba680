"""The plant's deviations from the nominal airframe (sim.plant: attitude gain, the kit's
second-order attitude form, yaw gain) and plant profile files, checked against scipy's
responses of the documented transfer functions (docs/plant-profiles.md §4, §5)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from scipy.signal import step

from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.config.schema import ConfigError, NoiseConfig
from ardrone_nmpc.sim.plant import AirframePlant, PlantParams

QUIET = NoiseConfig(mocap_position_std_m=0.0, mocap_angle_std_rad=0.0,
                    navdata_attitude_std_rad=0.0, navdata_yaw_std_rad=0.0,
                    navdata_altitude_std_m=0.0, navdata_velocity_std_mps=0.0)
E = 0.2094


def _hovering(**params) -> AirframePlant:
    return AirframePlant(PlantParams(initial_position_m=(0.0, 0.0, 1.0), command_delay_s=0.0,
                                     **params), QUIET)


def _pitch_response(plant: AirframePlant, frac: float, seconds: float, dt: float = 0.005):
    plant.command(0.0, frac, 0.0, 0.0)
    t, theta = [], []
    for _ in range(int(round(seconds / dt))):
        plant.advance(dt)
        t.append(plant.t_s)
        theta.append(plant.truth.pitch_rad)
    return np.array(t), np.array(theta)


@pytest.mark.parametrize("gain", [0.6, 1.0, 2.0])
def test_the_steady_tilt_is_gain_times_euler_angle_max(gain):
    plant = _hovering(attitude_gain=(1.0, gain))
    _, theta = _pitch_response(plant, -0.5, 1.5)
    assert theta[-1] == pytest.approx(0.5 * gain * E, rel=1e-4)  # −pitch = nose down = +θ


def test_the_second_order_form_is_the_kits_transfer_function():
    wn, zeta, tz = 3.45, 0.58, 0.517
    plant = _hovering(attitude_model="second_order", attitude_wn_radps=wn,
                      attitude_damping=zeta, attitude_zero_s=tz, attitude_gain=(1.3, 1.9))
    t, theta = _pitch_response(plant, -0.4, 4.0)
    _, expected = step(([wn * wn * tz, wn * wn], [1.0, 2 * zeta * wn, wn * wn]),
                       T=np.r_[0.0, t])  # the step at plant time 0
    np.testing.assert_allclose(theta, 0.4 * 1.9 * E * expected[1:], atol=2e-4)
    assert theta.max() > 1.2 * theta[-1]  # the kit's zero: an overshoot the lag has not


def test_the_second_order_state_restarts_with_each_flight():
    plant = AirframePlant(PlantParams(attitude_model="second_order"), QUIET)
    assert plant.takeoff()
    assert plant._tilt_aux == (0.0, 0.0)


def test_yaw_gain_scales_the_turn_rate():
    plant = _hovering(yaw_gain=1.5)
    plant.command(0.0, 0.0, 0.0, 0.4)
    plant.advance(1.0)
    assert plant.truth.psi_rate_radps == pytest.approx(-0.4 * 1.5 * 1.745, rel=1e-3)


def test_a_number_sets_both_attitude_gains_and_the_range_is_checked():
    cfg = load_config(None, ["sim.plant.attitude_gain=1.7"])
    assert cfg.sim.plant.attitude_gain == (1.7, 1.7)
    assert PlantParams.from_config(cfg.sim, cfg.drone).rhs_coefficients[0] == \
        pytest.approx(1.7 * cfg.drone.euler_angle_max_rad)
    with pytest.raises(ConfigError, match="sim.plant.attitude_gain"):
        load_config(None, ["sim.plant.attitude_gain=[1, 9]"])


def test_nominal_options_leave_the_coefficients_bit_for_bit():
    p = PlantParams()
    assert p.rhs_coefficients[0] == p.euler_angle_max_rad
    assert p.rhs_coefficients[3] == p.control_yaw_radps / p.tau_yaw_s
    assert not p.second_order_attitude


# ----------------------------------------------------------------------------- profile files
def _profile(tmp_path: Path, text: str, name: str = "drone.yaml") -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


PROFILE = """\
plant:
  command_delay_s: 0.15
  attitude_gain: [1.3, 1.9]
  drag_per_s: 0.5
vz_gain: 0.8
"""


def test_a_profile_file_fills_the_keys_the_config_leaves_out(tmp_path):
    path = _profile(tmp_path, PROFILE)
    cfg = load_config(None, [f"sim.plant.profile={path}", "sim.plant.drag_per_s=0.7"])
    plant = cfg.sim.plant
    assert plant.profile == str(path.resolve())
    assert (plant.command_delay_s, plant.attitude_gain) == (0.15, (1.3, 1.9))
    assert plant.drag_per_s == 0.7  # a value set explicitly wins
    assert cfg.sim.vz_gain == 0.8


def test_a_config_file_names_its_profile_relative_to_itself(tmp_path):
    _profile(tmp_path, PROFILE)
    config = tmp_path / "exp.yaml"
    config.write_text("sim:\n  plant:\n    profile: drone.yaml\n", encoding="utf-8")
    assert load_config(config).sim.plant.command_delay_s == 0.15


@pytest.mark.parametrize("text, message", [
    ("plant:\n  wings: 2\n", "plant.wings: not a sim.plant key"),
    ("plant:\n  profile: ardrone\n", "plant.profile: not a sim.plant key"),
    ("motors: 4\n", "unknown key 'motors'"),
    ("plant:\n  command_delay_s: -1\n", "sim.plant.command_delay_s"),
])
def test_a_bad_profile_file_is_one_line_per_problem(tmp_path, text, message):
    path = _profile(tmp_path, text)
    with pytest.raises(ConfigError) as info:
        load_config(None, [f"sim.plant.profile={path}"])
    assert any(message in m for m in info.value.messages), info.value.messages


def test_a_missing_profile_or_an_unknown_name_is_refused(tmp_path):
    with pytest.raises(ConfigError, match="no such file"):
        load_config(None, [f"sim.plant.profile={tmp_path / 'gone.yaml'}"])
    with pytest.raises(ConfigError, match="expected one of ardrone"):
        load_config(None, ["sim.plant.profile=ardrone_fast"])


def test_a_run_whose_profile_file_is_gone_still_reads(tmp_path):
    from ardrone_nmpc.config.io import dump_config

    path = _profile(tmp_path, PROFILE)
    cfg = load_config(None, [f"sim.plant.profile={path}"])
    saved = tmp_path / "config.yaml"
    saved.write_text(dump_config(cfg), encoding="utf-8")
    path.unlink()
    again = load_config(saved, allow_retired=True)  # how read_run loads a run's config
    assert again.sim.plant == cfg.sim.plant and math.isclose(again.sim.vz_gain, 0.8)
