"""`export RUN --format mcap|parquet`: every row and event read back bit for bit with the
`mcap` library's reader and pyarrow; the pose channels checked against foxglove-sdk's own
message classes."""

from __future__ import annotations

import json
import math
import struct
import sys

import numpy as np
import pytest
from typer.testing import CliRunner

from ardrone_nmpc.cli.app import app
from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.experiments.export import read_mcap, run_rows, write_mcap, write_parquet
from ardrone_nmpc.runs import channels as ch
from ardrone_nmpc.runs.log_columns import LOG_COLUMNS, STRING_COLUMNS
from ardrone_nmpc.runs.rundir import RunRecorder, read_run

TRICKY = [0.1, -0.0, 0.0, 5e-324, 2.2250738585072014e-308, 1.7976931348623157e308, math.inf,
          -math.inf, math.nan, 1e-7, -123456.789e-3, 2.0 ** 53 + 2.0, 1 / 3]


def _same_bits(a, b) -> bool:
    if isinstance(a, float) or isinstance(b, float):
        a, b = float(a), float(b)
        return (math.isnan(a) and math.isnan(b)) or struct.pack("<d", a) == struct.pack("<d", b)
    return a == b


@pytest.fixture
def run_dir(tmp_path):
    """A run whose rows hold every awkward double (−0.0, subnormals, ±inf, NaN, 1/3 …)."""
    rng = np.random.default_rng(4)
    cfg = load_config(None, ["name=export"])
    with RunRecorder.create(tmp_path, cfg, seed=3) as rec:
        rec.event(-1.5, "takeoff")
        for k in range(40):
            row = {}
            for i, col in enumerate(LOG_COLUMNS):
                if col in STRING_COLUMNS:
                    row[col] = ("track", "settle", "")[k % 3] if col == "mode" else "ok"
                else:
                    row[col] = TRICKY[(k + i) % len(TRICKY)] if k % 2 else rng.normal() * 10
            row["t_s"] = -0.5 + 0.065 * k
            if k == 3:
                row["x_m"] = math.nan          # no pose this tick: no /pose message
            rec.write_row(row)
            if k % 10 == 0:
                rec.event(row["t_s"], "note", value=TRICKY[k % len(TRICKY)], tags=["a", "b"],
                          nested={"x": -0.0, "y": [1, 2.5]})
        rec.event(2.0, "landed", t_exp_s=2.1)
    return rec.path


def test_mcap_round_trips_every_row_and_event_bit_for_bit(run_dir, tmp_path):
    out = tmp_path / "run.mcap"
    run = read_run(run_dir)
    n = write_mcap(run, out)
    back = read_mcap(out)
    rows = run_rows(run)
    assert len(back.rows) == len(rows) == 40
    for got, want in zip(back.rows, rows):
        assert list(got) == list(want)          # fields = the log's columns, in order
        bad = [c for c in want if not _same_bits(got[c], want[c])]
        assert not bad, bad
    assert len(back.events) == len(run.events) == 6
    for got, want in zip(back.events, run.events):
        assert json.dumps(got, sort_keys=True) == json.dumps(want, sort_keys=True)
        assert all(_same_bits(got[k], want[k]) for k in want if isinstance(want[k], float))
    assert back.config["seed"] == 3 and back.config["config"]["name"] == "export"
    assert n == 40 + 6 + 1 + 2 + len(back.poses["/pose"]) + len(back.poses["/reference"])
    finite = np.isfinite(np.c_[run.columns["x_m"], run.columns["y_m"], run.columns["z_m"]])
    assert len(back.poses["/pose"]) == finite.all(axis=1).sum() < 40   # none without a position


def test_mcap_log_time_is_the_row_time(run_dir, tmp_path):
    out = tmp_path / "run.mcap"
    run = read_run(run_dir)
    write_mcap(run, out)
    back = read_mcap(out)
    t = run.columns["t_s"]
    dt_ns = np.diff(back.row_log_times_ns)
    np.testing.assert_allclose(dt_ns, np.diff(t) * 1e9, atol=1.0)
    assert back.row_log_times_ns[0] > 1.6e18          # on the run's creation date (epoch ns)


