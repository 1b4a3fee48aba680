"""``ardrone-nmpc tune`` through typer's CliRunner: local (in-process and pool), Dask,
--resume, best.yaml, plot."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import optuna
import pytest
from typer.testing import CliRunner

from ardrone_nmpc.cli.app import app
from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.core import defaults
from ardrone_nmpc.experiments.tune.engine import plant_variants
from ardrone_nmpc.runtime.lockstep import run_lockstep

runner = CliRunner()
CONFIG = str(Path(__file__).resolve().parents[2] / "configs" / "step_z.yaml")
SHORT = ["--set", "duration_s=2", "--set", "sim.settle_s=0.5", "--seeds", "2"]
# every trial flies each seed on each plant profile of the schema (sim.plant.profile)
PROFILES = [label for label, _ in plant_variants()]
LABELS = [f"seed{s}+{p}" for p in PROFILES for s in (0, 1)] if PROFILES else ["seed0", "seed1"]
METRICS = ["score", "tracking_m", "rmse_m", "path_deviation_m", "settling_s", "overshoot_pct",
           "effort", "solver_failures", "supervisor_ticks", "aborted", "after_step_s", "unclean"]
# a z step searches the weights that shape z's response (space.STEP_WEIGHTS)
SPACE = ["controller.q[4]", "controller.q[5]", "controller.r[0]"]


def _tune(out, *extra):
    return runner.invoke(app, ["tune", CONFIG, *SHORT, "-o", str(out), *extra])


def _rows(out: Path) -> list[dict[str, str]]:
    with open(out / "trials.csv", newline="", encoding="utf-8") as f:
        return list(csv.DictReader(f))


def _study(out: Path, name: str = "step_z"):
    """The study in ``out/study.db``, loaded by the name a tune of step_z.yaml gives it."""
    return optuna.load_study(study_name=name, storage=f"sqlite:///{out / 'study.db'}")


def _check_trials(out: Path, n: int) -> list[dict[str, str]]:
    rows = _rows(out)
    assert list(rows[0]) == ["trial", "status", "score", *SPACE, "wall_s", "sim_s",
                             *(f"{label}:{m}" for label in LABELS for m in METRICS), "message"]
    assert [r["trial"] for r in rows] == [str(i) for i in range(n)]
    study = _study(out)
    for row, trial in zip(rows, sorted(study.trials, key=lambda t: t.number)):
        assert float(row["score"]) == trial.value
        assert row["status"] == "ok", row["message"]
        assert {k: float(row[k]) for k in SPACE} == trial.params
        for label in LABELS:
            assert 0.0 < float(row[f"{label}:tracking_m"]) < 2.0  # a 0.7 m climb in 2 s
            assert row[f"{label}:aborted"] == "0"
    # the first trial asked flies the config's own weights
    base = [defaults.Q_STATE[4], defaults.Q_STATE[5], defaults.R_INPUT[0]]  # the config's own
    assert [float(rows[0][k]) for k in SPACE] == base  # trial 0
    return rows


def _check_best(out: Path, rows) -> None:
    best_row = min(rows, key=lambda r: float(r["score"]))
    text = (out / "best.yaml").read_text()
    assert text.startswith("# Found by `ardrone-nmpc tune ")
    assert f"trial {best_row['trial']} of {len(rows)}" in text
    cfg = load_config(out / "best.yaml")
    q, r = cfg.controller.q, cfg.controller.r
    assert [q[4], q[5], r[0]] == pytest.approx([float(best_row[k]) for k in SPACE])
    assert (q[:4], q[6], r[1:]) == (defaults.Q_STATE[:4], defaults.Q_STATE[6],
                                    defaults.R_INPUT[1:])  # not searched: the config's
    assert cfg.duration_s == 2.0 and cfg.name == "step_z"
    assert run_lockstep(cfg).ending == "completed"  # it flies as is


def test_a_two_trial_local_tune_writes_trials_best_and_the_table(tmp_path):
    result = _tune(tmp_path, "--trials", "2", "--jobs", "1")
    assert result.exit_code == 0, result.output
    rows = _check_trials(tmp_path, 2)
    _check_best(tmp_path, rows)
    assert "best 2 of 2 trials" in result.stdout and "q[4]" in result.stdout
    assert f"2 trials (2 flown now, 0 before) × {len(LABELS)} scenarios" in result.stdout
    assert result.stdout.strip().splitlines()[-1] == f"best: {tmp_path / 'best.yaml'}"
    assert not (tmp_path / "runs").exists()  # no run directory without --keep-runs
    flown = runner.invoke(app, ["simulate", str(tmp_path / "best.yaml"), "--log-dir",
                                str(tmp_path / "logs"), "--quiet"])
    assert flown.exit_code == 0, flown.output


@pytest.mark.timeout(300)
def test_a_pool_tune_gives_the_same_flights(tmp_path):
    """Trial 0 (the config's weights) flies the same in a pool worker as in-process."""
    assert _tune(tmp_path / "one", "--trials", "1", "--jobs", "1").exit_code == 0
    result = _tune(tmp_path / "two", "--trials", "3", "--jobs", "2")
    assert result.exit_code == 0, result.output
    rows = _check_trials(tmp_path / "two", 3)
    rows = [r for r in rows if float(r["controller.q[4]"]) == 5.0]  # the config's weights
    (first,) = _rows(tmp_path / "one")
    deterministic = [c for c in first if c.endswith(("tracking_m", "settling_s", "overshoot_pct",
                                                     "effort"))]
    assert {c: rows[0][c] for c in deterministic} == {c: first[c] for c in deterministic}


@pytest.mark.timeout(300)
def test_a_two_trial_dask_tune(tmp_path):
    from dask.distributed import LocalCluster

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=False, protocol="tcp",
                      host="127.0.0.1", dashboard_address=None) as cluster:
        result = _tune(tmp_path, "--trials", "2", "--engine", "dask", "--scheduler",
                       cluster.scheduler_address)
    assert result.exit_code == 0, result.output
    assert "dask, " in result.stdout
    _check_best(tmp_path, _check_trials(tmp_path, 2))


