"""`export RUN --format mcap|parquet`: every row and event read back bit for bit with the
`mcap` library's reader and pyarrow; the typed channels (written by foxglove-sdk) decoded by
`mcap-protobuf-support` and their attitudes checked against scipy's rotations."""

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
    n_poses = len(back.poses["/pose"]) + len(back.poses["/reference"])
    assert n == 40 + 6 + 1 + 2 + 2 * n_poses          # every pose has its /tf transform too
    assert len(back.poses["/tf"]) == n_poses
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


def test_pose_channels_are_foxglove_typed_channels(run_dir, tmp_path):
    out = tmp_path / "run.mcap"
    run = read_run(run_dir)
    write_mcap(run, out)
    back = read_mcap(out)
    assert back.schemas["/pose"] == back.schemas["/reference"] == "foxglove.PoseInFrame"
    assert back.schemas["/tf"] == "foxglove.FrameTransform"
    assert back.schemas["/flight_path"] == "foxglove.PosesInFrame"
    assert {back.encodings[t] for t in ("/pose", "/tf", "/flight_path")} == {"protobuf"}
    assert back.encodings["/log"] == "json"
    msg = back.poses["/pose"][0]
    assert msg["frame_id"] == "world"
    q = msg["pose"]["orientation"]
    assert q["x"] ** 2 + q["y"] ** 2 + q["z"] ** 2 + q["w"] ** 2 == pytest.approx(1.0)
    # /tf: world → drone at the /pose, world → reference at the /reference
    drone = [m for m in back.poses["/tf"] if m["child_frame_id"] == "drone"]
    ref = [m for m in back.poses["/tf"] if m["child_frame_id"] == "reference"]
    assert {m["parent_frame_id"] for m in back.poses["/tf"]} == {"world"}
    assert [m["translation"] for m in drone] == [m["pose"]["position"]
                                                 for m in back.poses["/pose"]]
    assert [m["rotation"] for m in drone] == [m["pose"]["orientation"]
                                              for m in back.poses["/pose"]]
    assert len(ref) == len(back.poses["/reference"])
    # the paths: one PosesInFrame each, every pose of its channel, at the first row's time
    (path,) = back.poses["/flight_path"]
    (ref_path,) = back.poses["/reference_path"]
    assert [p_["position"] for p_ in path["poses"]] == \
        [m["pose"]["position"] for m in back.poses["/pose"]]
    assert len(ref_path["poses"]) == len(back.poses["/reference"])


def _body_axes_in_world(q: dict) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    return Rotation.from_quat([q["x"], q["y"], q["z"], q["w"]]).as_matrix()  # columns: axes


def test_pose_attitude_is_navdata_roll_and_pitch_with_mocap_heading(tmp_path):
    """docs/protocol.md §4.4: navdata roll > 0 is right wing down, pitch > 0 nose up; the
    world is x forward, y left, z up, ψ counter-clockwise (docs/design.md §4)."""
    from scipy.spatial.transform import Rotation

    cfg = load_config(None, ["name=tilt"])
    cases = [(10.0, 0.0, 0.0), (0.0, 10.0, 0.0), (5.0, -7.0, 2.0), (math.nan, 3.0, 1.0)]
    with RunRecorder.create(tmp_path, cfg, seed=0) as rec:
        for k, (roll, pitch, psi) in enumerate(cases):
            rec.write_row({"t_s": 0.065 * k, "x_m": 1.0, "y_m": 2.0, "z_m": 1.5, "psi_rad": psi,
                           "nav_roll_deg": roll, "nav_pitch_deg": pitch,
                           "x_ref_m": 0.0, "y_ref_m": 0.0, "z_ref_m": 1.0, "psi_ref_rad": psi})
    out = tmp_path / "tilt.mcap"
    write_mcap(read_run(rec.path), out)
    poses = [m["pose"]["orientation"] for m in read_mcap(out).poses["/pose"]]
    right_down, nose_up, mixed, no_nav = (_body_axes_in_world(q) for q in poses)
    assert right_down[2, 1] > 0.15       # body y (left wing) points up: right wing down
    assert abs(right_down[2, 0]) < 1e-12  # no pitch
    assert nose_up[2, 0] > 0.15          # body x (nose) points up
    assert abs(nose_up[2, 1]) < 1e-12
    # the whole rotation: scipy's intrinsic Z-Y-X (ψ, −pitch, roll), up to the quaternion's sign
    want = Rotation.from_euler("ZYX", [2.0, math.radians(7.0), math.radians(5.0)])
    assert (Rotation.from_matrix(mixed) * want.inv()).magnitude() < 1e-12
    # no navdata attitude: heading only
    assert np.allclose(no_nav, Rotation.from_euler("z", 1.0).as_matrix(), atol=1e-12)
    q = poses[3]
    assert q["x"] == q["y"] == 0.0