def test_pose_channels_are_foxglove_pose_in_frame(run_dir, tmp_path):
    import foxglove.messages as fg  # the 'foxglove' extra (in 'test')

    out = tmp_path / "run.mcap"
    write_mcap(read_run(run_dir), out)
    back = read_mcap(out)
    assert back.schemas["/pose"] == back.schemas["/reference"] == "foxglove.PoseInFrame"
    msg = back.poses["/pose"][0]
    # the SDK's own class takes exactly these fields (a misspelt one raises TypeError)
    pose = fg.PoseInFrame(
        timestamp=fg.Timestamp(**msg["timestamp"]), frame_id=msg["frame_id"],
        pose=fg.Pose(position=fg.Vector3(**msg["pose"]["position"]),
                     orientation=fg.Quaternion(**msg["pose"]["orientation"])))
    assert len(pose.encode()) > 0 and msg["frame_id"] == "world"
    # the paths: one PosesInFrame each, every pose of its channel, at the first row's time
    assert back.schemas["/flight_path"] == "foxglove.PosesInFrame"
    (path,) = back.poses["/flight_path"]
    (ref_path,) = back.poses["/reference_path"]
    assert [p_["position"] for p_ in path["poses"]] == \
        [m["pose"]["position"] for m in back.poses["/pose"]]
    assert len(ref_path["poses"]) == len(back.poses["/reference"])
    fg.PosesInFrame(timestamp=fg.Timestamp(**path["timestamp"]), frame_id=path["frame_id"],
                    poses=[fg.Pose(position=fg.Vector3(**p_["position"]),
                                   orientation=fg.Quaternion(**p_["orientation"]))
                           for p_ in path["poses"]])
    q = msg["pose"]["orientation"]
    assert q["x"] ** 2 + q["y"] ** 2 + q["z"] ** 2 + q["w"] ** 2 == pytest.approx(1.0)


def test_json_has_no_nan_or_infinity_tokens():
    assert ch.json_bytes({"a": np.float64(1.5), "b": np.int64(3)}) == b'{"a":1.5,"b":3}'
    text = ch.json_bytes({"a": math.nan, "b": math.inf, "c": -math.inf, "d": [-0.0]}).decode()
    assert text == '{"a":null,"b":1e999,"c":-1e999,"d":[-0.0]}'
    json.loads(text, parse_constant=lambda c: pytest.fail(f"non-standard {c}"))


def test_parquet_round_trips_the_log(run_dir, tmp_path):
    import pyarrow.parquet as pq  # the 'parquet' extra (in 'test')

    out = tmp_path / "run.parquet"
    run = read_run(run_dir)
    assert write_parquet(run, out) == 40
    table = pq.read_table(out)
    for name, values in run.columns.items():
        got = table.column(name).to_pylist()
        assert all(_same_bits(a, b) for a, b in zip(got, values.tolist())), name
    events = [json.loads(line) for line in
              table.schema.metadata[b"ardrone_nmpc.events"].splitlines()]
    assert [e["kind"] for e in events] == [e["kind"] for e in run.events]


def test_export_command(run_dir, tmp_path):
    out = tmp_path / "x.mcap"
    result = CliRunner().invoke(app, ["export", str(run_dir), "--format", "mcap", "-o", str(out)])
    assert result.exit_code == 0, result.output
    assert result.output.splitlines()[-1] == f"export: {out}"
    result = CliRunner().invoke(app, ["export", str(run_dir), "--format", "parquet"])
    assert result.exit_code == 0, result.output
    assert run_dir.with_name(run_dir.name + ".parquet").is_file()


def test_export_errors_are_one_line(run_dir, tmp_path, monkeypatch):
    result = CliRunner().invoke(app, ["export", str(run_dir), "--format", "csv"])
    assert result.exit_code == 1
    assert result.output == "error: --format: unknown format 'csv'; choose mcap, parquet\n"
    result = CliRunner().invoke(app, ["export", str(tmp_path / "nope"), "-o", "x.mcap"])
    assert result.exit_code == 1 and result.output.startswith("error: ")
    assert len(result.output.splitlines()) == 1
    monkeypatch.setitem(sys.modules, "mcap.writer", None)
    result = CliRunner().invoke(app, ["export", str(run_dir), "-o", str(tmp_path / "y.mcap")])
    assert result.exit_code == 1
    assert result.output == ("error: export --format mcap needs the 'mcap' library: "
                             "pip install 'ardrone-nmpc[mcap]'\n")
