"""The command line through typer's CliRunner: output, exit codes, error lines."""

import json

import pytest
import yaml
from typer.testing import CliRunner

from ardrone_nmpc.cli import app
from ardrone_nmpc.config import ExperimentConfig

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
    assert resolved.controller.q == (12, 2, 7, 2, 5, 10, 13)


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


@pytest.mark.parametrize("args, message", [
    (["--solvers", "fast"], "--solvers: unknown solver(s) fast"),
    (["--compare", "acados"], "--compare: unknown comparison"),
    (["--set", "controller.horizon_steps=0"], "controller.horizon_steps:"),
])
def test_bench_rejects_bad_options(args, message):
    result = runner.invoke(app, ["bench", "--steps", "10", *args])
    assert result.exit_code == 1
    assert message in result.output