def test_attitude_quaternion_is_scipys_zyx():
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(2)
    for roll, pitch, yaw in rng.uniform(-3.0, 3.0, size=(200, 3)):
        got = np.array(ch.attitude_quaternion(roll, pitch, yaw))
        want = Rotation.from_euler("ZYX", [yaw, pitch, roll]).as_quat()
        assert min(np.abs(got - want).max(), np.abs(got + want).max()) < 1e-12


def test_json_has_no_nan_or_infinity_tokens():
    assert ch.json_bytes({"a": np.float64(1.5), "b": np.int64(3)}) == b'{"a":1.5,"b":3}'
    text = ch.json_bytes({"a": math.nan, "b": math.inf, "c": -math.inf, "d": [-0.0]}).decode()
    assert text == '{"a":null,"b":1e999,"c":-1e999,"d":[-0.0]}'
    json.loads(text, parse_constant=lambda c: pytest.fail(f"non-standard {c}"))


def _parquet(run_dir, tmp_path):
    import pyarrow.parquet as pq  # the 'parquet' extra (in 'test')

    out = tmp_path / "run.parquet"
    run = read_run(run_dir)
    assert write_parquet(run, out) == run.n_rows
    return run, pq.read_table(out)


def test_parquet_round_trips_the_log(run_dir, tmp_path):
    run, table = _parquet(run_dir, tmp_path)
    assert table.num_rows == 40
    for name, values in run.columns.items():
        if name == "cmd_saturated":
            continue                       # four boolean columns: test_parquet_types
        got = table.column(name).to_pylist()
        want = values.tolist()
        if name in ("gmres_iterations", "newton_iterations", "nav_ctrl_state") and \
                str(table.column(name).type) == "int64":
            want = [None if math.isnan(v) else int(v) for v in want]
        assert all(_same_bits(a, b) or (a is None and b != b) for a, b in zip(got, want)), name
    events = [json.loads(line) for line in
              table.schema.metadata[b"ardrone_nmpc.events"].splitlines()]
    assert [e["kind"] for e in events] == [e["kind"] for e in run.events]


def test_parquet_types_units_and_utc_time(tmp_path):
    """Counts are integers, labels categorical, saturation flags booleans, time_utc an
    absolute UTC timestamp; every field has its unit."""
    import datetime as dt

    import pyarrow as pa

    cfg = load_config(None, ["name=types"])
    with RunRecorder.create(tmp_path, cfg, seed=0) as rec:
        for k in range(6):
            rec.write_row({"t_s": -0.13 + 0.065 * k, "x_m": 0.1 * k, "gmres_iterations": k,
                           "newton_iterations": math.nan if k == 2 else 0,
                           "nav_ctrl_state": 262144 + k, "mode": ("settle", "track")[k > 1],
                           "solver_status": "ok", "nav_mode": "flying",
                           "cmd_saturated": ("0000", "1010", "0001")[k % 3],
                           "battery_pct": 80.0 - k})
    created = dt.datetime.fromisoformat(
        next(line.split("created: ")[1] for line in
             (rec.path / "config.yaml").read_text().splitlines() if "created: " in line))
    run, table = _parquet(rec.path, tmp_path)
    schema = table.schema
    assert schema.field("gmres_iterations").type == pa.int64()
    assert table.column("gmres_iterations").to_pylist() == [0, 1, 2, 3, 4, 5]
    assert table.column("newton_iterations").to_pylist() == [0, 0, None, 0, 0, 0]
    assert table.column("nav_ctrl_state").to_pylist() == [262144 + k for k in range(6)]
    for name in ("mode", "solver_status", "nav_mode"):
        assert pa.types.is_dictionary(schema.field(name).type), name
    assert table.column("mode").to_pylist() == ["settle", "settle", "track", "track", "track",
                                                "track"]
    assert "cmd_saturated" not in schema.names
    assert table.column("cmd_saturated_roll").to_pylist() == [False, True, False] * 2
    assert table.column("cmd_saturated_gaz").to_pylist() == [False, True, False] * 2
    assert table.column("cmd_saturated_yaw").to_pylist() == [False, False, True] * 2
    assert schema.field("battery_pct").type == pa.float64()
    # the absolute time: the creation time for the first row, t_s apart after it
    assert schema.field("time_utc").type == pa.timestamp("ns", tz="UTC")
    assert schema.names.index("time_utc") == schema.names.index("t_s") + 1
    stamps = table.column("time_utc").cast(pa.int64()).to_pylist()
    assert stamps[0] == int(created.timestamp()) * 10 ** 9
    assert np.diff(stamps).tolist() == [65_000_000] * 5
    # units: per field and as one map in the schema
    units = json.loads(schema.metadata[b"ardrone_nmpc.units"])
    assert units["x_m"] == "m" and units["t_s"] == "s" and units["mocap_age_ms"] == "ms"
    assert units["u_zacc_mps2"] == "m/s²" and units["u_psirate_radps"] == "rad/s"
    assert units["solve_us"] == "µs" and units["battery_pct"] == "%"
    assert units["nav_roll_deg"] == "°" and units["cmd_roll_frac"] == "1"
    assert units["time_utc"] == "UTC" and units["gmres_iterations"] == "count"
    assert set(units) == set(schema.names)
    assert all(schema.field(n).metadata[b"unit"].decode() == u for n, u in units.items())


