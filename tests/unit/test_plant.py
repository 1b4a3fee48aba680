"""The simulated AR.Drone closed loop (ardrone_nmpc.sim.plant, docs/plant.md)."""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from ardrone_nmpc.core.angles import wrap_angle_rad
from ardrone_nmpc.config.schema import DroneConfig, NoiseConfig, SimConfig, config_from_dict
from ardrone_nmpc.sim.plant import (
    AirframePlant,
    FlightMode,
    PlantParams,
    airframe_derivative,
    mocap_rotation_xyz_rad,
    rotation_heading_rad,
)
from ardrone_nmpc.core.types import GRAVITY_MPS2, MocapPose, NavdataSample, PlantTruth

G = GRAVITY_MPS2
P0 = PlantParams()
E, V, Y = P0.euler_angle_max_rad, P0.control_vz_max_mps, P0.control_yaw_radps
H = P0.integration_step_s
TD = P0.command_delay_s

QUIET = NoiseConfig(mocap_position_std_m=0.0, mocap_angle_std_rad=0.0, navdata_attitude_std_rad=0.0,
                    navdata_yaw_std_rad=0.0, navdata_altitude_std_m=0.0,
                    navdata_velocity_std_mps=0.0)
NO_BIAS = dict(navdata_trim_bias_max_rad=0.0, navdata_yaw_drift_radps=0.0,
               navdata_yaw_walk_rad_per_sqrt_s=0.0, navdata_velocity_bias_std_mps=0.0)


def exact_params(**changes) -> PlantParams:
    """Default plant without navdata biases."""
    return PlantParams(**{**NO_BIAS, **changes})


def flying(z=1.0, psi=0.0, noise=QUIET, seed=0, **changes) -> AirframePlant:
    """A plant hovering at (0, 0, z) with heading psi (an initial altitude > 0 starts FLYING)."""
    params = exact_params(initial_position_m=(0.0, 0.0, z), initial_psi_rad=psi, **changes)
    plant = AirframePlant(params, noise, seed=seed)
    assert plant.mode is FlightMode.FLYING
    return plant


def run(plant: AirframePlant, seconds: float, step: float = H) -> list[PlantTruth]:
    """Advance in steps of ``step`` and return the truth after each."""
    out = []
    for _ in range(int(round(seconds / step))):
        plant.advance(step)
        out.append(plant.truth)
    return out


