"""Hostile input: decoders, the simulator's AT receiver, configs and run directories.

The decoder strategies build *structured* inputs — a valid packet/datagram with at most one
injected fault of a known kind (an option of size 0, a size that overruns, a bad checksum, a
second demo option, a lying item count, a duplicate object name, an out-of-range AT number, a
missing terminator …) — so that the examples reach the deep paths of each decoder, and each
test can say what must happen: an intact input decodes to what was built; a certain fault
raises the module's own error with the matching message; nothing else ever escapes.

The example counts come from the ``hostile-input`` hypothesis profile (500 per test; the
``HOSTILE_EXAMPLES`` environment variable overrides); the ≥ 100 000-input runs live in
``benchmarks/fuzz_decoders.py``.
"""

from __future__ import annotations

import math
import os
import re
import struct
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from ardrone_nmpc.config.schema import ConfigError
from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.reference.trajectories import ReferenceError, make_trajectory
from ardrone_nmpc.links.drone_link import navdata_sample_of, parse_config_text
from ardrone_nmpc.links.mocap_link import mocap_pose_of
from ardrone_nmpc.protocol.at import (
    AtCommand,
    AtParseError,
    Calib,
    Config,
    Ctrl,
    Pcmd,
    Ref,
    parse_datagram,
    parse_datagram_lenient,
)
from ardrone_nmpc.protocol.mocap import MocapError, decode_mocap
from ardrone_nmpc.protocol.navdata import (
    DEMO_SIZE,
    NAVDATA_MAGIC,
    NAVDATA_MAGIC_ALT,
    NAVDATA_MAX_BYTES,
    DroneState,
    NavdataError,
    decode_navdata,
)
from ardrone_nmpc.runs.log_columns import LOG_COLUMNS, STRING_COLUMNS
from ardrone_nmpc.runs.rundir import LogError, RunRecorder, read_run

