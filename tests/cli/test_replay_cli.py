"""``ardrone-nmpc replay`` through typer's CliRunner: tables, the rerun run directory, errors.

The run replayed is a short lockstep simulation (P controller: no solver start-up to wait
for); network only to 127.0.0.1.
"""

from __future__ import annotations

import json
import shutil
import socket
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from ardrone_nmpc.cli.app import app
from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.runs.rundir import LOG_FILE, RunRecorder, read_run
from ardrone_nmpc.experiments.replay import RERUN_COLUMNS, RERUN_FILE
from ardrone_nmpc.runtime.lockstep import run_lockstep

CONFIGS = Path(__file__).resolve().parents[2] / "configs"
runner = CliRunner()


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory) -> Path:
    cfg = load_config(CONFIGS / "step_x.yaml",
                      ["duration_s=3", "sim.settle_s=0.3", "controller.kind=p"])
    with RunRecorder.create(tmp_path_factory.mktemp("logs"), cfg, seed=3) as recorder:
        run_lockstep(cfg, recorder=recorder, seed=3)
    return recorder.path


@pytest.fixture(scope="module")
def old_run_dir(run_dir, tmp_path_factory) -> Path:
    """The same run as an older version wrote it: no raw measurement columns."""
    target = tmp_path_factory.mktemp("old") / run_dir.name
    shutil.copytree(run_dir, target)
    lines = [line.split(",") for line in (target / LOG_FILE).read_text().splitlines()]
    keep = [i for i, c in enumerate(lines[0]) if c not in RERUN_COLUMNS]
    (target / LOG_FILE).write_text(
        "".join(",".join(cells[i] for i in keep) + "\n" for cells in lines))
    return target


def assert_user_error(result, *fragments: str) -> None:
    assert result.exit_code == 1, result.output
    assert "Traceback" not in result.output
    errors = [line for line in result.output.splitlines() if line.startswith("error: ")]
    assert errors, result.output
    for fragment in fragments:
        assert any(fragment in line for line in errors), (fragment, result.output)


# ----------------------------------------------------------------------------- modes


def test_replay_re_summarises_without_touching_the_run(run_dir):
    before = {p.name: p.read_bytes() for p in run_dir.iterdir()}
    result = runner.invoke(app, ["replay", str(run_dir)])
    assert result.exit_code == 0, result.output
    assert "re-summarised" in result.output
    assert "settling_time" in result.output  # the step metrics of the summary table
    assert "--rerun possible" in result.output
    assert {p.name: p.read_bytes() for p in run_dir.iterdir()} == before


def test_rerun_reproduces_and_writes_a_linked_run_directory(run_dir, tmp_path):
    result = runner.invoke(app, ["replay", str(run_dir), "--rerun", "--log-dir", str(tmp_path)])
    assert result.exit_code == 0, result.output
    assert "reproduced" in result.output and "not reproduced" not in result.output
    last = result.output.strip().splitlines()[-1]
    assert last.startswith("run: ")
    new = Path(last[len("run: "):])
    assert new.parent == tmp_path and new.name.endswith("-rerun")
    for name in ("config.yaml", "log.csv", "events.jsonl", "summary.csv", RERUN_FILE):
        assert (new / name).is_file(), name
    events = [json.loads(line) for line in (new / "events.jsonl").read_text().splitlines()]
    assert events[0]["kind"] == "replay"
    assert Path(events[0]["source"]) == run_dir.resolve()
    diffs = np.genfromtxt(new / RERUN_FILE, delimiter=",", names=True, dtype=None,
                          encoding="utf-8")
    assert len(diffs) == read_run(run_dir).n_rows
    for name in diffs.dtype.names:
        if name.startswith("d_"):
            assert np.max(np.abs(diffs[name])) <= 1e-9, name