def test_resume_continues_without_flying_finished_trials_again(tmp_path):
    assert _tune(tmp_path, "--trials", "2", "--jobs", "1").exit_code == 0
    first = _rows(tmp_path)
    again = _tune(tmp_path, "--trials", "2", "--jobs", "1")
    assert again.exit_code == 1
    assert again.output.startswith(f"error: --output {tmp_path}: holds a study already")
    # a run stopped with a trial in flight: it was asked, never told
    _study(tmp_path).ask()
    result = _tune(tmp_path, "--trials", "4", "--jobs", "1", "--resume")
    assert result.exit_code == 0, result.output
    assert "4 trials (2 flown now, 2 before)" in result.stdout
    states = [t.state.name for t in sorted(_study(tmp_path).trials, key=lambda t: t.number)]
    assert states == ["COMPLETE", "COMPLETE", "FAIL", "COMPLETE", "COMPLETE"]
    rows = _rows(tmp_path)
    assert rows[:2] == first  # the finished trials kept, not flown again
    assert [r["trial"] for r in rows] == ["0", "1", "3", "4"]
    assert len({tuple(r[k] for k in SPACE) for r in rows}) == 4
    done = _tune(tmp_path, "--trials", "4", "--jobs", "1", "--resume")
    assert "4 trials (0 flown now, 4 before)" in done.stdout


def test_a_signal_between_a_result_and_its_count_does_not_split_the_counts(tmp_path,
                                                                          monkeypatch):
    """A Ctrl-C that lands after a trial's result came but before the command counted it
    (the race of a signal with two jobs, made certain here): the trial is stored, and the
    closing line counts it as flown now — the counts come from the record."""
    from ardrone_nmpc.experiments.tune import study as st

    real = st.run_study

    def interrupted_at_the_second_result(study, *, on_result, **kwargs):
        seen = []

        def late(result):
            seen.append(result)
            if len(seen) == 2:
                raise KeyboardInterrupt  # after run_study holds the result, before the count
            on_result(result)

        return real(study, on_result=late, **kwargs)

    monkeypatch.setattr(st, "run_study", interrupted_at_the_second_result)
    result = _tune(tmp_path, "--trials", "4", "--jobs", "1")
    assert result.exit_code != 0
    rows = _rows(tmp_path)
    assert [r["trial"] for r in rows] == ["0", "1"]  # both stored: the second had finished
    line = " ".join(result.stdout.split())
    assert "2 trials (2 flown now, 0 before)" in line, line
    simulated_s = sum(float(r["sim_s"]) for r in rows)
    assert f"{simulated_s:.0f} s simulated" in line


