"""The usual tick's shortcuts against the full paths they skip: ``Supervision.command``'s
nominal case against ``Supervision._command`` and ``Supervisor.check_feedback``'s one test
against ``Supervisor._feedback_chain`` — the same records, bits, state and verdicts."""

from __future__ import annotations

import itertools
import math
import struct
from types import SimpleNamespace

import numpy as np
import pytest

from ardrone_nmpc.config.schema import SafetyConfig
from ardrone_nmpc.control.mapping import DroneLimits
from ardrone_nmpc.core.types import AttitudeCommand, FlightMode, NavdataSample
from ardrone_nmpc.runtime.stages import Supervision
from ardrone_nmpc.safety import DRONE_ALARMS, Action, Decision, Supervisor

CFG = SafetyConfig()


def _floats(*values) -> tuple:
    return tuple((type(v), struct.pack("<d", v)) for v in values)


def _sent_bits(sent) -> tuple:
    p = sent.pcmd
    flown = (None if sent.flown is None else
             _floats(sent.flown.vz_ref_mps, sent.flown.phi_rad, sent.flown.theta_rad,
                     sent.flown.psirate_radps))
    return (_floats(p.roll_frac, p.pitch_frac, p.gaz_frac, p.yaw_frac), p.saturated,
            sent.u.dtype, sent.u.tobytes(), sent.progressive, sent.decision, flown,
            sent.saturated)


def _state_bits(s: Supervision) -> tuple:
    last = None if s._last is None else (s._last[0], s._last[1].tobytes())
    return _floats(s.vz_ref_mps, s.zacc_mps2), last


def _commands(rng):
    """Floats inside and beyond the tilt cap, numpy scalars, non-finite values."""
    specials = [math.nan, math.inf, -math.inf, 0.0, -0.0, 0.35, -0.35, 1e308]
    for _ in range(300):
        v = [float(x) for x in rng.normal(size=4) * rng.choice([0.05, 0.3, 2.0])]
        if rng.random() < 0.15:
            v[rng.integers(4)] = specials[rng.integers(len(specials))]
        if rng.random() < 0.1:
            j = rng.integers(4)
            v[j] = np.float64(v[j])
        zacc = float(rng.normal()) if rng.random() < 0.7 else specials[rng.integers(3)]
        if rng.random() < 0.05:
            zacc = np.float64(zacc)
        yield AttitudeCommand(*v), zacc


@pytest.mark.parametrize("gain", [1.0, 1.3, np.float64(0.8)])
def test_the_nominal_command_is_the_general_one(gain, monkeypatch):
    fast = Supervision(Supervisor(CFG), DroneLimits(), gain)
    full = Supervision(Supervisor(CFG), DroneLimits(), gain)
    rng = np.random.default_rng(26)
    actions = [Action.CONTROL] * 6 + [Action.FALLBACK, Action.HOLD, Action.HOVER]
    for cmd, zacc in _commands(rng):
        decision = Decision(actions[rng.integers(len(actions))], "r")
        got, want = fast.command(decision, cmd, zacc), full._command(decision, cmd, zacc)
        assert _sent_bits(got) == _sent_bits(want)
        assert _state_bits(fast) == _state_bits(full)
    # and the nominal tick does take the shortcut: the general path is not called
    monkeypatch.setattr(fast, "_command", None)
    sent = fast.command(Decision(Action.CONTROL), AttitudeCommand(0.1, 0.05, -0.02, 0.3), 0.2)
    assert sent.flown == AttitudeCommand(0.1, 0.05, -0.02, 0.3) and sent.saturated == "0000"


def _nav(mode=FlightMode.FLYING, battery=80.0, bits=None) -> NavdataSample:
    return NavdataSample(0.0, mode, battery, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, None, bits)


def _feedback_cases(cfg):
    ages = [0.0, cfg.mocap_hold_ms, cfg.mocap_hold_ms + 1e-9, cfg.mocap_hover_ms,
            cfg.mocap_hover_ms + 1.0, cfg.mocap_land_ms, cfg.mocap_land_ms + 1.0,
            cfg.navdata_land_ms, cfg.navdata_land_ms + 1.0, math.inf, math.nan]
    navs = [None, _nav(), _nav(bits=0), _nav(bits=1 << 3), _nav(mode=FlightMode.EMERGENCY),
            _nav(battery=cfg.battery_floor_pct), _nav(battery=math.nan)]
    navs += [_nav(bits=alarm.mask | 1) for alarm in DRONE_ALARMS]
    return itertools.product(ages, ages, navs)


@pytest.mark.parametrize("cfg", [
    CFG, CFG.model_copy(update={"mocap_hold_ms": 50.0, "navdata_land_ms": 80.0}),
    # an unvalidated config: limits out of order, then a NaN one — the shortcut must not
    # pass what the chain refuses
    SimpleNamespace(**{**CFG.model_dump(), "mocap_hold_ms": 300.0, "mocap_hover_ms": 200.0}),
    SimpleNamespace(**{**CFG.model_dump(), "mocap_hover_ms": math.nan}),
])
def test_the_feedback_shortcut_is_the_chain(cfg):
    for mocap_ms, navdata_ms, nav in _feedback_cases(cfg):
        fast, full = Supervisor(cfg), Supervisor(cfg)
        for _ in range(2):  # and again: a latched verdict stays
            got = fast.check_feedback(mocap_age_ms=mocap_ms, navdata_age_ms=navdata_ms,
                                      navdata=nav)
            want = full._feedback_chain(mocap_ms, navdata_ms, nav)
            assert got == want and fast.latched == full.latched


def test_a_new_config_moves_the_cached_limits():
    sup = Supervisor(CFG)
    ok = {"mocap_age_ms": 60.0, "navdata_age_ms": 30.0, "navdata": _nav()}
    assert sup.check_feedback(**ok).action is Action.CONTROL
    sup.cfg = CFG.model_copy(update={"mocap_hold_ms": 50.0, "max_speed_mps": 0.5})
    assert sup.check_feedback(**ok) == Decision(Action.HOLD, "stale-mocap")
    x = np.array([0.0, 1.0, 0.0, 0.0, 1.0, 0.0, 0.0])
    assert sup.check_state(x, None) == Decision(Action.HOVER, "speed")
    supervision = Supervision(sup, DroneLimits())
    sup.cfg = CFG.model_copy(update={"max_tilt_rad": 0.1})
    sent = supervision.command(Decision(Action.CONTROL), AttitudeCommand(0.0, 0.15, 0.0, 0.0),
                               0.0)
    assert sent.flown.phi_rad == 0.1 and sent.saturated == "1000"
