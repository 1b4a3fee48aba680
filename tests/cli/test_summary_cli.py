"""``summary`` of many runs: every run name whole, every metric a number, piped or not."""

from __future__ import annotations

import csv
import datetime as dt
import io
import math

import numpy as np
import pytest
from typer.testing import CliRunner

from ardrone_nmpc.cli.app import app
from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.runs.rundir import RunRecorder, read_run
from ardrone_nmpc.cli.tables import format_value
from ardrone_nmpc.runs.summary import summarise

runner = CliRunner()  # stdout is not a terminal: the piped layout


def make_runs(tmp_path, n: int, name: str = "hover-sweep-case") -> list:
    """``n`` short runs created in the same second (their names differ only at the end)."""
    cfg = load_config(overrides=[f"name={name}"])
    now = dt.datetime(2026, 12, 1, 16, 41, 0, tzinfo=dt.timezone.utc)
    paths = []
    for i in range(n):
        with RunRecorder.create(tmp_path, cfg, seed=i, now=now) as rec:
            for k in range(30):
                t = (k - 5) * 0.065
                rec.write_row({"t_s": t, "x_m": 0.01 * i * math.sin(k), "y_m": 0.0,
                               "z_m": 1.0 + 0.001 * i, "psi_rad": 0.0, "x_ref_m": 0.0,
                               "y_ref_m": 0.0, "z_ref_m": 1.0, "psi_ref_rad": 0.0,
                               "solve_us": 100.0 + i + k, "solver_status": "ok",
                               "mode": "track" if t >= 0 else "settle",
                               "mocap_age_ms": 2.0, "navdata_age_ms": 30.0 + i,
                               "battery_pct": 90.0, "tick_late_ms": 0.1 * i})
        paths.append(rec.path)
    return paths


def cells_of(line: str) -> list[str]:
    return [c.strip() for c in line.replace("┃", "│").split("│")[1:-1]]


def test_twelve_runs_piped_show_every_name_whole_and_every_metric_as_a_number(tmp_path):
    paths = make_runs(tmp_path, 12)
    result = runner.invoke(app, ["summary", *map(str, paths)])
    assert result.exit_code == 0, result.output
    assert "…" not in result.stdout  # nothing cut
    expected = {}
    for p in paths:
        for r in summarise(read_run(p)):
            expected[(p.name, r.axis, r.metric)] = format_value(r.value, r.unit)
    seen = {}
    axis = metric = None
    for line in result.stdout.splitlines():
        cells = cells_of(line)
        if len(cells) != 5 or cells[3] == "run":
            continue
        if cells[0]:
            axis, metric = cells[0], cells[1]
        seen[(cells[3], axis, metric)] = cells[4]
    assert seen == expected  # every (run, metric), with its value
    numbers = [v for v in seen.values() if v != "—"]
    assert len(numbers) > 12 * 20 and all(math.isfinite(float(v)) for v in numbers)


def test_runs_that_fit_sit_side_by_side_with_full_names(tmp_path):
    paths = make_runs(tmp_path, 2)
    result = runner.invoke(app, ["summary", *map(str, paths)])
    assert result.exit_code == 0, result.output
    header = next(line for line in result.stdout.splitlines() if "metric" in line)
    assert cells_of(header) == ["axis", "metric", "unit", *(p.name for p in paths)]
    assert "…" not in result.stdout


def test_the_layout_follows_the_width(tmp_path):
    from rich.console import Console

    from ardrone_nmpc.cli.summary import summary_command

    paths = make_runs(tmp_path, 4)
    for width, side_by_side in ((300, True), (150, False), (60, False)):
        console = Console(width=width, file=io.StringIO())
        summary_command(run_dirs=paths, console=console)
        text = console.file.getvalue()
        header = next(line for line in text.splitlines() if "metric" in line)
        assert (paths[0].name in header) == side_by_side, (width, header)
        assert all(len(line) <= width for line in text.splitlines())
        if width >= 150:  # narrower: a name wraps inside its cell, whole but on two lines
            assert all(p.name in text for p in paths)


def test_csv_holds_every_value_at_full_precision(tmp_path):
    paths = make_runs(tmp_path, 12)
    result = runner.invoke(app, ["summary", "--csv", *map(str, paths)])
    assert result.exit_code == 0, result.output
    rows = list(csv.DictReader(io.StringIO(result.stdout)))
    got = {(r["run"], r["axis"], r["metric"]): float(r["value"]) for r in rows}
    for p in paths:
        for r in summarise(read_run(p)):
            value = got.pop((p.name, r.axis, r.metric))
            assert value == r.value or (math.isnan(value) and math.isnan(r.value))
    assert got == {}


def test_warnings_about_a_run_go_to_stderr(tmp_path):
    (path,) = make_runs(tmp_path, 1)
    log = path / "log.csv"
    log.write_bytes(log.read_bytes()[:-9])  # killed mid-row
    result = runner.invoke(app, ["summary", str(path)])
    assert result.exit_code == 0, result.output
    assert "incomplete last line dropped" in result.stderr
    assert "warning" not in result.stdout


@pytest.mark.parametrize("n", [2, 12])
def test_same_named_runs_from_different_folders_are_told_apart(tmp_path, n):
    a = make_runs(tmp_path / "a", n)
    b = make_runs(tmp_path / "b", 1)
    result = runner.invoke(app, ["summary", "--csv", *map(str, a), str(b[0])])
    runs = {r["run"] for r in csv.DictReader(io.StringIO(result.stdout))}
    assert len(runs) == n + 1
    assert str(b[0]) in runs and np.all([str(p) in runs or p.name in runs for p in a])
