"""``export``'s edges against the run directory it reads: the origin without (or with a broken)
creation time in ``config.yaml`` — the first row then at the epoch —, an event before the
first row setting the origin, a run whose flight never started, the Parquet metadata as the
run's own files, and ``export_run``'s refusals and one-line report."""

from __future__ import annotations

import datetime as dt
import json
import math
import re

import pytest

from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.experiments.export import (
    PARQUET_CONFIG_KEY,
    PARQUET_EVENTS_KEY,
    ExportError,
    export_run,
    read_mcap,
    write_mcap,
    write_parquet,
)
from ardrone_nmpc.runs.outputs import OutputError, check_output_file
from ardrone_nmpc.runs.rundir import RunRecorder, read_run

T0_S = -0.13


def _run(tmp_path, *, events=(), rows=4, name="edges"):
    cfg = load_config(None, [f"name={name}"])
    with RunRecorder.create(tmp_path / "runs", cfg, seed=1) as rec:
        for t_s, kind in events:
            rec.event(t_s, kind)
        for k in range(rows):
            rec.write_row({"t_s": T0_S + 0.065 * k, "x_m": 0.1 * k, "mode": "track",
                           "solver_status": "ok"})
    return rec.path


def _created_ns(run_dir) -> int:
    stamp = re.search(r"^# created: (\S+)$", (run_dir / "config.yaml").read_text(),
                      flags=re.M).group(1)
    return round(dt.datetime.fromisoformat(stamp).timestamp() * 1e9)


def _without_created(run_dir, replacement: str | None = None) -> None:
    path = run_dir / "config.yaml"
    lines = [ln for ln in path.read_text().splitlines(keepends=True)
             if not ln.startswith("# created:")]
    if replacement is not None:
        lines.insert(0, replacement + "\n")
    path.write_text("".join(lines))


def _row_times(run_dir, tmp_path):
    out = tmp_path / "run.mcap"
    write_mcap(read_run(run_dir), out)
    back = read_mcap(out)
    return back.row_log_times_ns, back.event_log_times_ns


def test_the_first_row_falls_on_the_creation_time(tmp_path):
    run_dir = _run(tmp_path)
    rows, _ = _row_times(run_dir, tmp_path)
    created = _created_ns(run_dir)
    assert rows == [created + round(0.065e9 * k) for k in range(4)]


@pytest.mark.parametrize("replacement", [None, "# created: yesterday", "# created:"])
def test_without_a_readable_creation_time_the_first_row_is_at_the_epoch(tmp_path, replacement):
    run_dir = _run(tmp_path)
    _without_created(run_dir, replacement)
    rows, _ = _row_times(run_dir, tmp_path)
    assert rows == [round(0.065e9 * k) for k in range(4)]


def test_an_event_before_the_first_row_sets_the_origin(tmp_path):
    """The first event (take-off at t = −2 s) comes before the first row (t = −0.13 s): it is
    the one on the creation time, and the rows follow 1.87 s later."""
    run_dir = _run(tmp_path, events=[(-2.0, "takeoff"), (0.0, "start")])
    rows, events = _row_times(run_dir, tmp_path)
    created = _created_ns(run_dir)
    assert events == [created, created + 2_000_000_000]
    assert rows[0] == created + round((2.0 + T0_S) * 1e9)


def test_rows_after_time_zero_do_not_move_the_origin(tmp_path):
    """A run whose first row is at t = 0.2 s (no settle phase logged): t = 0 stays on the
    creation time — the origin only moves back for a negative first time."""
    cfg = load_config(None, ["name=late"])
    with RunRecorder.create(tmp_path / "runs", cfg, seed=1) as rec:
        for k in range(3):
            rec.write_row({"t_s": 0.2 + 0.065 * k, "mode": "track", "solver_status": "ok"})
    rows, _ = _row_times(rec.path, tmp_path)
    created = _created_ns(rec.path)
    assert rows == [created + round((0.2 + 0.065 * k) * 1e9) for k in range(3)]