# ----------------------------------------------------------------------------- closed forms
class TestClosedForms:
    def test_tilt_first_order_after_delay(self):
        plant = flying()
        plant.command(0.5, -1.0, 0.0, 0.0)
        plant.advance(TD + P0.tau_tilt_s)
        expected = 1.0 - math.exp(-1.0)
        truth = plant.truth
        assert truth.pitch_rad == pytest.approx(E * expected, rel=1e-3)  # world θ = −PCMD pitch
        assert truth.roll_rad == pytest.approx(0.5 * E * expected, rel=1e-3)

    def test_steady_horizontal_speed_and_rise(self):
        plant = flying()
        plant.command(0.0, -1.0, 0.0, 0.0)
        hist = run(plant, 15.0)
        steady = G * math.tan(E) / P0.drag_per_s
        assert steady == pytest.approx(3.6, abs=0.05)
        assert hist[-1].velocity_mps[0] == pytest.approx(steady, rel=1e-3)
        t63 = next(s.t_s for s in hist if s.velocity_mps[0] >= (1 - math.exp(-1)) * steady)
        rise = t63 - TD
        # 1/k_d ≈ 1.72 s, lengthened by at most the tilt lag
        assert rise >= 1.0 / P0.drag_per_s
        assert rise <= 1.0 / P0.drag_per_s + 2 * P0.tau_tilt_s

    def test_vertical_speed_loop(self):
        plant = flying()
        plant.command(0.0, 0.0, 0.6, 0.0)
        plant.advance(TD + P0.tau_vz_s)
        assert plant.truth.velocity_mps[2] == pytest.approx(0.6 * V * (1 - math.exp(-1)), rel=1e-6)
        plant.advance(5.0)
        assert plant.truth.velocity_mps[2] == pytest.approx(0.6 * V, rel=1e-3)

    def test_yaw_rate_loop_is_clockwise_for_positive_pcmd(self):
        plant = flying()
        plant.command(0.0, 0.0, 0.0, 0.5)
        plant.advance(TD + P0.tau_yaw_s)
        assert plant.truth.psi_rate_radps == pytest.approx(-0.5 * Y * (1 - math.exp(-1)), rel=1e-3)
        plant.advance(1.0)
        assert plant.truth.psi_rate_radps == pytest.approx(-0.5 * Y, rel=1e-3)
        assert plant.truth.psi_rad < -0.5  # ψ decreased (clockwise)

    def test_position_hold_rhs_decays_with_hover_tau(self):
        state = (0.0, 0.0, 1.0, 2.0, -1.0, 0.0, 0.0, 0.0, 0.7, 0.0)
        d = airframe_derivative(state, (0.9, -0.9, 0.0, 0.0, True), P0)
        assert d[3] == pytest.approx(-2.0 / P0.hover_tau_s, rel=1e-12)
        assert d[4] == pytest.approx(1.0 / P0.hover_tau_s, rel=1e-12)
        assert d[6] == 0.0 and d[7] == 0.0  # tilt references are 0: roll/pitch ignored

    def test_rhs_wind_drag_on_air_relative_velocity(self):
        state = (0.0, 0.0, 1.0, 0.5, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        d = airframe_derivative(state, (0.0, 0.0, 0.0, 0.0, False), P0, (2.0, -1.0, 0.0))
        assert d[3] == pytest.approx(-P0.drag_per_s * (0.5 - 2.0))
        assert d[4] == pytest.approx(-P0.drag_per_s * (0.0 + 1.0))

    def test_wind_sets_steady_drift_without_position_hold(self):
        plant = flying()
        plant.command(0.0, 0.0, 0.0, 0.0)  # progressive with zeros: attitude hold only
        plant.wind_mps = np.array([1.0, -0.5, 0.0])
        plant.advance(15.0)
        np.testing.assert_allclose(plant.truth.velocity_mps[:2], [1.0, -0.5], rtol=1e-3)

    def test_progressive_flag_zero_hovers(self):
        held, free = flying(), flying()
        for p in (held, free):
            p.command(0.0, -1.0, 0.0, 0.0)
            p.advance(5.0)
        v0 = held.truth.velocity_mps[0]
        assert v0 > 2.0
        held.command(0.3, -0.3, 0.5, 0.5, progressive=False)  # values must be ignored
        free.command(0.0, 0.0, 0.0, 0.0)
        held.advance(TD + 1.5)
        free.advance(TD + 1.5)
        assert abs(held.truth.velocity_mps[0]) < 0.1 * v0   # τ ≈ 0.5 s
        assert free.truth.velocity_mps[0] > 0.3 * v0        # drag alone: τ ≈ 1.7 s
        assert held.truth.velocity_mps[2] == pytest.approx(0.0, abs=1e-12)
        assert held.truth.psi_rate_radps == pytest.approx(0.0, abs=1e-12)


# ----------------------------------------------------------------------------- sign conventions
class TestSigns:
    def test_negative_pitch_flies_forward(self):
        plant = flying()
        plant.command(0.0, -0.5, 0.0, 0.0)
        plant.advance(2.0)
        t = plant.truth
        assert t.position_m[0] > 0.1 and abs(t.position_m[1]) < 1e-9
        assert t.pitch_rad > 0  # model convention: θ > 0 → +x

    def test_positive_roll_flies_right_minus_y(self):
        plant = flying()
        plant.command(0.5, 0.0, 0.0, 0.0)
        plant.advance(2.0)
        t = plant.truth
        assert t.position_m[1] < -0.1 and abs(t.position_m[0]) < 1e-9
        assert t.roll_rad > 0  # model convention: φ > 0 → −y

    def test_positive_gaz_climbs(self):
        plant = flying()
        plant.command(0.0, 0.0, 0.5, 0.0)
        plant.advance(2.0)
        assert plant.truth.position_m[2] > 1.3
        plant.command(0.0, 0.0, -0.5, 0.0)
        plant.advance(3.0)
        assert plant.truth.position_m[2] < 1.3

    def test_forward_at_psi_half_pi_is_plus_y(self):
        plant = flying(psi=math.pi / 2)
        plant.command(0.0, -0.5, 0.0, 0.0)
        plant.advance(2.0)
        p = plant.truth.position_m
        assert p[1] > 0.1 and abs(p[0]) < 1e-9

    @settings(max_examples=25, deadline=None)
    @given(st.floats(-math.pi, math.pi))
    def test_body_directions_rotate_with_heading(self, psi):
        fwd, right = flying(psi=psi), flying(psi=psi)
        fwd.command(0.0, -0.5, 0.0, 0.0)
        right.command(0.5, 0.0, 0.0, 0.0)
        fwd.advance(1.0)
        right.advance(1.0)
        d_fwd = fwd.truth.position_m[:2]
        d_right = right.truth.position_m[:2]
        np.testing.assert_allclose(d_fwd / np.linalg.norm(d_fwd), [math.cos(psi), math.sin(psi)],
                                   atol=1e-9)
        np.testing.assert_allclose(d_right / np.linalg.norm(d_right),
                                   [math.sin(psi), -math.cos(psi)], atol=1e-9)

    @settings(max_examples=25, deadline=None)
    @given(st.floats(-1, 1), st.floats(-1, 1), st.floats(-math.pi, math.pi))
    def test_mocap_thrust_axis_points_where_the_drone_accelerates(self, roll, pitch, psi):
        plant = flying(psi=psi)
        plant.command(roll, pitch, 0.0, 0.0)
        plant.advance(TD + 0.05)  # from rest: acceleration ∝ tilt
        v = plant.truth.velocity_mps[:2]
        pose = plant.mocap_pose()
        thrust = Rotation.from_euler("XYZ", pose.rotation_xyz_rad).as_matrix()[:, 2]
        if np.linalg.norm(v) < 1e-6:
            assert np.linalg.norm(thrust[:2]) < 1e-3
            return
        cos_angle = v @ thrust[:2] / (np.linalg.norm(v) * np.linalg.norm(thrust[:2]))
        assert cos_angle > 0.999


# ----------------------------------------------------------------------------- delay and RK4
@pytest.mark.parametrize("delay_s", [0.0, 0.1, 0.26, 0.4])
def test_command_delay(delay_s):
    plant = flying(command_delay_s=delay_s)
    plant.advance(0.5)
    assert np.linalg.norm(plant.truth.velocity_mps) == 0.0
    t0 = plant.t_s
    plant.command(0.0, -1.0, 0.0, 0.0)
    first = None
    for truth in run(plant, delay_s + 0.1):
        if np.linalg.norm(truth.velocity_mps) > 1e-6:
            first = truth.t_s - t0
            break
    assert first is not None
    assert delay_s < first <= delay_s + H + 1e-12


def test_rk4_step_halving_changes_position_below_1e6():
    def fly(step):
        plant = flying(integration_step_s=step)
        rng = np.random.default_rng(7)
        for _ in range(int(round(5.0 / 0.065))):
            plant.command(*rng.uniform(-1, 1, 3), rng.uniform(-0.3, 0.3))
            plant.advance(0.065)
        return plant.truth

    coarse, fine = fly(0.005), fly(0.0025)
    assert coarse.t_s == pytest.approx(fine.t_s)
    assert np.max(np.abs(coarse.position_m - fine.position_m)) < 1e-6
    assert np.linalg.norm(coarse.position_m - [0, 0, 1]) > 0.1  # it did move


def test_advance_carries_the_remainder():
    a, b = flying(), flying()
    for p in (a, b):
        p.command(0.2, -0.4, 0.3, 0.1)
    for _ in range(40):
        a.advance(0.0025)
    b.advance(0.1)
    assert a.t_s == pytest.approx(0.1) and b.t_s == pytest.approx(0.1)
    assert np.array_equal(a.truth.position_m, b.truth.position_m)
    c = flying()
    c.advance(0.0049)
    assert c.t_s == 0.0  # less than a step: nothing yet
    c.advance(0.0001)
    assert c.t_s == pytest.approx(H)
    c.advance(0.065 * 10)  # 13 whole steps per tick despite 0.065/0.005 = 13.000000000000002
    assert c.t_s == pytest.approx(H + 0.65)


def test_advance_and_command_validation():
    plant = flying()
    with pytest.raises(ValueError):
        plant.advance(-0.01)
    with pytest.raises(ValueError):
        plant.advance(math.nan)
    plant.command(0.1, 0.2, 0.3, 0.4)
    for bad in (math.nan, math.inf, -math.inf):
        with pytest.raises(ValueError, match="pitch_frac"):
            plant.command(0.0, bad, 0.0, 0.0)
    plant.advance(1.0)
    ref = flying()
    ref.command(0.1, 0.2, 0.3, 0.4)
    ref.advance(1.0)
    assert np.array_equal(plant.truth.position_m, ref.truth.position_m)  # bad calls changed nothing


def test_command_is_clipped():
    over, unit = flying(), flying()
    over.command(3.0, -7.0, 2.0, -1.5)
    unit.command(1.0, -1.0, 1.0, -1.0)
    over.advance(1.0)
    unit.advance(1.0)
    assert np.array_equal(over.truth.position_m, unit.truth.position_m)
    assert over.truth.psi_rad == unit.truth.psi_rad


# ----------------------------------------------------------------------------- determinism
def _stream(seed):
    plant = AirframePlant(PlantParams(), NoiseConfig(), seed=seed)
    plant.takeoff()
    rows = []
    for k in range(120):
        plant.command(0.3 * math.sin(k / 10), -0.5, 0.1, 0.2)
        plant.advance(0.065)
        pose, nav = plant.mocap_pose(), plant.navdata()
        rows.append([*pose.position_m, *pose.rotation_xyz_rad, pose.psi_rad, nav.roll_deg,
                     nav.pitch_deg, nav.yaw_deg, nav.altitude_m, nav.vx_body_mps,
                     nav.vy_body_mps, nav.vz_mps])
    return np.array(rows)


def test_same_seed_is_bit_identical_and_different_seed_differs():
    a, b, c = _stream(3), _stream(3), _stream(4)
    assert a.tobytes() == b.tobytes()
    assert not np.array_equal(a, c)


def test_mocap_stream_does_not_depend_on_navdata_sampling():
    a = AirframePlant(PlantParams(), NoiseConfig(), seed=5)
    b = AirframePlant(PlantParams(), NoiseConfig(), seed=5)
    pa, pb = [], []
    for _ in range(50):
        for p in (a, b):
            p.advance(0.01)
        b.navdata()
        b.navdata()
        pa.append(a.mocap_pose().position_m)
        pb.append(b.mocap_pose().position_m)
    assert np.array_equal(np.array(pa), np.array(pb))


# ----------------------------------------------------------------------------- noise
def test_mocap_noise_statistics():
    noise = NoiseConfig(mocap_position_std_m=0.0005, mocap_angle_std_rad=math.radians(0.1))
    plant = AirframePlant(exact_params(initial_position_m=(1.0, -2.0, 0.0)), noise, seed=11)
    poses = [plant.mocap_pose() for _ in range(5000)]
    pos = np.array([p.position_m for p in poses])
    ang = np.array([p.rotation_xyz_rad for p in poses])
    np.testing.assert_allclose(pos.std(axis=0), 0.0005, rtol=0.1)
    np.testing.assert_allclose(pos.mean(axis=0), [1.0, -2.0, 0.0], atol=5e-5)
    np.testing.assert_allclose(ang.std(axis=0), math.radians(0.1), rtol=0.1)


def test_navdata_noise_statistics():
    noise = NoiseConfig(navdata_velocity_std_mps=0.04, navdata_altitude_std_m=0.01,
                        navdata_attitude_std_rad=math.radians(0.2))
    plant = flying(noise=noise)
    nav = [plant.navdata() for _ in range(5000)]
    vx = np.array([n.vx_body_mps for n in nav])
    alt = np.array([n.altitude_m for n in nav])
    roll = np.array([n.roll_deg for n in nav])
    assert vx.std() == pytest.approx(0.04, rel=0.1)
    assert alt.std() == pytest.approx(0.01, rel=0.1)
    assert alt.mean() == pytest.approx(1.0, abs=1e-3)
    assert roll.std() == pytest.approx(0.2, rel=0.1)


@pytest.mark.parametrize("psi", [0.0, math.pi / 2, -2.0])
def test_navdata_velocities_are_body_frame(psi):
    plant = flying(psi=psi)
    plant.command(0.4, -0.8, 0.3, 0.0)
    plant.advance(3.0)
    t, nav = plant.truth, plant.navdata()
    vx, vy, vz = t.velocity_mps
    forward = math.cos(psi) * vx + math.sin(psi) * vy
    left = -math.sin(psi) * vx + math.cos(psi) * vy
    assert forward > 1.0 and left < -0.5  # pitch forward, roll right
    assert nav.vx_body_mps == pytest.approx(forward, abs=1e-12)
    assert nav.vy_body_mps == pytest.approx(-left, abs=1e-12)  # navdata vy: right positive
    assert nav.vz_mps == pytest.approx(-vz, abs=1e-12)         # navdata vz: down positive
    assert vz > 0.1


def test_navdata_at_half_pi_world_y_motion_reads_as_forward():
    plant = flying(psi=math.pi / 2)
    plant.command(0.0, -1.0, 0.0, 0.0)
    plant.advance(5.0)
    t, nav = plant.truth, plant.navdata()
    assert t.velocity_mps[1] > 2.0
    assert nav.vx_body_mps == pytest.approx(t.velocity_mps[1], abs=1e-9)
    assert nav.vy_body_mps == pytest.approx(0.0, abs=1e-9)


def test_navdata_attitude_signs_and_yaw_clockwise():
    plant = flying()
    nav0 = plant.navdata()
    plant.command(0.5, -0.5, 0.0, 0.5)  # bank right, nose down, turn clockwise
    plant.advance(1.0)
    t, nav = plant.truth, plant.navdata()
    assert nav.roll_deg == pytest.approx(math.degrees(t.roll_rad), abs=1e-9) and nav.roll_deg > 0
    assert nav.pitch_deg == pytest.approx(-math.degrees(t.pitch_rad), abs=1e-9)
    assert nav.pitch_deg < 0  # nose down: navdata theta < 0
    assert t.psi_rad < 0      # world ψ decreased ...
    dyaw = ((nav.yaw_deg - nav0.yaw_deg + 180.0) % 360.0) - 180.0
    assert dyaw == pytest.approx(-math.degrees(t.psi_rad), abs=1e-9)  # ... navdata psi increased
    assert -180.0 < nav.yaw_deg <= 180.0


def test_navdata_biases():
    plant = AirframePlant(PlantParams(initial_position_m=(0, 0, 1.0)), QUIET, seed=2)
    nav0 = plant.navdata()
    trim = nav0.roll_deg - math.degrees(plant.truth.roll_rad)
    assert 0.0 < abs(trim) <= 0.5
    plant.advance(60.0)  # hovering: ψ stays 0, the navdata yaw drifts
    drift = ((plant.navdata().yaw_deg - nav0.yaw_deg + 180.0) % 360.0) - 180.0
    assert 0.4 < abs(drift) < 1.6  # ≈ 1°/min (± random walk)
    vel = [plant.navdata().vx_body_mps for _ in range(10)]
    assert np.ptp(vel) == 0.0 and vel[0] != 0.0  # a bias, not white noise (σ = 0 here)


def test_trim_bias_is_redrawn_per_flight():
    plant = AirframePlant(PlantParams(), QUIET, seed=9)
    trims = []
    for _ in range(3):
        assert plant.takeoff()
        plant.advance(4.0)
        trims.append(plant.navdata().pitch_deg + math.degrees(plant.truth.pitch_rad))
        assert plant.land()
        plant.advance(4.0)
    assert len(set(trims)) == 3 and all(abs(x) <= 0.5 for x in trims)


# ----------------------------------------------------------------------------- flight modes
class TestModes:
    def test_takeoff_reaches_hover_height_and_flying(self):
        plant = AirframePlant(exact_params(), QUIET, seed=0)
        assert plant.mode is FlightMode.LANDED
        assert plant.takeoff()
        assert plant.mode is FlightMode.TAKING_OFF
        hist = run(plant, 5.0)
        t_flying = next(s.t_s for s in hist if s.mode is FlightMode.FLYING)
        assert t_flying < 5.0
        assert 0.8 <= hist[-1].position_m[2] <= 1.0
        hist += run(plant, 5.0)
        assert max(s.position_m[2] for s in hist) <= 1.0  # no overshoot past 1 m
        assert plant.mode is FlightMode.FLYING

    def test_takeoff_ignores_pcmd_until_flying(self):
        plant = AirframePlant(exact_params(), QUIET, seed=0)
        plant.takeoff()
        plant.command(0.5, -1.0, 0.0, 0.1)
        for s in run(plant, 5.0):
            if s.mode is FlightMode.TAKING_OFF:
                assert np.all(s.position_m[:2] == 0.0) and s.psi_rad == 0.0
        t = plant.truth  # afterwards the command acts
        assert t.position_m[0] > 0.5 and t.position_m[1] < 0.0 and t.psi_rad < 0.0

    def test_landing(self):
        plant = flying(z=1.2)
        assert plant.land()
        assert plant.mode is FlightMode.LANDING
        hist = run(plant, 5.0)
        assert min(s.velocity_mps[2] for s in hist) >= -P0.landing_speed_mps - 1e-9
        landed = [s for s in hist if s.mode is FlightMode.LANDED]
        assert landed and landed[-1].position_m[2] == 0.0
        assert landed[0].t_s > 1.2 / 0.5
        assert landed[0].t_s < 1.2 / 0.5 + 1.0
        assert np.all(landed[-1].velocity_mps == 0.0)

    def test_landed_ignores_pcmd(self):
        plant = AirframePlant(exact_params(initial_position_m=(0.5, 0.2, 0.0), initial_psi_rad=1.0),
                              QUIET, seed=0)
        plant.command(1.0, -1.0, 1.0, 1.0)
        before = plant.truth
        plant.advance(3.0)
        after = plant.truth
        assert np.array_equal(after.position_m, before.position_m)
        assert np.all(after.velocity_mps == 0.0)
        assert after.psi_rad == before.psi_rad and after.mode is FlightMode.LANDED
        nav = plant.navdata()
        assert nav.altitude_m == 0.0 and nav.vx_body_mps == 0.0

    @settings(max_examples=20, deadline=None)
    @given(st.lists(st.tuples(st.floats(-1, 1), st.floats(-1, 1), st.floats(-1, 1),
                              st.floats(-1, 1)), min_size=5, max_size=30),
           st.floats(0.0, 0.5))
    def test_ground_contact_never_below_zero(self, commands, z0):
        plant = flying(z=z0 + 0.01)
        for cmd in commands:
            plant.command(*cmd)
            for _ in range(13):
                plant.advance(H)
                assert plant.truth.position_m[2] >= 0.0

    def test_flying_into_the_floor_stops_there(self):
        plant = flying(z=0.3)
        plant.command(0.0, 0.0, -1.0, 0.0)
        hist = run(plant, 3.0)
        assert min(s.position_m[2] for s in hist) == 0.0
        assert hist[-1].position_m[2] == 0.0 and hist[-1].velocity_mps[2] == 0.0
        plant.command(0.0, 0.0, 1.0, 0.0)
        plant.advance(1.0)
        assert plant.truth.position_m[2] > 0.1  # still flying: it can climb away

    def test_battery_drains_only_with_motors_on(self):
        plant = AirframePlant(exact_params(), QUIET, seed=0)
        plant.advance(30.0)
        assert plant.truth.battery_pct == 100.0
        plant.takeoff()
        plant.advance(60.0)
        assert plant.truth.battery_pct == pytest.approx(100.0 - P0.battery_drain_pct_per_min,
                                                        abs=1e-9)
        plant.land()
        plant.advance(10.0)
        level = plant.truth.battery_pct
        plant.advance(30.0)
        assert plant.truth.battery_pct == level and plant.mode is FlightMode.LANDED

    def test_low_battery_refuses_takeoff_and_empty_battery_lands(self):
        low = AirframePlant(exact_params(battery_start_pct=15.0), QUIET, seed=0)
        assert not low.takeoff() and low.mode is FlightMode.LANDED
        plant = flying(battery_start_pct=0.05, battery_drain_pct_per_min=3.0)  # 1 s of flight
        plant.advance(2.0)
        assert plant.mode is FlightMode.LANDING
        assert plant.truth.battery_pct == 0.0
        plant.advance(5.0)
        assert plant.mode is FlightMode.LANDED

    def test_emergency_cuts_motors(self):
        plant = flying(z=1.0)
        plant.command(0.0, 0.0, 1.0, 0.0)
        assert plant.emergency()
        assert plant.mode is FlightMode.EMERGENCY
        plant.advance(0.3)
        assert plant.truth.position_m[2] == pytest.approx(1.0 - 0.5 * G * 0.3 ** 2, abs=1e-9)
        assert not plant.reset_emergency()  # not while airborne
        battery = plant.truth.battery_pct
        plant.advance(0.5)
        rest = plant.truth
        assert rest.position_m[2] == 0.0 and np.all(rest.velocity_mps == 0.0)
        plant.advance(3.0)
        assert np.array_equal(plant.truth.position_m, rest.position_m)
        assert plant.mode is FlightMode.EMERGENCY and plant.truth.battery_pct == battery
        assert not plant.takeoff()
        assert plant.reset_emergency() and plant.mode is FlightMode.LANDED
        assert plant.takeoff()

    def test_invalid_transitions_are_refused(self):
        plant = AirframePlant(exact_params(), QUIET, seed=0)
        assert not plant.land()
        assert not plant.reset_emergency()
        plant.takeoff()
        assert not plant.takeoff()
        assert plant.land() and not plant.land()


# ----------------------------------------------------------------------------- mocap rotation
small = st.floats(-0.4, 0.4)


@settings(max_examples=200)
@given(small, small, st.floats(-10.0, 10.0))
def test_mocap_angles_match_scipy_and_heading(roll, pitch, psi):
    rot = mocap_rotation_xyz_rad(roll, pitch, psi)
    r_true = Rotation.from_euler("ZYX", [psi, pitch, roll])
    np.testing.assert_allclose(rot, r_true.as_euler("XYZ"), atol=1e-12)
    np.testing.assert_allclose(Rotation.from_euler("XYZ", rot).as_matrix(), r_true.as_matrix(),
                               atol=1e-12)
    heading = rotation_heading_rad(*rot)
    assert -math.pi < heading <= math.pi
    assert abs(wrap_angle_rad(heading - psi)) < 1e-12


@settings(max_examples=30, deadline=None)
@given(st.floats(-1, 1), st.floats(-1, 1), st.floats(-1, 1), st.floats(-4.0, 4.0))
def test_plant_mocap_pose_matches_truth(roll, pitch, yaw, psi0):
    plant = flying(psi=psi0)
    plant.command(roll, pitch, 0.0, yaw)
    plant.advance(TD + 0.4)
    t, pose = plant.truth, plant.mocap_pose()
    assert isinstance(pose, MocapPose) and pose.t_s == t.t_s
    assert np.array_equal(pose.position_m, t.position_m)  # σ = 0
    assert abs(wrap_angle_rad(pose.psi_rad - t.psi_rad)) < 1e-12
    assert -math.pi < t.psi_rad <= math.pi
    expected = Rotation.from_euler("ZYX", [t.psi_rad, t.pitch_rad, t.roll_rad]).as_matrix()
    np.testing.assert_allclose(Rotation.from_euler("XYZ", pose.rotation_xyz_rad).as_matrix(),
                               expected, atol=1e-12)


# ----------------------------------------------------------------------------- config, records
def test_params_from_config():
    cfg = config_from_dict({"sim": {"seed": 4, "plant": {"command_delay_s": 0.2, "tau_vz_s": 0.3,
                                                          "initial_position_m": [1, 2, 0]}},
                            "drone": {"euler_angle_max_rad": 0.3}})
    params = PlantParams.from_config(cfg.sim, cfg.drone)
    assert params.command_delay_s == 0.2 and params.command_delay_steps == 40
    assert params.tau_vz_s == 0.3 and params.euler_angle_max_rad == 0.3
    assert params.control_vz_max_mps == DroneConfig().control_vz_max_mps
    assert params.initial_position_m == (1.0, 2.0, 0.0)
    assert PlantParams.from_config(SimConfig(), DroneConfig()).command_delay_steps == 52
    plant = AirframePlant.from_config(cfg.sim, cfg.drone)
    assert np.array_equal(plant.truth.position_m, [1.0, 2.0, 0.0])
    with pytest.raises(ValueError):
        PlantParams(tau_tilt_s=0.0)


def test_records_are_read_only():
    plant = flying()
    truth, nav = plant.truth, plant.navdata()
    assert isinstance(nav, NavdataSample) and nav.mode is FlightMode.FLYING
    with pytest.raises(ValueError):
        truth.position_m[0] = 5.0
    with pytest.raises(AttributeError):
        truth.t_s = 1.0  # type: ignore[misc]


def test_sim_does_not_import_control_or_estimation():
    code = ("import sys, ardrone_nmpc.sim.plant as p; p.AirframePlant(p.PlantParams()); "
            "bad = [m for m in sys.modules if m.startswith(('ardrone_nmpc.control', "
            "'ardrone_nmpc.estimation'))]; print(bad); sys.exit(1 if bad else 0)")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert result.returncode == 0, result.stdout + result.stderr


@settings(max_examples=200, deadline=None)
@given(st.lists(st.floats(-2.0, 2.0), min_size=10, max_size=10),
       st.lists(st.floats(-1.0, 1.0), min_size=4, max_size=4), st.booleans(),
       st.lists(st.floats(-3.0, 3.0), min_size=3, max_size=3))
def test_compiled_rk4_equals_the_python_reference(state, cmd, hold, wind):
    from ardrone_nmpc.sim.plant import airframe_rk4, rk4_step, airframe_derivative

    params = PlantParams()
    state = tuple(state)
    expected = rk4_step(airframe_derivative, state, 0.005, (*cmd, hold), params, tuple(wind))
    got = airframe_rk4(state, *cmd, hold, params.rhs_coefficients, tuple(wind), 0.005)
    np.testing.assert_allclose(got, expected, rtol=1e-13, atol=1e-13)


def _rk4_of_whole_arrays(x, cmd, hold, k, wind, h):
    """The RK4 step as the simulator formed it before its stages were held as tuples: every
    stage a whole state array through the array right-hand side (compiled, so its libm)."""
    from ardrone_nmpc.sim.airframe import _airframe_rhs

    def rhs(state):
        out = np.empty(state.size)
        _airframe_rhs(state, *cmd, hold, k, wind, out)
        return out

    hh = 0.5 * h
    a = rhs(x)
    b = rhs(np.array([x[i] + hh * a[i] for i in range(x.size)]))
    c = rhs(np.array([x[i] + hh * b[i] for i in range(x.size)]))
    d = rhs(np.array([x[i] + h * c[i] for i in range(x.size)]))
    h6 = h / 6.0
    return np.array([x[i] + h6 * (a[i] + 2.0 * (b[i] + c[i]) + d[i]) for i in range(x.size)])


@settings(max_examples=100, deadline=None)
@given(st.lists(st.floats(-2.0, 2.0), min_size=12, max_size=12),
       st.lists(st.floats(-1.0, 1.0), min_size=4, max_size=4), st.booleans(), st.booleans(),
       st.lists(st.floats(-3.0, 3.0), min_size=3, max_size=3))
def test_the_compiled_rk4_gives_the_bits_of_whole_stage_arrays(state, cmd, hold, second, wind):
    """Its stages skip the position (the RHS reads none) and live in tuples: the same bits as
    stepping whole arrays, for both attitude forms (10 and 12 states), held or not."""
    from ardrone_nmpc.sim.airframe import airframe_rk4_array

    params = PlantParams(attitude_model="second_order" if second else "lag")
    x = np.array(state[:12 if second else 10])
    k, wind = params.rhs_coefficients, tuple(wind)
    got = airframe_rk4_array(x, *cmd, hold, k, wind, 0.005)
    assert got.tobytes() == _rk4_of_whole_arrays(x, cmd, hold, k, wind, 0.005).tobytes()
