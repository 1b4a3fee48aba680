"""A flight's verdict (ardrone_nmpc/runs/verdict.py): reaching the end is not enough to be
completed — and what each runner makes of a failed verdict."""

from __future__ import annotations

import math

import pytest

from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.runs.verdict import (FAILED_VERDICTS, NO_TARGET, NO_TRACKING, VerdictTally,
                                       is_tracking, verdict_message)


def rows(*modes, t0=-0.13, target_age_ms=math.nan):
    return [{"t_s": t0 + 0.065 * k, "mode": m, "target_age_ms": target_age_ms}
            for k, m in enumerate(modes)]


def tally(rows_, follow=False):
    t = VerdictTally(follow=follow)
    for r in rows_:
        t.add(r)
    return t


@pytest.mark.parametrize("mode, tracking", [
    ("track", True), ("fallback-solver", True), ("settle", False), ("hover-speed", False),
    ("hold-stale-mocap", False), ("land-geofence", False), ("landing", False), ("", False)])
def test_a_tracking_tick_is_flown_by_a_controller(mode, tracking):
    assert is_tracking(mode) is tracking


def test_a_run_that_only_hovered_in_its_track_window_is_not_completed():
    t = tally(rows("settle", "settle", *["hover-speed"] * 40))
    assert t.tracking_ticks == 0 and t.verdict("completed") == NO_TRACKING
    # tracking only while settling (t < 0) does not count either
    assert tally(rows("track", "track", "hover-speed")).verdict("completed") == NO_TRACKING
    assert tally(rows("settle", "settle", "hover-speed", "track")).verdict("completed") == \
        "completed"
    assert tally(rows("settle", "settle", "fallback-solver")).verdict("completed") == \
        "completed"
    counted = tally(rows("settle", "settle", "track", "hover-speed", "track", "fallback-p"))
    assert counted.tracking_ticks == 3 and not counted.target_seen


def test_add_tick_counts_as_is_tracking_whatever_the_label_objects():
    """add_tick judges a mode when it is not the last one's object: labels equal but
    distinct, alternating, or the same object tick after tick count as is_tracking says."""
    import random

    rng = random.Random(5)
    labels = ["track", "settle", "fallback-solver", "hold-stale-mocap", "landing", ""]
    modes = []
    for _ in range(400):
        label = rng.choice(labels)
        # now the same object again, now an equal string of its own
        modes.append(label if rng.random() < 0.5 else "".join(list(label)))
    times = [rng.choice((-0.5, 0.0, 1.0)) for _ in modes]
    tally = VerdictTally(follow=False)
    for t_s, mode in zip(times, modes):
        tally.add_tick(t_s, mode)
    assert tally.tracking_ticks == sum(1 for t_s, m in zip(times, modes)
                                       if t_s >= 0 and is_tracking(m)) > 0


def test_a_landing_or_a_stop_keeps_its_own_ending():
    t = tally(rows("settle", "hover-speed"))
    for ending in ("land-geofence", "stop-emergency", "land-drone-landed-itself"):
        assert t.verdict(ending) == ending


def test_a_follow_run_that_never_saw_its_target_failed():
    assert tally(rows("settle", "track", "track", "track"), follow=True).verdict(
        "completed") == NO_TARGET
    seen = rows("settle", "track", "track", target_age_ms=12.0)
    assert tally(seen, follow=True).verdict("completed") == "completed"
    assert tally(rows("settle", "track", "track")).verdict("completed") == "completed"


def test_failed_verdicts_say_what_happened():
    assert FAILED_VERDICTS == {NO_TRACKING, NO_TARGET}
    assert "no tick of the experiment window was flown by the controller" in \
        verdict_message(NO_TRACKING)
    assert "followed object was never seen" in verdict_message(NO_TARGET)
    assert verdict_message("completed") == ""


# ----------------------------------------------------------------------------- the runners
HOVERING = ["duration_s=2", "sim.settle_s=0.2", "safety.max_speed_mps=0.01"]  # always too fast


def test_lockstep_gives_its_own_verdict_and_lands():
    from ardrone_nmpc.core.types import FlightMode
    from ardrone_nmpc.runtime.lockstep import run_lockstep

    result = run_lockstep(load_config(None, HOVERING))
    assert result.ending == NO_TRACKING and result.final_mode is FlightMode.LANDED
    follow = load_config("configs/follow_car.yaml", ["duration_s=2", "sim.target=null"])
    assert run_lockstep(follow).ending == NO_TARGET