def test_every_log_column_has_a_unit():
    from ardrone_nmpc.runs.table_schema import column_unit

    for name in LOG_COLUMNS:
        column_unit(name)          # a column added without a unit fails here


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
    assert result.exit_code == 2              # a command-line error
    assert result.output == "error: --format: unknown 'csv'; choose mcap, parquet\n"
    result = CliRunner().invoke(app, ["export", str(tmp_path / "nope"), "-o", "x.mcap"])
    assert result.exit_code == 1 and result.output.startswith("error: ")
    assert len(result.output.splitlines()) == 1
    monkeypatch.setitem(sys.modules, "foxglove", None)
    result = CliRunner().invoke(app, ["export", str(run_dir), "-o", str(tmp_path / "y.mcap")])
    assert result.exit_code == 1
    assert result.output == ("error: export --format mcap needs the 'foxglove' library: "
                             "pip install 'ardrone-nmpc[mcap]'\n")


# --- every channel against the run's own files (log.csv, events.jsonl, config.yaml) --------

def _flown(tmp_path):
    """A short lockstep ψ step (the heading moves, the drone tilts), exported as MCAP."""
    from pathlib import Path

    from ardrone_nmpc.experiments.record import record_lockstep

    cfg = load_config(Path("configs/step_psi.yaml"), ["duration_s=2", "sim.settle_s=0.5"])
    run_dir = record_lockstep(cfg, tmp_path / "runs").path
    write_mcap(read_run(run_dir), tmp_path / "run.mcap")
    return run_dir, read_mcap(tmp_path / "run.mcap")


def _log_csv(run_dir) -> list[dict]:
    import csv

    with open(run_dir / "log.csv", newline="") as f:
        lines = [line for line in f if not line.startswith("#")]
    return list(csv.DictReader(lines))


def _created_ns(run_dir) -> int:
    import datetime as dt
    import re

    stamp = re.search(r"created: (\S+)", (run_dir / "config.yaml").read_text()).group(1)
    return int(dt.datetime.fromisoformat(stamp).timestamp()) * 10**9


def _rotation(q: dict):
    from scipy.spatial.transform import Rotation

    return Rotation.from_quat([q["x"], q["y"], q["z"], q["w"]])


def test_the_export_is_the_log_and_the_events_channel_by_channel(tmp_path):
    from scipy.spatial.transform import Rotation

    run_dir, back = _flown(tmp_path)
    rows = _log_csv(run_dir)
    events = [json.loads(line) for line in (run_dir / "events.jsonl").read_text().splitlines()]
    num = lambda r, c: float(r[c]) if r[c] != "" else math.nan  # noqa: E731
    # /log: every row, every cell as log.csv has it
    assert len(back.rows) == len(rows)
    for got, want in zip(back.rows, rows):
        for c, text in want.items():
            v = got[c]
            assert (str(v) == text) if isinstance(v, str) else _same_bits(v, num(want, c)), c
    # log times: the earliest row or event on the creation time, the rest at their t_s
    t_rows = [num(r, "t_s") for r in rows]
    t_first = min(t_rows[0], events[0]["t_s"], 0.0)
    origin = _created_ns(run_dir) - round(t_first * 1e9)
    assert back.row_log_times_ns == [origin + round(t * 1e9) for t in t_rows]
    assert min(back.row_log_times_ns + back.event_log_times_ns) == _created_ns(run_dir)
    # /events: each event of events.jsonl at its own experiment time
    assert [e["kind"] for e in back.events] == [e["kind"] for e in events]
    assert back.event_log_times_ns == [origin + round(e["t_s"] * 1e9) for e in events]
    assert len({e["t_s"] for e in events}) >= 3
    # /pose: the measured position; attitude Rz(ψ)·Ry(−navdata pitch)·Rx(navdata roll)
    posed = [r for r in rows if all(math.isfinite(num(r, c)) for c in ("x_m", "y_m", "z_m"))]
    assert len(back.poses["/pose"]) == len(posed) > 0
    for msg, r in zip(back.poses["/pose"], posed):
        p = msg["pose"]["position"]
        assert (p["x"], p["y"], p["z"]) == (num(r, "x_m"), num(r, "y_m"), num(r, "z_m"))
        want = Rotation.from_euler("ZYX", [num(r, "psi_rad"), -math.radians(
            num(r, "nav_pitch_deg")), math.radians(num(r, "nav_roll_deg"))])
        assert (_rotation(msg["pose"]["orientation"]) * want.inv()).magnitude() < 1e-9
    psi = [num(r, "psi_rad") for r in posed]
    assert max(psi) - min(psi) > 0.5  # the heading moved: its sign is seen
    # /reference: the reference columns, not the measured ones
    refs = [r for r in rows if all(math.isfinite(num(r, c))
                                   for c in ("x_ref_m", "y_ref_m", "z_ref_m"))]
    assert len(back.poses["/reference"]) == len(refs)
    for msg, r in zip(back.poses["/reference"], refs):
        p = msg["pose"]["position"]
        assert (p["x"], p["y"], p["z"]) == (num(r, "x_ref_m"), num(r, "y_ref_m"),
                                            num(r, "z_ref_m"))
        want = Rotation.from_euler("z", num(r, "psi_ref_rad"))
        assert (_rotation(msg["pose"]["orientation"]) * want.inv()).magnitude() < 1e-9
    assert any(num(r, "z_m") != num(r, "z_ref_m") for r in refs)


