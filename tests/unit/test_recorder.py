"""Tests of the run directory writer and reader (ardrone_nmpc.runs.rundir)."""

from __future__ import annotations

import datetime as dt
import enum
import json
import math
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from ardrone_nmpc import __version__
from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.runs.log_columns import LOG_COLUMNS, REQUIRED_COLUMNS, STRING_COLUMNS
from ardrone_nmpc.runs.rundir import LogError, RunRecorder, _fast_line, format_number, read_run

NUMERIC_COLUMNS = [c for c in LOG_COLUMNS if c not in STRING_COLUMNS]
NOW = dt.datetime(2024, 5, 1, 12, 34, 56, tzinfo=dt.timezone.utc)


@pytest.fixture
def cfg():
    return load_config(overrides=["name=step_x", "duration_s=12", "reference.kind=step",
                                  "reference.target_m=[-1.5, 0, 1]"])


def full_row(k: int) -> dict:
    """A row with every column set; values depend on k."""
    row = {c: (k + i / 7.0) * (-1) ** i for i, c in enumerate(NUMERIC_COLUMNS)}
    row.update(cmd_saturated="0100", solver_status="ok", mode="track", nav_mode="flying",
               gmres_iterations=k)
    return row


def bits(a) -> np.ndarray:
    return np.asarray(a, dtype=np.float64).view(np.int64)


def assert_same_floats(got, expected) -> None:
    """Bit-equal, except that any NaN matches any NaN."""
    got = np.asarray(got, dtype=np.float64)
    expected = np.asarray(expected, dtype=np.float64)
    nan = np.isnan(expected)
    assert np.array_equal(np.isnan(got), nan)
    assert np.array_equal(bits(got)[~nan], bits(expected)[~nan])


def write_run(tmp_path, cfg, rows, events=()):
    with RunRecorder.create(tmp_path, cfg, seed=3, now=NOW) as rec:
        for row in rows:
            rec.write_row(row)
        for t, kind, fields in events:
            rec.event(t, kind, **fields)
    return rec.path


def rewrite_lines(path: Path, edit) -> None:
    lines = path.read_text(encoding="utf-8").split("\n")
    path.write_text("\n".join(edit(lines)), encoding="utf-8")


# ----------------------------------------------------------------------------- creation


def test_create_writes_config_before_any_row(tmp_path, cfg):
    rec = RunRecorder.create(tmp_path / "logs" / "nested", cfg, seed=42, now=NOW)
    try:
        assert rec.path == tmp_path / "logs" / "nested" / "20240501-123456-step_x"
        text = (rec.path / "config.yaml").read_text(encoding="utf-8")
        assert text.splitlines()[:3] == [f"# ardrone-nmpc {__version__}", "# seed: 42",
                                         "# created: 2024-05-01T12:34:56+00:00"]
        assert load_config(rec.path / "config.yaml") == cfg
        assert (rec.path / "log.csv").read_text() == ",".join(LOG_COLUMNS) + "\n"
        assert (rec.path / "events.jsonl").read_text() == ""
    finally:
        rec.close()
    run = read_run(rec.path)
    assert run.config == cfg and run.seed == 42 and run.version == __version__
    assert run.n_rows == 0 and run.events == [] and run.warnings == []
    assert set(LOG_COLUMNS) <= set(run.columns)


def test_name_collision_appends_a_suffix(tmp_path, cfg):
    paths = []
    for _ in range(3):
        with RunRecorder.create(tmp_path, cfg, seed=None, now=NOW) as rec:
            paths.append(rec.path.name)
    assert paths == ["20240501-123456-step_x", "20240501-123456-step_x-2",
                     "20240501-123456-step_x-3"]
    assert read_run(tmp_path / paths[2]).seed is None


def test_default_time_is_now(tmp_path, cfg):
    before = dt.datetime.now()
    with RunRecorder.create(tmp_path, cfg, seed=0) as rec:
        pass
    stamp = dt.datetime.strptime(rec.path.name[:15], "%Y%m%d-%H%M%S")
    assert before.replace(microsecond=0) - dt.timedelta(seconds=1) <= stamp
    assert stamp <= dt.datetime.now()


