"""The command line through typer's CliRunner: output, exit codes, error lines."""

import json
from pathlib import Path

import numpy as np

import pytest
import yaml
from typer.testing import CliRunner

from ardrone_nmpc.cli.app import app
from ardrone_nmpc.core import defaults
from ardrone_nmpc.config.schema import ExperimentConfig

runner = CliRunner()


def test_help_lists_the_commands():
    result = runner.invoke(app, ["--help"])
    assert result.exit_code == 0
    for command in ("check", "bench"):
        assert command in result.output


def test_check_prints_the_resolved_config(tmp_path):
    cfg = tmp_path / "x.yaml"
    cfg.write_text("name: demo\ncontroller:\n  horizon_steps: 8\n")
    result = runner.invoke(app, ["check", str(cfg), "--set", "controller.solver.kmax=7"])
    assert result.exit_code == 0, result.output
    resolved = ExperimentConfig.model_validate(yaml.safe_load(result.output))
    assert resolved.name == "demo"
    assert resolved.controller.horizon_steps == 8
    assert resolved.controller.solver.kmax == 7
    assert resolved.controller.q == defaults.Q_STATE  # the default, resolved


def test_check_reports_every_error_with_its_field_path(tmp_path):
    cfg = tmp_path / "bad.yaml"
    cfg.write_text("controller:\n  dtau_s: -0.1\n  bogus: 1\n")
    result = runner.invoke(app, ["check", str(cfg)])
    assert result.exit_code == 1
    assert "controller.dtau_s:" in result.output
    assert "controller.bogus:" in result.output
    assert "Traceback" not in result.output


def test_check_missing_file_is_one_clear_line(tmp_path):
    result = runner.invoke(app, ["check", str(tmp_path / "nope.yaml")])
    assert result.exit_code == 1
    assert "no such file" in result.output
    assert "Traceback" not in result.output


def test_bench_writes_the_json_rows(tmp_path):
    out = tmp_path / "bench.json"
    result = runner.invoke(app, ["bench", "--steps", "20", "--repeats", "1", "--solvers",
                                 "cgmres", "--horizon-steps", "10", "--kmax", "4",
                                 "--json", str(out)])
    assert result.exit_code == 0, result.output
    data = json.loads(out.read_text())
    (row,) = data["rows"]
    assert row["solver"] == "cgmres" and row["horizon_steps"] == 10 and row["kmax"] == 4
    assert row["steps"] == 20 and row["mean_us"] > 0
    assert "cgmres" in result.output


@pytest.mark.parametrize("args, code, message", [
    (["--solvers", "fast"], 2, "--solvers: unknown 'fast'; choose from cgmres, newton"),
    (["--solvers", ","], 2, "--solvers: unknown (empty); choose from cgmres, newton"),
    (["--compare", "acados"], 2, "--compare: unknown 'acados'; choose casadi"),
    (["--set", "controller.horizon_steps=0"], 1, "controller.horizon_steps:"),
])
def test_bench_rejects_bad_options(args, code, message):
    result = runner.invoke(app, ["bench", "--steps", "10", *args])
    assert result.exit_code == code
    assert message in result.output


def _simulate(tmp_path, *extra):
    return runner.invoke(app, ["simulate", "configs/step_x.yaml", "--log-dir", str(tmp_path),
                               "--set", "duration_s=2.0", "--set", "sim.settle_s=0.5",
                               *extra])


def test_simulate_writes_a_complete_run_directory(tmp_path):
    from ardrone_nmpc.runs.rundir import read_run

    result = _simulate(tmp_path, "--seed", "3")
    assert result.exit_code == 0, result.output
    last = result.output.strip().splitlines()[-1]
    assert last.startswith("run: ")
    run = read_run(last[len("run: "):])
    assert run.seed == 3 and run.config.sim.seed == 3
    assert run.config.duration_s == 2.0
    t = run.columns["t_s"]
    assert t[0] < 0 <= t[-1] and t[-1] == pytest.approx(2.0, abs=0.07)  # settle, then 2 s
    assert set(run.columns["mode"]) <= {"settle", "track"}
    assert any(e["kind"] == "landed" for e in run.events)
    assert (run.path / "summary.csv").read_text().startswith("axis,metric,value,unit")


def test_simulate_quiet_prints_only_the_run_line(tmp_path):
    result = _simulate(tmp_path, "--quiet")
    assert result.exit_code == 0, result.output
    assert result.output.strip().splitlines() == [result.output.strip()]
    assert result.output.startswith("run: ")


def test_simulate_is_deterministic_for_a_seed(tmp_path):
    from ardrone_nmpc.runs.rundir import read_run

    runs = []
    for sub in ("a", "b"):
        result = _simulate(tmp_path / sub, "--quiet", "--seed", "7")
        runs.append(read_run(result.output.strip()[len("run: "):]))
    for column in ("x_m", "z_m", "x_true_m", "u_theta_rad", "cmd_pitch_frac"):
        assert np.array_equal(runs[0].columns[column], runs[1].columns[column], equal_nan=True)


