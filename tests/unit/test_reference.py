"""Tests of the reference trajectories (ardrone_nmpc.reference.trajectories)."""

from __future__ import annotations

import math
import re
import typing
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ardrone_nmpc.core.angles import wrap_angle_rad
from ardrone_nmpc.config.schema import ReferenceConfig
from ardrone_nmpc.reference.trajectories import (
    POLYLINE_SPACING_M,
    Ellipse,
    Hover,
    Lorenz,
    ReferenceError,
    Square,
    SquareAltitudes,
    Step,
    Trajectory,
    Waypoints,
    horizon,
    make_trajectory,
)
from ardrone_nmpc.reference.waypoints import read_waypoint_file
from ardrone_nmpc.config.limits import (MAX_COORDINATE_M, MAX_PATH_FILE_BYTES,
                                        MAX_PATH_LENGTH_M, MAX_WAYPOINTS)
from ardrone_nmpc.errors import UserError
from ardrone_nmpc.core.types import IX_PSI, IX_VX, IX_VY, IX_VZ, IX_X, IX_Y, IX_Z

TRAJ_DIR = Path(__file__).resolve().parents[2] / "trajectories"


def load_waypoints_csv(path) -> Waypoints:
    return Waypoints.from_file(read_waypoint_file(path))
POS = [IX_X, IX_Y, IX_Z]
VEL = [IX_VX, IX_VY, IX_VZ]


def finite_difference_velocity(traj, t, h=1e-5):
    """Central difference of the positions at times ``t`` (s): (len(t), 3) m/s."""
    t = np.asarray(t, dtype=float)
    return (traj.state_at(t + h)[:, POS] - traj.state_at(t - h)[:, POS]) / (2 * h)


def segment_lengths(points):
    return np.linalg.norm(np.diff(points, axis=0), axis=1)


@pytest.fixture(scope="module")
def lorenz_default():
    return Lorenz()


# A few trajectories of each family for the property tests (Lorenz is slow to build: not here).
TRAJECTORIES = {
    "hover": Hover((0.3, -0.2, 1.1), 0.4),
    "step": Step((0.0, 0.0, 1.0), 0.0, (-1.5, 0.0, 1.0), 1.0, 2.0),
    "square": Square((0.0, 0.0, 1.0), 1.0, 5.0, 0.0),
    "square_altitudes": SquareAltitudes((0.5, -0.5), 1.2, (0.8, 1.0, 1.2, 1.4), 4.0, 0.3),
    "ellipse": Ellipse((0.2, -0.1), (1.0, 0.6), 1.2, 20.0, 0.0),
    "waypoints": Waypoints([0.0, 1.0, 3.0, 6.0], [[0, 0, 1], [1, 0, 1], [1, 2, 1.5], [0, 0, 1]],
                           [0.0, 3.0, -3.0, 0.5]),
}


# ----------------------------------------------------------------------------- horizon


@settings(max_examples=150, deadline=None)
@given(name=st.sampled_from(sorted(TRAJECTORIES)),
       t=st.floats(-5.0, 40.0, allow_nan=False),
       dtau=st.floats(0.005, 0.5, allow_nan=False),
       n=st.integers(1, 30))
def test_horizon_rows_are_state_at_stage_times(name, t, dtau, n):
    traj = TRAJECTORIES[name]
    ref = horizon(traj, t, dtau, n)
    assert ref.shape == (n + 1, 7)
    for i in range(n + 1):
        expected = traj.state_at(np.array([t + i * dtau]))[0]
        np.testing.assert_allclose(ref[i], expected, rtol=0, atol=1e-12)


@settings(max_examples=50, deadline=None)
@given(t=st.floats(0.0, 30.0, allow_nan=False), dtau=st.floats(0.01, 0.3, allow_nan=False),
       n=st.integers(2, 20))
def test_horizon_is_not_the_current_point_repeated(t, dtau, n):
    ellipse = TRAJECTORIES["ellipse"]
    ref = horizon(ellipse, t, dtau, n)
    # each stage has moved along the ellipse by ω·i·Δτ
    moved = np.linalg.norm(ref[1:, POS] - ref[0, POS], axis=1)
    assert np.all(moved > 0)
    np.testing.assert_allclose(ref[-1], ellipse.state_at(np.array([t + n * dtau]))[0], atol=1e-12)