def test_a_named_run_directory_is_made_as_named_or_refused(tmp_path, cfg):
    # a sweep's staging directory: made under the parents, never suffixed
    with RunRecorder.create(tmp_path / "stage", cfg, seed=5, now=NOW, name="case-1") as rec:
        rec.write_row(full_row(0))
    assert rec.path == tmp_path / "stage" / "case-1"
    assert read_run(rec.path).seed == 5 and read_run(rec.path).n_rows == 1
    with pytest.raises(FileExistsError):
        RunRecorder.create(tmp_path / "stage", cfg, seed=5, now=NOW, name="case-1")
    assert [p.name for p in (tmp_path / "stage").iterdir()] == ["case-1"]


def test_context_manager_closes_the_files(tmp_path, cfg):
    with RunRecorder.create(tmp_path, cfg, seed=0, now=NOW) as rec:
        rec.write_row(full_row(0))
        assert not rec.closed
    assert rec.closed
    with pytest.raises(ValueError):
        rec.write_row(full_row(1))
    rec.close()  # idempotent


# ----------------------------------------------------------------------------- rows


def test_rows_round_trip(tmp_path, cfg):
    rows = [full_row(k) for k in range(5)]
    rows[2]["mocap_age_ms"] = math.inf
    rows[3]["navdata_age_ms"] = -math.inf
    rows[4]["u_zacc_mps2"] = math.nan
    rows[1]["x_m"] = np.float64(0.1)   # numpy scalars, as the loop writes them
    rows[1]["y_m"] = np.float32(0.1)
    rows[0]["solve_us"] = True
    path = write_run(tmp_path, cfg, rows)
    run = read_run(path)
    assert run.n_rows == 5 and len(run) == 5
    for c in NUMERIC_COLUMNS:
        assert run.columns[c].dtype == np.float64
        assert_same_floats(run.columns[c], [float(r[c]) for r in rows])
    assert run.columns["y_m"][1] == np.float32(0.1)  # float32 is written exactly too
    for c in STRING_COLUMNS:
        assert run.columns[c].dtype == object
        assert list(run.columns[c]) == [r[c] for r in rows]


def test_missing_values_are_empty_cells_and_none_is_nan(tmp_path, cfg):
    row = full_row(1)
    for c in ("x_true_m", "y_true_m", "z_true_m", "psi_true_rad", "vz_true_mps", "mode"):
        del row[c]
    row["solve_us"] = None
    row["battery_pct"] = ""
    path = write_run(tmp_path, cfg, [row, {"t_s": 2.0}])
    line = (path / "log.csv").read_text().splitlines()[1]
    assert line.endswith(",,,,,")
    assert line.split(",")[LOG_COLUMNS.index("solve_us")] == "nan"
    assert line.split(",")[LOG_COLUMNS.index("battery_pct")] == ""
    assert line.split(",")[LOG_COLUMNS.index("mode")] == ""
    run = read_run(path)
    assert np.isnan(run.columns["x_true_m"]).all()
    assert np.isnan(run.columns["solve_us"]).all()
    assert np.isnan(run.columns["battery_pct"]).all()
    assert list(run.columns["mode"]) == ["", ""]
    assert run.columns["t_s"].tolist() == [1.0, 2.0]
    assert np.isnan(run.columns["x_m"][1])


special_floats = st.sampled_from([0.0, -0.0, 5e-324, -5e-324, 2.2250738585072014e-308,
                                  1.7976931348623157e308, -1.7976931348623157e308, 1e16,
                                  0.1, 1 / 3, math.inf, -math.inf, math.nan])
any_float = st.one_of(special_floats, st.floats(allow_nan=True, allow_infinity=True))


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                         HealthCheck.function_scoped_fixture])
@given(st.lists(st.lists(any_float, min_size=len(NUMERIC_COLUMNS),
                         max_size=len(NUMERIC_COLUMNS)), min_size=1, max_size=4))