def test_an_older_runs_events_go_to_their_experiment_time(tmp_path):
    """A run written before every event carried experiment time in ``t_s`` (fly stamped its
    wall time there and the experiment time in ``t_exp_s``): an event with ``t_exp_s`` is
    placed at it, one without it at its wall time less the clocks' offset."""
    cfg = load_config(None, ["name=old"])
    with RunRecorder.create(tmp_path, cfg, seed=0) as rec:
        for k in range(10):
            rec.write_row({"t_s": -0.13 + 0.065 * k, "x_m": 0.0, "y_m": 0.0, "z_m": 1.0})
    old = [{"t_s": 100.0, "kind": "links"}, {"t_s": 101.0, "kind": "takeoff"},
           {"t_s": 110.0, "kind": "mode", "t_exp_s": 0.0},
           {"t_s": 110.1, "kind": "mode", "t_exp_s": 0.1},
           {"t_s": 110.6, "kind": "fault", "t_exp_s": 0.3}]   # written 0.3 s late
    (rec.path / "events.jsonl").write_text("".join(json.dumps(e) + "\n" for e in old))
    run = read_run(rec.path)
    assert [e["t_s"] for e in run.events] == [-10.0, -9.0, 0.0, 0.1, 0.3]
    write_mcap(run, tmp_path / "old.mcap")
    back = read_mcap(tmp_path / "old.mcap")
    origin = back.row_log_times_ns[0] + round(0.13 * 1e9)
    assert back.event_log_times_ns == [origin + round(t * 1e9) for t in
                                       (-10.0, -9.0, 0.0, 0.1, 0.3)]


class _InterruptedStream:
    """A file whose ``write`` is interrupted by Ctrl-C after ``after`` writes (the signal lands
    while foxglove-sdk's writer is writing)."""

    def __init__(self, after: int) -> None:
        self.after = after
        self.position = 0

    def write(self, data) -> int:
        if self.after == 0:
            raise KeyboardInterrupt
        self.after -= 1
        self.position += len(data)
        return len(data)

    def seek(self, offset, whence=0) -> int:
        self.position = offset if whence == 0 else self.position + offset
        return self.position

    def tell(self) -> int:
        return self.position

    def flush(self) -> None:
        pass


@pytest.mark.parametrize("after", [0, 1, 3])
def test_a_ctrl_c_inside_the_writers_write_is_reported_as_the_interrupt(after):
    """The writer left failed by the interrupt raises an I/O error of its own when closed; that
    error once replaced the Ctrl-C (export exited 1 with a traceback instead of 130)."""
    from ardrone_nmpc.runs.foxglove_channels import write_mcap_messages

    row = {"t_s": 0.0, "x_m": 1.0, "y_m": 0.0, "z_m": 1.0, "psi_rad": 0.0}
    messages = [(k * 65_000_000, topic, data) for k in range(2000)
                for topic, data in ch.row_messages(dict(row, t_s=0.065 * k), ch.PathBuilder())]
    with pytest.raises(KeyboardInterrupt):
        write_mcap_messages(_InterruptedStream(after), iter(messages))
