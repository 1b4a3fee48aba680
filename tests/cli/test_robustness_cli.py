"""``ardrone-nmpc robustness``, ``tune --robust`` and ``identify`` through typer's CliRunner."""

from __future__ import annotations

import csv
from pathlib import Path

import pytest
from typer.testing import CliRunner

from ardrone_nmpc.cli.app import app

runner = CliRunner()
CONFIGS = Path(__file__).resolve().parents[2] / "configs"
SHORT = ["--set", "duration_s=8", "--set", "sim.settle_s=1",
         "--set", "reference.target_m=[-0.5, 0, 1]"]
GRID = """\
axes:
  sim.plant.command_delay_s: [0.0, 0.4]
  sim.plant.attitude_gain: [1.0, 2.0]
map: {x: sim.plant.command_delay_s, y: sim.plant.attitude_gain}
"""


def _grid(tmp_path: Path, text: str = GRID) -> Path:
    path = tmp_path / "grid.yaml"
    path.write_text(text, encoding="utf-8")
    return path


def _rows(path: Path) -> list[dict[str, str]]:
    with open(path, newline="", encoding="utf-8") as f:
        return list(csv.DictReader(f))


def test_robustness_flies_the_grid_judges_each_flight_and_draws_the_map(tmp_path):
    out = tmp_path / "rob"
    args = ["robustness", str(CONFIGS / "step_x.yaml"), "--grid-file", str(_grid(tmp_path)),
            "--jobs", "1", "-o", str(out), *SHORT]
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    assert result.output.strip().splitlines()[-1] == f"robustness: {out / 'robustness.csv'}"
    assert (out / "robustness.png").stat().st_size > 1000
    rows = _rows(out / "robustness.csv")
    assert len(rows) == 4
    assert list(rows[0])[:3] == ["case", "sim.plant.command_delay_s", "sim.plant.attitude_gain"]
    for row in rows:
        assert row["verdict"] in ("settled", "limit cycle", "supervisor", "diverged")
        assert row["clean"] in ("true", "false")
        assert 0.0 <= float(row["saturation_frac"]) <= 1.0
        assert (out / row["run_dir"] / "summary.csv").is_file()
    assert "flights clean over command_delay_s 0.0–0.4, attitude_gain 1.0–2.0" in result.output
    again = runner.invoke(app, args)  # resumes: judged again from the run directories
    assert again.exit_code == 0 and "(0 flown, 4 resumed)" in again.output
    assert _rows(out / "robustness.csv") == rows


@pytest.mark.parametrize("text, message", [
    ("axes: {a.b: []}\n", "axes.a.b: expected a non-empty list"),
    ("axes: {sim.plant.command_delay_s: [0.1]}\n", "at least two axes"),
    ("- 1\n", "expected a mapping"),
])
def test_a_bad_grid_file_is_one_line_and_nothing_flies(tmp_path, text, message):
    result = runner.invoke(app, ["robustness", str(CONFIGS / "hover.yaml"), "--grid-file",
                                 str(_grid(tmp_path, text)), "-o", str(tmp_path / "o")])
    assert result.exit_code == 1 and message in result.output
    assert not (tmp_path / "o" / "robustness.csv").exists()


def test_a_grid_value_the_config_refuses_fails_before_flying(tmp_path):
    grid = _grid(tmp_path, "axes:\n  sim.plant.command_delay_s: [0.1, -1]\n"
                           "  sim.plant.attitude_gain: [1.0]\n")
    result = runner.invoke(app, ["robustness", str(CONFIGS / "hover.yaml"), "--grid-file",
                                 str(grid), "-o", str(tmp_path / "o")])
    assert result.exit_code == 1 and "sim.plant.command_delay_s" in result.output


def test_tune_robust_scores_a_trial_by_its_worst_plant(tmp_path):
    out = tmp_path / "tune"
    result = runner.invoke(app, ["tune", str(CONFIGS / "step_x.yaml"), "--robust",
                                 "--grid-file", str(_grid(tmp_path)), "--trials", "1",
                                 "--jobs", "1", "-o", str(out), *SHORT])
    assert result.exit_code == 0, result.output
    (row,) = _rows(out / "trials.csv")
    labels = ["seed0+--", "seed0+-+", "seed0++-", "seed0+++", "seed0+centre"]
    scores = [float(row[f"{label}:score"]) for label in labels]
    assert float(row["score"]) == pytest.approx(max(scores))  # the worst, alone
    assert all(row[f"{label}:unclean"] in ("0.0", "1.0", "0", "1") for label in labels)


def test_tune_grid_file_needs_robust(tmp_path):
    result = runner.invoke(app, ["tune", str(CONFIGS / "step_x.yaml"), "--grid-file",
                                 str(_grid(tmp_path)), "-o", str(tmp_path / "t")])
    assert result.exit_code == 1 and "--grid-file: only with --robust" in result.output


def test_identify_prints_each_parameter_and_writes_a_profile(tmp_path):
    sim = runner.invoke(app, ["simulate", str(CONFIGS / "identify.yaml"), "--quiet",
                              "--log-dir", str(tmp_path), "--set", "duration_s=40",
                              "--set", "sim.plant.command_delay_s=0.15",
                              "--set", "sim.plant.attitude_gain=1.5"])
    assert sim.exit_code == 0, sim.output
    run = sim.output.strip().splitlines()[-1].removeprefix("run: ")
    profile = tmp_path / "drone.yaml"
    result = runner.invoke(app, ["identify", run, "-o", str(profile)])
    assert result.exit_code == 0, result.output
    lines = result.output.strip().splitlines()
    assert lines[-1] == f"profile: {profile}"
    delay = next(line for line in lines if line.startswith("command delay: "))
    value, _, std = delay.removeprefix("command delay: ").partition(" s ± ")
    assert abs(float(value) - 0.15) < 0.03 and float(std) > 0
    assert any(line.startswith("pitch gain: 1.") for line in lines)
    assert any(line.startswith("held-out fit, attitude: ") for line in lines)
    check = runner.invoke(app, ["check", str(CONFIGS / "step_x.yaml"),
                                "--set", f"sim.plant.profile={profile}"])
    assert check.exit_code == 0 and "command_delay_s: 0.1" in check.output


def test_identify_refuses_a_run_without_enough_flight(tmp_path):
    sim = runner.invoke(app, ["simulate", str(CONFIGS / "hover.yaml"), "--quiet",
                              "--log-dir", str(tmp_path), "--set", "duration_s=0.5",
                              "--set", "sim.settle_s=0"])
    run = sim.output.strip().splitlines()[-1].removeprefix("run: ")
    result = runner.invoke(app, ["identify", run, "-o", str(tmp_path / "p.yaml")])
    assert result.exit_code == 1
    assert result.output.startswith("error: ") and "too little flown" in result.output
    assert not (tmp_path / "p.yaml").exists()