@pytest.mark.parametrize("n, dtau", [(0, 0.1), (-1, 0.1), (5, 0.0), (5, -0.1), (5, math.nan)])
def test_horizon_rejects_bad_arguments(n, dtau):
    with pytest.raises(ValueError):
        horizon(TRAJECTORIES["hover"], 0.0, dtau, n)


@pytest.mark.parametrize("name", sorted(TRAJECTORIES))
def test_state_at_is_vectorised(name):
    traj = TRAJECTORIES[name]
    t = np.linspace(-1.0, 25.0, 53)
    many = traj.state_at(t)
    assert many.shape == (t.size, 7)
    one_by_one = np.vstack([traj.state_at(np.array([ti])) for ti in t])
    np.testing.assert_array_equal(many, one_by_one)
    assert traj.state_at(3.0).shape == (1, 7)
    assert isinstance(traj, Trajectory)


# ----------------------------------------------------------------------------- hover and step


def test_hover_is_constant_with_zero_velocity():
    s = Hover((0.3, -0.2, 1.1), 0.4).state_at(np.array([-1.0, 0.0, 7.5, 1e4]))
    np.testing.assert_array_equal(s, np.tile([0.3, 0, -0.2, 0, 1.1, 0, 0.4], (4, 1)))
    assert Hover((0, 0, 1)).duration_s == math.inf
    np.testing.assert_array_equal(Hover((0.3, -0.2, 1.1)).polyline_m(), [[0.3, -0.2, 1.1]])


def test_step_switches_exactly_at_step_time():
    step = Step((0.0, 0.0, 1.0), 0.0, (-1.5, 0.5, 1.2), 1.0, 2.0)
    before = np.nextafter(2.0, -math.inf)
    s = step.state_at(np.array([-1.0, 0.0, before, 2.0, 2.0 + 1e-12, 50.0]))
    start = [0, 0, 0, 0, 1, 0, 0]
    target = [-1.5, 0, 0.5, 0, 1.2, 0, 1.0]
    np.testing.assert_array_equal(s[:3], np.tile(start, (3, 1)))
    np.testing.assert_array_equal(s[3:], np.tile(target, (3, 1)))


def test_step_at_time_zero_starts_at_target():
    # thesis take-off step: step_time 0 → the target from t = 0
    step = Step((0, 0, 0), 0.0, (0, 0, 1), 0.0, 0.0)
    assert step.state_at(0.0)[0, IX_Z] == 1.0
    assert step.state_at(-0.01)[0, IX_Z] == 0.0


def test_step_polyline():
    np.testing.assert_array_equal(Step((0, 0, 1), 0, (-1.5, 0, 1), 0, 1).polyline_m(),
                                  [[0, 0, 1], [-1.5, 0, 1]])
    # a heading-only step has one point (no zero-length segment)
    np.testing.assert_array_equal(Step((0, 0, 1), 0, (0, 0, 1), 1.0, 1).polyline_m(), [[0, 0, 1]])


# ----------------------------------------------------------------------------- squares


@pytest.mark.parametrize("start, side, leg", [((0.0, 0.0, 1.0), 1.0, 5.0),
                                              ((-0.4, 0.7, 1.3), 1.7, 3.0)])
def test_square_corners_counter_clockwise(start, side, leg):
    sq = Square(start, side, leg, 0.2)
    x0, y0, z0 = start
    corners = np.array([[x0, y0], [x0 + side, y0], [x0 + side, y0 + side], [x0, y0 + side],
                        [x0, y0]])
    s = sq.state_at(leg * np.arange(5.0))
    np.testing.assert_allclose(s[:, [IX_X, IX_Y]], corners, atol=1e-12)
    np.testing.assert_array_equal(s[:, IX_Z], z0)
    np.testing.assert_array_equal(s[:, IX_PSI], 0.2)
    assert sq.duration_s == 4 * leg
    # counter-clockwise seen from above: the signed area of the corner loop is positive
    area = 0.5 * np.sum(corners[:-1, 0] * corners[1:, 1] - corners[1:, 0] * corners[:-1, 1])
    assert area == pytest.approx(side**2)


