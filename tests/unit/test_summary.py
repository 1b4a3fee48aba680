"""Tests of the run metrics (runs.metrics), the summary (runs.summary) and its tables (cli.tables)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from rich.console import Console

from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.runs.rundir import RunRecorder, read_run
from ardrone_nmpc.reference.trajectories import make_trajectory
from ardrone_nmpc.runs.rundir import SummaryRow, read_summary
from ardrone_nmpc.cli.tables import render_side_by_side, render_summary
from ardrone_nmpc.runs.metrics import (input_stats, path_deviation, skipped_deadlines,
                                       solver_stats, step_metrics)
from ardrone_nmpc.runs.summary import summarise

TAU = 0.7
T_STEP = 1.0


def first_order(t, tau=TAU, t_step=T_STEP, y0=0.0, y_final=1.0):
    s = np.where(t >= t_step, 1.0 - np.exp(-(t - t_step) / tau), 0.0)
    return y0 + (y_final - y0) * s


def second_order(t, zeta, wn=2.0, t_step=T_STEP):
    tt = np.maximum(t - t_step, 0.0)
    wd = wn * math.sqrt(1 - zeta**2)
    s = 1 - np.exp(-zeta * wn * tt) / math.sqrt(1 - zeta**2) * np.sin(wd * tt + math.acos(zeta))
    return np.where(t >= t_step, s, 0.0)


def brute_settling(t, y, y0, y_final, t_step, band=0.02):
    """Independent: the time of the last sample outside the band, on a very dense grid."""
    out = np.abs(y - y_final) > band * abs(y_final - y0)
    out &= t >= t_step
    return t[np.flatnonzero(out)[-1]] - t_step


# ----------------------------------------------------------------------------- step metrics


def test_first_order_step():
    t = np.arange(0.0, 12.0, 1e-4)
    m = step_metrics(t, first_order(t), y0=0.0, y_final=1.0, t_step_s=T_STEP)
    assert m["rise_time_s"] == pytest.approx(TAU * math.log(9), abs=1e-3)
    assert m["settling_time_s"] == pytest.approx(TAU * math.log(50), abs=1e-3)
    assert m["overshoot_pct"] == 0.0
    # error over the last 10 % of the record, [10.8, 12): −e^{−(t−1)/τ} ≈ −1.5e-6
    assert -1e-5 < m["steady_state_error"] < 0
    span = t[-1] - T_STEP  # RMS of e^{−s/τ} over [0, span]
    rms = math.sqrt(TAU / (2 * span) * (1 - math.exp(-2 * span / TAU)))
    assert m["rmse"] == pytest.approx(rms, rel=1e-3)


def test_first_order_step_coarse_sampling_is_interpolated():
    t = np.arange(0.0, 12.0, 0.065)
    m = step_metrics(t, first_order(t), y0=0.0, y_final=1.0, t_step_s=T_STEP)
    assert m["rise_time_s"] == pytest.approx(TAU * math.log(9), abs=0.01)
    assert m["settling_time_s"] == pytest.approx(TAU * math.log(50), abs=0.01)


@pytest.mark.parametrize("zeta", [0.2, 0.45, 0.7])
def test_second_order_overshoot(zeta):
    t = np.arange(0.0, 25.0, 1e-3)
    y = second_order(t, zeta)
    m = step_metrics(t, y, y0=0.0, y_final=1.0, t_step_s=T_STEP)
    expected = 100 * math.exp(-zeta * math.pi / math.sqrt(1 - zeta**2))
    assert m["overshoot_pct"] == pytest.approx(expected, abs=0.5)
    assert m["settling_time_s"] == pytest.approx(brute_settling(t, y, 0, 1, T_STEP), abs=2e-3)


def test_negative_step_measures_in_the_step_direction():
    t = np.arange(0.0, 12.0, 1e-4)
    m = step_metrics(t, first_order(t, y_final=-1.5), y0=0.0, y_final=-1.5, t_step_s=T_STEP)
    assert m["rise_time_s"] == pytest.approx(TAU * math.log(9), abs=1e-3)
    assert m["settling_time_s"] == pytest.approx(TAU * math.log(50), abs=1e-3)
    assert m["overshoot_pct"] == 0.0
    assert 0 < m["steady_state_error"] < 1e-5  # approaching −1.5 from above
    # underdamped: y goes below −1.5 — that is the overshoot
    t = np.arange(0.0, 25.0, 1e-3)
    m = step_metrics(t, -1.5 * second_order(t, 0.3), y0=0.0, y_final=-1.5, t_step_s=T_STEP)
    assert m["overshoot_pct"] == pytest.approx(100 * math.exp(-0.3 * math.pi
                                                              / math.sqrt(1 - 0.09)), abs=0.5)


def test_excursion_against_the_step_is_not_overshoot():
    """A response that first moves the wrong way (non-minimum phase) has no overshoot."""
    t = np.arange(0.0, 12.0, 1e-3)
    tt = np.maximum(t - T_STEP, 0.0)
    s = 1 - np.exp(-tt / TAU) - 3 * tt * np.exp(-tt / 0.15)  # < 0 early on, never above 1
    y = 2.0 - 1.0 * s  # a step 2 → 1 that first rises above 2
    assert y.max() > 2.01
    m = step_metrics(t, y, y0=2.0, y_final=1.0, t_step_s=T_STEP)
    assert m["overshoot_pct"] == 0.0
    assert 0 < m["rise_time_s"] < 3


def test_offset_start_and_step_time():
    t = np.arange(0.0, 15.0, 1e-4)
    y = first_order(t, t_step=3.0, y0=1.0, y_final=1.8)
    m = step_metrics(t, y, y0=1.0, y_final=1.8, t_step_s=3.0)
    assert m["rise_time_s"] == pytest.approx(TAU * math.log(9), abs=1e-3)
    assert m["settling_time_s"] == pytest.approx(TAU * math.log(50), abs=1e-3)


def test_never_settling_and_never_rising():
    t = np.arange(0.0, 10.0, 1e-3)
    y = np.where(t >= T_STEP, 1.0 + 0.5 * np.sin(2 * np.pi * (t - T_STEP) + 0.5), 0.0)
    m = step_metrics(t, y, y0=0.0, y_final=1.0, t_step_s=T_STEP)
    assert math.isnan(m["settling_time_s"])
    assert m["overshoot_pct"] == pytest.approx(50.0, abs=0.01)
    stuck = np.where(t >= T_STEP, 0.5, 0.0)
    m = step_metrics(t, stuck, y0=0.0, y_final=1.0, t_step_s=T_STEP)
    assert math.isnan(m["rise_time_s"]) and math.isnan(m["settling_time_s"])
    assert m["steady_state_error"] == pytest.approx(-0.5)
    assert m["rmse"] == pytest.approx(0.5)


def test_ideal_step_settles_at_once():
    t = np.arange(0.0, 5.0, 0.01)
    y = np.where(t >= T_STEP, 1.0, 0.0)
    m = step_metrics(t, y, y0=0.0, y_final=1.0, t_step_s=T_STEP)
    assert m == {"rise_time_s": 0.0, "settling_time_s": 0.0, "overshoot_pct": 0.0,
                 "steady_state_error": 0.0, "rmse": 0.0}


def test_nan_samples_are_ignored_and_bad_arguments_rejected():
    t = np.arange(0.0, 12.0, 1e-3)
    y = first_order(t)
    y[::7] = np.nan
    m = step_metrics(t, y, y0=0.0, y_final=1.0, t_step_s=T_STEP)
    assert m["rise_time_s"] == pytest.approx(TAU * math.log(9), abs=1e-3)
    with pytest.raises(ValueError, match="must differ"):
        step_metrics(t, y, y0=1.0, y_final=1.0, t_step_s=T_STEP)
    with pytest.raises(ValueError, match="band"):
        step_metrics(t, y, y0=0.0, y_final=1.0, t_step_s=T_STEP, band=0.0)
    assert all(math.isnan(v) for v in
               step_metrics(t, y, y0=0.0, y_final=1.0, t_step_s=100.0).values())


# ----------------------------------------------------------------------------- path deviation

SQUARE = np.array([[0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1], [0, 0, 1]], dtype=float)


def test_points_offset_from_a_square():
    s = np.linspace(0.2, 0.8, 13)
    pts = np.vstack([
        np.column_stack([s, np.full_like(s, -0.1), np.ones_like(s)]),   # outside, side 1
        np.column_stack([np.full_like(s, 0.9), s, np.ones_like(s)]),    # inside, side 2
        np.column_stack([s, np.ones_like(s), np.full_like(s, 1.1)]),    # above, side 3
        np.column_stack([np.full_like(s, -0.1), s, np.ones_like(s)]),   # outside, side 4
    ])
    mean, mx = path_deviation(pts, SQUARE)
    assert mean == pytest.approx(0.1, abs=1e-12)
    assert mx == pytest.approx(0.1, abs=1e-12)
    # the same against the densified square of the reference module
    poly = make_trajectory(load_config(overrides=["reference.kind=square"]).reference).polyline_m()
    assert path_deviation(pts, poly) == pytest.approx((0.1, 0.1), abs=1e-9)


def test_point_beyond_a_segment_end_measures_to_the_endpoint():
    line = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    pts = np.array([[2.0, 0.0, 0.0], [1.3, 0.4, 0.0], [-0.3, 0.0, -0.4], [0.5, 0.2, 0.0]])
    mean, mx = path_deviation(pts, line)
    assert mx == pytest.approx(1.0)
    assert mean == pytest.approx((1.0 + 0.5 + 0.5 + 0.2) / 4)
    # per point, via one-point arrays
    assert path_deviation(pts[:1], line) == pytest.approx((1.0, 1.0))


def test_single_point_polyline_and_corner_cases():
    p = np.array([[1.0, 2.0, 3.0]])
    pts = np.array([[1.0, 2.0, 3.5], [4.0, 6.0, 3.0], [np.nan, 0, 0]])
    assert path_deviation(pts, p) == pytest.approx((2.75, 5.0))
    assert all(math.isnan(v) for v in path_deviation(np.full((2, 3), np.nan), SQUARE))
    # repeated vertices (zero-length segments) are harmless
    dup = np.vstack([SQUARE[:2], SQUARE[1:]])
    assert path_deviation([[0.5, -0.2, 1.0]], dup) == pytest.approx((0.2, 0.2))
    with pytest.raises(ValueError):
        path_deviation(pts, np.empty((0, 3)))


def test_path_deviation_against_brute_force(rng):
    pts = rng.normal(size=(500, 3))
    poly = np.cumsum(rng.normal(size=(300, 3)) * 0.1, axis=0)
    whole = path_deviation(pts, poly)
    mean = np.mean([path_deviation(q[None], poly)[0] for q in pts])
    assert whole[0] == pytest.approx(mean)
    # brute force for a few points
    a, b = poly[:-1], poly[1:]
    for q in pts[:5]:
        u = np.clip(np.einsum("ij,ij->i", q - a, b - a) / np.einsum("ij,ij->i", b - a, b - a),
                    0, 1)
        d = np.min(np.linalg.norm(q - (a + u[:, None] * (b - a)), axis=1))
        assert path_deviation(q[None], poly)[0] == pytest.approx(d)


# ----------------------------------------------------------------------------- inputs, solver


def test_input_stats():
    u = np.array([[0.5, -1.0, 0.0, 0.1],
                  [-1.0, 0.2, 0.0, np.nan],
                  [1.0, -0.3, 0.0, np.nan],
                  [0.2, 1.5, 0.0, -2.0]])
    st = input_stats(u, [-1, -1, -1, -2], [1, 1, 1, 2])
    assert st["peak_abs"].tolist() == [1.0, 1.5, 0.0, 2.0]
    assert st["saturated_fraction"].tolist() == [0.5, 0.5, 0.0, 0.5]
    empty = input_stats(np.full((3, 4), np.nan), [-1] * 4, [1] * 4)
    assert np.isnan(empty["peak_abs"]).all() and np.isnan(empty["saturated_fraction"]).all()
    with pytest.raises(ValueError, match="bounds"):
        input_stats(u, [-1, -1], [1, 1])


def test_solver_stats():
    times = np.array([100.0, 200.0, 300.0, np.nan, 400.0])
    status = ["ok", "ok", "diverged", "", "max-iterations"]
    st = solver_stats(times, status)
    assert st["mean_us"] == 250.0 and st["max_us"] == 400.0
    assert st["p99_us"] == pytest.approx(np.percentile([100, 200, 300, 400], 99))
    assert st["solves"] == 4 and st["non_ok"] == 2
    assert st["by_status"] == {"diverged": 1, "max-iterations": 1}
    none = solver_stats(np.full(3, np.nan), ["", "", ""])
    assert math.isnan(none["mean_us"]) and none["non_ok"] == 0


@pytest.mark.parametrize("seed", range(8))
def test_the_percentiles_and_statuses_are_each_computed_as_alone(seed):
    """p50 and p99 from one np.percentile call are the bits of one call each; statuses
    counted once per distinct value are counted as one by one."""
    from ardrone_nmpc.runs.metrics import percentiles

    rng = np.random.default_rng(seed)
    x = rng.normal(0.0, 10.0, int(rng.integers(1, 2000)))
    x[rng.integers(0, x.size, 2)] = np.nan
    finite = x[np.isfinite(x)]
    want = (float(np.percentile(finite, 50)), float(np.percentile(finite, 99)),
            float(finite.max()))
    assert np.array(percentiles(x)).tobytes() == np.array(want).tobytes()
    status = rng.choice(np.array(["ok", "", "diverged", None, math.nan, "nan-input"],
                                 dtype=object), x.size)
    by_status: dict = {}
    for v in status:
        v = "" if v is None or (isinstance(v, float) and math.isnan(v)) else str(v)
        if v and v != "ok":
            by_status[v] = by_status.get(v, 0) + 1
    st = solver_stats(x, status)
    assert st["by_status"] == dict(sorted(by_status.items()))
    assert st["non_ok"] == sum(by_status.values())


# ----------------------------------------------------------------------------- summarise


def by_key(rows):
    return {(r.axis, r.metric): r for r in rows}


def test_summarise_step_run(tmp_path):
    cfg = load_config(overrides=["name=step_x", "duration_s=12", "reference.kind=step",
                                 "reference.start_m=[0, 0, 1]", "reference.target_m=[-1.5, 0, 1]",
                                 "reference.step_time_s=1.0"])
    period = cfg.loop.period_s
    t = np.arange(-10, round(12 / period) + 1) * period
    t = np.delete(t, [101, 102])  # tick 100 overran two deadlines: they were skipped
    x_true = first_order(t, y_final=-1.5)
    with RunRecorder.create(tmp_path, cfg, seed=5) as rec:
        for k, tk in enumerate(t):
            row = dict(t_s=tk, x_m=x_true[k] + 0.3, y_m=0.0, z_m=1.0, psi_rad=0.0,
                       x_true_m=x_true[k], y_true_m=0.0, z_true_m=1.0, psi_true_rad=0.0,
                       x_ref_m=-1.5 if tk >= 1.0 else 0.0, y_ref_m=0.0, z_ref_m=1.0,
                       psi_ref_rad=0.0, u_zacc_mps2=0.0, u_phi_rad=0.0,
                       u_theta_rad=1.0 if 1.0 <= tk < 1.2 else 0.1, u_psirate_radps=0.0,
                       solve_us=100.0 + k, solver_status="ok", cmd_saturated="0000",
                       mode="settle" if tk < 0 else "track", tick_late_ms=0.5,
                       mocap_age_ms=2.0, navdata_age_ms=30.0, compute_us=150.0)
            if k == 100:
                row.update(mode="p", solver_status="diverged", tick_late_ms=70.0,
                           cmd_saturated="0100")
            rec.write_row(row)
        run = read_run(rec.path)
        rows = summarise(run)
        rec.write_summary(rows)
    got = by_key(rows)
    # truth columns preferred (the measured x is 0.3 m off)
    assert got[("run", "truth_source")].value == 1.0
    sel = t >= 0
    direct = step_metrics(t[sel], x_true[sel], y0=0.0, y_final=-1.5, t_step_s=1.0)
    assert got[("x", "rise_time")] == SummaryRow("x", "rise_time", direct["rise_time_s"], "s")
    assert got[("x", "rise_time")].value == pytest.approx(TAU * math.log(9), abs=0.01)
    assert got[("x", "settling_time")].value == pytest.approx(TAU * math.log(50), abs=0.01)
    assert got[("x", "overshoot")].value == 0.0
    assert abs(got[("x", "steady_state_error")].value) < 1e-4
    assert got[("x", "steady_state_error")].unit == "m"
    assert not any(r.axis in ("y", "z", "psi") for r in rows)  # only x steps
    assert got[("u_theta", "saturated_fraction")].value == pytest.approx(3 / sel.sum())
    assert got[("u_theta", "peak_abs")].value == 1.0
    assert got[("cmd_pitch", "saturated_fraction")].value == pytest.approx(1 / sel.sum())
    assert got[("solver", "non_ok")].value == 1.0
    assert got[("solver", "status_diverged")].value == 1.0
    assert got[("solver", "solve_time_max")].value == 100.0 + len(t) - 1
    assert got[("loop", "fallbacks")].value == 1.0     # the "p" row; "settle" rows are t < 0
    assert got[("loop", "overruns")].value == 2.0  # the skipped deadlines, not late wake-ups
    assert got[("loop", "tick_late_max")].value == 70.0
    assert got[("run", "ticks")].value == len(t)
    assert got[("mocap", "no_data_ticks")].value == 0.0
    back = read_summary(run.path)
    assert [(r.axis, r.metric, r.unit) for r in back] == [(r.axis, r.metric, r.unit)
                                                          for r in rows]
    np.testing.assert_array_equal([r.value for r in back], [r.value for r in rows])


@pytest.mark.parametrize("ticks, expected", [
    ([0, 1, 2, 3], 0), ([0, 1, 4, 5], 2), ([0, 2, 4], 2), ([0, 1, 2, 10], 7), ([5], 0), ([], 0),
])
def test_skipped_deadlines_are_the_gaps_in_the_tick_times(ticks, expected):
    period = 0.001  # rounding of k·period must not add or lose a deadline
    t = np.asarray(ticks, dtype=float) * period - 0.25
    assert skipped_deadlines(np.append(t, np.nan), period) == expected


def test_summarise_uses_measured_columns_without_truth(tmp_path):
    cfg = load_config(overrides=["name=psi", "reference.kind=step",
                                 "reference.target_psi_rad=1.0"])
    t = np.arange(0, 200) * 0.065
    psi = first_order(t, y_final=1.0)
    with RunRecorder.create(tmp_path, cfg, seed=0) as rec:
        for k, tk in enumerate(t):
            rec.write_row(dict(t_s=tk, psi_rad=psi[k], x_m=0.0, y_m=0.0, z_m=1.0, mode="track"))
        rows = by_key(summarise(read_run(rec.path)))
    assert rows[("run", "truth_source")].value == 0.0
    assert rows[("psi", "settling_time")].value == pytest.approx(TAU * math.log(50), abs=0.01)
    assert rows[("psi", "rmse")].unit == "rad"
    assert ("x", "rise_time") not in rows


def test_summarise_square_path(tmp_path):
    cfg = load_config(overrides=["name=square", "duration_s=20", "reference.kind=square"])
    traj = make_trajectory(cfg.reference)
    t = np.arange(-20, 300) * 0.065
    ref = traj.state_at(np.maximum(t, 0.0))
    with RunRecorder.create(tmp_path, cfg, seed=0) as rec:
        for k, tk in enumerate(t):
            taking_off = k < 30
            rec.write_row(dict(
                t_s=tk, x_m=ref[k, 0], y_m=ref[k, 2], z_m=0.0 if taking_off else ref[k, 4] + 0.1,
                psi_rad=ref[k, 6], x_ref_m=ref[k, 0], y_ref_m=ref[k, 2], z_ref_m=ref[k, 4],
                psi_ref_rad=ref[k, 6], mode="taking_off" if taking_off else "track"))
        rows = by_key(summarise(read_run(rec.path)))
    assert rows[("path", "mean_deviation")].value == pytest.approx(0.1, abs=1e-9)
    assert rows[("path", "max_deviation")].value == pytest.approx(0.1, abs=1e-9)
    assert rows[("z", "rmse")].value == pytest.approx(0.1, abs=1e-12)
    assert rows[("x", "rmse")].value == 0.0
    assert rows[("xyz", "rmse")].value == pytest.approx(0.1, abs=1e-12)
    assert math.isnan(rows[("solver", "solve_time_mean")].value)
    assert ("loop", "overruns") not in rows  # no tick_late_ms logged


def test_summarise_single_mode_uses_all_ticks(tmp_path):
    """With one mode value throughout (even a ground one), every tick counts."""
    cfg = load_config(overrides=["name=ell", "reference.kind=ellipse"])
    traj = make_trajectory(cfg.reference)
    t = np.arange(0, 100) * 0.065
    ref = traj.state_at(t)
    with RunRecorder.create(tmp_path, cfg, seed=0) as rec:
        for k, tk in enumerate(t):
            rec.write_row(dict(t_s=tk, x_m=ref[k, 0], y_m=ref[k, 2], z_m=ref[k, 4] - 0.05,
                               mode="landing"))
        rows = by_key(summarise(read_run(rec.path)))
    assert rows[("path", "mean_deviation")].value == pytest.approx(0.05, abs=1e-6)
    assert rows[("loop", "fallbacks")].value == len(t)  # not "track"


# ----------------------------------------------------------------------------- tables


def render(table) -> str:
    console = Console(record=True, width=200)
    console.print(table)
    return console.export_text()


def test_render_summary_and_side_by_side():
    a = [SummaryRow("x", "rise_time", 1.23456, "s"), SummaryRow("solver", "non_ok", 2.0, "count"),
         SummaryRow("x", "settling_time", math.nan, "s")]
    b = [SummaryRow("x", "rise_time", 2.5, "s"), SummaryRow("path", "mean_deviation", 0.1045, "m")]
    text = render(render_summary(a, "run A"))
    assert "run A" in text and "rise_time" in text and "1.235" in text
    assert "non_ok" in text and " 2 " in text and "—" in text
    table = render_side_by_side([("A", a), ("B", b)])
    assert [c.header for c in table.columns] == ["axis", "metric", "unit", "A", "B"]
    assert table.row_count == 4
    text = render(table)
    line = next(x for x in text.splitlines() if "rise_time" in x)
    assert "1.235" in line and "2.5" in line
    line = next(x for x in text.splitlines() if "mean_deviation" in x)
    assert "0.1045" in line and "1.235" not in line


def test_an_oscillation_ending_in_the_band_has_not_settled():
    """A sustained ±20 % oscillation sampled so that its last sample is inside the 2 % band:
    the final stay inside is one sample long, shorter than min_dwell_s → NaN, not 'settled
    at the end of the run'."""
    t = np.arange(0.0, 30.0, 0.065)
    y = 1.0 + 0.2 * np.sin(2 * np.pi * t / 2.25)
    y[-1] = 1.0  # the record happens to end on the target
    m = step_metrics(t, y, y0=0.0, y_final=1.0, t_step_s=0.0)
    assert math.isnan(m["settling_time_s"])
    # a response that really settles keeps its settling time
    y_ok = 1.0 - np.exp(-t)
    m_ok = step_metrics(t, y_ok, y0=0.0, y_final=1.0, t_step_s=0.0)
    assert m_ok["settling_time_s"] == pytest.approx(-math.log(0.02), abs=0.07)
    assert step_metrics(t, y, y0=0.0, y_final=1.0, t_step_s=0.0, min_dwell_s=0.0)[
        "settling_time_s"] > 29.0


def test_the_percentiles_of_signed_zeros_are_each_computed_as_alone():
    """+0 and −0 compare equal, so which one a partition leaves at a percentile's index
    depends on the partition: one call for p50 and p99 could answer the other zero than
    each call alone ("-0" for "0" in summary.csv)."""
    from ardrone_nmpc.runs.metrics import percentiles

    rng = np.random.default_rng(9)
    cases = [np.array([0.0, -0.0, 0.0, 0.0, 0.0, -0.0, -0.0]),
             np.array([-0.0, -0.0, -0.0, -0.0, 0.0, 0.0, 0.0, -0.0])]
    cases += [np.where(rng.random(int(rng.integers(1, 300))) < 0.5, 0.0, -0.0)
              for _ in range(300)]
    cases += [rng.choice([0.0, -0.0, 1.0, -1.0, 2.0], int(rng.integers(1, 300)))
              for _ in range(300)]
    for x in cases:
        want = (float(np.percentile(x, 50)), float(np.percentile(x, 99)), float(x.max()))
        assert np.array(percentiles(x)).tobytes() == np.array(want).tobytes(), x.tolist()
