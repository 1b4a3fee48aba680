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