settings.register_profile(
    "hostile-input", max_examples=int(os.environ.get("HOSTILE_EXAMPLES", "500")),
    deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
HOSTILE = settings.get_profile("hostile-input")

U16 = st.integers(0, 0xFFFF)
U32 = st.integers(0, 0xFFFFFFFF)
I32 = st.integers(-(2**31), 2**31 - 1)
# float32 bit patterns: ordinary values, the specials, and any 4 bytes (NaN payloads).
F32_BYTES = st.one_of(
    st.floats(width=32).map(lambda x: struct.pack("<f", x)),
    st.sampled_from([struct.pack("<f", v) for v in (math.inf, -math.inf, math.nan, -0.0,
                                                     3.4028234663852886e38, 1e-45)]),
    st.binary(min_size=4, max_size=4))
F64 = st.one_of(st.floats(), st.sampled_from([math.inf, -math.inf, math.nan, 1e308, -0.0]))


# ----------------------------------------------------------------------------- navdata

NAV_FAULTS = (None, "zero_size", "small_size", "overrun", "bad_checksum", "checksum_size",
              "no_checksum", "bad_magic", "second_demo", "short_demo", "truncated", "too_long",
              "desync")
# What each certain fault must be rejected with (desync: only "no other exception").
NAV_MESSAGES = {
    "zero_size": "invalid size 0", "small_size": r"invalid size [123]\b",
    "overrun": "overruns", "bad_checksum": "checksum mismatch",
    "checksum_size": "checksum option has size|overruns",
    "no_checksum": "no checksum option|shorter than header",
    "bad_magic": "bad magic", "second_demo": "second demo option",
    "short_demo": "demo option of size", "truncated": ".", "too_long": "exceeds 4096",
}


@st.composite
def demo_payloads(draw) -> bytes:
    """The 144 bytes after a demo option's head, every float a hostile bit pattern."""
    f = lambda n: b"".join(draw(F32_BYTES) for _ in range(n))  # noqa: E731
    return (struct.pack("<II", draw(U32), draw(U32)) + f(3) + struct.pack("<i", draw(I32))
            + f(3) + struct.pack("<I", draw(U32)) + f(12)
            + struct.pack("<II", draw(U32), draw(U32)) + f(12))


@st.composite
def navdata_cases(draw):
    """(packet, fault kind or None, the non-demo option tags built, demo built?, state bits,
    sequence number)."""
    fault = draw(st.none() | st.sampled_from(NAV_FAULTS))   # half of them intact
    magic = NAVDATA_MAGIC_ALT if draw(st.booleans()) else NAVDATA_MAGIC
    if fault == "bad_magic":
        magic = draw(U32.filter(lambda m: m not in (NAVDATA_MAGIC, NAVDATA_MAGIC_ALT)))
    state, seq = draw(U32), draw(U32)
    header = struct.pack("<IIIi", magic, state, seq, draw(I32))
    options: list[list] = []                     # [tag, payload] in wire order
    if draw(st.booleans()) or fault in ("second_demo", "short_demo"):
        options.append([0, draw(demo_payloads()) + draw(st.binary(max_size=8))])
    tags = draw(st.lists(st.integers(1, 0xFFFE), max_size=4))
    for tag in tags:
        options.append([tag, draw(st.binary(max_size=40))])
    if fault == "second_demo":
        options.insert(draw(st.integers(1, len(options))), [0, draw(demo_payloads())])
    sizes = [len(p) + 4 for _, p in options]
    if fault == "short_demo":
        sizes[0] = draw(st.integers(4, DEMO_SIZE - 1))
    if fault in ("zero_size", "small_size", "overrun", "desync") and not options:
        options.append([draw(st.integers(1, 0xFFFE)), draw(st.binary(min_size=1, max_size=40))])
        sizes.append(len(options[-1][1]) + 4)
    if fault in ("zero_size", "small_size", "overrun", "desync"):
        k = draw(st.integers(0, len(options) - 1))
        remaining = 8 + sum(len(p) + 4 for _, p in options[k:])   # bytes from option k on
        if fault == "zero_size":
            sizes[k] = 0
        elif fault == "small_size":
            sizes[k] = draw(st.integers(1, 3))
        elif fault == "overrun":                 # past the end of the packet
            sizes[k] = draw(st.integers(remaining + 1, 0xFFFF))
        else:                                    # in bounds but wrong: the walk loses step
            sizes[k] = draw(st.integers(4, remaining).filter(lambda s, k=k: s != sizes[k]))
    body = header + b"".join(struct.pack("<HH", t, s) + p
                             for (t, p), s in zip(options, sizes))
    cks = sum(body) & 0xFFFFFFFF
    if fault == "bad_checksum":
        cks ^= 1 << draw(st.integers(0, 31))
    cks_size = 8 if fault != "checksum_size" else draw(U16.filter(lambda s: s >= 4 and s != 8))
    packet = body + (b"" if fault == "no_checksum" else struct.pack("<HHI", 0xFFFF, cks_size, cks))
    if fault == "truncated":
        packet = packet[:draw(st.integers(0, len(packet) - 1))]
    elif fault == "too_long":
        packet += bytes(NAVDATA_MAX_BYTES + 1 - len(packet))
    elif fault not in ("no_checksum", "overrun"):
        packet += draw(st.binary(max_size=16))   # bytes after the checksum are ignored
    assert len(packet) <= NAVDATA_MAX_BYTES or fault == "too_long"
    has_demo = any(t == 0 for t, _ in options)
    return packet, fault, [t for t, _ in options if t != 0], has_demo, state, seq


@HOSTILE
@given(navdata_cases())
def test_navdata_structured_faults_raise_only_navdata_error(case):
    packet, fault, tags, has_demo, state, seq = case
    try:
        decoded = decode_navdata(packet)
    except NavdataError as exc:
        assert fault is not None, f"an intact packet was rejected: {exc}"
        if fault in NAV_MESSAGES:
            assert re.search(NAV_MESSAGES[fault], str(exc)), (fault, str(exc))
        return
    assert fault in (None, "desync"), f"fault {fault!r} was not detected"
    if fault is None:
        assert [o.tag for o in decoded.options] == tags
        assert (decoded.demo is not None) == has_demo
        assert int(decoded.state) == state and decoded.sequence == seq
    # what the link does with every decoded packet must not raise either
    sample = navdata_sample_of(decoded, 0.0)
    assert (sample is None) == (decoded.demo is None)


def _demo_packet(yaw_mdeg: float, altitude_mm: int = 1000) -> bytes:
    demo = struct.pack("<HHIIfffifffI9f3fII9f3f", 0, DEMO_SIZE, 4 << 16, 50, 0.0, 0.0,
                       yaw_mdeg, altitude_mm, math.nan, math.inf, -math.inf, 0,
                       *([0.0] * 12), 0, 3, *([0.0] * 12))
    body = struct.pack("<IIIi", NAVDATA_MAGIC, int(DroneState.FLY), 7, 0) + demo
    return body + struct.pack("<HHI", 0xFFFF, 8, sum(body) & 0xFFFFFFFF)


@pytest.mark.parametrize("yaw_mdeg", [math.inf, -math.inf, math.nan])
def test_checksum_valid_non_finite_yaw_gives_nan_not_an_exception(yaw_mdeg):
    # math.remainder(inf, 360) raised ValueError in the link's receiver thread.
    sample = navdata_sample_of(decode_navdata(_demo_packet(yaw_mdeg)), 1.0)
    assert math.isnan(sample.yaw_deg)
    assert sample.altitude_m == pytest.approx(1.0)
    assert math.isnan(sample.vx_body_mps) and sample.vy_body_mps == math.inf


@HOSTILE
@given(st.binary(max_size=300))
def test_config_dump_text_from_the_control_port_never_raises(raw):
    # read_config decodes the TCP dump with errors="replace" before this split
    text = raw.decode("ascii", errors="replace")
    parsed = parse_config_text(text)
    for key, value in parsed.items():
        assert key and key == key.strip() and value == value.strip()
        assert "\n" not in key + value and "\r" not in key + value


# ----------------------------------------------------------------------------- mocap

MOCAP_FAULTS = (None, "count_high", "count_low", "short_pose", "overrun", "duplicate",
                "truncated")
MOCAP_MESSAGES = {"count_high": "overruns|has size 0", "short_pose": r"has size \d+ < 72",
                  "overrun": "overruns", "duplicate": "appears twice", "truncated": "overruns"}
NAMES = st.one_of(
    st.text(alphabet=st.characters(min_codepoint=0x21, max_codepoint=0x7E), min_size=1,
            max_size=24).map(str.encode),
    st.binary(min_size=1, max_size=24),                                # non-ASCII, NULs
    st.just(b"x" * 24))                                                # no NUL terminator


def _wire_name(raw: bytes) -> str:
    return raw.split(b"\0", 1)[0].decode("ascii", errors="backslashreplace")


@st.composite
def mocap_cases(draw):
    """(datagram, fault kind or None, {decoded name: six floats} built for the poses)."""
    fault = draw(st.none() | st.sampled_from(MOCAP_FAULTS))
    items: list[tuple[int, bytes, str | None, tuple]] = []   # (id, data, name, six floats)
    names = draw(st.lists(NAMES, min_size=1 if fault in ("duplicate", "short_pose", "overrun",
                                                         "truncated", "count_low") else 0,
                          max_size=5, unique_by=_wire_name))
    for raw in names:
        values = tuple(draw(F64) for _ in range(6))
        data = struct.pack("<24s6d", raw, *values) + draw(st.binary(max_size=4))
        items.append((0, data, _wire_name(raw), values))
    for _ in range(draw(st.integers(0, 2))):     # unknown items are stepped over by size
        items.insert(draw(st.integers(0, len(items))),
                     (draw(st.integers(1, 255)), draw(st.binary(max_size=30)), None, ()))
    pose_at = [i for i, item in enumerate(items) if item[0] == 0]
    if fault == "duplicate":
        items.append(items[pose_at[0]])
    if fault == "short_pose":
        k = draw(st.sampled_from(pose_at))
        items[k] = (0, items[k][1][:draw(st.integers(0, 71))], None, ())
    count = len(items)
    if fault == "count_high":
        count = draw(st.integers(count + 1, 255))
    elif fault == "count_low":
        count = draw(st.integers(0, count - 1))
    poses = {name: values for _, _, name, values in items[:count] if name is not None}
    encoded = [struct.pack("<BH", i, len(d)) + d for i, d, _, _ in items]
    if fault == "overrun":
        k = draw(st.integers(0, len(items) - 1))
        after = sum(len(e) for e in encoded[k:]) - 3
        encoded[k] = (struct.pack("<BH", items[k][0], draw(st.integers(after + 1, 0xFFFF)))
                      + items[k][1])
    datagram = struct.pack("<IB", draw(U32), count) + b"".join(encoded)
    if fault == "truncated":
        datagram = datagram[:draw(st.integers(0, len(datagram) - 1))]
    elif fault not in ("count_high", "overrun"):   # padding would read as items there
        datagram += bytes(max(0, draw(st.sampled_from([0, 256, 1024])) - len(datagram)))
    return datagram, fault, poses


def _same_float(a: float, b: float) -> bool:
    return struct.pack("<d", a) == struct.pack("<d", b) or (math.isnan(a) and math.isnan(b))


@HOSTILE
@given(mocap_cases())
def test_mocap_structured_faults_raise_only_mocap_error(case):
    datagram, fault, poses = case
    try:
        frame = decode_mocap(datagram)
    except MocapError as exc:
        assert fault not in (None, "count_low"), f"an intact datagram was rejected: {exc}"
        if fault == "truncated" and len(datagram) < 5:
            assert "shorter than" in str(exc)
        else:
            assert re.search(MOCAP_MESSAGES[fault], str(exc)), (fault, str(exc))
        return
    assert fault in (None, "count_low"), f"fault {fault!r} was not detected"
    assert list(frame.poses) == list(poses)       # non-ASCII names as \xNN escapes
    for name, values in poses.items():
        pose = frame.poses[name]
        got = pose.translation_mm + pose.rotation_xyz_rad
        assert all(_same_float(g, v) for g, v in zip(got, values))
        record = mocap_pose_of(pose, 0.0)            # the link's conversion never raises
        assert record.position_m.shape == (3,)
        if not all(math.isfinite(v) for v in values):
            assert not pose.fresh                    # never reaches the controller


# ----------------------------------------------------------------------------- AT commands

F32 = st.floats(width=32, allow_nan=False, allow_infinity=False)
TEXT = st.text(alphabet="".join(chr(c) for c in range(0x20, 0x7F) if c != 0x22), max_size=30)
GOOD = st.one_of(st.builds(Ref, I32), st.builds(Pcmd, I32, F32, F32, F32, F32),
                 st.builds(Calib, I32), st.builds(Config, TEXT, TEXT), st.builds(Ctrl, I32, I32))
# One malformed command of each kind, with the message the parser must give.
BAD = st.sampled_from([
    (b"AT*REF=5,2147483648\r", "outside int32"),
    (b"AT*REF=5,-2147483649\r", "outside int32"),
    (b"AT*PCMD=5,1,0,0,0\r", "takes 5 arguments, got 4"),
    (b"AT*PCMD=5,1,0,0,0,0,0\r", "takes 5 arguments, got 6"),
    (b"AT*PCMD=5,1,2143289344,0,0,0\r", "must be finite"),        # NaN bits
    (b"AT*PCMD=5,1,2139095040,0,0,0\r", "must be finite"),        # +inf bits
    (b'AT*CONFIG=5,"a:b",3\r', "wrong type"),
    (b'AT*CONFIG=5,"a:b","unterminated\r', "malformed command"),
    (b'AT*CONFIG=5,"a"b","c"\r', "malformed command"),
    (b"AT*REF=9999999999,1\r", "invalid command"),                # seq beyond int32
    (b"AT*REF=-1,1\r", "malformed command"),
    (b"AT*REF=x,1\r", "malformed command"),
    (b"AT*REF=5,1.5\r", "malformed command"),
    (b"AT*REF=5,12345678901\r", "malformed command"),             # 11 digits
    (b"AT*REF=5,,1\r", "malformed command"),
    (b"AT*REF 5,1\r", "malformed command"),
    (b"AT*ref=5,1\r", "malformed command"),
    (b"AT*=5\r", "malformed command"),
    (b"AT*REF=5,\xe9\r", "non-ASCII"),
    (b"AT*REF=5,1\x00\r", "malformed command"),
    (b"\x00\xff\x10\r", "non-ASCII"),
])


@st.composite
def at_cases(draw):
    """(datagram, the commands that must parse, in order, the expected error messages).

    Good commands, at most one bad one among them (a message it must be rejected with), and
    one time in ten the last command's ``\\r`` removed (it is then dropped as unterminated).
    """
    commands = [AtCommand(draw(st.integers(0, 2**31 - 1)), body)
                for body in draw(st.lists(GOOD, max_size=6))]
    parts: list[tuple[bytes, object]] = [(c.encode(), c) for c in commands]
    bad = draw(st.none() | BAD)
    if bad is not None:
        parts.insert(draw(st.integers(0, len(parts))), (bad[0], None))
    unterminated = bool(parts) and draw(st.integers(0, 9)) == 0
    data = b"".join(raw for raw, _ in parts)
    if unterminated:
        data = data[:-1]
        parts[-1] = (parts[-1][0], "unterminated")
    messages = [bad[1] if what is None else "unterminated command"
                for _, what in parts if what is None or what == "unterminated"]
    good = [what for _, what in parts if isinstance(what, AtCommand)]
    return data, good, messages


@HOSTILE
@given(at_cases())
def test_at_one_bad_command_among_good_ones(case):
    data, good, messages = case
    commands, errors = parse_datagram_lenient(data)
    assert commands == good                      # the good ones, in order, around the bad one
    assert len(errors) == len(messages)
    for error, message in zip(errors, messages):
        assert re.search(message, str(error)), (message, str(error))
    if not messages:
        assert parse_datagram(data) == good
    else:                                        # strict: the first problem in datagram order
        with pytest.raises(AtParseError, match=messages[0]):
            parse_datagram(data)


@pytest.fixture(scope="module")
def drone_server():
    """A simulated drone whose AT receiver is fed directly (sockets bound on 127.0.0.1, threads
    not started: the datagram handling alone, no timing)."""
    from ardrone_nmpc.config.schema import ExperimentConfig
    from ardrone_nmpc.sim.drone_server import DroneServer
    from ardrone_nmpc.sim.plant import AirframePlant

    cfg = ExperimentConfig()
    server = DroneServer(AirframePlant.from_config(cfg.sim, cfg.drone))
    yield server
    server.stop()


@settings(HOSTILE, max_examples=max(50, HOSTILE.max_examples // 4))
@given(case=at_cases())
def test_simulator_counts_bad_datagrams_and_keeps_the_good_commands(drone_server, case):
    data, good, messages = case
    before = drone_server.counters
    drone_server.handle_at_datagram(data)
    after = drone_server.counters
    assert after.at_datagrams_in == before.at_datagrams_in + 1
    assert after.malformed_datagrams == before.malformed_datagrams + bool(messages)
    assert after.malformed_commands == before.malformed_commands + len(messages)
    assert after.at_commands_in == before.at_commands_in + len(good)


@pytest.mark.parametrize("key, value, field, expected", [
    ("control:control_vz_max", "1e300", "control_vz_max_mps", 2.0),
    ("control:control_vz_max", "1e-300", "control_vz_max_mps", 0.2),
    ("control:control_yaw", "1e300", "control_yaw_radps", 6.11),
    ("control:control_yaw", "0.001", "control_yaw_radps", 0.7),
])
def test_simulator_clamps_hostile_limits_to_the_documented_ranges(drone_server, key, value,
                                                                  field, expected):
    # unclamped, 1e300 mm/s climbed past what navdata's int32 altitude holds: the navdata
    # thread died building the next packet
    drone_server.handle_at_datagram(f'AT*CONFIG=1,"{key}","{value}"\r'.encode())
    assert getattr(drone_server.plant.params, field) == pytest.approx(expected)
    assert drone_server.config[key] == value


# ----------------------------------------------------------------------------- configs


def _yaml(tmp_path: Path, text: str, name: str = "x.yaml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


@pytest.mark.parametrize("text, match", [
    ("controller:\n  horizon_steps: abc\n", r"controller\.horizon_steps: .*valid integer"),
    ("controller:\n  horizon_steps: true\n", r"controller\.horizon_steps: expected an integer, "
                                             r"got the boolean true"),
    ("controller:\n  q: [1, 2, false, 4, 5, 6, 7]\n",
     r"controller\.q: expected a list of numbers, got the boolean false at index 2"),
    ("controller:\n  dtau_s: yes\n", r"controller\.dtau_s: expected a number, got the boolean"),
    ("controller: 5\n", r"^controller: Input should be a valid dictionary"),
    ("controller:\n  q: [.nan, 1, 1, 1, 1, 1, 1]\n", r"controller\.q\.0: .*finite"),
    ("controller:\n  r: [1, .inf, 1, 1]\n", r"controller\.r\.1: .*finite"),
    ("controller:\n  dtau_s: -0.1\n", r"controller\.dtau_s: .*greater than 0"),
    ("controller:\n  horizon_steps: 0\n",
     r"controller\.horizon_steps: .*greater than or equal to 1"),
    ("controller:\n  horizon_steps: 100000000000000000000\n",
     r"controller\.horizon_steps: .*less than or equal to 1000"),
    ("controller:\n  delay_compensation_s: 1.0e+300\n", r"controller\.delay_compensation_s: "),
    ("loop:\n  period_s: 1.0e-300\n", r"loop\.period_s: .*greater than or equal to 0\.001"),
    ("sim:\n  plant:\n    tau_tilt_s: 1.0e-300\n",
     r"sim\.plant\.integration_step_s: must be at most tau_tilt_s"),
    ("sim:\n  plant:\n    drag_per_s: 1.0e+300\n",
     r"sim\.plant\.integration_step_s: must be at most 1 / drag_per_s"),
    ("reference:\n  side_m: 1.0e+300\n", r"reference\.side_m: .*less than or equal to 1000"),
    ("reference:\n  semi_axes_m: [1.0e+300, 1]\n",
     r"reference\.semi_axes_m\.0: .*less than or equal to 1000"),
    ("reference:\n  lorenz_scale_m: 1.0e+300\n", r"reference\.lorenz_scale_m: .*less than"),
    ("estimator:\n  luenberger_lambda0_per_s: 1.0e+300\n",
     r"estimator\.luenberger_lambda0_per_s: .*less than or equal to 1000"),
    ("bogus: 1\n", r"^bogus: Extra inputs are not permitted"),
    ("- 1\n- 2\n", r"x\.yaml: the top level must be a mapping"),
    ("controller: [\n", r"x\.yaml: invalid YAML \(line 2\)"),
    ("name: a\nname: b\n", r"x\.yaml: invalid YAML \(line 2\): duplicate key 'name'"),
])
def test_hostile_config_is_one_config_error_per_problem(tmp_path, text, match):
    with pytest.raises(ConfigError) as info:
        load_config(_yaml(tmp_path, text))
    assert len(info.value.messages) == 1, info.value.messages
    assert re.search(match, info.value.messages[0]), info.value.messages


def test_booleans_stay_valid_where_the_field_is_boolean(tmp_path):
    cfg = load_config(_yaml(tmp_path, "drone:\n  navdata_demo: false\n"
                                      "controller:\n  solver:\n    condensed: false\n"))
    assert cfg.drone.navdata_demo is False and cfg.controller.solver.condensed is False


@pytest.mark.parametrize("rows, match", [
    ("0,0,0,1,0\n2,1,0,1,0\n1,1,1,1,0\n", r"path\.csv:4: time 1\.0 is not after the previous 2\.0"),
    ("0,0,0,1,0\n1,x,0,1,0\n", r"path\.csv:3: column 'x_m': 'x' is not a number"),
    ("0,0,0,1,0\n1,nan,0,1,0\n", r"path\.csv:3: column 'x_m': 'nan' is not a finite number"),
    ("0,0,0,1,0\n1,0,0\n", r"path\.csv:3: expected 5 values, got 3"),
    ("0,0,0,1,0\n", r"path\.csv:2: at least 2 waypoints"),
])
def test_a_bad_path_file_is_a_reference_error_naming_its_line(tmp_path, rows, match):
    # the config loads (it reads no file); building the trajectory reads and checks it
    (tmp_path / "path.csv").write_text("t_s,x_m,y_m,z_m,psi_rad\n" + rows)
    cfg = load_config(_yaml(tmp_path, "reference:\n  kind: path\n  path_file: path.csv\n"))
    with pytest.raises(ReferenceError) as info:
        make_trajectory(cfg.reference)
    (message,) = info.value.messages
    assert message.startswith("reference.path_file: ")
    assert re.search(match, message), message


def test_a_path_file_that_is_not_utf8_is_a_reference_error(tmp_path):
    (tmp_path / "path.csv").write_bytes(b"t_s,x_m\n\xff\xfe")
    cfg = load_config(_yaml(tmp_path, "reference:\n  kind: path\n  path_file: path.csv\n"))
    with pytest.raises(ReferenceError, match=r"reference\.path_file: .*path\.csv:2: not UTF-8"):
        make_trajectory(cfg.reference)


# ----------------------------------------------------------------------------- run directories

NUMERIC = [c for c in LOG_COLUMNS if c not in STRING_COLUMNS]


@pytest.fixture
def run_dir(tmp_path):
    """A run directory with 20 rows (log.csv lines 2–21)."""
    cfg = load_config(overrides=["name=hostile"])
    with RunRecorder.create(tmp_path, cfg, seed=0) as rec:
        for k in range(20):
            row = {c: 0.5 * k for c in NUMERIC}
            row.update(cmd_saturated="0000", solver_status="ok", mode="track",
                       nav_mode="flying")
            rec.write_row(row)
    return rec.path


def _rewrite_log(run_dir: Path, edit) -> Path:
    log = run_dir / "log.csv"
    log.write_bytes(edit(log.read_bytes()))
    return log


def _lines(data: bytes) -> list[bytes]:
    return data.split(b"\n")


@pytest.mark.parametrize("edit, match", [
    pytest.param(lambda d: b"\n".join(_lines(d)[:8] + [_lines(d)[8][:25]] + _lines(d)[9:]),
                 r"log\.csv:9: expected \d+ cells, got \d+ \(a torn or corrupted row\)",
                 id="torn-middle-row"),
    pytest.param(lambda d: d.replace(b"\n3.5,", b"\n3.5x,", 1),
                 r"log\.csv:9: column t_s: '3\.5x' is not a number", id="non-numeric-cell"),
    pytest.param(lambda d: d.replace(b"z_m,", b"zed,", 1), r"log\.csv:1: missing column z_m",
                 id="missing-column"),
    pytest.param(lambda d: b"", r"log\.csv:1: empty file", id="empty"),
    pytest.param(lambda d: bytes(range(256)) * 4, r"log\.csv:2: not UTF-8 text", id="binary"),
    pytest.param(lambda d: d[:300] + b"\xc3\x28" + d[300:], r"log\.csv:\d+: not UTF-8 text",
                 id="non-utf8"),
    pytest.param(lambda d: b"\n".join(_lines(d)[:5] + [b""] + _lines(d)[5:]),
                 r"log\.csv:6: expected \d+ cells, got 1", id="blank-line"),
    pytest.param(lambda d: _lines(d)[0][:40], r"log\.csv:1: incomplete header row",
                 id="torn-header"),
])
def test_corrupt_log_is_a_log_error_naming_file_and_line(run_dir, edit, match):
    _rewrite_log(run_dir, edit)
    with pytest.raises(LogError, match=match):
        read_run(run_dir)


def test_truncated_last_row_is_dropped_with_a_warning(run_dir):
    _rewrite_log(run_dir, lambda d: d[:-7])
    run = read_run(run_dir)
    assert run.n_rows == 19
    (warning,) = run.warnings
    assert re.search(r"log\.csv:21: incomplete last line dropped", warning)


def test_missing_log_is_a_log_error_naming_the_file(run_dir):
    (run_dir / "log.csv").unlink()
    with pytest.raises(LogError, match=r"log\.csv: no such file"):
        read_run(run_dir)


def test_corrupt_config_of_a_run_is_a_log_error(run_dir):
    (run_dir / "config.yaml").write_bytes(b"\x00\xff not yaml")
    with pytest.raises(LogError, match=r"config\.yaml:1: not UTF-8 text"):
        read_run(run_dir)
    (run_dir / "config.yaml").write_text("controller: [\n")
    with pytest.raises(LogError, match=r"config\.yaml: invalid YAML \(line 2\)"):
        read_run(run_dir)