def test_floats_round_trip_bit_exact(cfg, values):
    with tempfile.TemporaryDirectory() as d:
        rows = [dict(zip(NUMERIC_COLUMNS, v)) for v in values]
        run = read_run(write_run(Path(d), cfg, rows))
        for j, c in enumerate(NUMERIC_COLUMNS):
            assert_same_floats(run.columns[c], [v[j] for v in values])


def test_every_finite_double_pattern_round_trips(tmp_path, cfg):
    rng = np.random.default_rng(7)
    raw = rng.integers(np.iinfo(np.int64).min, np.iinfo(np.int64).max, 400 * len(NUMERIC_COLUMNS),
                       dtype=np.int64, endpoint=True)
    values = raw.view(np.float64).reshape(400, len(NUMERIC_COLUMNS))
    rows = [dict(zip(NUMERIC_COLUMNS, map(float, v))) for v in values]
    run = read_run(write_run(tmp_path, cfg, rows))
    for j, c in enumerate(NUMERIC_COLUMNS):
        assert_same_floats(run.columns[c], values[:, j])


def repr_text(v: float) -> str:
    """The documented cell text: repr without a trailing '.0'."""
    r = repr(float(v))
    return r[:-2] if r.endswith(".0") else r


def test_number_text_is_shortest_repr():
    specials = [0.0, -0.0, 1.0, -5.0, 100.0, 1e15, 1e16, 1e-4, 1e-5, 0.1, 1 / 3, 5e-324,
                -2.2250738585072014e-308, 1.7976931348623157e308, 123456789.123, 2.5e-7,
                math.nan, math.inf, -math.inf]
    expected = ["0", "-0", "1", "-5", "100", "1000000000000000", "1e+16", "0.0001", "1e-05",
                "0.1", "0.3333333333333333", "5e-324", "-2.2250738585072014e-308",
                "1.7976931348623157e+308", "123456789.123", "2.5e-07", "nan", "inf", "-inf"]
    assert [format_number(v) for v in specials] == expected
    assert format_number(np.float32(0.1)) == "0.10000000149011612"
    assert format_number(7) == "7" and format_number(True) == "1"
    with pytest.raises(TypeError):
        format_number("1.5")


