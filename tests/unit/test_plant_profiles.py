"""Plant profiles (sim.plant.profile, docs/plant-profiles.md): the kit backend against the kit's
documented transfer functions (scipy, independent of the backend's state-space code), the signs
per axis, the delay, the selection by config and the turbulence."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from scipy import signal

from ardrone_nmpc.config.schema import DroneConfig, NoiseConfig, SimConfig

from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.core.types import FlightMode
from ardrone_nmpc.sim.backends import make_plant
from ardrone_nmpc.sim.plant import AirframePlant, PlantParams
from ardrone_nmpc.sim.plant_kit import KitPlant

QUIET = NoiseConfig(mocap_position_std_m=0.0, mocap_angle_std_rad=0.0,
                    navdata_attitude_std_rad=0.0, navdata_yaw_std_rad=0.0,
                    navdata_altitude_std_m=0.0, navdata_velocity_std_mps=0.0)
H = 0.005
DELAY_S = 0.26

# The kit's transfer functions as docs/plant.md §4 prints them (PCMD fraction in; rad, m/s, m,
# rad out, in the kit's body axes and drone signs).
TF_ROLL = ([1.4834, 3.5236], [1.0, 4.2683, 12.6865])
TF_ROLL2V = ([4.7737], [1.0, 0.4596])
TF_PITCH = ([2.5139, 4.8661], [1.0, 3.9784, 11.9184])
TF_PITCH2U = ([-6.1543], [1.0, 0.6650])
TF_GZC = ([0.1526, 5.153], [1.0, 5.82, 0.0])
TF_YAW = ([1.265], [1.0, 0.0059])
# the printed composites, to check the stage products against (docs/plant.md §4)
TF_GYC = ([7.081, 16.82], [1.0, 4.728, 14.65, 5.83])
TF_GXC = ([-15.47, -29.95], [1.0, 4.643, 14.56, 7.926])


def series(*tfs):
    num, den = [1.0], [1.0]
    for n, d in tfs:
        num, den = np.polymul(num, n), np.polymul(den, d)
    return num, den


INTEGRATOR = ([1.0], [1.0, 0.0])


def delayed_step_response(tf, amplitude: float, t_s: np.ndarray) -> np.ndarray:
    """scipy's response to ``amplitude`` applied at t = 0 and delayed by the kit's 0.26 s."""
    u = np.where(t_s >= DELAY_S - 1e-9, amplitude, 0.0)
    _, y, _ = signal.lsim(signal.TransferFunction(*tf), u, t_s, interp=False)
    return y


def kit_flying(**changes) -> KitPlant:
    params = PlantParams(initial_position_m=(0.0, 0.0, 1.0), navdata_trim_bias_max_rad=0.0,
                         navdata_yaw_drift_radps=0.0, navdata_yaw_walk_rad_per_sqrt_s=0.0,
                         navdata_velocity_bias_std_mps=0.0, **changes)
    plant = KitPlant(params, QUIET, seed=0)
    assert plant.mode is FlightMode.FLYING
    return plant


def fly(plant, command, seconds: float):
    """Hold ``command`` (roll, pitch, gaz, yaw) for ``seconds``; truth at t = 0, h, 2h, …."""
    plant.command(*command)
    t = np.arange(int(round(seconds / H)) + 1) * H
    out = [plant.truth]
    for _ in t[1:]:
        plant.advance(H)
        out.append(plant.truth)
    return t, out


def test_documented_stage_products_match_the_printed_composites():
    # the oracle itself: each command→speed composite is the product of its two stages
    for stages, composite in (((TF_ROLL, TF_ROLL2V), TF_GYC), ((TF_PITCH, TF_PITCH2U), TF_GXC)):
        num, den = series(*stages)
        np.testing.assert_allclose(num, composite[0], rtol=2e-3)
        np.testing.assert_allclose(den, composite[1], rtol=2e-3)


def test_pitch_step_flies_forward_as_the_transfer_functions_say():
    t, out = fly(kit_flying(), (0.0, -0.2, 0.0, 0.0), 6.0)
    theta = np.array([-o.pitch_rad for o in out])          # the kit's θ_k = −θ_world
    vx = np.array([o.velocity_mps[0] for o in out])
    x = np.array([o.position_m[0] for o in out])
    np.testing.assert_allclose(theta, delayed_step_response(TF_PITCH, -0.2, t), atol=2e-4)
    np.testing.assert_allclose(vx, delayed_step_response(series(TF_PITCH, TF_PITCH2U), -0.2, t),
                               atol=2e-3)
    np.testing.assert_allclose(
        x, delayed_step_response(series(TF_PITCH, TF_PITCH2U, INTEGRATOR), -0.2, t), atol=3e-3)
    assert x[-1] > 1.0 and out[-1].pitch_rad > 0.0          # nose down (world θ > 0), forward
    assert abs(out[-1].position_m[1]) < 1e-12


def test_roll_step_moves_right_as_the_transfer_functions_say():
    t, out = fly(kit_flying(), (0.2, 0.0, 0.0, 0.0), 6.0)
    phi = np.array([o.roll_rad for o in out])
    vy = np.array([o.velocity_mps[1] for o in out])
    y = np.array([o.position_m[1] for o in out])
    np.testing.assert_allclose(phi, delayed_step_response(TF_ROLL, 0.2, t), atol=2e-4)
    # the kit's v is to the right; world y points left
    np.testing.assert_allclose(-vy, delayed_step_response(series(TF_ROLL, TF_ROLL2V), 0.2, t),
                               atol=2e-3)
    np.testing.assert_allclose(
        -y, delayed_step_response(series(TF_ROLL, TF_ROLL2V, INTEGRATOR), 0.2, t), atol=3e-3)
    assert y[-1] < -0.5 and abs(out[-1].position_m[0]) < 1e-12


def test_yaw_step_turns_clockwise_as_the_transfer_function_says():
    t, out = fly(kit_flying(), (0.0, 0.0, 0.0, 0.2), 3.0)
    psi = np.unwrap([o.psi_rad for o in out])
    # rtol: the printed gain 1.265 is the stored 1.265268 rounded
    np.testing.assert_allclose(-psi, delayed_step_response(TF_YAW, 0.2, t), rtol=1e-3, atol=1e-5)
    assert psi[-1] < -0.5                                    # clockwise: ψ decreases
    # the reported yaw rate is the rate of ψ (central differences, away from the 0.26 s jump)
    rate = np.array([o.psi_rate_radps for o in out])
    late = t >= 0.5
    np.testing.assert_allclose(rate[late][1:-1], np.gradient(psi, t)[late][1:-1], atol=1e-4)


def test_gaz_step_climbs_as_the_transfer_function_says():
    t, out = fly(kit_flying(), (0.0, 0.0, 0.5, 0.0), 3.0)
    z = np.array([o.position_m[2] for o in out])
    np.testing.assert_allclose(z - 1.0, delayed_step_response(TF_GZC, 0.5, t), atol=1e-4)
    assert z[-1] > 2.0


@pytest.mark.parametrize("command", [(0.2, 0, 0, 0), (0, -0.2, 0, 0), (0, 0, 0.5, 0),
                                     (0, 0, 0, 0.2)])
def test_kit_commands_act_after_the_026_s_delay(command):
    plant = kit_flying()
    assert plant.params.command_delay_steps == 52 and plant.params.integration_step_s == H
    t, out = fly(plant, command, 0.3)
    at_rest = [o for ti, o in zip(t, out) if ti <= DELAY_S + 1e-9]
    moving = out[-1]
    for o in at_rest:
        assert (o.roll_rad, o.pitch_rad, o.psi_rate_radps, o.velocity_mps[2]) == (0, 0, 0, 0)
    assert max(abs(moving.roll_rad), abs(moving.pitch_rad), abs(moving.psi_rate_radps),
               abs(moving.velocity_mps[2])) > 1e-3


def test_kit_takes_off_lands_and_starts_the_next_flight_at_rest():
    plant = KitPlant(PlantParams(), QUIET, seed=1)
    assert plant.takeoff()
    for _ in range(2000):
        plant.advance(H)
        if plant.mode is FlightMode.FLYING:
            break
    assert plant.mode is FlightMode.FLYING and 0.7 < plant.truth.position_m[2] < 1.1
    plant.command(0.0, -0.3, 0.0, 0.2)
    plant.advance(2.0)
    assert plant.land()
    plant.advance(10.0)
    assert plant.mode is FlightMode.LANDED and plant.truth.position_m[2] == 0.0
    assert not np.any(plant._kit[4:])          # the kit's channels rest with the drone


def _sim(**plant) -> SimConfig:
    return SimConfig(plant=plant)


def test_profile_selects_the_backend_and_its_defaults():
    drone = DroneConfig()
    assert type(make_plant(_sim(), drone)) is AirframePlant
    assert type(make_plant(_sim(profile="ardrone"), drone)) is AirframePlant
    kit = make_plant(_sim(profile="thesis_kit"), drone)
    assert type(kit) is KitPlant and kit.params.command_delay_s == DELAY_S
    lab = make_plant(_sim(profile="ardrone_lab"), drone)
    assert type(lab) is AirframePlant
    assert lab.params.command_delay_s == 0.12 and lab.params.turbulence_std_mps > 0.0
    # a profile fills only what the config leaves out
    assert _sim(profile="ardrone_lab", command_delay_s=0.2).plant.command_delay_s == 0.2
    assert _sim().plant.turbulence_std_mps == 0.0 and _sim().plant.command_delay_s == DELAY_S


def test_profile_from_a_config_file_override():
    cfg = load_config(Path("configs/hover.yaml"), ["sim.plant.profile=thesis_kit"])
    assert type(make_plant(cfg.sim, cfg.drone)) is KitPlant
    with pytest.raises(Exception):
        load_config(Path("configs/hover.yaml"), ["sim.plant.profile=gazebo"])


def test_turbulence_is_a_gauss_markov_wind_of_the_configured_size():
    sigma, tau = 0.3, 1.0   # a short τ keeps the run short
    plant = AirframePlant(PlantParams(initial_position_m=(0, 0, 1), turbulence_std_mps=sigma,
                                      turbulence_tau_s=tau), QUIET, seed=3)
    gusts = []
    for _ in range(40000):
        plant.advance(0.05)
        gusts.append(plant._gust_mps)
    g = np.array(gusts)
    assert np.std(g, axis=0) == pytest.approx([sigma, sigma], rel=0.12)
    lag = int(round(tau / 0.05))
    rho = np.mean([np.corrcoef(g[:-lag, i], g[lag:, i])[0, 1] for i in range(2)])
    assert rho == pytest.approx(math.exp(-1.0), abs=0.08)
    assert np.abs(plant.truth.velocity_mps[:2]).max() > 0.0   # it pushed the hovering drone


def test_turbulence_leaves_the_sensor_noise_of_a_seed_unchanged():
    noisy = NoiseConfig()
    still = AirframePlant(PlantParams(initial_position_m=(0, 0, 1)), noisy, seed=5)
    windy = AirframePlant(PlantParams(initial_position_m=(0, 0, 1), turbulence_std_mps=0.5),
                          noisy, seed=5)
    a, b = still.mocap_pose(), windy.mocap_pose()
    np.testing.assert_array_equal(a.position_m, b.position_m)
    assert still.navdata().vx_body_mps == windy.navdata().vx_body_mps
    still.advance(1.0)
    windy.advance(1.0)
    assert still.truth.position_m[0] == 0.0 and windy.truth.position_m[0] != 0.0


@pytest.mark.slow
def test_ardrone_lab_square_matches_the_thesis_experiment_within_30_percent():
    """Calibration reproducible: the thesis formulation on the square, one seed."""
    import tempfile

    from ardrone_nmpc.experiments.record import record_lockstep
    from ardrone_nmpc.experiments.reproduce import FORMULATIONS, LAB_OVERRIDES

    cfg = load_config(Path("configs/square.yaml"),
                      [*LAB_OVERRIDES, *FORMULATIONS["thesis"], "sim.plant.profile=ardrone_lab"])
    with tempfile.TemporaryDirectory() as d:
        rows = record_lockstep(cfg, d, seed=0).summary
    deviation = {(r.axis, r.metric): r.value for r in rows}[("path", "mean_deviation")]
    assert 0.7 * 0.1045 <= deviation <= 1.3 * 0.1045


# --- the kit's speed channels in closed form: hold and wind at a heading -------------------

U_POLE, V_POLE = 0.6650, 0.4596   # ssPitch2U, ssRoll2V poles as docs/plant.md §4 prints them


def _kit_steps(x0, hold: bool, wind, hover_tau_s: float, seconds: float):
    """kit_rk4 from ``x0`` with zero commands; the state and outputs at each 5 ms step."""
    from ardrone_nmpc.sim.plant_kit import KIT, kit_rk4

    k = KIT.coefficients(hover_tau_s)
    x, states, outs = np.asarray(x0, float), [], []
    for _ in range(int(round(seconds / H))):
        x, out = kit_rk4(x, 0.0, 0.0, 0.0, 0.0, hold, k, tuple(map(float, wind)), H)
        states.append(x.copy())
        outs.append(out)
    t = H * np.arange(1, len(states) + 1)
    return t, np.array(states), np.array(outs)


@pytest.mark.parametrize("hover_tau_s", [0.5, 3.0])
@pytest.mark.parametrize("psi", [0.0, 0.7, -2.5])
def test_the_kit_hold_damps_both_body_speeds_at_any_heading(psi, hover_tau_s):
    """The position hold (PCMD flag 0): the tilt commands are 0, so u and v decay from their
    values alone, each at the faster of 1/hover_tau_s and the kit's own pole (the hold adds
    damping, it never removes the pole's); the drone coasts along the body axes turned by ψ
    (forward (cos ψ, sin ψ), right (sin ψ, −cos ψ): world y is left)."""
    u0, v0 = -0.3, 0.5
    x0 = np.zeros(12)
    x0[0], x0[1], x0[2], x0[3], x0[8], x0[9] = 1.0, -2.0, 1.5, psi, u0, v0
    t, x, out = _kit_steps(x0, True, (0.0, 0.0, 0.0), hover_tau_s, 2.0)
    ru, rv = max(1.0 / hover_tau_s, U_POLE), max(1.0 / hover_tau_s, V_POLE)
    u, v = u0 * np.exp(-ru * t), v0 * np.exp(-rv * t)
    np.testing.assert_allclose(x[:, 8], u, rtol=2e-4, atol=1e-9)
    np.testing.assert_allclose(x[:, 9], v, rtol=2e-4, atol=1e-9)
    c, s = math.cos(psi), math.sin(psi)
    du, dv = u0 * (1 - np.exp(-ru * t)) / ru, v0 * (1 - np.exp(-rv * t)) / rv
    np.testing.assert_allclose(x[:, 0], 1.0 + c * du + s * dv, atol=2e-4)
    np.testing.assert_allclose(x[:, 1], -2.0 + s * du - c * dv, atol=2e-4)
    np.testing.assert_allclose(out[:, 0], c * u + s * v, atol=2e-4)   # the world velocity
    np.testing.assert_allclose(out[:, 1], s * u - c * v, atol=2e-4)
    assert np.all(x[:, 2] == 1.5) and np.all(x[:, 3] == psi)


@pytest.mark.parametrize("psi", [0.0, 1.0, -2.2])
def test_the_kit_drifts_with_a_wind_at_any_heading(psi):
    """No command, no hold, a constant horizontal wind (wx, wy): the air-relative body speeds
    decay through the kit's poles, u → w_u, v → w_v with w turned into the body frame, so the
    drone's world velocity tends to the wind's — and its vertical channel ignores the wind
    (the kit has no vertical drag: docs/plant-profiles.md)."""
    wx, wy = 0.4, -0.25
    x0 = np.zeros(12)
    x0[2], x0[3] = 1.0, psi
    t, x, out = _kit_steps(x0, False, (wx, wy, 0.3), 0.5, 6.0)
    c, s = math.cos(psi), math.sin(psi)
    w_u, w_v = c * wx + s * wy, s * wx - c * wy
    u, v = w_u * (1 - np.exp(-U_POLE * t)), w_v * (1 - np.exp(-V_POLE * t))
    np.testing.assert_allclose(x[:, 8], u, rtol=2e-4, atol=1e-6)
    np.testing.assert_allclose(x[:, 9], v, rtol=2e-4, atol=1e-6)
    np.testing.assert_allclose(out[:, 0], c * u + s * v, atol=1e-4)
    np.testing.assert_allclose(out[:, 1], s * u - c * v, atol=1e-4)
    assert np.all(x[:, 2] == 1.0) and np.all(out[:, 2] == 0.0)


def _noisy_kit_sim(seed: int) -> SimConfig:
    return SimConfig(plant={"profile": "thesis_kit"}, seed=seed,
                     noise=NoiseConfig(mocap_position_std_m=0.01, mocap_angle_std_rad=0.0,
                                       navdata_attitude_std_rad=0.0, navdata_yaw_std_rad=0.0,
                                       navdata_altitude_std_m=0.0,
                                       navdata_velocity_std_mps=0.0))


def _mocap_positions(plant, n: int = 5) -> list:
    return [tuple(plant.mocap_pose().position_m) for _ in range(n)]


def test_the_kit_from_a_config_is_seeded_by_sim_seed_or_the_seed_given():
    """As AirframePlant.from_config: ``seed`` (default ``sim.seed``) seeds the noise, so the
    same seed draws the same mocap noise and another seed other noise."""
    drone = DroneConfig()
    by_config = _mocap_positions(KitPlant.from_config(_noisy_kit_sim(3), drone))
    assert by_config == _mocap_positions(KitPlant.from_config(_noisy_kit_sim(3), drone))
    assert by_config == _mocap_positions(KitPlant.from_config(_noisy_kit_sim(9), drone, seed=3))
    assert by_config != _mocap_positions(KitPlant.from_config(_noisy_kit_sim(9), drone))
    airframe = AirframePlant(PlantParams.from_config(_noisy_kit_sim(3), drone),
                             _noisy_kit_sim(3).noise, seed=3)
    assert by_config == _mocap_positions(airframe)  # the same streams: at rest, the same pose
    params, noise = PlantParams.from_config(_noisy_kit_sim(0), drone), _noisy_kit_sim(0).noise
    assert _mocap_positions(KitPlant(params, noise)) == _mocap_positions(
        AirframePlant(params, noise))  # the default seed is the airframe's


def test_a_kit_drone_hovers_where_it_starts():
    """No command, no wind: every kit channel rests, so the drone stays at its initial
    position and heading (wherever that is, not only at the origin)."""
    params = PlantParams(initial_position_m=(1.0, -2.0, 1.2), initial_psi_rad=0.7,
                         navdata_trim_bias_max_rad=0.0, navdata_yaw_drift_radps=0.0,
                         navdata_yaw_walk_rad_per_sqrt_s=0.0, navdata_velocity_bias_std_mps=0.0)
    _, truth = fly(KitPlant(params, QUIET, seed=0), (0.0, 0.0, 0.0, 0.0), 1.0)
    for tr in truth:
        np.testing.assert_allclose(tr.position_m, (1.0, -2.0, 1.2), atol=1e-12)
        assert tr.psi_rad == pytest.approx(0.7, abs=1e-12)


def test_the_kits_take_off_and_landing_climb_at_their_speeds_with_the_hold_on():
    """The on-board take-off and landing command the climb rate through Gzc: its step
    response (0.1526 s + 5.153)/(s + 5.82) reaches takeoff_climb_mps (landing_speed_mps down)
    within e^(−5.82 t); and they fly with the position hold, so a wind w along x pushes the
    drone only to u = τ_h·|a_u|·w (du/dt = −u/τ_h + |a_u|·w, τ_h = hover_tau_s), not to w."""
    params = PlantParams(takeoff_climb_mps=0.6, landing_speed_mps=0.4, hover_tau_s=0.5)
    plant = KitPlant(params, QUIET, seed=1)
    plant.wind_mps = np.array([0.4, 0.0, 0.0])
    assert plant.takeoff()
    a_u = 0.665041  # ssPitch2U's pole as the kit stores it (docs/plant.md §4)
    for _ in range(int(round(1.2 / H))):
        plant.advance(H)
    assert plant.mode is FlightMode.TAKING_OFF
    vx, vy, vz = plant.truth.velocity_mps
    gain, feed = 5.153 / 5.82, 0.1526  # Gzc·s at s = 0 and at s → ∞
    gaz = 0.6 / gain
    assert vz == pytest.approx(gaz * (gain + (feed - gain) * math.exp(-5.82 * 1.2)), abs=1e-4)
    assert vx == pytest.approx(0.5 * a_u * 0.4 * (1 - math.exp(-1.2 / 0.5)), abs=2e-3)
    while plant.mode is FlightMode.TAKING_OFF:
        plant.advance(H)
    plant.wind_mps = np.zeros(3)
    assert plant.land()
    for _ in range(int(round(1.5 / H))):
        plant.advance(H)
    assert plant.mode is FlightMode.LANDING
    assert plant.truth.velocity_mps[2] == pytest.approx(-0.4, abs=1e-3)  # e^(−5.82·1.5) left


def test_the_kits_take_off_hands_over_where_the_climb_settles_at_the_take_off_altitude():
    """FLYING once the climb will settle at ``takeoff_altitude_m`` (docs/plant.md): with the
    commands then at 0, the kit's vertical channel (pole 5.82/s) coasts up to it — within
    what Gzc's direct feed-through (0.1526·gaz, gone with the gaz) and one 5 ms step leave."""
    params = PlantParams(takeoff_altitude_m=1.1, takeoff_climb_mps=0.5)
    plant = KitPlant(params, QUIET, seed=0)
    assert plant.takeoff()
    while plant.mode is FlightMode.TAKING_OFF:
        plant.advance(H)
    plant.command(0.0, 0.0, 0.0, 0.0)
    plant.advance(3.0)
    gaz = 0.5 / (5.153 / 5.82)
    assert plant.truth.position_m[2] == pytest.approx(1.1, abs=0.1526 * gaz / 5.82 + 0.5 * H)