def test_square_constant_speed_on_legs():
    side, leg = 1.0, 5.0
    sq = Square((0, 0, 1), side, leg)
    for k, direction in enumerate([(1, 0), (0, 1), (-1, 0), (0, -1)]):
        t = np.linspace(k * leg, (k + 1) * leg, 41)[:-1]
        v = sq.state_at(t)[:, VEL]
        np.testing.assert_allclose(v, np.tile([*direction, 0], (t.size, 1)) * side / leg,
                                   atol=1e-15)
        np.testing.assert_allclose(np.linalg.norm(v, axis=1), side / leg, rtol=1e-12)


def test_square_velocity_is_derivative_of_position():
    sq = Square((0.2, -0.3, 1.0), 1.0, 5.0)
    t = np.linspace(0.0, 20.0, 801)
    t = t[np.abs(t / 5.0 - np.round(t / 5.0)) * 5.0 > 1e-3]  # away from corners
    np.testing.assert_allclose(sq.state_at(t)[:, VEL], finite_difference_velocity(sq, t),
                               atol=1e-6)


def test_square_closes_and_holds():
    sq = Square((0.2, -0.3, 1.0), 1.0, 5.0, 0.5)
    end = sq.state_at(np.array([20.0, 21.0, 100.0]))
    np.testing.assert_allclose(end[:, POS], np.tile([0.2, -0.3, 1.0], (3, 1)), atol=1e-12)
    np.testing.assert_array_equal(end[:, VEL], 0.0)
    before = sq.state_at(-1.0)[0]
    np.testing.assert_array_equal(before, [0.2, 0, -0.3, 0, 1.0, 0, 0.5])
    poly = sq.polyline_m()
    np.testing.assert_array_equal(poly[0], poly[-1])
    assert segment_lengths(poly).max() <= POLYLINE_SPACING_M + 1e-12
    assert segment_lengths(poly).min() > 0
    assert segment_lengths(poly).sum() == pytest.approx(4.0)


def test_square_altitudes_corners_and_climb_rate():
    alt = (0.8, 1.0, 1.2, 1.4)
    sq = SquareAltitudes((0.0, 0.0), 1.0, alt, 5.0)
    s = sq.state_at(5.0 * np.arange(5.0))
    np.testing.assert_allclose(s[:, IX_Z], [*alt, alt[0]], atol=1e-12)
    np.testing.assert_allclose(s[:, [IX_X, IX_Y]], [[0, 0], [1, 0], [1, 1], [0, 1], [0, 0]],
                               atol=1e-12)
    rates = [(1.0 - 0.8) / 5, (1.2 - 1.0) / 5, (1.4 - 1.2) / 5, (0.8 - 1.4) / 5]
    for k, rate in enumerate(rates):
        t = np.linspace(5.0 * k + 0.1, 5.0 * (k + 1) - 0.1, 9)
        st_ = sq.state_at(t)
        np.testing.assert_allclose(st_[:, IX_VZ], rate, rtol=1e-12)
        np.testing.assert_allclose(st_[:, VEL], finite_difference_velocity(sq, t), atol=1e-6)
    assert sq.state_at(25.0)[0, IX_VZ] == 0.0
    # a (3,) start is accepted, its z ignored in favour of the corner altitudes
    t_all = np.linspace(-1.0, 22.0, 47)
    np.testing.assert_array_equal(SquareAltitudes((0.0, 0.0, 1.0), 1.0, alt, 5.0).state_at(t_all),
                                  sq.state_at(t_all))


# ----------------------------------------------------------------------------- ellipse


