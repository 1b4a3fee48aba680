"""``export``'s MCAP file against what the ``mcap`` library reads in it: the limits of an MCAP
log time (nanoseconds since 1970 in an unsigned 64-bit field, docs/live-view.md) — a row or
event beyond them refused naming its line, a run starting before 1970 − 584 y refused naming
the run, the times just inside kept exactly —, where ``/config`` and the whole paths sit in
the file, the extra named when foxglove-sdk is missing, and ``read_mcap`` on files it did not
write (a recorder's: out of log-time order, a channel without a schema, two configs)."""

from __future__ import annotations

import json
import math
import sys

import pytest

from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.core.extras import MissingExtra
from ardrone_nmpc.experiments.export import ExportError, export_run, read_mcap, write_mcap
from ardrone_nmpc.runs.rundir import RunRecorder, read_run

from tests.unit.test_export_edges import _created_ns, _without_created

#: the largest MCAP log time, written out (the spec's uint64), not taken from the module
U64_MAX = 18_446_744_073_709_551_615


def _run(tmp_path, rows, events=(), name="limits"):
    """A run of ``rows`` (``t_s`` or a whole row dict) and ``events`` (``t_s``, kind)."""
    cfg = load_config(None, [f"name={name}"])
    with RunRecorder.create(tmp_path / "runs", cfg, seed=1) as rec:
        for t_s, kind in events:
            rec.event(t_s, kind)
        for row in rows:
            rec.write_row(row if isinstance(row, dict) else
                          {"t_s": row, "mode": "track", "solver_status": "ok"})
    return rec.path


def _beyond(where, t_s) -> str:
    return (f"{where}: t_s = {t_s!r} s is beyond what an MCAP log time holds (nanoseconds "
            "since 1970, up to the year 2554); export it as --format parquet")


def _file_messages(path):
    """``(topic, log ns)`` of every message, in file order, read by the mcap library."""
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        return [(channel.topic, message.log_time) for _, channel, message
                in make_reader(f).iter_messages(log_time_order=False)]


# ----------------------------------------------------------------------------- time limits


def test_a_row_beyond_the_last_log_time_is_refused_naming_its_line(tmp_path):
    run_dir = _run(tmp_path, [-0.13, -0.065, 1e11, 1e11 + 0.065])   # 1e11 s: 3170 years
    out = tmp_path / "run.mcap"
    with pytest.raises(ExportError) as err:
        write_mcap(read_run(run_dir), out)
    assert str(err.value) == _beyond(run_dir / "log.csv:4", 1e11)   # header, then rows 2…
    assert not out.exists()


def test_an_event_beyond_the_last_log_time_is_refused_naming_it(tmp_path):
    run_dir = _run(tmp_path, [-0.13, 0.0], events=[(-1.0, "takeoff"), (2e10, "late")])
    with pytest.raises(ExportError) as err:
        write_mcap(read_run(run_dir), tmp_path / "run.mcap")
    assert str(err.value) == _beyond(f"{run_dir / 'events.jsonl'}: event 2", 2e10)


def test_a_row_one_second_inside_the_last_log_time_keeps_its_exact_time(tmp_path):
    created = 1_767_225_600 * 10 ** 9                     # 2026-01-01T00:00:00Z
    t_s = (U64_MAX - created) / 1e9 - 1.0                 # 1 s before the year 2554 ends
    run_dir = _run(tmp_path, [0.0, t_s])
    _without_created(run_dir, "# created: 2026-01-01T00:00:00+00:00")
    assert _created_ns(run_dir) == created
    out = tmp_path / "run.mcap"
    write_mcap(read_run(run_dir), out)
    want = [created, created + round(t_s * 1e9)]
    assert want[1] <= U64_MAX and read_mcap(out).row_log_times_ns == want


def test_a_run_starting_before_1970_minus_584_years_is_refused_naming_the_run(tmp_path):
    run_dir = _run(tmp_path, [-1e11, 0.0])
    with pytest.raises(ExportError) as err:
        write_mcap(read_run(run_dir), tmp_path / "run.mcap")
    assert str(err.value) == _beyond(run_dir, -1e11)


def test_a_run_starting_just_after_1970_minus_584_years_is_exported(tmp_path):
    """−U64_MAX ns is −1.8446744073709552e10 s; a first row 9.2 s later is still inside (its
    own log time is the creation time, as every run's first row)."""
    t_s = -1.84467440645e10
    assert t_s * 1e9 > -U64_MAX and t_s * 1.000000001e9 < -U64_MAX
    run_dir = _run(tmp_path, [t_s])
    out = tmp_path / "run.mcap"
    write_mcap(read_run(run_dir), out)
    created = _created_ns(run_dir)
    assert read_mcap(out).row_log_times_ns == [created]
    assert set(_file_messages(out)) == {("/config", created), ("/log", created)}