def test_simulate_exits_1_with_one_line_and_the_run(tmp_path):
    from typer.testing import CliRunner

    from ardrone_nmpc.cli.app import app

    args = ["simulate", "configs/hover.yaml", "--quiet", "--log-dir", str(tmp_path)]
    for s in HOVERING:
        args += ["--set", s]
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 1
    assert result.stderr.startswith("error: failed-no-tracking: no tick of the experiment")
    assert len(result.stderr.strip().splitlines()) == 1 and "Traceback" not in result.stderr
    run = result.stdout.strip().splitlines()[-1]
    assert run.startswith("run: ") and (tmp_path / run.split("/")[-1] / "summary.csv").exists()


def test_a_sweep_case_and_a_tune_trial_that_did_not_track_failed(tmp_path):
    from ardrone_nmpc.config.io import config_to_dict
    from ardrone_nmpc.experiments.sweep.cases import run_case
    from ardrone_nmpc.experiments.sweep.grid import build_cases, parse_grid
    from ardrone_nmpc.experiments.tune.engine import Scenario, TrialSpec, run_trial
    from ardrone_nmpc.experiments.tune.objective import parse_objective
    from ardrone_nmpc.experiments.tune.space import default_space

    case = build_cases(config_path=None, overrides=HOVERING,
                       grid=parse_grid(["sim.seed=0"]))[0]
    result = run_case(case, out_dir=tmp_path)
    assert result.status == "failed" and result.message.startswith("failed-no-tracking: ")
    assert not (tmp_path / case.case_id / "summary.csv").exists()  # flown again on resume
    cfg = load_config(None, HOVERING)
    trial = run_trial(TrialSpec(0, {}, config_to_dict(cfg), default_space(cfg),
                                (Scenario("seed0", 0),), parse_objective(None)))
    assert trial.status == "failed" and trial.message.startswith("seed0: failed-no-tracking")


def test_a_reference_outside_the_fence_flies_nothing_and_leaves_no_run_directory(tmp_path):
    from typer.testing import CliRunner

    from ardrone_nmpc.cli.app import app

    for command in (["simulate", "configs/square.yaml", "--quiet"],
                    ["check", "configs/square.yaml"]):
        result = CliRunner().invoke(app, [*command, "--set", "reference.side_m=50",
                                          *(["--log-dir", str(tmp_path / "logs")]
                                            if command[0] == "simulate" else [])])
        assert result.exit_code == 1 and result.stderr.startswith(
            "error: reference: the square reference leaves the geofence at t = 0.31 s, at "
            "(3.10, 0.00, 1.00) m outside [-3, 3] × [-3, 3] × [-0.2, 2.5] m")
    assert not (tmp_path / "logs").exists()
    step = load_config(None, ["reference.kind=step", "reference.target_m=[0,0,2.6]"])
    from ardrone_nmpc.reference.experiment import experiment_trajectory
    from ardrone_nmpc.reference.trajectories import ReferenceError

    with pytest.raises(ReferenceError, match=r"step reference leaves the geofence .* 2\.60\) m"):
        experiment_trajectory(step)
    inside = load_config(None, ["reference.kind=step", "reference.target_m=[0,0,2.5]"])
    experiment_trajectory(inside)                       # on the fence is inside


def test_a_reference_is_checked_against_its_fence_once_and_again_for_another_fence(
        monkeypatch):
    """experiment_trajectory keeps the references found inside (a sweep flies one many
    times): the same reference, duration and fence are not sampled again, but a narrower
    fence or a changed reference are — and refused."""
    from ardrone_nmpc.reference import experiment
    from ardrone_nmpc.reference.trajectories import ReferenceError

    square = ["reference.kind=square", "reference.side_m=2"]
    cfg = load_config(None, square)
    experiment.experiment_trajectory(cfg)
    assert experiment._fence_key(cfg) in experiment._INSIDE
    checked = []
    check = experiment.check_inside_geofence
    monkeypatch.setattr(experiment, "check_inside_geofence",
                        lambda c, t: (checked.append(c), check(c, t)))
    experiment.experiment_trajectory(load_config(None, square))  # an equal one: not again
    assert checked == []
    for overrides in (["safety.geofence_max_m=[1.5,3,2.5]"], ["reference.side_m=4"]):
        with pytest.raises(ReferenceError, match="leaves the geofence"):
            experiment.experiment_trajectory(load_config(None, square + overrides))
    assert len(checked) == 2