def test_ellipse_on_curve_with_analytic_velocity():
    cx, cy, a, b, T = 0.2, -0.1, 1.0, 0.6, 20.0
    el = Ellipse((cx, cy), (a, b), 1.2, T, 0.3)
    t = np.linspace(-3.0, 45.0, 1001)
    s = el.state_at(t)
    np.testing.assert_allclose(((s[:, IX_X] - cx) / a) ** 2 + ((s[:, IX_Y] - cy) / b) ** 2, 1.0,
                               atol=1e-12)
    np.testing.assert_array_equal(s[:, IX_Z], 1.2)
    np.testing.assert_array_equal(s[:, IX_VZ], 0.0)
    np.testing.assert_array_equal(s[:, IX_PSI], 0.3)
    np.testing.assert_allclose(s[:, VEL], finite_difference_velocity(el, t), atol=1e-8)
    # starts at (cx + a, cy) moving towards +y (counter-clockwise), one lap per period
    np.testing.assert_allclose(el.state_at(0.0)[0], [cx + a, 0, cy, b * 2 * math.pi / T, 1.2, 0,
                                                     0.3], atol=1e-15)
    np.testing.assert_allclose(el.state_at(T)[0], el.state_at(0.0)[0], atol=1e-12)
    assert el.duration_s == math.inf


def test_ellipse_polyline():
    el = Ellipse((0.2, -0.1), (1.0, 0.6), 1.2, 20.0)
    poly = el.polyline_m()
    assert segment_lengths(poly).max() <= POLYLINE_SPACING_M
    np.testing.assert_array_equal(poly[0], poly[-1])
    np.testing.assert_allclose(((poly[:, 0] - 0.2) / 1.0) ** 2 + ((poly[:, 1] + 0.1) / 0.6) ** 2,
                               1.0, atol=1e-12)


# ----------------------------------------------------------------------------- Lorenz


def test_lorenz_velocity_matches_finite_differences(lorenz_default):
    lz = lorenz_default
    t = np.linspace(0.01, lz.duration_s - 0.01, 2001)
    np.testing.assert_allclose(lz.state_at(t)[:, VEL], finite_difference_velocity(lz, t, 1e-4),
                               atol=1e-6)


def test_lorenz_stays_in_a_box_and_is_slow_enough(lorenz_default):
    lz = lorenz_default
    s = lz.state_at(np.linspace(0.0, lz.duration_s, 24001))
    assert np.all(np.abs(s[:, IX_X]) < 1.0) and np.all(np.abs(s[:, IX_Y]) < 1.4)
    assert np.all(s[:, IX_Z] > 0.25) and np.all(s[:, IX_Z] < 2.3)
    peak = np.linalg.norm(s[:, VEL], axis=1).max()
    assert 0.3 < peak <= 1.0
    assert lz.peak_speed_mps() == pytest.approx(peak, rel=0.02)
    np.testing.assert_array_equal(s[:, IX_PSI], 0.0)


def test_lorenz_scaling_and_time_scale(lorenz_default):
    # doubling the scale doubles the offsets from the centre; doubling the time scale makes the
    # same path twice as fast
    lz = lorenz_default
    big = Lorenz(scale_m=0.1, time_scale=0.05, center_m=(0, 0), altitude_m=1.25, duration_s=20)
    fast = Lorenz(scale_m=0.05, time_scale=0.1, center_m=(0, 0), altitude_m=1.25, duration_s=10)
    t = np.linspace(0.0, 10.0, 101)
    ref = lz.state_at(t)
    sb = big.state_at(t)
    np.testing.assert_allclose(sb[:, [IX_X, IX_Y]], 2 * ref[:, [IX_X, IX_Y]], atol=1e-7)
    np.testing.assert_allclose(sb[:, IX_Z] - 1.25, 2 * (ref[:, IX_Z] - 1.25), atol=1e-7)
    sf = fast.state_at(t / 2)
    np.testing.assert_allclose(sf[:, POS], ref[:, POS], atol=1e-7)
    np.testing.assert_allclose(sf[:, VEL], 2 * ref[:, VEL], atol=1e-6)


def test_lorenz_is_deterministic_and_holds_outside_its_span(lorenz_default):
    lz = lorenz_default
    t = np.linspace(0, 30, 31)
    np.testing.assert_array_equal(Lorenz().state_at(t), lz.state_at(t))
    out = lz.state_at(np.array([-1.0, lz.duration_s + 1.0]))
    np.testing.assert_array_equal(out[:, VEL], 0.0)
    np.testing.assert_array_equal(out[0, POS], lz.state_at(0.0)[0, POS])
    np.testing.assert_array_equal(out[1, POS], lz.state_at(lz.duration_s)[0, POS])


