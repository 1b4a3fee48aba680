"""The simulated plant's disturbance options (sim.vz_gain, sim.battery_sag_frac,
sim.navdata_velocity_bias_mps; constant wind is faults.wind) against closed forms of the
vertical first-order loop and the wind's drag balance."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.config.schema import ConfigError, DroneConfig, NoiseConfig
from ardrone_nmpc.core.types import FlightMode
from ardrone_nmpc.sim.plant import AirframePlant, PlantParams

QUIET = NoiseConfig(mocap_position_std_m=0.0, mocap_angle_std_rad=0.0,
                    navdata_attitude_std_rad=0.0, navdata_yaw_std_rad=0.0,
                    navdata_altitude_std_m=0.0, navdata_velocity_std_mps=0.0)
NO_BIAS = dict(navdata_trim_bias_max_rad=0.0, navdata_yaw_drift_radps=0.0,
               navdata_yaw_walk_rad_per_sqrt_s=0.0, navdata_velocity_bias_std_mps=0.0,
               battery_drain_pct_per_min=0.0, command_delay_s=0.0)


def hovering(**changes) -> AirframePlant:
    plant = AirframePlant(PlantParams(initial_position_m=(0.0, 0.0, 1.0), **{**NO_BIAS, **changes}),
                          QUIET)
    assert plant.mode is FlightMode.FLYING
    return plant


@pytest.mark.parametrize("gain", [1.0, 0.7, 1.3])
def test_vertical_speed_is_gain_times_the_commanded_first_order(gain):
    plant = hovering(vz_gain=gain)
    plant.command(0.0, 0.0, 0.5, 0.0)
    t_s = 1.0
    plant.advance(t_s)
    expected = gain * 0.5 * plant.params.control_vz_max_mps * (1 - math.exp(-t_s / 0.5))
    assert plant.truth.velocity_mps[2] == pytest.approx(expected, rel=1e-6)


def test_battery_sag_scales_the_vertical_gain_linearly_in_the_discharge():
    p = PlantParams(vz_gain=0.9, battery_sag_frac=0.4)
    full = p.coefficients_at(100.0)
    assert full == p.rhs_coefficients
    for pct in (75.0, 40.0, 0.0):
        k = p.coefficients_at(pct)
        assert k[1] == pytest.approx(full[1] * (1 - 0.4 * (1 - pct / 100)))
        assert k[0] == full[0] and k[2:] == full[2:]
    plant = hovering(battery_sag_frac=0.5, battery_start_pct=40.0)
    plant.command(0.0, 0.0, 1.0, 0.0)
    plant.advance(5.0)  # ten time constants: the steady speed
    assert plant.truth.velocity_mps[2] == pytest.approx(0.7 * 0.7, rel=1e-4)


def test_defaults_leave_the_plant_coefficients_as_they_were():
    p = PlantParams()
    assert p.rhs_coefficients[1] == p.control_vz_max_mps / p.tau_vz_s  # bit for bit
    assert p.coefficients_at(12.0) is p.rhs_coefficients


def test_navdata_velocity_bias_reads_at_rest_in_the_body_frame():
    plant = hovering(navdata_velocity_bias_mps=(0.05, -0.03), initial_psi_rad=1.0)
    nav = plant.navdata()
    assert (nav.vx_body_mps, nav.vy_body_mps) == pytest.approx((0.05, -0.03), abs=1e-12)
    assert np.all(plant.truth.velocity_mps == 0.0)


def test_constant_wind_fault_drags_to_the_drag_balance():
    """faults.wind is the one home of constant wind: v → w with time constant 1/k_d."""
    plant = hovering()
    plant.wind_mps = np.array([0.3, 0.2, 0.0])
    plant.command(0.0, 0.0, 0.0, 0.0)  # progressive, level: only drag acts
    plant.advance(2.0)
    kd = plant.params.drag_per_s
    np.testing.assert_allclose(plant.truth.velocity_mps[:2],
                               np.array([0.3, 0.2]) * (1 - math.exp(-kd * 2.0)), rtol=1e-5)


def test_config_fields_reach_the_plant_and_are_validated():
    cfg = load_config(None, ["sim.vz_gain=0.7", "sim.battery_sag_frac=0.3",
                             "sim.navdata_velocity_bias_mps=[0.02,0.01]"])
    p = PlantParams.from_config(cfg.sim, DroneConfig())
    assert (p.vz_gain, p.battery_sag_frac, p.navdata_velocity_bias_mps) == (0.7, 0.3, (0.02, 0.01))
    for bad in ("sim.vz_gain=0", "sim.battery_sag_frac=1", "sim.navdata_velocity_bias_mps=[1]"):
        with pytest.raises(ConfigError):
            load_config(None, [bad])


@pytest.mark.parametrize("gain", [0.7, 1.0])
def test_kit_backend_takes_the_same_vertical_gain(gain):
    """thesis_kit: the linear gaz → vz channel scaled by G; its steady climb rate is
    G · gaz · vz_per_frac (the channel's own DC gain, from its transfer function)."""
    from ardrone_nmpc.sim.plant_kit import KitPlant

    plant = KitPlant(PlantParams(initial_position_m=(0.0, 0.0, 1.0),
                                 **{**NO_BIAS, "vz_gain": gain}), QUIET)
    plant.command(0.0, 0.0, 0.3, 0.0)
    plant.advance(3.0)  # 17 time constants of the 1/5.82 s channel
    assert plant.truth.velocity_mps[2] == pytest.approx(gain * 0.3 * plant.model.vz_per_frac_mps,
                                                        rel=1e-3)
