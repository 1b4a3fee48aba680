"""What ``auto`` does with the flight's own estimate of the delay and the attitude gain: the
prediction's delay, the command mapping's gain, their events — in a lockstep flight against
a plant whose delay and gain are not the configured ones."""

from __future__ import annotations

import numpy as np
import pytest

from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.control.mapping import DroneLimits
from ardrone_nmpc.core.types import AttitudeCommand
from ardrone_nmpc.runs.memory import MemoryRecorder
from ardrone_nmpc.runtime.lockstep import run_lockstep
from ardrone_nmpc.runtime.stages import DelayPrediction, Supervision
from ardrone_nmpc.safety import Action, Decision, Supervisor
from ardrone_nmpc.config.schema import SafetyConfig


def test_the_prediction_takes_a_new_delay_to_the_nearest_tick_within_its_memory():
    d = DelayPrediction(0.26, 0.065, max_delay_s=0.5)
    assert d.delay_ticks == 4
    for k in range(8):
        d.push(np.array([0.0, 0.0, 0.01 * k, 0.0]))
    assert d.set_delay_s(0.152) and d.delay_ticks == 2
    assert not d.set_delay_s(0.14)  # still 2 ticks: no change
    assert d.set_delay_s(2.0) and d.delay_ticks == 8  # capped at what it remembers
    x = np.zeros(7)
    x[4] = 1.0
    moved = d.predict(x)  # the 8 newest inputs, pitch 0 … 0.07 rad: it moves forward
    assert moved[0] > 0.0 and moved[1] > 0.0


def test_the_mapping_divides_the_drones_gain_out():
    sup = Supervision(Supervisor(SafetyConfig()), DroneLimits(0.2, 0.7, 1.745),
                      attitude_gain=2.0)
    sent = sup.command(Decision(Action.CONTROL), AttitudeCommand(0.0, 0.1, -0.05, 0.0), 0.0)
    assert (sent.pcmd.roll_frac, sent.pcmd.pitch_frac) == pytest.approx((0.25, 0.125))
    np.testing.assert_allclose(sent.u[1:3], [0.1, -0.05])  # the tilt meant, for the predictor


def _fly(*overrides):
    cfg = load_config("configs/step_x.yaml", ["duration_s=10", *overrides])
    rec = MemoryRecorder()
    run_lockstep(cfg, recorder=rec)
    return rec.run_data(cfg, seed=0)


def test_auto_uses_the_measured_delay_and_gain_and_says_so():
    run = _fly("sim.plant.command_delay_s=0.1", "sim.plant.attitude_gain=2.0")
    kinds = {e["kind"]: e for e in run.events}
    delay, gain = kinds["delay_compensation"], kinds["attitude_gain"]
    assert delay["previous_s"] == pytest.approx(0.26)
    assert delay["delay_s"] == pytest.approx(0.13)  # 0.1 s to the nearest tick: 2 × 65 ms
    assert delay["estimate_s"] == pytest.approx(0.1, abs=0.02)
    assert gain["previous"] == 1.0 and gain["gain"] == pytest.approx(2.0, rel=0.1)
    estimates = [e for e in run.events if e["kind"] == "attitude_estimate"]
    assert estimates and estimates[-1]["delay_confident"] and estimates[-1]["gain_confident"]
    # after the change the drone is asked for half the tilt: PCMD pitch stays within ±0.3
    late = run.columns["t_s"] > gain["t_s"] + 1.0
    assert np.max(np.abs(run.columns["cmd_pitch_frac"][late])) < 0.3


def test_fixed_values_neither_estimate_nor_change():
    run = _fly("sim.plant.command_delay_s=0.1", "controller.delay_compensation_s=0.26",
               "controller.attitude_gain=1.0")
    assert not [e for e in run.events if e["kind"] in ("attitude_estimate",
                                                       "delay_compensation", "attitude_gain")]


def test_the_bounds_hold_whatever_the_estimate():
    run = _fly("sim.plant.attitude_gain=2.0", "controller.adaptation.gain_max=1.5",
               "controller.adaptation.delay_max_s=0.2")
    gains = [e["gain"] for e in run.events if e["kind"] == "attitude_gain"]
    delays = [e["delay_s"] for e in run.events if e["kind"] == "delay_compensation"]
    assert gains and max(gains) == 1.5
    assert all(d <= 0.2 for d in delays)