def test_lorenz_polyline(lorenz_default):
    poly = lorenz_default.polyline_m()
    seg = segment_lengths(poly)
    assert seg.max() <= POLYLINE_SPACING_M and seg.min() > 0
    np.testing.assert_allclose(poly[0], lorenz_default.state_at(0.0)[0, POS])


def test_lorenz_config_defaults_peak_speed_at_most_1_mps():
    traj = make_trajectory(ReferenceConfig(kind="lorenz"), duration_s=120.0)
    assert traj.peak_speed_mps() <= 1.0


# ----------------------------------------------------------------------------- waypoints


def test_waypoints_interpolation_exact_at_and_between_points():
    t = [0.0, 2.0, 3.0, 7.0]
    p = np.array([[0, 0, 1], [1, 0, 1], [1, 2, 1.5], [-1, 0, 0.5]], dtype=float)
    wp = Waypoints(t, p, [0.0, 0.5, 1.0, 0.0])
    s = wp.state_at(np.array(t))
    np.testing.assert_array_equal(s[:, POS], p)
    np.testing.assert_array_equal(s[:, IX_PSI], [0.0, 0.5, 1.0, 0.0])
    # velocity at a waypoint is that of the segment starting there, zero at the last
    np.testing.assert_allclose(s[:, VEL], [[0.5, 0, 0], [0, 2, 0.5], [-0.5, -0.5, -0.25],
                                           [0, 0, 0]], atol=1e-15)
    mid = wp.state_at(np.array([1.0, 2.5, 5.0]))
    np.testing.assert_allclose(mid[:, POS], [[0.5, 0, 1], [1, 1, 1.25], [0, 1, 1.0]], atol=1e-15)
    np.testing.assert_allclose(mid[:, IX_PSI], [0.25, 0.75, 0.5], atol=1e-15)
    tt = np.linspace(0.01, 6.99, 500)
    tt = tt[np.min(np.abs(tt[:, None] - np.array(t)), axis=1) > 1e-3]
    np.testing.assert_allclose(wp.state_at(tt)[:, VEL], finite_difference_velocity(wp, tt),
                               atol=1e-6)
    assert wp.duration_s == 7.0


def test_waypoints_hold_before_and_after():
    wp = Waypoints([1.0, 2.0], [[0, 0, 1], [1, 1, 2]], [0.0, 1.0])
    s = wp.state_at(np.array([-5.0, 0.999, 2.0, 2.5, 1e6]))
    np.testing.assert_array_equal(s[:2], np.tile([0, 0, 0, 0, 1, 0, 0], (2, 1)))
    np.testing.assert_array_equal(s[2:], np.tile([1, 0, 1, 0, 2, 0, 1], (3, 1)))


def test_waypoints_psi_takes_the_shortest_way_across_pi():
    wp = Waypoints([0.0, 1.0, 2.0], np.zeros((3, 3)), [3.0, -3.0, 3.0])
    psi = wp.state_at(np.linspace(0.0, 2.0, 201))[:, IX_PSI]
    # 3.0 → −3.0 is 0.283 rad counter-clockwise across π, not 6 rad clockwise
    assert np.all(np.abs(np.diff(psi)) < 0.01)
    assert psi[100] == pytest.approx(2 * math.pi - 3.0)
    assert abs(wrap_angle_rad(psi[50])) == pytest.approx(math.pi, abs=1e-12)
    np.testing.assert_allclose(wrap_angle_rad(psi[[0, 100, 200]]), [3.0, -3.0, 3.0], atol=1e-12)


@pytest.mark.parametrize("args, message", [
    (([0.0], [[0, 0, 1]], [0.0]), "at least 2"),
    (([0.0, 0.0], [[0, 0, 1], [1, 0, 1]], [0.0, 0.0]), "not after"),
    (([0.0, 1.0], [[0, 0, 1]], [0.0, 0.0]), "positions_m"),
    (([0.0, 1.0], [[0, 0, 1], [1, 0, 1]], [0.0]), "psi_rad"),
    (([0.0, 1.0], [[0, 0, 1], [1, math.nan, 1]], [0.0, 0.0]), "finite"),
])
def test_waypoints_constructor_errors(args, message):
    with pytest.raises(ValueError, match=message):
        Waypoints(*args)