def test_resume_refuses_a_study_of_another_setup(tmp_path):
    assert _tune(tmp_path, "--trials", "1", "--jobs", "1").exit_code == 0
    result = _tune(tmp_path, "--trials", "2", "--jobs", "1", "--resume",
                   "--objective", "tracking")
    assert result.exit_code == 1
    assert result.output == (f"error: --resume: the study in {tmp_path} optimises another "
                             "objective; use another --output\n")


def test_keep_runs_writes_each_flight_s_run_directory(tmp_path):
    result = _tune(tmp_path, "--trials", "1", "--jobs", "1", "--keep-runs")
    assert result.exit_code == 0, result.output
    runs = sorted((tmp_path / "runs" / "trial-00000").iterdir())
    assert all((r / "summary.csv").is_file() for r in runs)
    flown = sorted((load_config(r / "config.yaml").sim.seed,
                    getattr(load_config(r / "config.yaml").sim.plant, "profile", ""))
                   for r in runs)
    assert len(runs) == len(LABELS)
    assert flown == sorted((int(label[4]), label.partition("+")[2]) for label in LABELS)


@pytest.mark.parametrize("args, message", [
    (["--objective", "fast"], "error: --objective: unknown preset 'fast'"),
    (["--scheduler", "tcp://127.0.0.1:1"], "error: --scheduler: only with --engine dask"),
    (["--variant", "nothing"], "error: --variant 'nothing': expected"),
    (["--space", "/nonexistent/space.yaml"], "error: --space /nonexistent/space.yaml: cannot read"),
    (["--set", "controller.dtau_s=-1"], "error: controller.dtau_s: "),
])
def test_mistakes_are_one_line_and_nothing_flies(tmp_path, args, message):
    result = _tune(tmp_path / "out", "--trials", "1", "--jobs", "1", *args)
    assert result.exit_code == 1
    assert result.output.startswith(message), result.output
    assert "Traceback" not in result.output
    assert not (tmp_path / "out" / "study.db").exists()


def test_an_unknown_engine_is_a_command_line_error(tmp_path):
    result = _tune(tmp_path / "out", "--trials", "1", "--jobs", "1", "--engine", "ray")
    assert result.exit_code == 2
    assert result.output == "error: --engine: unknown 'ray'; choose local, dask\n"
    assert not (tmp_path / "out").exists()


def test_a_space_file_and_variants_shape_the_study(tmp_path):
    space = tmp_path / "space.yaml"
    space.write_text("default: false\nparams:\n"
                     "  controller.horizon_steps: {low: 8, high: 20, type: int}\n"
                     "  controller.q[4]: {low: 5, high: 100, log: true}\n")
    result = _tune(tmp_path / "out", "--trials", "2", "--jobs", "1", "--space", str(space),
                   "--variant", "slow:sim.plant.tau_vz_s=0.7", "--variant",
                   "sim.plant.tau_vz_s=0.3;sim.noise.mocap_position_std_m=0.001")
    assert result.exit_code == 0, result.output
    rows = _rows(tmp_path / "out")
    assert [c for c in rows[0] if c.startswith("controller.")] == [
        "controller.horizon_steps", "controller.q[4]"]
    labels = sorted({c.split(":")[0] for c in rows[0] if ":" in c})
    assert labels == ["seed0+slow", "seed0+v1", "seed1+slow", "seed1+v1"]
    assert all(float(r["controller.horizon_steps"]).is_integer() for r in rows)
    assert load_config(tmp_path / "out" / "best.yaml").controller.horizon_steps in range(8, 21)


