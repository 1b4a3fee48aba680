"""The mode-label grammar (core/modes.py) against the labels the writers produce."""

from __future__ import annotations

import math

import pytest

from ardrone_nmpc.core.modes import GROUND_MODES, LANDING, SETTLE, TRACK, Mode
from ardrone_nmpc.runtime.lockstep import SELF_LANDED
from ardrone_nmpc.safety import Action, Decision

# every (action, reason) safety.py and runtime/stages.py decide
DECISIONS = [(Action.STOP, "emergency"), (Action.LAND, "battery"), (Action.LAND, "navdata-lost"),
             (Action.LAND, "mocap-lost"), (Action.LAND, "geofence"),
             (Action.HOVER, "stale-mocap"), (Action.HOLD, "stale-mocap"),
             (Action.HOVER, "nonfinite-state"), (Action.HOVER, "geofence"),
             (Action.HOVER, "speed"), (Action.HOVER, "tilt"), (Action.HOLD, "solver"),
             (Action.FALLBACK, "solver"), (Action.HOVER, "solver"),
             (Action.HOVER, "nonfinite-command")]


@pytest.mark.parametrize("action, reason", DECISIONS)
def test_every_supervisor_label_parses_back_to_its_decision(action, reason):
    label = Decision(action, reason).mode(TRACK)
    mode = Mode.parse(label)
    assert (mode.action, mode.reason, mode.label) == (action.value, reason, label)
    assert mode.is_fallback and not mode.is_nominal and not mode.is_ground
    assert mode.is_abort == (action in (Action.LAND, Action.STOP))
    assert mode.is_airborne == (action in (Action.HOLD, Action.FALLBACK, Action.HOVER))
    assert mode.is_landing == (action is Action.LAND)
    assert mode.is_emergency_stop == (label == "stop-emergency")


@pytest.mark.parametrize("label", [SETTLE, TRACK])
def test_the_runner_labels_are_nominal_and_airborne(label):
    mode = Mode.parse(Decision(Action.CONTROL).mode(label))
    assert mode.is_nominal and mode.is_airborne and not mode.is_abort
    assert mode.is_tracking == (label == TRACK)
    assert mode.is_fallback == (label == SETTLE)   # set, and not tracking


@pytest.mark.parametrize("label", sorted(GROUND_MODES))
def test_ground_labels_are_not_split_at_their_underscore_or_dash(label):
    mode = Mode.parse(label)
    assert mode == Mode(label) and mode.is_ground and mode.is_abort and not mode.is_airborne
    assert mode.is_landing == (label == LANDING)


@pytest.mark.parametrize("cell", ["", None, math.nan, 3.0])
def test_an_empty_or_non_text_cell_is_no_mode(cell):
    mode = Mode.parse(cell)
    assert mode == Mode("") and not mode.is_set and mode.is_nominal and not mode.is_fallback


def test_the_self_landed_ending_is_a_landing_with_its_reason():
    mode = Mode.parse(SELF_LANDED)
    assert (mode.action, mode.reason) == ("land", "drone-landed-itself") and mode.is_abort
