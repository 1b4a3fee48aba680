"""Hostile input at the command line: bad configs and corrupt run directories.

Every case must end with exit code 1, one ``error: …`` line per problem naming the field path
(or the file and line), and no traceback. ``simulate`` gets the same configs as ``check``: it
validates before it creates anything, so these runs are quick and leave no run directory.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from typer.testing import CliRunner

from ardrone_nmpc.cli.app import app
from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.runs.log_columns import LOG_COLUMNS, STRING_COLUMNS
from ardrone_nmpc.runs.rundir import RunRecorder

runner = CliRunner()

MONOTONIC_PATH = "t_s,x_m,y_m,z_m,psi_rad\n0,0,0,1,0\n2,1,0,1,0\n"
BACKWARDS_PATH = "t_s,x_m,y_m,z_m,psi_rad\n0,0,0,1,0\n2,1,0,1,0\n1,1,1,1,0\n"


def error_lines(output: str) -> list[str]:
    return [line for line in output.splitlines() if line.startswith("error: ")]


def assert_user_error(result, *patterns: str) -> None:
    """Exit 1, exactly one ``error:`` line per pattern (in order), no traceback."""
    assert result.exit_code == 1, result.output
    assert "Traceback" not in result.output
    assert result.exception is None or isinstance(result.exception, SystemExit), \
        repr(result.exception)
    lines = error_lines(result.output)
    assert len(lines) == len(patterns), result.output
    for line, pattern in zip(lines, patterns):
        assert re.search(pattern, line), (pattern, line)


def run(command: str, config: Path, *extra: str, log_dir: Path | None = None):
    args = [command, str(config), *extra]
    if command == "simulate":
        args += ["--quiet", "--log-dir", str(log_dir or config.parent / "logs")]
    return runner.invoke(app, args)


CASES = [
    pytest.param("controller:\n  horizon_steps: abc\n", [],
                 [r"^error: controller\.horizon_steps: .*valid integer"], id="wrong-type-str"),
    pytest.param("controller:\n  horizon_steps: true\n", [],
                 [r"^error: controller\.horizon_steps: expected an integer, got the boolean"],
                 id="wrong-type-bool"),
    pytest.param("controller: [1, 2]\n", [],
                 [r"^error: controller: Input should be a valid dictionary"],
                 id="wrong-type-section"),
    pytest.param("bogus: 1\ncontroller:\n  kmax: 3\n", [],
                 [r"^error: controller\.kmax: Extra inputs", r"^error: bogus: Extra inputs"],
                 id="unknown-keys"),
    pytest.param("{}\n", ["--set", "controller.q=[nan,1,1,1,1,1,1]"],
                 [r"^error: controller\.q\.0: Input should be a finite number"],
                 id="nan-weight-set"),
    pytest.param("controller:\n  r: [1, 1, .nan, 1]\n", [],
                 [r"^error: controller\.r\.2: Input should be a finite number"],
                 id="nan-weight-yaml"),
    pytest.param("controller:\n  dtau_s: -0.1\n", [],
                 [r"^error: controller\.dtau_s: Input should be greater than 0"],
                 id="negative-dtau"),
    pytest.param("{}\n", ["--set", "controller.horizon_steps=0"],
                 [r"^error: controller\.horizon_steps: .*greater than or equal to 1"],
                 id="N-zero"),
    pytest.param("reference:\n  kind: path\n  path_file: backwards.csv\n", [],
                 [r"^error: reference\.path_file: .*backwards\.csv:4: time 1\.0 is not after "
                  r"the previous 2\.0$"], id="path-non-monotonic"),
    pytest.param("reference:\n  kind: path\n  path_file: nowhere.csv\n", [],
                 [r"^error: reference\.path_file: no such file: .*nowhere\.csv$"],
                 id="path-missing"),
    pytest.param("", [], [r"^error: .*x\.yaml: empty file \(no settings\)"], id="empty-yaml"),
    pytest.param("- controller\n- loop\n", [],
                 [r"^error: .*x\.yaml: the top level must be a mapping .* not a list$"],
                 id="yaml-list"),
    pytest.param("controller:\n  q: [1, 2\n", [],
                 [r"^error: .*x\.yaml: invalid YAML \(line \d\): "], id="invalid-yaml"),
    pytest.param("controller:\n\thorizon_steps: 5\n", [],
                 [r"^error: .*x\.yaml: invalid YAML \(line 2\): found character '\\t'"],
                 id="tab-yaml"),
    pytest.param("{}\n", ["--set", "controller.horizon_steps"],
                 [r"^error: override 'controller\.horizon_steps': expected dotted\.path=value"],
                 id="override-without-value"),
    pytest.param("{}\n", ["--set", "controller.solver.kmax=100000000000000000000"],
                 [r"^error: controller\.solver\.kmax: .*less than or equal to 1000"],
                 id="huge-kmax"),
    pytest.param("{}\n", ["--set", "sim.plant.command_delay_s=1.0e+300"],
                 [r"^error: sim\.plant\.command_delay_s: .*less than or equal to 2"],
                 id="huge-delay"),
]


@pytest.mark.parametrize("command", ["check", "simulate"])
@pytest.mark.parametrize("text, extra, patterns", CASES)
def test_bad_config_is_one_error_line_per_problem(tmp_path, command, text, extra, patterns):
    (tmp_path / "backwards.csv").write_text(BACKWARDS_PATH)
    config = tmp_path / "x.yaml"
    config.write_text(text)
    assert_user_error(run(command, config, *extra, log_dir=tmp_path / "logs"), *patterns)
    assert not (tmp_path / "logs").exists()       # simulate validated before creating a run


@pytest.mark.parametrize("command", ["check", "simulate"])
def test_missing_config_file(tmp_path, command):
    assert_user_error(run(command, tmp_path / "nope.yaml"), r"^error: .*nope\.yaml: no such file$")


@pytest.mark.parametrize("command", ["check", "simulate"])
def test_binary_config_file(tmp_path, command):
    config = tmp_path / "x.yaml"
    config.write_bytes(b"\x89PNG\r\n\x1a\n\x00\xff")
    assert_user_error(run(command, config), r"^error: .*x\.yaml: cannot read: .*utf-8")


def test_check_accepts_a_monotonic_path_file(tmp_path):
    (tmp_path / "ok.csv").write_text(MONOTONIC_PATH)
    config = tmp_path / "x.yaml"
    config.write_text("reference:\n  kind: path\n  path_file: ok.csv\n")
    result = run("check", config)
    assert result.exit_code == 0, result.output
    assert str((tmp_path / "ok.csv").resolve()) in result.output


# ----------------------------------------------------------------------------- summary

NUMERIC = [c for c in LOG_COLUMNS if c not in STRING_COLUMNS]


@pytest.fixture
def run_dir(tmp_path) -> Path:
    """A finished run of 20 rows (log.csv lines 2–21)."""
    cfg = load_config(overrides=["name=hostile", "reference.kind=step",
                                 "reference.target_m=[-1.5, 0, 1]"])
    with RunRecorder.create(tmp_path / "logs", cfg, seed=0) as rec:
        for k in range(20):
            row = {c: 0.0 for c in NUMERIC}
            row.update(t_s=0.065 * k, x_m=-0.05 * k, z_m=1.0, z_ref_m=1.0, x_ref_m=-1.5,
                       cmd_saturated="0000", solver_status="ok", mode="track",
                       nav_mode="flying", solve_us=120.0)
            rec.write_row(row)
    return rec.path


def corrupt(run_dir: Path, edit) -> None:
    log = run_dir / "log.csv"
    log.write_bytes(edit(log.read_bytes()))


def _cut_line(data: bytes, index: int, keep: int) -> bytes:
    lines = data.split(b"\n")
    lines[index] = lines[index][:keep]
    return b"\n".join(lines)


@pytest.mark.parametrize("edit, pattern", [
    pytest.param(lambda d: _cut_line(d, 10, 30),
                 r"log\.csv:11: expected \d+ cells, got \d+ \(a torn or corrupted row\)$",
                 id="torn-middle"),
    pytest.param(lambda d: d.replace(b"\n0.13,", b"\nzero,", 1),
                 r"log\.csv:4: column t_s: 'zero' is not a number$", id="non-numeric"),
    pytest.param(lambda d: d.replace(b",psi_rad,", b",heading,", 1),
                 r"log\.csv:1: missing column psi_rad$", id="missing-column"),
    pytest.param(lambda d: b"", r"log\.csv:1: empty file: expected a header row$", id="empty"),
    pytest.param(lambda d: bytes(range(256)) * 8, r"log\.csv:2: not UTF-8 text$", id="binary"),
    pytest.param(lambda d: d.replace(b"\n0.13,", b"\n0.13\xff,", 1),
                 r"log\.csv:4: not UTF-8 text$", id="non-utf8"),
])
def test_summary_of_a_corrupt_log_names_the_file_and_line(run_dir, edit, pattern):
    corrupt(run_dir, edit)
    result = runner.invoke(app, ["summary", str(run_dir)])
    assert_user_error(result, r"^error: .*/" + re.escape(run_dir.name) + "/" + pattern)


def test_summary_of_a_missing_log(run_dir):
    (run_dir / "log.csv").unlink()
    assert_user_error(runner.invoke(app, ["summary", str(run_dir)]),
                      r"^error: .*log\.csv: no such file$")


def test_summary_drops_a_torn_last_row_with_a_warning(run_dir):
    corrupt(run_dir, lambda d: d[:-9])                # killed mid-row
    result = runner.invoke(app, ["summary", str(run_dir)])
    assert result.exit_code == 0, result.output
    assert re.search(r"warning: .*log\.csv:21: incomplete last line dropped", result.output)
    assert "Traceback" not in result.output


def test_summary_names_the_bad_run_among_good_ones(run_dir, tmp_path):
    bad = run_dir.parent / "broken"
    bad.mkdir()
    (bad / "config.yaml").write_text((run_dir / "config.yaml").read_text())
    (bad / "log.csv").write_bytes(b"\x00" * 64 + b"\n")
    (bad / "events.jsonl").write_text("")
    result = runner.invoke(app, ["summary", str(run_dir), str(bad)])
    assert_user_error(result, r"^error: .*broken/log\.csv:1: missing columns ")