def test_fast_row_text_reads_back_bit_exact_on_random_doubles():
    """The orjson row printer: random bit patterns (all exponents, subnormals), powers of two
    and ten and their neighbours, decimals — every cell reads back to the same double."""
    rng = np.random.default_rng(11)
    raw = rng.integers(np.iinfo(np.int64).min, np.iinfo(np.int64).max, 200_000,
                       dtype=np.int64, endpoint=True).view(np.float64)
    raw = raw[np.isfinite(raw)]  # NaN/inf: printed as text (tested below)
    powers = [s * 10.0**e for e in range(-323, 309) for s in (1, -1, 3, 7)]
    twos = [2.0**e for e in range(-1074, 1024)]
    near = [np.nextafter(v, d) for v in twos + powers[::4] for d in (0.0, math.inf)]
    subnormal = np.arange(1, 5000, dtype=np.int64).view(np.float64)
    for values in (raw, powers, twos, near, subnormal, np.arange(-3000.0, 3000.0), [-0.0]):
        values = np.asarray(values, dtype=np.float64)
        values = values[np.isfinite(values)]  # 7e308 overflows to inf (tested below)
        for chunk in np.array_split(values, max(1, values.size // 38)):
            line = _fast_line(list(chunk), 0)
            assert line is not None and line.endswith(b"\n")
            back = np.array([float(c) for c in line[:-1].split(b",")])
            assert np.array_equal(back.view(np.int64), chunk.view(np.int64))


def test_fast_row_prints_non_finite_cells_as_the_careful_path():
    """orjson writes NaN, ±inf and None as ``null``: the fast row prints them as
    ``format_number`` does (None is NaN), numpy scalars too, and still refuses a string in a
    numeric cell beside them."""
    assert _fast_line([1.0, math.nan], 0) == b"1.0,nan\n"
    assert _fast_line([math.inf, 2.0, -math.inf], 0) == b"inf,2.0,-inf\n"
    assert _fast_line([None, np.float32("nan"), np.float64("-inf"), "", 0.5], 2) == (
        b"nan,nan,-inf,,0.5\n")
    assert _fast_line([math.nan, "abc"], 0) is None
    for cells in ([math.nan, 1e-05, -0.0], [None, 3.0], [np.float64(math.inf)]):
        line = _fast_line(list(cells), 0)
        back = [float(c) for c in line[:-1].split(b",")]
        assert np.array_equal(np.array(back, dtype=np.float64),
                              np.array([math.nan if c is None else c for c in cells],
                                       dtype=np.float64), equal_nan=True)


def test_fast_row_defers_bools_and_containers_to_the_careful_path():
    assert _fast_line([True, 2.0], 0) is None
    assert _fast_line([[1.0], 2.0], 0) is None
    assert _fast_line(["abc", 2.0], 0) is None  # a string where a number belongs
    assert _fast_line([1.5, "", "ok"], 4) == b"1.5,,ok\n"


def test_str_enum_writes_its_value(tmp_path, cfg):
    class Status(str, enum.Enum):
        OK = "ok"

    run = read_run(write_run(tmp_path, cfg, [{**full_row(0), "solver_status": Status.OK}]))
    assert run.columns["solver_status"].tolist() == ["ok"]


def test_unknown_column_is_rejected(tmp_path, cfg):
    with RunRecorder.create(tmp_path, cfg, seed=0, now=NOW) as rec:
        with pytest.raises(ValueError, match="'bogus_col'"):
            rec.write_row({"t_s": 0.0, "bogus_col": 1.0})
        with pytest.raises(ValueError, match="'bogus_col'"):  # not cached after the first
            rec.write_row({"t_s": 0.0, "bogus_col": 1.0})
    assert read_run(rec.path).n_rows == 0


@pytest.mark.parametrize(("row", "match"), [
    ({"z_m": "abc"}, r"column z_m: 'abc' is not a number"),
    ({"mode": 1.5}, r"column mode: 1\.5 is not a string"),
    ({"mode": "a,b"}, r"column mode: 'a,b' contains"),
    ({"solver_status": 'x"y'}, r"column solver_status: .* contains"),
    ({"mode": "two\nlines"}, r"column mode: .* contains"),
    ({"x_m": [1.0]}, r"column x_m: \[1\.0\] is not a number"),
])
def test_bad_values_are_rejected_and_nothing_written(tmp_path, cfg, row, match):
    with RunRecorder.create(tmp_path, cfg, seed=0, now=NOW) as rec:
        rec.write_row(full_row(0))
        with pytest.raises(ValueError, match=match):
            rec.write_row({**full_row(1), **row})
        rec.write_row(full_row(2))
    run = read_run(rec.path)
    assert run.columns["gmres_iterations"].tolist() == [0, 2]


def test_events_round_trip(tmp_path, cfg):
    events = [
        (-0.5, "mode", {"old": "settle", "new": "track"}),
        (1.25, "warning", {"message": "mocap stale", "age_ms": np.float64(120.5),
                           "counts": np.arange(3), "flag": np.bool_(True)}),
        (2.0, "fault", {}),
    ]
    run = read_run(write_run(tmp_path, cfg, [full_row(0)], events))
    assert run.events == [
        {"t_s": -0.5, "kind": "mode", "old": "settle", "new": "track"},
        {"t_s": 1.25, "kind": "warning", "message": "mocap stale", "age_ms": 120.5,
         "counts": [0, 1, 2], "flag": True},
        {"t_s": 2.0, "kind": "fault"},
    ]
    lines = (run.path / "events.jsonl").read_text().splitlines()
    assert [json.loads(x)["kind"] for x in lines] == ["mode", "warning", "fault"]


# ----------------------------------------------------------------------------- damage


def test_torn_last_line_is_dropped_with_a_warning(tmp_path, cfg):
    path = write_run(tmp_path, cfg, [full_row(k) for k in range(3)])
    with open(path / "log.csv", "a", encoding="utf-8") as f:
        f.write("3.5,1.25,-0.7")  # a crash in the middle of a row: no newline
    run = read_run(path)
    assert run.n_rows == 3
    assert len(run.warnings) == 1
    assert re.search(r"log\.csv:5: incomplete last line dropped", run.warnings[0])


def test_torn_last_event_is_dropped_with_a_warning(tmp_path, cfg):
    path = write_run(tmp_path, cfg, [], [(0.0, "mode", {"new": "track"})])
    with open(path / "events.jsonl", "a", encoding="utf-8") as f:
        f.write('{"t_s": 1.0, "ki')
    run = read_run(path)
    assert run.events == [{"t_s": 0.0, "kind": "mode", "new": "track"}]
    assert any("events.jsonl:2" in w for w in run.warnings)


def test_torn_middle_line_is_an_error(tmp_path, cfg):
    path = write_run(tmp_path, cfg, [full_row(k) for k in range(4)])
    rewrite_lines(path / "log.csv", lambda lines: lines[:3] + [lines[3][:40]] + lines[4:])
    with pytest.raises(LogError, match=rf"log\.csv:4: expected {len(LOG_COLUMNS)} cells, got \d+"):
        read_run(path)


def test_non_numeric_cell_names_file_line_and_column(tmp_path, cfg):
    path = write_run(tmp_path, cfg, [full_row(k) for k in range(60)])
    z = LOG_COLUMNS.index("z_m")

    def corrupt(lines):
        cells = lines[56].split(",")  # line 57 of the file
        cells[z] = "abc"
        lines[56] = ",".join(cells)
        return lines

    rewrite_lines(path / "log.csv", corrupt)
    with pytest.raises(LogError) as info:
        read_run(path)
    assert str(info.value) == f"{path / 'log.csv'}:57: column z_m: 'abc' is not a number"


def test_missing_required_column_is_an_error(tmp_path, cfg):
    path = write_run(tmp_path, cfg, [full_row(0)])
    z = LOG_COLUMNS.index("z_m")
    rewrite_lines(path / "log.csv",
                  lambda lines: [",".join(c for i, c in enumerate(line.split(",")) if i != z)
                                 if line else line for line in lines])
    with pytest.raises(LogError, match=r"log\.csv:1: missing column z_m"):
        read_run(path)


def test_optional_columns_may_be_absent_and_extra_ones_are_kept(tmp_path, cfg):
    """An older/other writer: only the docs/design.md §5 columns plus an extra one."""
    (tmp_path / "run").mkdir()
    run_dir = tmp_path / "run"
    with RunRecorder.create(tmp_path / "tmp", cfg, seed=0, now=NOW) as rec:
        pass
    (run_dir / "config.yaml").write_bytes((rec.path / "config.yaml").read_bytes())
    (run_dir / "events.jsonl").write_text("")
    header = list(REQUIRED_COLUMNS) + ["extra_note", "extra_value"]
    cells = ["1.5" if c not in STRING_COLUMNS else "ok" for c in REQUIRED_COLUMNS]
    (run_dir / "log.csv").write_text(",".join(header) + "\n" + ",".join(cells + ["hi", "2"])
                                     + "\n")
    run = read_run(run_dir)
    assert run.columns["x_m"].tolist() == [1.5]
    assert np.isnan(run.columns["tick_late_ms"]).all()
    assert run.columns["cmd_saturated"].tolist() == [""]
    assert run.columns["extra_note"].tolist() == ["hi"]
    assert run.columns["extra_value"].tolist() == [2.0]


def test_duplicate_column_is_an_error(tmp_path, cfg):
    path = write_run(tmp_path, cfg, [])
    rewrite_lines(path / "log.csv", lambda lines: [lines[0] + ",x_m"] + lines[1:])
    with pytest.raises(LogError, match=r"log\.csv:1: column 'x_m' appears more than once"):
        read_run(path)


def test_missing_directory_and_files(tmp_path, cfg):
    with pytest.raises(LogError, match="no such run directory"):
        read_run(tmp_path / "nope")
    for name in ("log.csv", "events.jsonl", "config.yaml"):
        path = write_run(tmp_path / name, cfg, [full_row(0)])
        (path / name).unlink()
        with pytest.raises(LogError, match=re.escape(str(path / name)) + ": no such file"):
            read_run(path)


def test_empty_log_is_an_error(tmp_path, cfg):
    path = write_run(tmp_path, cfg, [])
    (path / "log.csv").write_text("")
    with pytest.raises(LogError, match=r"log\.csv:1: empty file"):
        read_run(path)


def test_invalid_config_is_a_log_error_naming_the_file(tmp_path, cfg):
    path = write_run(tmp_path, cfg, [full_row(0)])
    with open(path / "config.yaml", "a", encoding="utf-8") as f:
        f.write("bogus_section: 1\n")
    with pytest.raises(LogError, match=r"config\.yaml.*bogus_section"):
        read_run(path)


def test_invalid_event_line_is_an_error(tmp_path, cfg):
    path = write_run(tmp_path, cfg, [], [(0.0, "a", {}), (1.0, "b", {})])
    rewrite_lines(path / "events.jsonl", lambda lines: [lines[0], "[1, 2]"] + lines[2:])
    with pytest.raises(LogError, match=r"events\.jsonl:2: expected a JSON object"):
        read_run(path)


# ----------------------------------------------------------------------------- summary file


def test_write_summary(tmp_path, cfg):
    from ardrone_nmpc.runs.rundir import SummaryRow, read_summary

    rows = [SummaryRow("x", "rise_time", 1 / 3, "s"), SummaryRow("x", "settling_time",
                                                                 math.nan, "s")]
    with RunRecorder.create(tmp_path, cfg, seed=0, now=NOW) as rec:
        rec.write_summary(rows)
        rec.write_summary(rows)  # replaces
    text = (rec.path / "summary.csv").read_text()
    assert text == "axis,metric,value,unit\nx,rise_time,0.3333333333333333,s\n" \
                   "x,settling_time,nan,s\n"
    back = read_summary(rec.path)
    assert back[0] == rows[0]
    assert back[1].metric == "settling_time" and math.isnan(back[1].value)
    with pytest.raises(ValueError, match="contains"):
        rec.write_summary([SummaryRow("x,y", "m", 1.0, "s")])


# ----------------------------------------------------------------------------- inputs

PATH_CSV = "t_s,x_m,y_m,z_m,psi_rad\n0,0,0,1,0\n4,1,0,1,0\n8,1,1,1,0\n"


def path_cfg(tmp_path, text=PATH_CSV):
    source = tmp_path / "src" / "lap.csv"
    source.parent.mkdir(exist_ok=True)
    source.write_text(text)
    return load_config(overrides=["name=lap", "reference.kind=path",
                                  f"reference.path_file={source}"]), source


def test_the_path_file_is_copied_and_the_run_reads_the_copy(tmp_path):
    from ardrone_nmpc.reference.trajectories import make_trajectory
    from ardrone_nmpc.runs.summary import summarise

    cfg, source = path_cfg(tmp_path)
    with RunRecorder.create(tmp_path / "logs", cfg, seed=0, now=NOW) as rec:
        for k in range(40):
            rec.write_row({**full_row(k), "t_s": k * 0.2, "x_m": k / 40, "y_m": 0.0,
                           "z_m": 1.0, "x_true_m": math.nan, "mode": "track"})
    copy = rec.path / "inputs" / "lap.csv"
    assert copy.read_bytes() == source.read_bytes()
    assert Path(rec.config.reference.path_file) == copy.resolve()  # what the run flies
    text = (rec.path / "config.yaml").read_text()
    assert "  path_file: inputs/lap.csv\n" in text          # relative: the directory can move
    assert f"# reference.path_file: copied from {source}\n" in text
    source.write_text("t_s,x_m,y_m,z_m,psi_rad\n0,9,9,9,0\n1,9,9,8,0\n")  # edited …
    moved = tmp_path / "elsewhere"
    os.replace(rec.path, moved)                                            # … and moved
    source.unlink()                                                       # … and deleted
    run = read_run(moved)
    assert Path(run.config.reference.path_file) == (moved / "inputs" / "lap.csv").resolve()
    assert run.warnings == []
    wp = make_trajectory(run.config.reference)
    np.testing.assert_array_equal(wp.positions_m, [[0, 0, 1], [1, 0, 1], [1, 1, 1]])
    metrics = {(r.axis, r.metric): r.value for r in summarise(run)}
    assert math.isfinite(metrics[("path", "mean_deviation")])


@pytest.mark.parametrize("text, message", [
    ("t_s,x_m,y_m,z_m,psi_rad\n0,0,0,1,0\n2,100000000,0,1,0\n",
     r"^reference\.path_file: .*lap\.csv:3: column 'x_m': 100000000 is outside ±1000 m$"),
    ("t_s,x_m,y_m,z_m,psi_rad\n0,0,0,1,0\n", r"lap\.csv:2: at least 2 waypoints"),
    (None, r"^reference\.path_file: no such file: .*lap\.csv$"),
])
def test_a_bad_input_file_leaves_no_run_directory(tmp_path, text, message):
    from ardrone_nmpc.reference.waypoints import ReferenceError

    cfg, source = path_cfg(tmp_path, text or PATH_CSV)
    if text is None:
        source.unlink()
    with pytest.raises(ReferenceError, match=message):
        RunRecorder.create(tmp_path / "logs", cfg, seed=0)
    assert not (tmp_path / "logs").exists()


def test_a_failure_while_filling_the_directory_removes_it(tmp_path, cfg, monkeypatch):
    import ardrone_nmpc.runs.rundir as rundir

    def disk_full(*args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(rundir, "dump_config", disk_full)
    with pytest.raises(OSError, match="No space left"):
        RunRecorder.create(tmp_path, cfg, seed=0)
    assert list(tmp_path.iterdir()) == []


def test_an_older_run_naming_its_path_file_absolutely_still_reads(tmp_path):
    from ardrone_nmpc.runs.summary import summarise

    cfg, source = path_cfg(tmp_path)
    with RunRecorder.create(tmp_path / "logs", cfg, seed=0, now=NOW) as rec:
        for k in range(10):
            rec.write_row({**full_row(k), "t_s": k * 0.2, "mode": "track"})
    # as written before inputs/ existed: an absolute path, no copy, and a retired key
    config = rec.path / "config.yaml"
    config.write_text(config.read_text().replace("path_file: inputs/lap.csv",
                                                 f"path_file: {source}")
                      .replace("  port: 51001\n", "  port: 51001\n  rate_hz: 100.0\n"))
    shutil.rmtree(rec.path / "inputs")
    assert read_run(rec.path).config.reference.path_file == str(source)
    source.unlink()  # and then its file was deleted: it still reads, with a warning
    run = read_run(rec.path)
    assert any("reference.path_file" in w and "is gone" in w for w in run.warnings)
    metrics = {(r.axis, r.metric): r.value for r in summarise(run)}
    assert math.isnan(metrics[("path", "mean_deviation")])
    assert math.isfinite(metrics[("xyz", "rmse")])


def test_the_longest_name_fits_the_file_system_with_every_suffix(tmp_path):
    from ardrone_nmpc.config.limits import MAX_NAME_CHARS, RERUN_SUFFIX

    cfg = load_config(overrides=[f"name={'n' * (MAX_NAME_CHARS - len(RERUN_SUFFIX))}"
                                 f"{RERUN_SUFFIX}"])
    paths = []
    for _ in range(12):  # same second: -2 … -12 appended
        with RunRecorder.create(tmp_path, cfg, seed=0, now=NOW) as rec:
            paths.append(rec.path)
    assert paths[-1].name.endswith(f"{RERUN_SUFFIX}-12")
    assert max(len(p.name.encode()) for p in paths) <= 255
    assert read_run(paths[-1]).config.name == cfg.name


# ----------------------------------------------------------------------------- crash safety

CHILD = r"""
import sys
from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.runs.rundir import RunRecorder, LOG_COLUMNS, STRING_COLUMNS
cfg = load_config(overrides=["name=killed"])
rec = RunRecorder.create(sys.argv[1], cfg, seed=1)
print(rec.path, flush=True)
cols = [c for c in LOG_COLUMNS if c not in STRING_COLUMNS]
k = 0
while True:
    row = {c: k + i * 1e-3 for i, c in enumerate(cols)}
    row.update(mode="track", solver_status="ok", cmd_saturated="0000", t_s=float(k))
    rec.write_row(row)
    rec.event(float(k), "tick", k=k)
    k += 1
    print(k, flush=True)
"""


@pytest.mark.timeout(30)
def test_sigkill_loses_at_most_one_row(tmp_path):
    proc = subprocess.Popen([sys.executable, "-c", CHILD, str(tmp_path)], stdout=subprocess.PIPE,
                            text=True)
    try:
        run_dir = Path(proc.stdout.readline().strip())
        reported = 0
        while reported < 300:
            line = proc.stdout.readline()
            assert line, "the child stopped early"
            reported = int(line)
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=10)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        proc.stdout.close()
    assert proc.returncode == -signal.SIGKILL
    run = read_run(run_dir)
    assert run.n_rows >= reported - 1
    t = run.columns["t_s"]
    assert t.tolist() == list(map(float, range(run.n_rows)))  # complete rows, in order
    assert_same_floats(run.columns["x_m"], t + 1e-3)
    assert len(run.events) >= reported - 1
    assert len(run.warnings) <= 2


def test_events_of_an_older_fly_run_are_read_on_the_experiment_clock(tmp_path, cfg):
    """fly runs written before one clock stamped their session's wall time in ``t_s`` and the
    loop's experiment time in ``t_exp_s``: read back, ``t_s`` is experiment time for all (the
    offset from the events carrying both) and the old stamp ``wall_s``."""
    old = [{"t_s": 0.01, "kind": "links", "sim": True},
           {"t_s": 2.48, "kind": "takeoff"},
           {"t_s": 11.5, "kind": "mode", "t_exp_s": 1.0, "mode": "hold-solver"},
           {"t_s": 27.5, "kind": "landing", "reason": "end"},
           {"t_s": math.nan, "kind": "exception", "error": "x"}]
    as_written = lambda events: [(e.pop("t_s"), e.pop("kind"), e) for e in map(dict, events)]  # noqa: E731
    path = write_run(tmp_path, cfg, [full_row(0)], as_written(old))
    events = read_run(path).events
    assert [e["kind"] for e in events] == [e["kind"] for e in old]
    assert [e["t_s"] for e in events[:4]] == pytest.approx([-10.49, -8.02, 1.0, 17.0])
    assert [e["wall_s"] for e in events[:4]] == [0.01, 2.48, 11.5, 27.5]
    assert "t_exp_s" not in events[2] and events[2]["mode"] == "hold-solver"
    assert math.isnan(events[4]["t_s"])
    # a run of one clock is read as written
    new = [{"t_s": -3.0, "kind": "links", "wall_s": 0.0}, {"t_s": 2.0, "kind": "mode"}]
    path = write_run(tmp_path / "new", cfg, [full_row(0)], as_written(new))
    assert read_run(path).events == new