def test_plot_draws_the_history_and_no_importances_from_three_trials(tmp_path):
    from ardrone_nmpc.viz.tune_figures import MIN_IMPORTANCE_TRIALS

    assert _tune(tmp_path, "--trials", "3", "--jobs", "1").exit_code == 0
    result = runner.invoke(app, ["plot", str(tmp_path)])
    assert result.exit_code == 0, result.output
    files = [Path(line.split(": ", 1)[1]) for line in result.stdout.splitlines()]
    assert files == [tmp_path / "plot-history.png"]
    assert files[0].read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and files[0].stat().st_size > 5000
    assert (f"plot-importance.png: not drawn: parameter importances need at least "
            f"{MIN_IMPORTANCE_TRIALS} finished trials, the study has 3") in result.stderr
    assert not (tmp_path / "plot-importance.png").exists()
    assert not math.isnan(_study(tmp_path).best_value)


def test_the_study_is_what_optuna_and_its_dashboard_read(tmp_path):
    """Named after the config (or --study), its metric named, each metric a flat number,
    real durations, trials_dataframe(); --storage holds the same trials."""
    shared = f"sqlite:///{tmp_path / 'dash.db'}"
    out = tmp_path / "a"
    assert _tune(out, "--trials", "2", "--jobs", "1", "--storage", shared).exit_code == 0
    study = _study(out)
    assert study.metric_names == ["score"]
    rows = _rows(out)
    for trial, row in zip(sorted(study.trials, key=lambda t: t.number), rows):
        numbers = {k: v for k, v in trial.user_attrs.items()
                   if isinstance(v, float) and math.isfinite(v)}
        assert numbers["tracking_m"] == pytest.approx(
            sum(float(row[f"{label}:tracking_m"]) for label in LABELS) / len(LABELS))
        assert numbers[f"{LABELS[0]}:rmse_m"] == float(row[f"{LABELS[0]}:rmse_m"])
        assert numbers["wall_s"] == float(row["wall_s"]) and len(numbers) >= 3
        # a metric with no finite value (a 2 s flight never settles) is left out, not NaN
        assert ("settling_s" in numbers) == any(
            math.isfinite(float(row[f"{label}:settling_s"])) for label in LABELS)
        assert 0.0 < trial.duration.total_seconds() < 600.0
    frame = study.trials_dataframe()
    assert list(frame["number"]) == [0, 1] and "user_attrs_tracking_m" in frame.columns
    assert "value_score" in frame.columns  # the metric name
    mirror = optuna.load_study(study_name="step_z", storage=shared)
    assert [t.params for t in mirror.trials] == [t.params for t in study.trials]
    assert [t.value for t in mirror.trials] == [t.value for t in study.trials]
    # the shared database refuses a second study of the same name; --study names another
    again = _tune(tmp_path / "b", "--trials", "1", "--jobs", "1", "--storage", shared)
    assert again.exit_code == 1
    assert again.stderr.splitlines()[-1] == (
        f"error: --storage {shared}: holds a study 'step_z' with 2 trials of another run; "
        "name this one with --study")
    assert not (tmp_path / "b" / "study.db").exists()
    named = _tune(tmp_path / "b", "--trials", "1", "--jobs", "1", "--storage", shared,
                  "--study", "z-second")
    assert named.exit_code == 0, named.output
    assert _study(tmp_path / "b", "z-second").trials[0].number == 0
    assert set(optuna.get_all_study_names(shared)) == {"step_z", "z-second"}


def test_the_same_seed_asks_the_same_trials_whatever_the_jobs(tmp_path):
    """The sampler is told in trial order (study.ASK_AHEAD): two runs with two workers and
    one in this process ask for the same parameters, trial by trial."""
    runs = {}
    for name, jobs in (("a", "2"), ("b", "2"), ("c", "1")):
        result = _tune(tmp_path / name, "--trials", "12", "--jobs", jobs, "--seed", "3")
        assert result.exit_code == 0, result.output
        runs[name] = [[r[k] for k in ("trial", "score", *SPACE)] for r in _rows(tmp_path / name)]
    assert len(runs["a"]) == 12
    assert runs["a"] == runs["b"] == runs["c"]
    assert len({tuple(r[2:]) for r in runs["a"]}) == 12  # twelve different trials
