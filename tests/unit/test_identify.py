"""``identify``'s fits on flights synthesised by scipy from known channels (``signal.lsim`` of
the documented transfer functions; not the fit's own simulator), and the excitation reference
of the identification flight."""

from __future__ import annotations

import math

import numpy as np
import pytest
import yaml
from scipy.signal import lsim

from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.experiments.identify.channels import fit_attitude, fit_velocity
from ardrone_nmpc.experiments.identify.data import Flight, held_out
from ardrone_nmpc.experiments.identify.profile import identify, profile_data, write_profile
from ardrone_nmpc.reference.excitation import Excitation, prbs_bits

E, V, Y = 0.2094, 0.7, 1.745
G = 9.80665


def _held(t_cmd, u, grid, delay):
    k = np.clip(np.searchsorted(t_cmd, grid - delay, side="right") - 1, 0, None)
    return u[k]


def _synthetic(*, delay=0.15, gains=(1.3, 1.8), tilt_sys=None, drag=0.5, vz=(0.8, 0.3),
               yaw=(1.0, 0.07), seconds=60.0, seed=0) -> Flight:
    """A flight whose channels are exactly the documented forms, sampled as a log is."""
    rng = np.random.default_rng(seed)
    t_cmd = np.arange(0.0, seconds, 0.065)
    cmd = np.zeros((t_cmd.size, 4))
    for a in range(4):
        k = 0
        while k < t_cmd.size:
            hold = int(rng.integers(4, 30))
            cmd[k:k + hold, a] = rng.uniform(-0.5, 0.5) * (k // 150 % 4 == a or a == 2)
            k += hold
    grid = np.arange(0.0, seconds, 0.002)
    tilt_sys = tilt_sys or ([1.0], [0.1, 1.0])
    tilt = np.column_stack([gains[a] * lsim(tilt_sys, E * _held(t_cmd, cmd[:, a], grid, delay),
                                            grid)[1] for a in range(2)])
    # world/model signs at ψ = 0: forward speed from θ = −pitch, left from −φ
    v_fwd = lsim(([G], [1.0, drag]), np.tan(-tilt[:, 1]), grid)[1]
    v_left = lsim(([G], [1.0, drag]), -np.tan(tilt[:, 0]), grid)[1]
    climb = lsim(([vz[0] * V], [vz[1], 1.0]), _held(t_cmd, cmd[:, 2], grid, delay), grid)[1]
    turn = lsim(([-yaw[0] * Y], [yaw[1], 1.0]), _held(t_cmd, cmd[:, 3], grid, delay), grid)[1]
    step = grid[1] - grid[0]
    pose = np.column_stack([np.cumsum(v) * step for v in (v_fwd, v_left, climb, turn)])
    pose[:, 2] += 1.0
    t_nav = np.arange(0.5, seconds - 0.1, 1 / 15)
    nav = np.column_stack([np.interp(t_nav, grid, tilt[:, a])
                           + rng.normal(0, math.radians(0.2), t_nav.size) for a in range(2)])
    t_pose = t_cmd[10:-2] + 0.002
    poses = np.column_stack([np.interp(t_pose, grid, pose[:, a]) for a in range(4)])
    poses[:, :3] += rng.normal(0, 5e-4, (t_pose.size, 3))
    return Flight("synthetic", t_cmd, cmd, t_nav, nav, t_pose, poses, ((0.0, seconds - 0.2),),
                  E, V, Y)


def test_a_lagged_drone_is_identified_as_one():
    ident = identify([_synthetic()])
    a = ident.attitude.params
    assert ident.attitude.model == "lag"
    assert a["delay"].value == pytest.approx(0.15, abs=0.01)
    assert (a["roll_gain"].value, a["pitch_gain"].value) == pytest.approx((1.3, 1.8), rel=0.03)
    assert a["lag"].value == pytest.approx(0.1, rel=0.15)
    v = ident.velocity.params
    assert v["drag_forward"].value == pytest.approx(0.5, rel=0.1)
    assert v["accel_forward"].value == pytest.approx(G, rel=0.05)
    assert ident.vertical.params["gain"].value == pytest.approx(0.8, rel=0.05)
    assert ident.vertical.params["tau"].value == pytest.approx(0.3, rel=0.15)
    assert ident.yaw.params["gain"].value == pytest.approx(1.0, rel=0.05)
    for p in (*a.values(), *v.values()):
        assert 0.0 < p.std < math.inf  # every parameter states its uncertainty


def test_the_kits_form_is_chosen_by_its_held_out_fit():
    kit = ([2.5139 / 0.408, 4.8661 / 0.408], [1.0, 3.9784, 11.9184])  # pitch, unit gain
    fit = fit_attitude([_synthetic(tilt_sys=kit, seconds=40.0)])
    assert fit.model == "second_order"
    p = fit.params
    assert p["pitch_gain"].value == pytest.approx(1.8, rel=0.05)
    assert p["delay"].value == pytest.approx(0.15, abs=0.03)
    assert p["wn"].value == pytest.approx(math.sqrt(11.9184), rel=0.15)
    assert "second order with a zero" in fit.notes[0]


def test_velocity_needs_no_attitude_model():
    fit = fit_velocity([_synthetic(drag=0.8, seconds=40.0)])
    assert fit.params["drag_left"].value == pytest.approx(0.8, rel=0.1)
    assert min(fit.held_out_fit_pct) > 80.0


def test_held_out_blocks_are_a_quarter_spread_over_the_flight():
    t = np.arange(0.0, 60.0, 0.01)
    test = held_out(t)
    assert test.mean() == pytest.approx(0.25, abs=0.01)
    assert test[(t > 10) & (t < 20)].any() and test[(t > 40) & (t < 50)].any()


def test_the_profile_is_a_plant_profile_the_simulator_takes(tmp_path):
    ident = identify([_synthetic(seconds=40.0)])
    data = profile_data(ident)
    assert data["plant"]["attitude_model"] == "lag" and "tau_tilt_s" in data["plant"]
    path = write_profile(ident, tmp_path / "drone.yaml", command="ardrone-nmpc identify x")
    text = path.read_text(encoding="utf-8")
    assert text.startswith("# plant profile identified") and "command delay: " in text
    assert yaml.safe_load(text) == data
    cfg = load_config(None, [f"sim.plant.profile={path}"])
    assert cfg.sim.plant.command_delay_s == data["plant"]["command_delay_s"]
    assert cfg.sim.vz_gain == data["vz_gain"]


# ----------------------------------------------------------------------------- excitation
def test_the_excitation_steps_one_axis_at_a_time_within_its_amplitudes():
    e = Excitation((0.0, 0.0, 1.0), 0.0, (0.25, 0.25, 0.15), 0.4, axis_s=10.0, bit_s=1.2,
                   rest_s=2.0, sweep_m=0.4, sweep_mps=0.2)
    assert e.duration_s == pytest.approx(2 * (10 + 8 + 2) + 2 * (10 + 2))
    t = np.arange(0.0, e.duration_s + 2.0, 0.01)
    s = e.state_at(t)
    moved = np.abs(s[:, [0, 2, 4, 6]] - [0.0, 0.0, 1.0, 0.0]) > 1e-12
    assert moved.sum(axis=1).max() == 1  # never two axes at once
    assert np.abs(s[:, 0]).max() == pytest.approx(0.4)
    assert np.abs(s[:, 4] - 1).max() == pytest.approx(0.15)
    assert np.abs(s[:, 6]).max() == pytest.approx(0.4)
    sweep = (t >= 10.0) & (t < 18.0)  # x's sweep: its speed is the position's slope
    slope = np.diff(s[sweep, 0]) / np.diff(t[sweep])
    speed = s[sweep, 1][:-1]
    legs = speed[1:] == speed[:-1]  # not across a turn
    np.testing.assert_allclose(slope[:-1][legs], speed[:-1][legs], atol=1e-6)
    assert set(np.round(speed, 9)) == {0.2, -0.2}
    assert np.all(s[t >= e.duration_s] == s[0] * 0 + [0, 0, 0, 0, 1.0, 0, 0])


def test_the_prbs_is_the_maximal_length_sequence():
    bits = prbs_bits(254)
    assert np.array_equal(bits[:127], bits[127:])  # period 127 …
    assert bits[:127].sum() == 1  # … with one more +1 than −1
    assert list(bits[:10]) == [1, -1, -1, 1, -1, -1, 1, 1, -1, 1]
