"""``tune``'s objective and sampler against closed forms: a term that is not finite costs the
abort penalty, a path experiment's tracking is its path deviation (a drone on the path but
late is on track), and the sampler draws a ``log: true`` range log-uniformly (scipy's KS test
against the uniform law of log x)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import optuna
import pytest
from scipy import stats

from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.config.schema import ConfigError
from ardrone_nmpc.experiments.tune.objective import Objective, parse_objective, scenario_metrics
from ardrone_nmpc.experiments.tune.space import Param
from ardrone_nmpc.reference.trajectories import make_trajectory
from ardrone_nmpc.runs.memory import MemoryRecorder
from ardrone_nmpc.runs.summary import summarise

CONFIGS = Path(__file__).resolve().parents[2] / "configs"
WEIGHTS = {"tracking": 2.0, "settling": 0.5, "overshoot": 3.0, "effort": 7.0, "solver": 1.5,
           "supervisor": 0.25, "abort": 1000.0, "unclean": 4.0}
FINITE = {"score": math.nan, "tracking_m": 0.1, "rmse_m": 0.1, "path_deviation_m": math.nan,
          "settling_s": 2.0, "overshoot_pct": 4.0, "effort": 0.05, "solver_failures": 2.0,
          "supervisor_ticks": 8.0, "aborted": 0.0, "after_step_s": 9.0, "unclean": 1.0}


def test_the_score_is_the_weighted_sum_of_the_terms():
    expected = 2.0 * 0.1 + 0.5 * 2.0 + 3.0 * 4.0 + 7.0 * 0.05 + 1.5 * 2.0 + 0.25 * 8.0 + 4.0
    assert Objective(WEIGHTS).score(FINITE) == pytest.approx(expected, rel=1e-12)
    # a flight robustness could not judge (unclean NaN) is not penalised as unclean
    assert Objective(WEIGHTS).score(dict(FINITE, unclean=math.nan)) == pytest.approx(
        expected - 4.0, rel=1e-12)


@pytest.mark.parametrize("metric, term", [("tracking_m", "tracking"), ("effort", "effort"),
                                          ("solver_failures", "solver"),
                                          ("supervisor_ticks", "supervisor")])
@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_a_term_that_is_not_finite_costs_the_abort_penalty(metric, term, bad):
    """A NaN or infinite term (a metric the flight could not give) must not score 0 — nor
    ±inf, which would poison the study: it costs its weight × the abort weight."""
    obj = Objective(WEIGHTS)
    m = dict(FINITE, **{metric: bad})
    finite_part = obj.score(dict(FINITE, **{metric: 0.0}))
    assert obj.score(m) == pytest.approx(finite_part + WEIGHTS[term] * WEIGHTS["abort"],
                                         rel=1e-12)
    zero = Objective(dict(WEIGHTS, **{term: 0.0}))  # a term weighted 0 costs nothing
    assert zero.score(m) == pytest.approx(zero.score(dict(FINITE, **{metric: 0.0})), rel=1e-12)


def _square_flown(lag_s: float, dz_m: float):
    """The thesis square flown exactly on its path, ``lag_s`` late and ``dz_m`` high."""
    cfg = load_config(CONFIGS / "square.yaml")
    traj = make_trajectory(cfg.reference, duration_s=cfg.duration_s)
    t = np.arange(0.0, cfg.duration_s + 1e-9, 0.01)
    ref = traj.state_at(t)
    flown = traj.state_at(np.maximum(t - lag_s, 0.0))
    rec = MemoryRecorder()
    for k, tk in enumerate(t):
        x, y, z = flown[k, 0], flown[k, 2], flown[k, 4] + dz_m
        rec.write_row({"t_s": tk, "x_m": x, "y_m": y, "z_m": z, "psi_rad": 0.0,
                       "x_true_m": x, "y_true_m": y, "z_true_m": z, "psi_true_rad": 0.0,
                       "x_ref_m": ref[k, 0], "y_ref_m": ref[k, 2], "z_ref_m": ref[k, 4],
                       "psi_ref_rad": 0.0, "cmd_roll_frac": 0.0, "cmd_pitch_frac": 0.0,
                       "cmd_gaz_frac": 0.0, "cmd_yaw_frac": 0.0, "solve_us": 10.0,
                       "solver_status": "ok", "mode": "track"})
    run = rec.run_data(cfg, seed=0)
    return scenario_metrics(run, summarise(run))


def test_a_path_experiments_tracking_is_its_path_deviation():
    """On the path but 0.5 s late and 3 cm high: every position is 3 cm from the square (the
    offset is vertical, the square horizontal), while the distance to the reference of the
    same instant also holds the lag (0.1 m along a 0.2 m/s leg)."""
    m = _square_flown(0.5, 0.03)
    assert m["path_deviation_m"] == pytest.approx(0.03, abs=1e-9)
    assert m["tracking_m"] == m["path_deviation_m"]
    assert m["rmse_m"] > 0.08
    on_time = _square_flown(0.0, 0.03)
    assert on_time["rmse_m"] == pytest.approx(0.03, abs=1e-9)
    scores = [parse_objective("tracking").score(dict(x, score=math.nan)) for x in (m, on_time)]
    assert scores[0] == pytest.approx(scores[1], rel=1e-9)  # lateness on the path is free


@pytest.mark.parametrize("kind", ["float", "int"])
def test_the_sampler_draws_a_log_range_log_uniformly(kind):
    from ardrone_nmpc.experiments.tune.study import _suggest

    space = {"a": Param("a", 1.0, 1000.0, True, kind), "b": Param("b", 1.0, 1000.0, False, kind)}
    study = optuna.create_study(sampler=optuna.samplers.RandomSampler(seed=3))
    drawn = {"a": [], "b": []}
    for _ in range(600):
        values = _suggest(study.ask(), space)
        for name in drawn:
            drawn[name].append(values[name])
    a, b = np.array(drawn["a"], float), np.array(drawn["b"], float)
    assert a.min() >= 1 and a.max() <= 1000 and b.min() >= 1 and b.max() <= 1000
    if kind == "float":
        log_a = stats.kstest(np.log(a), stats.uniform(0.0, math.log(1000.0)).cdf)
        lin_b = stats.kstest(b, stats.uniform(1.0, 999.0).cdf)
        assert log_a.pvalue > 1e-3 and lin_b.pvalue > 1e-3
    # log-uniform: half the draws below √1000 ≈ 31.6; uniform: 3 %
    assert 0.4 < np.mean(a < math.sqrt(1000.0)) < 0.6
    assert np.mean(b < math.sqrt(1000.0)) < 0.1


# ------------------------------------------------------------------ terms at their edges

AXES = {"x": 0, "y": 1, "z": 2}


def _step_flown(cfg, taus: dict, *, t_end_s=15.0, dt=0.002, mode="track"):
    """A run of the step ``cfg`` (start → target at t = 1 s) whose true position and heading
    follow first-order responses with the time constants ``taus`` (axis → τ; ∞: stalls at
    half way); the others sit on the reference."""
    ref_cfg = cfg.reference
    t = np.arange(0.0, t_end_s + dt / 2, dt)
    start = [*ref_cfg.start_m, ref_cfg.start_psi_rad]
    target = [*ref_cfg.target_m, ref_cfg.target_psi_rad]
    names = ("x", "y", "z", "psi")
    ref = {a: np.where(t >= 1.0, target[i], start[i]) for i, a in enumerate(names)}
    flown = {}
    for i, a in enumerate(names):
        tau = taus.get(a)
        s = np.maximum(t - 1.0, 0.0)
        frac = (0.5 * (t >= 1.0) if tau == math.inf else
                1.0 - np.exp(-s / tau) if tau else (t >= 1.0).astype(float))
        flown[a] = start[i] + (target[i] - start[i]) * frac
    rec = MemoryRecorder()
    for k, tk in enumerate(t):
        rec.write_row({"t_s": tk, "x_m": flown["x"][k], "y_m": flown["y"][k],
                       "z_m": flown["z"][k], "psi_rad": flown["psi"][k],
                       "x_true_m": flown["x"][k], "y_true_m": flown["y"][k],
                       "z_true_m": flown["z"][k], "psi_true_rad": flown["psi"][k],
                       "x_ref_m": ref["x"][k], "y_ref_m": ref["y"][k], "z_ref_m": ref["z"][k],
                       "psi_ref_rad": ref["psi"][k], "cmd_roll_frac": 0.0,
                       "cmd_pitch_frac": 0.0, "cmd_gaz_frac": 0.0, "cmd_yaw_frac": 0.0,
                       "solve_us": 10.0, "solver_status": "ok",
                       "mode": mode if isinstance(mode, str) else mode(tk)})
    run = rec.run_data(cfg, seed=0)
    return run, summarise(run)


STEPS = {"x": ["reference.start_m=[0,0,1]", "reference.target_m=[1,0,1]"],
         "y": ["reference.start_m=[0,0,1]", "reference.target_m=[0,1,1]"],
         "psi": ["reference.start_m=[0,0,1]", "reference.target_m=[0,0,1]",
                 "reference.target_psi_rad=1"]}


@pytest.mark.parametrize("axis", ["x", "y", "psi"])
def test_each_stepped_axis_counts_towards_settling(axis):
    """A first-order response settles into the 2 % band at τ·ln 50 after the step; on a
    step of two axes the worse one counts, and one that never settles makes it NaN."""
    cfg = load_config(CONFIGS / "step_z.yaml", STEPS[axis])
    m = scenario_metrics(*_step_flown(cfg, {axis: 0.5}))
    assert m["settling_s"] == pytest.approx(0.5 * math.log(50.0), abs=0.005)
    assert m["overshoot_pct"] == 0.0
    m = scenario_metrics(*_step_flown(cfg, {axis: math.inf}))
    assert math.isnan(m["settling_s"])


def test_the_worst_of_two_stepped_axes_counts_and_a_stalled_one_is_nan():
    cfg = load_config(CONFIGS / "step_z.yaml", ["reference.target_m=[1,0,1]"])  # x and z
    m = scenario_metrics(*_step_flown(cfg, {"x": 0.2, "z": 0.6}))
    assert m["settling_s"] == pytest.approx(0.6 * math.log(50.0), abs=0.005)
    for taus in ({"x": math.inf, "z": 0.2}, {"x": 0.2, "z": math.inf}):  # either one stalls
        m = scenario_metrics(*_step_flown(cfg, taus))
        assert math.isnan(m["settling_s"]), taus


def test_metrics_are_the_documented_set_and_a_missing_summary_row_is_nan():
    from ardrone_nmpc.experiments.tune.objective import METRICS

    cfg = load_config(CONFIGS / "step_z.yaml")
    run, rows = _step_flown(cfg, {"z": 0.3})
    m = scenario_metrics(run, rows)
    assert list(m) == list(METRICS) and math.isnan(m["score"])
    assert m["solver_failures"] == 0.0 and m["supervisor_ticks"] == 0.0
    m = scenario_metrics(run, [r for r in rows if r.axis != "solver"])
    assert math.isnan(m["solver_failures"])


def test_only_a_step_has_a_time_after_the_step():
    m = _square_flown(0.0, 0.0)
    assert math.isnan(m["after_step_s"])
    assert math.isnan(m["settling_s"]) and math.isnan(m["overshoot_pct"])


def test_an_abort_in_the_window_or_an_early_end_is_an_aborted_unclean_flight():
    cfg = load_config(CONFIGS / "step_z.yaml")
    clean = scenario_metrics(*_step_flown(cfg, {"z": 0.3}))
    assert (clean["aborted"], clean["unclean"]) == (0.0, 0.0)
    ended = scenario_metrics(*_step_flown(cfg, {"z": 0.3}), ending="land-geofence")
    assert (ended["aborted"], ended["unclean"]) == (1.0, 1.0)
    landed = scenario_metrics(*_step_flown(
        cfg, {"z": 0.3}, mode=lambda t: "track" if t < 14.0 else "land-battery"))
    assert landed["aborted"] == 1.0
    stalled = scenario_metrics(*_step_flown(cfg, {"z": math.inf}))  # 35 cm short: not clean
    assert (stalled["aborted"], stalled["unclean"]) == (0.0, 1.0)


def test_terms_of_a_flight_that_is_no_step_and_an_aborted_one():
    obj = Objective(WEIGHTS)
    m = dict(FINITE, settling_s=math.nan, after_step_s=math.nan, overshoot_pct=math.nan)
    terms = obj.terms(m)
    assert list(terms) == list(TERMS_ORDER)
    assert (terms["settling"], terms["overshoot"]) == (0.0, 0.0)
    assert obj.score(dict(m, aborted=1.0)) == pytest.approx(obj.score(m) + 1000.0, rel=1e-12)
    assert obj.terms(dict(FINITE, settling_s=math.nan))["settling"] == 9.0  # never settled


TERMS_ORDER = ("tracking", "settling", "overshoot", "effort", "solver", "supervisor", "abort",
               "unclean")


def test_objective_text_all_mistakes_and_the_worst_edge():
    obj = parse_objective("step, worst=1, effort=0")
    assert obj.worst == 1.0 and obj.weights["effort"] == 0.0
    assert obj.text == "step, worst=1, effort=0"
    with pytest.raises(ConfigError) as err:
        parse_objective("fast,tracking=1=2,colour=3,effort=-1,settling=x,worst=2")
    assert err.value.messages == [
        "--objective: unknown preset 'fast'; choose default, step, tracking, robust "
        "(or term=weight items)",
        "--objective: tracking: '1=2' is not a number",
        "--objective: 'colour=3': expected term=weight with term one of tracking, settling, "
        "overshoot, effort, solver, supervisor, abort, unclean, worst",
        "--objective: effort: must be a finite weight ≥ 0",
        "--objective: settling: 'x' is not a number",
        "--objective: worst: must be in [0, 1]"]