# ----------------------------------------------------------------------------- CSV files


def write_csv(tmp_path, text, name="bad.csv"):
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


HEADER = "t_s,x_m,y_m,z_m,psi_rad\n"


@pytest.mark.parametrize("text, line, message", [
    ("", 1, "empty file"),
    ("\n\n", 1, "empty file"),
    ("t_s,x_m,y_m,z_m\n0,0,0,1\n1,1,0,1\n", 1, "missing column 'psi_rad'"),
    ("time,x,y,z,psi\n0,0,0,1,0\n", 1, "missing columns 't_s', 'x_m', 'y_m', 'z_m', 'psi_rad'"),
    ("t_s,x_m,y_m,z_m,psi_rad,x_m\n", 1, "column 'x_m' appears more than once"),
    (HEADER + "0,0,0,1,0\n1,abc,0,1,0\n", 3, "column 'x_m': 'abc' is not a number"),
    (HEADER + "0,0,0,1,0\n1,1,0,,0\n", 3, "column 'z_m': '' is not a number"),
    (HEADER + "0,0,0,1,0\n1,1,0,1,nan\n", 3, "column 'psi_rad': 'nan' is not a finite number"),
    (HEADER + "0,0,0,1,0\n1,1,0,1\n", 3, "expected 5 values, got 4"),
    (HEADER + "0,0,0,1,0\n1,1,0,1,0\n2,1,1,1,0\n4.0,0,1,1,0\n5,0,0,1,0\n6,0,0,1,0\n3.0,0,0,1,0\n",
     8, "time 3.0 is not after the previous 6.0"),
    (HEADER + "0,0,0,1,0\n5,1,0,1,0\n5,1,1,1,0\n", 4, "time 5.0 is not after the previous 5.0"),
    (HEADER, 1, "at least 2 waypoints are needed, got 0"),
    (HEADER + "0,0,0,1,0\n", 2, "at least 2 waypoints are needed, got 1"),
    ("# comment\n\n" + HEADER + "\n0,0,0,1,0\n# x\n1,1,0,1,0\n0.5,0,0,1,0\n", 8,
     "time 0.5 is not after the previous 1.0"),
])
def test_csv_errors_name_file_and_line(tmp_path, text, line, message):
    path = write_csv(tmp_path, text)
    with pytest.raises(ReferenceError, match=re.escape(f"{path}:{line}: {message}")) as info:
        load_waypoints_csv(path)
    assert isinstance(info.value, ValueError) and isinstance(info.value, UserError)
    assert "bad.csv" in str(info.value)


def _far(n_rows: int, step_m: float) -> str:
    return HEADER + "".join(f"{i},{(i % 2) * step_m},0,1,0\n" for i in range(n_rows))


@pytest.mark.parametrize("text, line, message", [
    (HEADER + "0,0,0,1,0\n2,100000000,0,1,0\n", 3, "column 'x_m': 100000000 is outside ±1000 m"),
    (HEADER + "0,0,0,1,0\n2,1e300,0,1,0\n", 3, "column 'x_m': 1e300 is outside ±1000 m"),
    (HEADER + "0,0,0,1,0\n2,0,0,-1000.5,0\n", 3, "column 'z_m': -1000.5 is outside ±1000 m"),
    (HEADER + "0,0,0,1,0\n0.0005,1,0,1,0\n", 3,
     "time 0.0005 is less than 1 ms after the previous 0.0"),
    (_far(MAX_WAYPOINTS + 5, 0.0), MAX_WAYPOINTS + 2, f"more than {MAX_WAYPOINTS} waypoints"),
    (_far(12, 1000.0), 13, "the path is 11000 m long; at most 10000 m"),
])
def test_csv_limits_name_file_and_line(tmp_path, text, line, message):
    path = write_csv(tmp_path, text)
    with pytest.raises(ReferenceError, match=re.escape(f"{path}:{line}: {message}")):
        load_waypoints_csv(path)


