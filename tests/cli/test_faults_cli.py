"""`ardrone-nmpc faults`: a small subset of the matrix through the CLI, and its errors."""

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from ardrone_nmpc.cli.app import app

CONFIGS = Path(__file__).parents[2] / "configs"
runner = CliRunner()


@pytest.mark.timeout(300)
def test_faults_subset_writes_json_and_markdown(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # the report names run directories relative to the cwd
    out_json, out_md = tmp_path / "m.json", tmp_path / "m.md"
    result = runner.invoke(app, ["faults", "--experiments", "hover", "--faults",
                                 "battery_floor,solver_diverge", "--config-dir", str(CONFIGS),
                                 "--log-dir", str(tmp_path / "runs"), "--json", str(out_json),
                                 "--markdown", str(out_md)])
    assert result.exit_code == 0, result.output
    assert "2/2 cases pass" in result.output
    cases = {c["fault"]: c for c in json.loads(out_json.read_text())}
    assert cases["battery_floor"]["outcome"] == "landed"
    assert cases["battery_floor"]["ending"] == "land-battery"
    assert cases["solver_diverge"]["outcome"] == "completed"
    assert all(c["log_complete"] and c["nonfinite_cmds"] == 0 for c in cases.values())
    assert Path(cases["battery_floor"]["run_dir"]).is_dir()
    assert all(c["run_dir"].startswith("runs/") for c in cases.values())
    text = out_md.read_text()
    assert "**2 of 2 cases pass**" in text and "| hover | battery_floor | landed |" in text


@pytest.mark.parametrize("args, code, message", [
    (["--faults", "meteor"], 2, "--faults: unknown 'meteor'"),
    (["--experiments", "loop"], 2, "--experiments: unknown 'loop'"),
    (["--config-dir", "/nonexistent-dir"], 1, "not found"),
])
def test_faults_errors_are_one_line(args, code, message, tmp_path):
    result = runner.invoke(app, ["faults", "--log-dir", str(tmp_path), *args])
    assert result.exit_code == code
    assert message in result.output
    assert "Traceback" not in result.output