def test_an_event_without_experiment_time_goes_to_the_origin(tmp_path):
    """A flight that never started: its events have t_s NaN and sit at the origin."""
    run_dir = _run(tmp_path, events=[(math.nan, "preflight_failed")], rows=0)
    _, events = _row_times(run_dir, tmp_path)
    assert events == [_created_ns(run_dir)]


def test_parquet_metadata_is_the_runs_own_events_and_config(tmp_path):
    import pyarrow.parquet as pq

    run_dir = _run(tmp_path, events=[(-1.0, "takeoff"), (0.1, "note")])
    out = tmp_path / "run.parquet"
    write_parquet(read_run(run_dir), out)
    meta = pq.read_schema(out).metadata
    assert meta[PARQUET_CONFIG_KEY] == (run_dir / "config.yaml").read_bytes()
    with open(run_dir / "events.jsonl") as f:
        want = [json.loads(line)["kind"] for line in f if line.strip()]
    got = [json.loads(line)["kind"] for line in meta[PARQUET_EVENTS_KEY].splitlines()]
    assert got == want == ["takeoff", "note"]


def test_export_run_reports_what_it_wrote_in_one_line(tmp_path):
    run_dir = _run(tmp_path, events=[(-1.0, "takeoff")])
    out = tmp_path / "a.mcap"
    line = export_run(run_dir, "mcap", out)
    n = len(read_mcap(out).rows)
    assert n == 4
    assert re.fullmatch(rf"{re.escape(str(out))}: \d+ messages \(4 rows, 1 events\)", line)
    out = tmp_path / "a.parquet"
    assert export_run(run_dir, "parquet", out) == f"{out}: 4 rows, 1 events in the metadata"


def test_export_run_refuses_an_unknown_format_and_a_directory(tmp_path):
    run_dir = _run(tmp_path)
    with pytest.raises(ExportError, match=r"^--format: unknown format 'csv'; choose mcap, "
                                          r"parquet$"):
        export_run(run_dir, "csv", tmp_path / "a.csv")
    # a directory as the output is the caller's check (export_run's contract), one line
    with pytest.raises(OutputError, match=r"^-o .*: is a directory; give a file name$"):
        check_output_file(tmp_path, option="-o")
    assert not list(tmp_path.glob("*.mcap"))


def test_the_config_channel_names_the_seed_and_version_the_run_recorded(tmp_path):
    import yaml

    run_dir = _run(tmp_path)
    out = tmp_path / "run.mcap"
    write_mcap(read_run(run_dir), out)
    back = read_mcap(out)
    config = back.config
    assert back.n_configs == 1
    first, seed = (run_dir / "config.yaml").read_text().splitlines()[:2]
    assert config["seed"] == 1 and seed == "# seed: 1"
    assert first == f"# ardrone-nmpc {config['version']}"   # the header's version line
    assert config["config"]["name"] == yaml.safe_load((run_dir / "config.yaml").read_text())[
        "name"] == "edges"


@pytest.mark.parametrize("module, library", [("mcap.reader", "mcap"),
                                             ("mcap_protobuf.decoder", "mcap_protobuf")])
def test_reading_mcap_without_the_library_names_the_extra(tmp_path, monkeypatch, module,
                                                          library):
    import sys

    from ardrone_nmpc.core.extras import MissingExtra

    monkeypatch.setitem(sys.modules, module, None)
    with pytest.raises(MissingExtra) as err:
        read_mcap(tmp_path / "absent.mcap")
    assert str(err.value) == (f"reading MCAP needs the '{library}' library: "
                              "pip install 'ardrone-nmpc[mcap]'")


@pytest.mark.parametrize("module", ["pyarrow", "pyarrow.parquet"])
def test_writing_parquet_without_pyarrow_names_the_extra(tmp_path, monkeypatch, module):
    import sys

    from ardrone_nmpc.core.extras import MissingExtra

    run = read_run(_run(tmp_path))
    monkeypatch.setitem(sys.modules, module, None)
    with pytest.raises(MissingExtra) as err:
        write_parquet(run, tmp_path / "x.parquet")
    assert str(err.value) == ("export --format parquet needs the 'pyarrow' library: "
                              "pip install 'ardrone-nmpc[parquet]'")