# ----------------------------------------------------------------------------- file layout


def test_config_and_whole_paths_come_first_at_the_first_rows_time(tmp_path):
    """``/config`` and the two whole paths are at the first row's log time (not at t_s = 0),
    in that order, before the first row's own messages."""
    rows = [{"t_s": -0.13 + 0.065 * k, "x_m": 0.1 * k, "y_m": 0.0, "z_m": 1.0,
             "psi_rad": 0.0, "x_ref_m": 0.5, "y_ref_m": 0.0, "z_ref_m": 1.0,
             "psi_ref_rad": 0.0, "mode": "track", "solver_status": "ok"} for k in range(3)]
    run_dir = _run(tmp_path, rows)
    out = tmp_path / "run.mcap"
    write_mcap(read_run(run_dir), out)
    created = _created_ns(run_dir)
    messages = _file_messages(out)
    assert messages[:3] == [("/config", created), ("/flight_path", created),
                            ("/reference_path", created)]
    first_row = [topic for topic, t in messages[3:] if t == created]
    assert first_row[0] == "/log" and set(first_row) == {"/log", "/pose", "/reference", "/tf"}
    assert len(first_row) == 5                             # /tf twice: drone and reference
    assert [t for topic, t in messages if topic == "/log"] == [
        created + round(0.065e9 * k) for k in range(3)]


def test_without_rows_the_config_is_at_the_origin(tmp_path):
    run_dir = _run(tmp_path, [], events=[(math.nan, "preflight_failed")])
    out = tmp_path / "run.mcap"
    write_mcap(read_run(run_dir), out)
    created = _created_ns(run_dir)
    assert sorted(_file_messages(out)) == [("/config", created), ("/events", created)]


def test_an_event_without_a_number_for_its_time_goes_to_the_origin(tmp_path):
    """Another tool's ``"t_s": null`` (JSON has no NaN): the event sits at the origin, and
    the first row still falls on the creation time."""
    run_dir = _run(tmp_path, [-0.13, -0.065])
    with open(run_dir / "events.jsonl", "a") as f:
        f.write(json.dumps({"t_s": None, "kind": "note"}) + "\n")
    out = tmp_path / "run.mcap"
    write_mcap(read_run(run_dir), out)
    back = read_mcap(out)
    created = _created_ns(run_dir)
    assert back.row_log_times_ns == [created, created + 65_000_000]
    assert back.event_log_times_ns == [created + 130_000_000]       # t_s = 0
    assert back.events == [{"t_s": None, "kind": "note"}]


def test_writing_mcap_without_foxglove_names_the_extra(tmp_path, monkeypatch):
    run = read_run(_run(tmp_path, [0.0]))
    monkeypatch.setitem(sys.modules, "foxglove", None)
    with pytest.raises(MissingExtra) as err:
        write_mcap(run, tmp_path / "run.mcap")
    assert str(err.value) == ("export --format mcap needs the 'foxglove' library: "
                              "pip install 'ardrone-nmpc[mcap]'")


def test_export_run_given_the_run_does_not_read_the_directory_again(tmp_path):
    run_dir = _run(tmp_path, [-0.13, -0.065, 0.0])
    run = read_run(run_dir)
    (run_dir / "log.csv").unlink()                     # the run as read is what is exported
    out = tmp_path / "run.mcap"
    line = export_run(run_dir, "mcap", out, run=run)
    assert line.endswith("(3 rows, 0 events)") and len(read_mcap(out).rows) == 3


# ----------------------------------------------------------------------------- read_mcap


def test_read_mcap_keeps_file_order_schemaless_channels_and_counts_configs(tmp_path):
    """A file written by the mcap library itself, as a recorder might: ``/log`` on a channel
    without a schema, its rows out of log-time order, two ``/config`` messages."""
    from mcap.writer import Writer

    path = tmp_path / "recorded.mcap"
    with open(path, "wb") as f:
        w = Writer(f)
        w.start()
        log = w.register_channel("/log", "json", schema_id=0)
        config = w.register_channel("/config", "json", schema_id=0)
        for t_ns, x in [(3_000, 0.3), (1_000, 0.1), (2_000, 0.2)]:
            w.add_message(log, t_ns, json.dumps({"t_s": t_ns * 1e-9, "x_m": x}).encode(),
                          t_ns)
        for seed in (1, 2):
            w.add_message(config, 4_000, json.dumps({"seed": seed}).encode(), 4_000)
        w.finish()
    back = read_mcap(path)
    assert [r["x_m"] for r in back.rows] == [0.3, 0.1, 0.2]
    assert back.row_log_times_ns == [3_000, 1_000, 2_000]
    assert back.schemas == {"/log": "", "/config": ""}
    assert back.n_configs == 2 and back.config == {"seed": 2}