def test_rerun_with_set_is_the_counterfactual_and_records_the_config(run_dir, tmp_path):
    result = runner.invoke(app, ["replay", str(run_dir), "--rerun", "--log-dir", str(tmp_path),
                                 "--set", "controller.p_gains.k3_rad_per_mps=0.4"])
    assert result.exit_code == 0, result.output
    assert "counterfactual" in result.output
    assert "open-loop counterfactual" in result.output  # what the cost means
    new = Path(result.output.strip().splitlines()[-1][len("run: "):])
    assert read_run(new).config.controller.p_gains.k3_rad_per_mps == 0.4
    events = [json.loads(line) for line in (new / "events.jsonl").read_text().splitlines()]
    assert events[0]["overrides"] == ["controller.p_gains.k3_rad_per_mps=0.4"]


@pytest.mark.timeout(30)
def test_broadcast_sends_one_datagram_per_logged_pose(run_dir):
    run = read_run(run_dir)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.bind(("127.0.0.1", 0))
        sock.settimeout(5.0)
        result = runner.invoke(app, ["replay", str(run_dir), "--broadcast", "--speed", "50",
                                     "--port", str(sock.getsockname()[1])])
        assert result.exit_code == 0, result.output
        got = [sock.recv(2048) for _ in range(run.n_rows)]  # one new pose per tick here
    assert f"sent {run.n_rows} poses" in result.output
    assert all(len(d) == 256 for d in got)


# ----------------------------------------------------------------------------- errors


def test_not_a_run_directory(tmp_path):
    assert_user_error(runner.invoke(app, ["replay", str(tmp_path / "nope")]),
                      "no such run directory")
    (tmp_path / "empty").mkdir()
    assert_user_error(runner.invoke(app, ["replay", str(tmp_path / "empty"), "--rerun"]),
                      "config.yaml: no such file")


def test_old_log_re_summarises_but_refuses_rerun_naming_the_columns(old_run_dir, tmp_path):
    result = runner.invoke(app, ["replay", str(old_run_dir)])
    assert result.exit_code == 0, result.output
    assert "--rerun not possible" in result.output
    result = runner.invoke(app, ["replay", str(old_run_dir), "--rerun", "--log-dir",
                                 str(tmp_path)])
    assert_user_error(result, "mocap_t_s, nav_vx_body_mps, nav_vy_body_mps, nav_mode")
    assert not any(tmp_path.iterdir())  # no run directory made for nothing
    assert_user_error(runner.invoke(app, ["replay", str(old_run_dir), "--broadcast",
                                          "--port", "9"]), "mocap_t_s")


@pytest.mark.parametrize(("override", "fragment"), [
    ("controller.horizon_steps=0", "controller.horizon_steps:"),
    ("controller.bogus=1", "controller.bogus:"),
    ("nonsense", "expected dotted.path=value"),
])
def test_bad_set_is_a_field_error(run_dir, tmp_path, override, fragment):
    result = runner.invoke(app, ["replay", str(run_dir), "--rerun", "--log-dir", str(tmp_path),
                                 "--set", override])
    assert_user_error(result, fragment)
    assert not any(tmp_path.iterdir())


@pytest.mark.parametrize(("args", "fragment"), [
    (["--rerun", "--broadcast"], "choose one"),
    (["--set", "duration_s=2"], "--set applies to --rerun only"),
    (["--log-dir", "x"], "--log-dir applies to --rerun only"),
    (["--speed", "2"], "--speed applies to --broadcast only"),
    (["--port", "9"], "--port applies to --broadcast only"),
])
def test_option_combinations(run_dir, args, fragment):
    assert_user_error(runner.invoke(app, ["replay", str(run_dir), *args]), fragment)


@pytest.mark.parametrize("args", [["--speed", "0"], ["--speed", "1e-300"], ["--speed", "nan"],
                                  ["--speed", "inf"], ["--port", "0"], ["--port", "70000"],
                                  ["--host", ""]])
def test_broadcast_option_values_are_checked_before_anything_is_sent(run_dir, args):
    result = runner.invoke(app, ["replay", str(run_dir), "--broadcast", *args])
    assert result.exit_code == 2, result.output
    errors = [line for line in result.output.splitlines() if line.startswith("error: ")]
    assert len(errors) == 1 and errors[0].startswith(f"error: {args[0]}: "), result.output
    assert "broadcasting" not in result.output and "Traceback" not in result.output
