"""``tune``'s parts: the search space, the objective on synthetic runs (closed forms), the
in-memory recorder against a run directory, and a trial."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from ardrone_nmpc.config.io import config_to_dict, load_config
from ardrone_nmpc.config.schema import ConfigError
from ardrone_nmpc.experiments.tune.engine import Scenario, TrialSpec, run_trial, scenarios
from ardrone_nmpc.experiments.tune.objective import (PRESETS, TERMS, Objective,
                                                     parse_objective, scenario_metrics)
from ardrone_nmpc.experiments.tune.space import (apply_params, config_with, default_space,
                                                 load_space, parse_space)
from ardrone_nmpc.runs.memory import MemoryRecorder
from ardrone_nmpc.runs.summary import summarise

CONFIGS = Path(__file__).resolve().parents[2] / "configs"


@pytest.fixture(scope="module")
def step_z():
    return load_config(CONFIGS / "step_z.yaml")


# ----------------------------------------------------------------------------- space


def test_default_space_is_q_and_r_log_uniform_a_decade_each_way():
    square = load_config(CONFIGS / "square.yaml")
    space = default_space(square)
    assert list(space) == [f"controller.q[{i}]" for i in range(7)] + \
        [f"controller.r[{i}]" for i in range(4)]
    for name, p in space.items():
        vec, i = name[len("controller."):-3], int(name[-2])
        base = getattr(square.controller, vec)[i]
        assert (p.low, p.high, p.log, p.kind, p.base) == pytest.approx(
            (base / 10, base * 10, True, "float", base))


@pytest.mark.parametrize("sets, expected", [
    ([], ["q[4]", "q[5]", "r[0]"]),                                  # z: ż weight and z̈ input
    (["reference.start_m=[0,0,1]", "reference.target_m=[1,0,1]"], ["q[0]", "q[1]", "r[2]"]),
    (["reference.start_m=[0,0,1]", "reference.target_m=[0,1,1]"], ["q[2]", "q[3]", "r[1]"]),
    (["reference.start_m=[0,0,1]", "reference.target_m=[0,0,1]",
      "reference.target_psi_rad=1"], ["q[6]", "r[3]"]),
    (["reference.target_m=[1,0,1]"], ["q[0]", "q[1]", "q[4]", "q[5]", "r[0]", "r[2]"]),
])
def test_a_steps_default_space_is_its_stepped_axes_weights(sets, expected):
    cfg = load_config(CONFIGS / "step_z.yaml", sets)
    space = default_space(cfg)
    assert list(space) == [f"controller.{w}" for w in expected]
    for name, p in space.items():  # the same decade each way as the full space
        vec, i = name[len("controller."):-3], int(name[-2])
        assert (p.low, p.high) == pytest.approx((getattr(cfg.controller, vec)[i] / 10,
                                                 getattr(cfg.controller, vec)[i] * 10))


def test_the_full_space_of_a_step_is_one_space_file_away(step_z):
    space = parse_space({"params": {"controller.q": {"factor": 10},
                                    "controller.r": {"factor": 10}}}, step_z)
    assert sorted(space) == sorted([f"controller.q[{i}]" for i in range(7)]
                                   + [f"controller.r[{i}]" for i in range(4)])


def test_a_zero_state_weight_is_not_searched():
    cfg = load_config(None, ["controller.q=[0, 2, 7, 2, 5, 10, 13]"])
    assert "controller.q[0]" not in default_space(cfg)
    assert len(default_space(cfg)) == 10


def test_a_space_file_adds_ranges_factors_vectors_and_overrides_elements(step_z):
    # a tuned delay compensation is a number (its default, 'auto', is the flight's estimate)
    step_z = load_config(CONFIGS / "step_z.yaml", ["controller.delay_compensation_s=0.26"])
    space = parse_space({
        "factor": 4,
        "params": {
            "controller.horizon_steps": {"low": 8, "high": 30, "type": "int"},
            "controller.dtau_s": {"low": 0.05, "high": 0.2, "log": True},
            "estimator.kalman_q": {"factor": 10},
            "controller.delay_compensation_s": {"low": 0.1, "high": 0.35},
            "controller.q[4]": {"low": 10, "high": 500, "log": True},
        }}, step_z)
    assert space["controller.q[5]"].low == pytest.approx(step_z.controller.q[5] / 4)  # ×1/4…×4
    assert "controller.q[0]" not in space  # a z step: x's weight keeps the config's value
    assert space["controller.q[4]"].low == 10 and space["controller.q[4]"].high == 500
    hs = space["controller.horizon_steps"]
    assert (hs.kind, hs.log, hs.low, hs.high, hs.base) == ("int", False, 8, 30, 15)
    kq = space["estimator.kalman_q"]
    assert (kq.low, kq.high) == pytest.approx((2.8559e-5, 2.8559e-3))
    assert space["controller.delay_compensation_s"].log is False


def test_a_vector_with_a_factor_searches_its_nonzero_elements(step_z):
    cfg = load_config(None, ["controller.q_terminal=[1, 0, 1, 0, 2, 0, 0]"])
    space = parse_space({"default": False, "params": {"controller.q_terminal": {"factor": 3}}},
                        cfg)
    assert list(space) == ["controller.q_terminal[0]", "controller.q_terminal[2]",
                           "controller.q_terminal[4]"]
    assert space["controller.q_terminal[4]"].high == pytest.approx(6.0)


def test_space_mistakes_fail_one_line_each_before_anything_flies(step_z):
    with pytest.raises(ConfigError) as err:
        parse_space({"colour": 1, "params": {
            "controller.nope": {"low": 1, "high": 2},
            "controller.dtau_s": {"low": 0.2, "high": 0.1},
            "controller.horizon_steps": {"low": 0, "high": 9, "log": True},
            "controller.kind": {"low": 0, "high": 1},
            "controller.q": {"low": 1, "high": 2},
            "controller.obstacle_weight": {"factor": 10, "low": 1},
            "controller.vz_lead_s": {"factor": 0.5},
            "estimator.kalman_r": {"lo": 1},
        }}, step_z, where="--space s.yaml")
    messages = err.value.messages
    assert len(messages) == 9
    assert "--space s.yaml: colour: unknown key" in messages[0]
    expected = ["params.controller.nope: no such config value",
                "params.controller.dtau_s: needs finite numbers low < high",
                "params.controller.horizon_steps: log: true needs low > 0",
                "params.controller.kind: not a number",
                "params.controller.q: a vector takes {factor: F}",
                "params.controller.obstacle_weight: give factor or low/high, not both",
                "params.controller.vz_lead_s: factor 0.5: must be a finite number > 1",
                "params.estimator.kalman_r: unknown key(s) lo"]
    for text in expected:
        assert any(text in m for m in messages), text


@pytest.mark.parametrize("spec, message", [
    ({"params": {"controller.dtau_s": {"low": -math.inf, "high": 0.2}}},
     "params.controller.dtau_s: needs finite numbers low < high"),
    ({"params": {"controller.dtau_s": {"low": 0.05, "high": math.inf}}},
     "params.controller.dtau_s: needs finite numbers low < high"),
    ({"params": {"estimator.kalman_q": {"factor": math.inf}}},
     "params.estimator.kalman_q: factor inf: must be a finite number > 1"),
    ({"factor": math.inf}, "factor: inf must be a finite number > 1"),
    ({"factor": 1e308}, "factor: 1e+308: the range"),
    ({"default": False, "params": {"controller.horizon_steps":
                                   {"low": 10.2, "high": 10.8, "type": "int"}}},
     "params.controller.horizon_steps: type int: no integer lies in 10.2 … 10.8"),
])
def test_a_space_the_sampler_cannot_draw_from_is_refused(step_z, spec, message):
    with pytest.raises(ConfigError) as err:
        parse_space(spec, step_z, where="--space s.yaml")
    assert any(message in m for m in err.value.messages), err.value.messages


def test_a_space_file_that_is_not_text_is_one_line(step_z, tmp_path):
    bad = tmp_path / "s.yaml"
    bad.write_bytes(b"params:\n  \xff\xfe: {}\n")
    with pytest.raises(ConfigError, match=r"s\.yaml: not UTF-8 text"):
        load_space(bad, step_z)


def test_an_empty_space_is_refused(step_z):
    with pytest.raises(ConfigError, match="the space is empty"):
        parse_space({"default": False}, step_z)


def test_params_apply_to_vector_elements_and_round_ints(step_z):
    space = parse_space({"params": {"controller.horizon_steps": {"low": 5, "high": 30,
                                                                  "type": "int"}}}, step_z)
    data = config_to_dict(step_z)
    out = apply_params(data, {"controller.q[4]": 80.0, "controller.r[0]": 2.0,
                              "controller.horizon_steps": 11.6}, space)
    q = list(step_z.controller.q)
    q[4] = 80.0
    assert out["controller"]["q"] == q
    assert out["controller"]["r"][0] == 2.0 and out["controller"]["horizon_steps"] == 12
    assert data["controller"]["q"][4] == 5.0  # the original is untouched
    cfg = config_with(step_z, {"controller.q[4]": 80.0}, space, ["sim.seed=7"])
    assert cfg.controller.q[4] == 80.0 and cfg.sim.seed == 7


# ----------------------------------------------------------------------------- objective


def test_objective_presets_and_weights_parse():
    obj = parse_objective(None)
    assert dict(obj.weights) == {k: v for k, v in PRESETS["default"].items() if k != "worst"}
    assert obj.worst == PRESETS["default"]["worst"]
    obj = parse_objective("step,overshoot=2,worst=0")
    assert obj.weights["overshoot"] == 2.0 and obj.weights["settling"] == 1.0
    assert obj.worst == 0.0 and set(obj.weights) == set(TERMS)
    assert parse_objective("tracking=3").weights["settling"] == PRESETS["default"]["settling"]


@pytest.mark.parametrize("text, message", [
    ("fastest", "unknown preset 'fastest'"),
    ("speed=1", "'speed=1': expected term=weight"),
    ("tracking=abc", "tracking: 'abc' is not a number"),
    ("effort=-1", "effort: must be a finite weight ≥ 0"),
    ("worst=2", "worst: must be in [0, 1]"),
])
def test_objective_mistakes_are_one_line_each(text, message):
    with pytest.raises(ConfigError) as err:
        parse_objective(text)
    assert len(err.value.messages) == 1
    assert err.value.messages[0].startswith(f"--objective: {message}")


DT = 0.001  # fine sampling: the discrete metrics meet the continuous closed forms


def _synthetic_step(cfg, z_of_t, t_end_s=12.0, cmd=(0.1, -0.2, 0.3, 0.0), mode="track"):
    """A run of ``cfg`` (a z step 0.3 → 1 m at t = 1 s) whose true z follows ``z_of_t``."""
    rec = MemoryRecorder()
    t = np.arange(0.0, t_end_s + DT / 2, DT)
    z = z_of_t(t)
    for k, tk in enumerate(t):
        rec.write_row({"t_s": tk, "x_m": 0.0, "y_m": 0.0, "z_m": z[k], "psi_rad": 0.0,
                       "x_true_m": 0.0, "y_true_m": 0.0, "z_true_m": z[k], "psi_true_rad": 0.0,
                       "x_ref_m": 0.0, "y_ref_m": 0.0, "z_ref_m": 1.0 if tk >= 1.0 else 0.3,
                       "psi_ref_rad": 0.0, "cmd_roll_frac": cmd[0], "cmd_pitch_frac": cmd[1],
                       "cmd_gaz_frac": cmd[2], "cmd_yaw_frac": cmd[3], "solve_us": 10.0,
                       "solver_status": "ok", "mode": mode})
    run = rec.run_data(cfg, seed=0)
    return run, summarise(run)


def test_first_order_step_terms_meet_their_closed_forms(step_z):
    tau = 0.4
    run, rows = _synthetic_step(
        step_z, lambda t: np.where(t < 1.0, 0.3, 1.0 - 0.7 * np.exp(-(t - 1.0) / tau)))
    m = scenario_metrics(run, rows)
    assert m["settling_s"] == pytest.approx(tau * math.log(50.0), abs=2 * DT)  # 2 % band
    assert m["overshoot_pct"] == 0.0
    # RMSE of the distance: 0.7·e^(−s/τ) sampled every DT after the step (geometric series)
    n_all = int(round(12.0 / DT)) + 1
    r2 = math.exp(-2 * DT / tau)
    k_after = n_all - int(round(1.0 / DT))
    assert m["tracking_m"] == pytest.approx(
        math.sqrt(0.49 * (1 - r2 ** k_after) / (1 - r2) / n_all), rel=1e-9)
    assert m["effort"] == pytest.approx(0.1 ** 2 + 0.2 ** 2 + 0.3 ** 2, rel=1e-12)
    assert (m["solver_failures"], m["supervisor_ticks"], m["aborted"]) == (0.0, 0.0, 0.0)
    assert m["after_step_s"] == pytest.approx(11.0)


def test_second_order_overshoot_meets_its_closed_form(step_z):
    zeta, wn = 0.3, 4.0
    wd = wn * math.sqrt(1 - zeta ** 2)

    def z(t):
        s = np.maximum(t - 1.0, 0.0)
        e = np.exp(-zeta * wn * s) * (np.cos(wd * s) + zeta * wn / wd * np.sin(wd * s))
        return 1.0 - 0.7 * e

    m = scenario_metrics(*_synthetic_step(step_z, z))
    assert m["overshoot_pct"] == pytest.approx(
        100 * math.exp(-math.pi * zeta / math.sqrt(1 - zeta ** 2)), rel=1e-4)
    # settled once the envelope 0.7·e^(−ζωn s)/√(1−ζ²) is inside the band, at the latest
    envelope_s = math.log(50.0 / math.sqrt(1 - zeta ** 2)) / (zeta * wn)
    assert 0.5 * envelope_s < m["settling_s"] <= envelope_s


def _first_order(tau_s):
    return lambda t: np.where(t < 1.0, 0.3, 1.0 - 0.7 * np.exp(-(t - 1.0) / tau_s))


def _second_order(zeta, wn):
    wd = wn * math.sqrt(1 - zeta ** 2)

    def z(t):
        s = np.maximum(t - 1.0, 0.0)
        return 1.0 - 0.7 * np.exp(-zeta * wn * s) * (np.cos(wd * s) + zeta * wn / wd * np.sin(wd * s))
    return z


@pytest.mark.parametrize("preset", ["default", "step"])
def test_the_objective_ranks_a_slow_or_overshooting_step_below_a_fast_clean_one(step_z, preset):
    """What a step's user asks for (settled within 3 s, overshoot ≤ 5 %) scores best: a fast
    first-order climb (settles in 1.2 s) beats a slow one (5.9 s) and a ringing one (ζ 0.3:
    37 % overshoot) with the same effort, and a critically damped climb (ζ 0.9, 0.2 %
    overshoot) beats a faster one that overshoots 16 %."""
    obj = parse_objective(preset)

    def score(z):
        return obj.score(scenario_metrics(*_synthetic_step(step_z, z)))

    good = score(_first_order(0.3))
    assert good < score(_first_order(1.5))
    assert good < score(_second_order(0.3, 4.0))
    assert score(_second_order(0.9, 4.0)) < score(_second_order(0.5, 6.0))
    # and a trial is ranked by its scenarios: one slow seed costs it the lead
    assert obj.combine([good, good]) < obj.combine([good, score(_first_order(1.5))])


def test_score_is_the_weighted_sum_and_never_settling_counts_the_window(step_z):
    run, rows = _synthetic_step(step_z, lambda t: np.where(t < 1.0, 0.3, 0.8))  # stalls short
    m = scenario_metrics(run, rows)
    assert math.isnan(m["settling_s"])
    obj = Objective({"tracking": 2.0, "settling": 0.5, "overshoot": 3.0, "effort": 7.0,
                     "solver": 1.0, "supervisor": 1.0, "abort": 1000.0}, worst=0.25)
    expected = 2.0 * m["tracking_m"] + 0.5 * 11.0 + 0.0 + 7.0 * m["effort"]
    assert obj.score(m) == pytest.approx(expected, rel=1e-12)
    assert obj.combine([1.0, 3.0, 5.0]) == pytest.approx(0.75 * 3.0 + 0.25 * 5.0)


def test_supervised_ticks_and_landings_are_heavy_penalties(step_z):
    run, rows = _synthetic_step(step_z, lambda t: np.full_like(t, 1.0), t_end_s=3.0,
                                mode="hover-stale-mocap")
    m = scenario_metrics(run, rows)
    assert m["supervisor_ticks"] == 3001  # every tick of the window t = 0…3 s, DT apart
    assert m["aborted"] == 0.0
    run, rows = _synthetic_step(step_z, lambda t: np.full_like(t, 1.0), t_end_s=3.0,
                                mode="land-geofence")
    m = scenario_metrics(run, rows, ending="land-geofence")
    assert m["aborted"] == 1.0
    obj = parse_objective(None)
    assert obj.score(m) >= 1000.0
    assert obj.score(dict(m, aborted=1.0, tracking_m=math.nan)) == 10_000.0


# ----------------------------------------------------------------------------- flights


def test_scenarios_are_seeds_times_variants():
    assert [s.label for s in scenarios(base_seed=4, n_seeds=2)] == ["seed4", "seed5"]
    sc = scenarios(base_seed=0, n_seeds=2, variants=[("slow", ("sim.plant.tau_vz_s=0.7",)),
                                                     ("fast", ("sim.plant.tau_vz_s=0.3",))])
    assert [(s.label, s.seed, s.overrides) for s in sc] == [
        ("seed0+slow", 0, ("sim.plant.tau_vz_s=0.7",)), ("seed1+slow", 1, ("sim.plant.tau_vz_s=0.7",)),
        ("seed0+fast", 0, ("sim.plant.tau_vz_s=0.3",)), ("seed1+fast", 1, ("sim.plant.tau_vz_s=0.3",))]


def test_a_trial_flies_every_scenario_and_an_invalid_one_fails_with_the_penalty():
    cfg = load_config(CONFIGS / "step_z.yaml", ["duration_s=2", "sim.settle_s=0.5"])
    space = default_space(cfg)
    obj = parse_objective(None)
    sc = (Scenario("seed0", 0), Scenario("seed1", 1))
    result = run_trial(TrialSpec(3, {"controller.q[4]": 50.0}, config_to_dict(cfg), space, sc, obj))
    assert result.number == 3 and result.status == "ok", result.message
    assert list(result.metrics) == ["seed0", "seed1"]
    scores = [result.metrics[s.label]["score"] for s in sc]
    assert result.score == pytest.approx(obj.combine(scores))
    assert result.metrics["seed0"]["tracking_m"] != result.metrics["seed1"]["tracking_m"]
    bad = run_trial(TrialSpec(4, {}, config_to_dict(cfg), space,
                              (Scenario("x", 0, ("controller.dtau_s=-1",)),), obj))
    assert bad.status == "failed" and bad.message.startswith("x: controller.dtau_s")
    assert bad.score == 10 * obj.weights["abort"]


def test_params_on_a_config_as_written_copy_only_what_they_set(step_z):
    """Trials change the config as written, so defaults that follow other keys (a plant
    profile's) still follow a scenario's overrides; a vector left out is copied whole."""
    out = apply_params({"name": "w", "sim": {"seed": 4}}, {"controller.q[4]": 80.0,
                                                          "estimator.kalman_q": 1e-3},
                       resolved=config_to_dict(step_z))
    q = list(step_z.controller.q)
    q[4] = 80.0
    assert out == {"name": "w", "sim": {"seed": 4}, "controller": {"q": q},
                   "estimator": {"kalman_q": 1e-3}}


def test_the_written_config_keeps_left_out_keys_out(step_z, tmp_path):
    from ardrone_nmpc.experiments.tune.space import written_config

    data = written_config(CONFIGS / "step_z.yaml", ["sim.seed=5", "controller.r=[1,2,3,4]"])
    assert data["sim"] == {"settle_s": 8.0, "seed": 5}
    assert data["controller"] == {"r": [1, 2, 3, 4]}
    assert "plant" not in data["sim"] and "estimator" not in data


def test_importances_refuse_too_few_trials_and_rank_the_parameter_that_matters():
    """fANOVA on a score that is one of two parameters (a closed form), with the minimum
    number of trials: that one ranks first; one trial fewer is refused."""
    import random

    import optuna

    from ardrone_nmpc.viz.figure import PlotError
    from ardrone_nmpc.viz.tune_figures import MIN_IMPORTANCE_TRIALS, figure_importance

    dist = {"a": optuna.distributions.FloatDistribution(0.0, 1.0),
            "b": optuna.distributions.FloatDistribution(0.0, 1.0)}
    rng = random.Random(0)

    def study_of(n: int):
        study = optuna.create_study()
        for _ in range(n):
            a, b = rng.random(), rng.random()
            study.add_trial(optuna.trial.create_trial(params={"a": a, "b": b},
                                                      distributions=dist,
                                                      value=a))
        return study

    with pytest.raises(PlotError, match=f"at least {MIN_IMPORTANCE_TRIALS} finished trials; "
                                        f"the study has {MIN_IMPORTANCE_TRIALS - 1}"):
        figure_importance(study_of(MIN_IMPORTANCE_TRIALS - 1))
    fig = figure_importance(study_of(MIN_IMPORTANCE_TRIALS))
    ax = fig.axes[0]
    assert [t.get_text() for t in ax.get_yticklabels()] == ["b", "a"]  # the largest on top
    assert f"over {MIN_IMPORTANCE_TRIALS} trials" in ax.get_title()


def test_a_study_file_of_an_earlier_version_is_read_whatever_its_name(tmp_path):
    """Studies were named 'tune' before they were named after the config: the record is
    the one study the file holds."""
    import optuna

    from ardrone_nmpc.runs.tune_record import STUDY_FILE, load_record, stored_trials

    old = optuna.create_study(study_name="tune", storage=f"sqlite:///{tmp_path / STUDY_FILE}")
    old.add_trial(optuna.trial.create_trial(
        params={"q": 1.0}, distributions={"q": optuna.distributions.FloatDistribution(0, 2)},
        value=3.0, user_attrs={"result": {"status": "ok"}}))
    record = load_record(tmp_path)
    assert record.study_name == "tune" and record.best_value == 3.0
    assert stored_trials(tmp_path) == 1


@pytest.mark.parametrize("data", [
    {"name": "a", "sim": {"seed": 7, "settle_s": 1.0}, "duration_s": 5},
    {"name": "a"},  # no sim: made
    {"sim": {"plant": {"profile": "x"}}, "name": "b"},
    {"sim": None},  # not a mapping: the override's own error
    {"sim": 3},
])
@pytest.mark.parametrize("sc", [Scenario("s0", 0), Scenario("s3", 3, ("duration_s=2",)),
                                Scenario("s5", 5, ("sim.settle_s=0.5", "name=q"))])
def test_a_scenario_s_data_is_its_overrides_and_seed_applied(data, sc):
    from ardrone_nmpc.config.io import apply_overrides
    from ardrone_nmpc.experiments.tune.engine import _scenario_data

    def outcome(make):
        try:
            got = make()
        except ConfigError as err:
            return ("error", err.messages)
        return ("data", got, [list(got)] + [list(v) for v in got.values() if isinstance(v, dict)])

    before = repr(data)
    want = outcome(lambda: apply_overrides(data, [*sc.overrides, f"sim.seed={sc.seed}"]))
    assert outcome(lambda: _scenario_data(data, sc)) == want  # key order too
    assert repr(data) == before  # left alone
