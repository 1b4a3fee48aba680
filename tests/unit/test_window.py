"""ardrone_nmpc.runs.window: the experiment window and the flying rows."""

from __future__ import annotations

import math

import numpy as np

from ardrone_nmpc.runs.window import GROUND_MODES, experiment_rows, flying_rows


def test_the_window_is_the_rows_from_experiment_time_zero():
    t = np.array([-0.13, -0.065, 0.0, 0.065, math.nan, 0.13])
    assert experiment_rows(t).tolist() == [False, False, True, True, False, True]


def test_a_log_that_never_reached_time_zero_is_its_own_window():
    t = np.array([-0.2, math.nan, -0.1])
    assert experiment_rows(t).tolist() == [True, False, True]


def test_among_restricts_the_window_and_its_fallback():
    t = np.array([-0.1, 0.0, 0.1, 0.2])
    has_state = np.array([True, False, True, False])
    assert experiment_rows(t, among=has_state).tolist() == [False, False, True, False]
    only_settle = np.array([True, False, False, False])
    assert experiment_rows(t, among=only_settle).tolist() == [True, False, False, False]
    nothing = np.zeros(4, dtype=bool)
    assert not experiment_rows(t, among=nothing).any()


def test_flying_rows_leave_out_the_ground_modes():
    mode = np.array(["taking_off", "settle", "track", "hover-stale-mocap", "landing",
                     "landed"], dtype=object)
    assert flying_rows(mode).tolist() == [False, True, True, True, False, False]
    assert GROUND_MODES == {"landed", "taking_off", "landing"}


def test_a_mode_column_with_one_value_says_nothing_about_the_ground():
    assert flying_rows(np.array(["landing"] * 3, dtype=object)).tolist() == [True] * 3
    assert flying_rows(np.array([""] * 2, dtype=object)).tolist() == [True] * 2
    assert flying_rows(np.array([], dtype=object)).size == 0