def test_summary_prints_runs_side_by_side(tmp_path):
    paths = [_simulate(tmp_path / s, "--quiet", "--seed", s).output.strip()[5:] for s in "12"]
    result = runner.invoke(app, ["summary", *paths])
    assert result.exit_code == 0, result.output
    assert "rmse" in result.output
    for p in paths:
        assert Path(p).name[:15] in result.output


def test_summary_of_a_missing_run_is_one_clear_line(tmp_path):
    result = runner.invoke(app, ["summary", str(tmp_path / "nope")])
    assert result.exit_code == 1
    assert "Traceback" not in result.output


def test_simulate_rejects_a_bad_override(tmp_path):
    result = _simulate(tmp_path, "--set", "controller.kind=pid")
    assert result.exit_code == 1
    assert "controller.kind:" in result.output


def test_a_run_flown_from_a_path_file_survives_the_file(tmp_path):
    """The run directory holds its own copy: delete the CSV, and summary, replay (also
    --rerun) and plot still work — and give the same path metrics."""
    import shutil

    source = tmp_path / "lap.csv"
    source.write_text("t_s,x_m,y_m,z_m,psi_rad\n0,0,0,1,0\n1.5,0.3,0,1,0\n3,0.3,0.3,1,0\n")
    result = runner.invoke(app, ["simulate", "configs/hover.yaml", "--log-dir", str(tmp_path),
                                 "--quiet", "--set", "reference.kind=path",
                                 "--set", f"reference.path_file={source}",
                                 "--set", "duration_s=2", "--set", "sim.settle_s=0.5"])
    assert result.exit_code == 0, result.output
    run = Path(result.output.strip().splitlines()[-1][len("run: "):])
    before = runner.invoke(app, ["summary", "--csv", str(run)]).stdout
    source.unlink()
    moved = tmp_path / "moved" / run.name
    shutil.move(str(run), moved)  # and to another folder (another machine)
    after = runner.invoke(app, ["summary", "--csv", str(moved)])
    assert after.exit_code == 0 and after.stderr == "", after.output
    assert after.stdout == before and "path,mean_deviation," in before
    assert runner.invoke(app, ["replay", str(moved)]).exit_code == 0
    rerun = runner.invoke(app, ["replay", str(moved), "--rerun", "--log-dir", str(tmp_path)])
    assert rerun.exit_code == 0, rerun.output
    assert "reproduced" in rerun.stdout
    plot = runner.invoke(app, ["plot", str(moved), "--kind", "path3d"])
    assert plot.exit_code == 0, plot.output
    assert (moved / "plot-path3d.png").is_file()


@pytest.mark.timeout(120)
def test_overruns_agree_between_summary_and_loop_timing_at_1_ms(tmp_path):
    """At period_s = 0.001 a tick takes longer than a period: deadlines are skipped. The
    summary (from the t_s gaps of log.csv) and fly's loop_timing event count the same."""
    import csv

    from ardrone_nmpc.runs.rundir import read_run

    result = runner.invoke(app, ["fly", "configs/hover.yaml", "--sim", "--no-dashboard",
                                 "--log-dir", str(tmp_path), "--set", "loop.period_s=0.001",
                                 "--set", "duration_s=0.5", "--set", "sim.settle_s=0.2",
                                 # a horizon of 100 steps: a tick outlasts 1 ms on any machine
                                 "--set", "controller.horizon_steps=100"])
    assert result.exit_code == 0, result.output
    run = read_run(result.stdout.strip().splitlines()[-1][len("run: "):])
    (timing,) = [e for e in run.events if e["kind"] == "loop_timing"]
    rows = {(r["axis"], r["metric"]): float(r["value"])
            for r in csv.DictReader(open(run.path / "summary.csv"))}
    assert timing["overruns"] > 0  # the case the issue found: deadlines were skipped
    assert rows[("loop", "overruns")] == timing["overruns"]


def test_fly_opens_the_drone_its_address_names(tmp_path):
    """--drone takes an address or a URI: sim://lockstep flies the simulated drone as simulate
    does; a scheme no backend serves, or faults on a drone that is not simulated, are one
    error line each and leave no run directory."""
    base = ["fly", "configs/hover.yaml", "--no-dashboard", "--log-dir", str(tmp_path),
            "--duration-s", "2", "--set", "sim.settle_s=0.5"]
    flown = runner.invoke(app, [*base, "--drone", "sim://lockstep"])
    assert flown.exit_code == 0, flown.output
    run = Path(flown.stdout.strip().splitlines()[-1][len("run: "):])
    events = [json.loads(line) for line in (run / "events.jsonl").read_text().splitlines()]
    assert [e["kind"] for e in events][-1] == "simulated" and (run / "summary.csv").exists()
    for drone, message in (("radio://0/80/2M", "no such drone backend"),
                           ("udp://127.0.0.1", "only in simulation")):
        refused = runner.invoke(app, [*base, "--drone", drone,
                                      "--set", "faults.wind.velocity_mps=[0.5,0,0]"])
        assert refused.exit_code == 1 and message in refused.stderr, refused.output
        assert refused.stderr.count("error:") == 1 and "Traceback" not in refused.output
    assert sorted(p.name for p in tmp_path.iterdir()) == [run.name]
