"""The supervision's mapping (``Supervision.command``: ``mapping.pcmd_of_floats`` on the limits
unpacked once) against the checked ``pcmd_of`` it replaced, and the delay ring's one-view
push against the two rows it writes: the same bits."""

from __future__ import annotations

import math
import struct

import numpy as np
import pytest

from ardrone_nmpc.config.schema import SafetyConfig
from ardrone_nmpc.control.mapping import DroneLimits, KIT_SCALES, pcmd_of, pcmd_of_floats
from ardrone_nmpc.core.types import AttitudeCommand
from ardrone_nmpc.runtime.stages import DelayPrediction, Supervision
from ardrone_nmpc.safety import Action, Decision, Supervisor


def _bits(pcmd) -> tuple:
    fracs = (pcmd.roll_frac, pcmd.pitch_frac, pcmd.gaz_frac, pcmd.yaw_frac)
    assert all(type(v) is float for v in fracs)  # a numpy scalar would log differently
    return tuple(struct.pack("<d", v) for v in fracs), pcmd.saturated


def _values(rng, n: int):
    # inside and beyond the limits, signed zeros included
    for _ in range(n):
        yield tuple(float(v) for v in rng.normal(size=4) * rng.choice([0.01, 0.3, 3.0]))
    yield (0.0, -0.0, 0.0, -0.0)
    yield (-0.0, 0.0, -0.0, 0.0)


@pytest.mark.parametrize("limits", [DroneLimits(), KIT_SCALES, DroneLimits(0.1, 0.5, 2.0)])
def test_pcmd_of_floats_is_pcmd_of(limits):
    rng = np.random.default_rng(26)
    scales = (limits.euler_angle_max_rad, limits.control_vz_max_mps, limits.control_yaw_radps)
    for vz, phi, theta, rate in _values(rng, 400):
        assert (_bits(pcmd_of_floats(vz, phi, theta, rate, *scales))
                == _bits(pcmd_of(vz, phi, theta, rate, limits)))


@pytest.mark.parametrize("action", [Action.CONTROL, Action.FALLBACK])
@pytest.mark.parametrize("gain", [1.0, 1.3])
def test_the_supervision_maps_as_pcmd_of_did(action, gain):
    limits = DroneLimits()
    supervision = Supervision(Supervisor(SafetyConfig()), limits, gain)
    cap = SafetyConfig().max_tilt_rad
    rng = np.random.default_rng(7)
    for vz, phi, theta, rate in _values(rng, 300):
        # numpy scalars too, as a caller may hand them: the fractions are Python floats
        cmd = AttitudeCommand(np.float64(vz), phi, np.float64(theta), rate)
        sent = supervision.command(Decision(action, ""), cmd, 0.5)
        roll = min(max(phi, -cap), cap)
        pitch = min(max(theta, -cap), cap)
        k = gain if action is Action.CONTROL else 1.0
        if k != 1.0:
            roll, pitch = roll / k, pitch / k
        assert _bits(sent.pcmd) == _bits(pcmd_of(vz, roll, pitch, rate, limits))


def test_the_supervision_follows_new_limits():
    supervision = Supervision(Supervisor(SafetyConfig()), DroneLimits())
    supervision.limits = KIT_SCALES
    sent = supervision.command(Decision(Action.FALLBACK, ""), AttitudeCommand(0.3, 0.1, 0.0, 0.0),
                               math.nan)
    assert _bits(sent.pcmd) == _bits(pcmd_of(0.3, 0.1, 0.0, 0.0, KIT_SCALES))


@pytest.mark.parametrize("delay_s, max_delay_s", [(0.0, 0.0), (0.065, 0.0), (0.13, 0.5)])
def test_a_push_writes_both_rows_of_the_ring(delay_s, max_delay_s):
    delay = DelayPrediction(delay_s, 0.065, max_delay_s=max_delay_s)
    cap = delay._capacity
    rng = np.random.default_rng(3)
    expected = np.zeros((2 * cap, 4))
    for k in range(3 * cap + 1):
        u = rng.normal(size=4)
        i = k % cap
        expected[i] = expected[i + cap] = u
        delay.push(u)
        assert np.array_equal(delay._sent, expected)