def test_csv_at_the_limits_loads(tmp_path):
    # the longest path, the farthest coordinates and the most rows are all still valid
    side = MAX_COORDINATE_M
    n = int(MAX_PATH_LENGTH_M // (2 * side))  # segments of 2 km
    rows = "".join(f"{i},{side if i % 2 else -side},{-side},{side},0\n" for i in range(n + 1))
    wp = load_waypoints_csv(write_csv(tmp_path, HEADER + rows, "far.csv"))
    assert wp.positions_m[:, 0].max() == side and len(wp.t_s) == n + 1
    wp = load_waypoints_csv(write_csv(tmp_path, _far(MAX_WAYPOINTS, 0.0), "many.csv"))
    assert len(wp.t_s) == MAX_WAYPOINTS


def test_csv_larger_than_the_limit_is_refused_before_it_is_read(tmp_path):
    path = tmp_path / "huge.csv"
    with open(path, "wb") as f:
        f.truncate(MAX_PATH_FILE_BYTES + 1)  # sparse: nothing is written or read
    with pytest.raises(ReferenceError, match=r"huge\.csv: \d+ bytes; a waypoint file may hold at "
                                             r"most 16 MiB"):
        load_waypoints_csv(path)


def test_make_trajectory_names_the_field_for_a_bad_path_file(tmp_path):
    cfg = ReferenceConfig(kind="path", path_file=str(tmp_path / "gone.csv"))
    with pytest.raises(ReferenceError, match=r"^reference\.path_file: no such file: .*gone\.csv$"):
        make_trajectory(cfg)


def test_csv_thesis_style_message(tmp_path):
    text = HEADER + "0,0,0,1,0\n1,1,0,1,0\n2,1,1,1,0\n4.0,0,1,1,0\n5,0,0,1,0\n3.0,0,0,1,0\n"
    path = write_csv(tmp_path, text, "square.csv")
    with pytest.raises(ReferenceError, match=r"square\.csv:7: time 3\.0 is not after the "
                                             r"previous 5\.0$"):
        load_waypoints_csv(path)


def test_csv_missing_file(tmp_path):
    with pytest.raises(ReferenceError, match="no such file: .*nope.csv"):
        load_waypoints_csv(tmp_path / "nope.csv")


def test_csv_column_order_comments_extra_columns_and_bom(tmp_path):
    text = ("\ufeff# a hand-written path\npsi_rad, z_m ,y_m,x_m,t_s,note\n"
            "0.5,1.0,0,0,0,start\n\n1.0,1.5,2,1,4,end\n")
    wp = load_waypoints_csv(write_csv(tmp_path, text, "ok.csv"))
    np.testing.assert_allclose(wp.state_at(np.array([0.0, 2.0, 4.0])),
                               [[0, 0.25, 0, 0.5, 1.0, 0.125, 0.5],
                                [0.5, 0.25, 1, 0.5, 1.25, 0.125, 0.75],
                                [1, 0, 2, 0, 1.5, 0, 1.0]], atol=1e-15)


def test_shipped_square_csv_matches_analytic_square():
    wp = load_waypoints_csv(TRAJ_DIR / "square.csv")
    sq = Square((0.0, 0.0, 1.0), 1.0, 5.0, 0.0)
    t = np.concatenate([np.linspace(-2.0, 27.0, 2901), 5.0 * np.arange(5.0)])
    np.testing.assert_allclose(wp.state_at(t), sq.state_at(t), rtol=0, atol=1e-9)
    assert wp.duration_s == sq.duration_s == 20.0


def test_shipped_square_altitudes_csv_matches_analytic():
    wp = load_waypoints_csv(TRAJ_DIR / "square_altitudes.csv")
    sq = SquareAltitudes((0.0, 0.0), 1.0, (0.8, 1.0, 1.2, 1.4), 5.0, 0.0)
    t = np.concatenate([np.linspace(-2.0, 27.0, 2901), 5.0 * np.arange(5.0)])
    np.testing.assert_allclose(wp.state_at(t), sq.state_at(t), rtol=0, atol=1e-9)
    header = (TRAJ_DIR / "square_altitudes.csv").read_text(encoding="utf-8").splitlines()[0]
    assert header == "t_s,x_m,y_m,z_m,psi_rad"


# ----------------------------------------------------------------------------- make_trajectory


KINDS = typing.get_args(ReferenceConfig.model_fields["kind"].annotation)


def config_for(kind, tmp_path):
    if kind == "path":
        path = write_csv(tmp_path, HEADER + "0,0,0,1,0\n2,1,0,1,0.5\n", "path.csv")
        return ReferenceConfig(kind=kind, path_file=str(path))
    return ReferenceConfig(kind=kind)


def test_every_config_kind_is_covered():
    assert set(KINDS) == {"hover", "step", "square", "square_altitudes", "ellipse", "lorenz",
                          "path", "follow", "excitation"}


@pytest.mark.parametrize("kind", KINDS)
def test_make_trajectory_every_kind_from_defaults(kind, tmp_path):
    cfg = config_for(kind, tmp_path)
    traj = make_trajectory(cfg, duration_s=30.0)
    assert isinstance(traj, Trajectory)
    s = traj.state_at(np.linspace(0.0, 30.0, 61))
    assert s.shape == (61, 7) and np.all(np.isfinite(s))
    assert horizon(traj, 1.0, 0.1, 15).shape == (16, 7)
    poly = traj.polyline_m()
    assert poly.ndim == 2 and poly.shape[1] == 3 and len(poly) >= 1
    if len(poly) > 1:
        assert segment_lengths(poly).min() > 0
    # follow: a live point until the object is seen; excitation: set points, as a step's
    if kind not in ("hover", "step", "follow", "excitation"):
        assert segment_lengths(poly).max() <= POLYLINE_SPACING_M + 1e-12


def test_make_trajectory_maps_fields(tmp_path):
    step = make_trajectory(ReferenceConfig(kind="step", start_m=(0, 0, 1), target_m=(-1.5, 0, 1),
                                           target_psi_rad=0.3, step_time_s=2.0))
    np.testing.assert_array_equal(step.state_at(np.array([1.9, 2.0]))[:, [IX_X, IX_PSI]],
                                  [[0, 0], [-1.5, 0.3]])
    sq = make_trajectory(ReferenceConfig(kind="square", start_m=(0.5, 0.5, 1.2), side_m=0.8,
                                         leg_duration_s=4.0, start_psi_rad=0.1))
    np.testing.assert_allclose(sq.state_at(4.0)[0], [1.3, 0, 0.5, 0.2, 1.2, 0, 0.1], atol=1e-12)
    sqa = make_trajectory(ReferenceConfig(kind="square_altitudes", altitudes_m=(1, 2, 1.5, 1.1)))
    np.testing.assert_allclose(sqa.state_at(np.array([0.0, 5.0, 10.0, 15.0]))[:, IX_Z],
                               [1, 2, 1.5, 1.1])
    el = make_trajectory(ReferenceConfig(kind="ellipse", center_m=(0.1, 0.2),
                                         semi_axes_m=(0.9, 0.5), period_s=10.0,
                                         start_m=(0, 0, 1.4)))
    np.testing.assert_allclose(el.state_at(2.5)[0], [0.1, -0.9 * 2 * math.pi / 10, 0.7, 0, 1.4,
                                                     0, 0], atol=1e-12)
    lz = make_trajectory(ReferenceConfig(kind="lorenz", lorenz_time_scale=0.05,
                                         start_m=(0, 0, 1.25)), duration_s=120.0)
    np.testing.assert_allclose(lz.state_at(np.linspace(0, 120, 13)),
                               Lorenz().state_at(np.linspace(0, 120, 13)), atol=1e-12)
    assert lz.duration_s == 120.0


def test_lorenz_polyline_has_at_most_the_point_cap(monkeypatch):
    import ardrone_nmpc.reference.trajectories as trajectories

    fine = Lorenz(duration_s=20.0).polyline_m()
    monkeypatch.setattr(trajectories, "MAX_POLYLINE_POINTS", len(fine) // 4)
    coarse = Lorenz(duration_s=20.0).polyline_m()
    assert len(coarse) <= len(fine) // 4
    np.testing.assert_array_equal(coarse[[0, -1]], fine[[0, -1]])  # the same path, sparser
