"""The command convention (``drone.command_convention``, docs/design.md §4 and
docs/plant-profiles.md §2): the SDK's fractions of the configured limits, or the Simulink kit's
rad, m/s, rad/s written as the fraction. The kit's is a command convention, not a drone limit:
the limits written to (and verified on) the drone stay the firmware's, and the `ardrone` plant,
which applies them, never tilts beyond them."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.config.schema import ConfigError
from ardrone_nmpc.control.mapping import DroneLimits, command_scales, map_to_pcmd
from ardrone_nmpc.core.types import AttitudeCommand, IU_PHI, IU_PSIRATE, IU_THETA
from ardrone_nmpc.experiments.record import record_lockstep
from ardrone_nmpc.runtime.tick import effective_controller


def test_sdk_scales_are_the_configured_limits_and_the_kits_are_one():
    sdk = load_config(None, ["drone.euler_angle_max_rad=0.3", "drone.control_vz_max_mps=1.2",
                             "drone.control_yaw_radps=2.0"])
    assert command_scales(sdk.drone) == DroneLimits(0.3, 1.2, 2.0)
    kit = load_config(None, ["drone.command_convention=kit", "drone.euler_angle_max_rad=0.3"])
    assert command_scales(kit.drone) == DroneLimits(1.0, 1.0, 1.0)
    assert kit.drone.euler_angle_max_rad == 0.3  # still what the drone is told


def test_kit_convention_writes_rad_ms_rads_as_the_fraction_and_saturates_at_one():
    scales = command_scales(load_config(None, ["drone.command_convention=kit"]).drone)
    pcmd = map_to_pcmd(AttitudeCommand(vz_ref_mps=0.4, phi_rad=0.3, theta_rad=0.5,
                                       psirate_radps=-0.7), scales)
    assert (pcmd.roll_frac, pcmd.pitch_frac, pcmd.gaz_frac, pcmd.yaw_frac) == (0.3, -0.5, 0.4, 0.7)
    assert not pcmd.any_saturated
    big = map_to_pcmd(AttitudeCommand(1.5, -1.2, 0.2, 0.0), scales)
    assert (big.gaz_frac, big.roll_frac, big.saturated) == (1.0, -1.0, (True, False, True, False))


def test_the_nmpc_plans_within_plus_minus_one_under_the_kits_convention():
    """Eq. 4.17's ±1 on φ, θ, ψ̇: under the SDK's convention the tilt bound narrows to the
    drone's 0.21 rad; under the kit's it stays ±1 — each times planned_tilt_frac (the thesis
    formulation plans all of it; the default keeps a 0.55 margin)."""
    for frac in (1.0, 0.55):
        for convention, tilt in (("sdk", 0.2094), ("kit", 1.0)):
            cfg = load_config(None, [f"drone.command_convention={convention}",
                                     f"controller.planned_tilt_frac={frac}"])
            ctl = effective_controller(cfg.controller, command_scales(cfg.drone))
            assert ctl.u_max[IU_PHI] == ctl.u_max[IU_THETA] == pytest.approx(tilt * frac)
            assert ctl.u_min[IU_THETA] == pytest.approx(-tilt * frac)
            assert ctl.u_max[IU_PSIRATE] == 1.0


def test_the_convention_is_a_choice_of_two_and_the_firmware_cap_stays():
    with pytest.raises(ConfigError, match="command_convention"):
        load_config(None, ["drone.command_convention=radians"])
    with pytest.raises(ConfigError, match="euler_angle_max_rad"):
        load_config(None, ["drone.command_convention=kit", "drone.euler_angle_max_rad=1.0"])


def test_a_drone_flown_in_the_kits_convention_keeps_its_firmware_tilt(tmp_path):
    """The `ardrone` plant applies the limits it was configured with: P in the kit's convention
    on a 1.5 m step asks for 0.75 rad (port 0.75) and the drone tilts 0.75 × 0.2094 rad."""
    cfg = load_config(Path("configs/step_x.yaml"), [
        "drone.command_convention=kit", "controller.kind=p", "controller.p_gains.k3_rad_per_mps=0.5",
        "sim.noise.navdata_attitude_std_rad=0", "safety.max_tilt_rad=1.0"])
    cols = record_lockstep(cfg, tmp_path).run.columns
    t = np.asarray(cols["t_s"], float)
    assert np.nanmax(np.abs(np.asarray(cols["u_theta_rad"], float)[t >= 0])) == \
        pytest.approx(0.75, rel=0.03)  # the settled start is a few mm off
    pitch = np.deg2rad(np.abs(np.asarray(cols["nav_pitch_deg"], float)[t >= 0]))
    trim = np.deg2rad(0.5)  # the plant's per-flight navdata trim (docs/plant.md §3)
    assert np.nanmax(pitch) <= cfg.drone.euler_angle_max_rad + trim
    assert np.nanmax(pitch) >= 0.7 * 0.75 * cfg.drone.euler_angle_max_rad
