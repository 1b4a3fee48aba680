"""Tests of the navdata encoder and decoder (ardrone_nmpc.protocol.navdata).

The bootstrap packet of docs/protocol.md §4.1 (captured from a drone) is the byte-exact
fixture; demo packets are built with the spec's own ``struct`` format, independently of the
encoder.
"""

from __future__ import annotations

import random
import struct

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from ardrone_nmpc.protocol.navdata import (
    CHECKSUM_TAG,
    DEMO_FORMAT,
    DEMO_SIZE,
    NAVDATA_MAGIC,
    NAVDATA_MAGIC_ALT,
    NAVDATA_MAX_BYTES,
    NAVDATA_WAKEUP,
    CtrlMajor,
    DemoOption,
    DroneState,
    Navdata,
    NavdataError,
    NavdataOption,
    OptionTag,
    ctrl_state_value,
    decode_navdata,
    empty_vision_detect_option,
    encode_navdata,
    navdata_checksum,
)

FUZZ = settings(max_examples=2000, deadline=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
PROPERTY = settings(max_examples=300, deadline=None,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])

# §4.1 worked example: bootstrap packet (header + checksum option only).
BOOTSTRAP = bytes.fromhex("88776655 100C804F 01000000 00000000 FFFF0800 A6020000")
SPEC_DEMO_FORMAT = "<HHIIfffifffI9f3fII9f3f"


def with_checksum(body: bytes) -> bytes:
    """Append a checksum option computed independently of the module."""
    return body + struct.pack("<HHI", 0xFFFF, 8, sum(body) & 0xFFFFFFFF)


def demo_bytes(*, ctrl_major=4, ctrl_minor=0, battery=87, theta=1500.0, phi=-2500.0,
               psi=-170000.0, altitude=1234, vx=100.0, vy=-50.0, vz=25.0, size=DEMO_SIZE):
    raw = struct.pack(SPEC_DEMO_FORMAT, 0, size, (ctrl_major << 16) | ctrl_minor, battery,
                      theta, phi, psi, altitude, vx, vy, vz, 42, *([0.0] * 12), 0, 3,
                      *range(9), 1.0, 2.0, 3.0)
    return raw + bytes(size - DEMO_SIZE)


def header(state=0x0000_0401, seq=7, vision=0, magic=0x55667788) -> bytes:
    return struct.pack("<IIIi", magic, state, seq, vision)


# ----------------------------------------------------------------------------- fixtures


def test_bootstrap_example_decodes():
    assert len(BOOTSTRAP) == 24
    assert navdata_checksum(BOOTSTRAP[:16]) == 678 == 0x2A6
    nav = decode_navdata(BOOTSTRAP)
    assert nav.magic == NAVDATA_MAGIC and nav.sequence == 1 and nav.vision_flag == 0
    assert int(nav.state) == 0x4F800C10
    expected_bits = {4, 10, 11, 23, 24, 25, 26, 27, 30}
    assert {b for b in range(32) if nav.state & (1 << b)} == expected_bits
    assert DroneState.NAVDATA_BOOTSTRAP in nav.state and DroneState.COM_WATCHDOG in nav.state
    assert DroneState.FLY not in nav.state and DroneState.COMMAND not in nav.state
    assert nav.demo is None and nav.options == ()


def test_bootstrap_example_encodes_byte_exact():
    nav = Navdata(DroneState(0x4F800C10), 1)
    assert encode_navdata(nav) == BOOTSTRAP


def test_ack_state_after_config():
    acked = DroneState(0x4F800C50)
    assert DroneState.COMMAND in acked and acked & ~DroneState.COMMAND == 0x4F800C10


@pytest.mark.parametrize("name, bit", [
    ("FLY", 0), ("VIDEO", 1), ("VISION", 2), ("CONTROL", 3), ("ALTITUDE", 4),
    ("USER_FEEDBACK_START", 5), ("COMMAND", 6), ("CAMERA", 7), ("TRAVELLING", 8), ("USB", 9),
    ("NAVDATA_DEMO", 10), ("NAVDATA_BOOTSTRAP", 11), ("MOTORS", 12), ("COM_LOST", 13),
    ("SOFTWARE_FAULT", 14), ("VBAT_LOW", 15), ("USER_EL", 16), ("TIMER_ELAPSED", 17),
    ("MAGNETO_NEEDS_CALIB", 18), ("ANGLES_OUT_OF_RANGE", 19), ("WIND", 20),
    ("ULTRASOUND", 21), ("CUTOUT", 22), ("PIC_VERSION", 23), ("ATCODEC_THREAD_ON", 24),
    ("NAVDATA_THREAD_ON", 25), ("VIDEO_THREAD_ON", 26), ("ACQ_THREAD_ON", 27),
    ("CTRL_WATCHDOG", 28), ("ADC_WATCHDOG", 29), ("COM_WATCHDOG", 30), ("EMERGENCY", 31),
])
def test_state_bits_match_spec(name, bit):
    assert DroneState[name] == 1 << bit


def test_state_aliases():
    assert DroneState.FLYING is DroneState.FLY
    assert DroneState.COMMAND_ACK is DroneState.COMMAND
    assert DroneState.LOW_BATTERY is DroneState.VBAT_LOW


def test_constants():
    assert struct.calcsize(DEMO_FORMAT) == DEMO_SIZE == 148 and DEMO_FORMAT == SPEC_DEMO_FORMAT
    assert NAVDATA_WAKEUP == b"\x01\x00\x00\x00"
    assert OptionTag.VISION_DETECT == 16 and OptionTag.CHECKSUM == CHECKSUM_TAG == 0xFFFF
    assert ctrl_state_value(CtrlMajor.HOVERING, 8) == 0x0004_0008
    with pytest.raises(ValueError):
        ctrl_state_value(1 << 16)


def test_demo_packet_decodes_with_units():
    body = header(state=int(DroneState.FLY | DroneState.NAVDATA_DEMO)) + demo_bytes() + \
        struct.pack("<HH", 16, 328) + bytes(324)
    packet = with_checksum(body)
    assert len(packet) == 500                    # the default demo-mode packet size (§4.3)
    assert packet[16 + 4:16 + 8] == b"\x00\x00\x04\x00"   # bytes 4-5 minor, 6-7 major
    nav = decode_navdata(packet)
    d = nav.demo
    assert d is not None and DroneState.FLYING in nav.state
    assert (d.ctrl_major, d.ctrl_minor, d.battery_pct) == (CtrlMajor.HOVERING, 0, 87)
    assert (d.theta_mdeg, d.phi_mdeg, d.psi_mdeg) == (1500.0, -2500.0, -170000.0)
    assert (d.pitch_deg, d.roll_deg, d.yaw_deg) == (1.5, -2.5, -170.0)
    assert d.altitude_mm == 1234 and d.altitude_m == pytest.approx(1.234)
    assert (d.vx_body_mps, d.vy_body_mps, d.vz_mps) == (0.1, -0.05, 0.025)
    assert d.num_frames == 42 and d.detection_camera_type == 3
    assert d.drone_camera_rot == tuple(float(i) for i in range(9))
    assert d.drone_camera_trans == (1.0, 2.0, 3.0)
    assert nav.options == (empty_vision_detect_option(),)
    assert nav.option(16) == empty_vision_detect_option() and nav.option(99) is None
    assert encode_navdata(nav) == packet


def test_negative_altitude_is_signed():
    nav = decode_navdata(with_checksum(header() + demo_bytes(altitude=-5)))
    assert nav.demo.altitude_mm == -5


def test_unknown_options_are_skipped_by_size():
    body = header() + demo_bytes() + struct.pack("<HH", 28, 10) + b"\xAA" * 6 + \
        struct.pack("<HH", 43150, 4)
    nav = decode_navdata(with_checksum(body))
    assert nav.demo is not None
    assert nav.options == (NavdataOption(28, b"\xAA" * 6), NavdataOption(43150, b""))


def test_grown_demo_option_is_read_and_skipped():
    nav = decode_navdata(with_checksum(header() + demo_bytes(size=160) +
                                       struct.pack("<HH", 1, 8) + b"\x01\x02\x03\x04"))
    assert nav.demo.altitude_mm == 1234
    assert nav.options == (NavdataOption(1, b"\x01\x02\x03\x04"),)


def test_alternative_magic_and_trailing_bytes_accepted():
    nav = decode_navdata(with_checksum(header(magic=NAVDATA_MAGIC_ALT)) + b"\x00" * 10)
    assert nav.magic == NAVDATA_MAGIC_ALT


MALFORMED = {
    "empty": b"",
    "short": BOOTSTRAP[:23],
    "bad magic": with_checksum(header(magic=0x55667790)),
    "size 0 (ardrone_autonomy #69)": with_checksum(header() + struct.pack("<HH", 43150, 0)),
    "size 3": with_checksum(header() + struct.pack("<HH", 5, 3)),
    "overrun": header() + struct.pack("<HH", 5, 200) + bytes(20),
    "no checksum": header() + struct.pack("<HH", 1, 8) + bytes(4),
    "truncated option head": header() + b"\x01\x00",
    "bad checksum": BOOTSTRAP[:-4] + struct.pack("<I", 0x2A7),
    "checksum size 12": header() + struct.pack("<HHII", 0xFFFF, 12, 678, 0),
    "short demo": with_checksum(header() + struct.pack("<HH", 0, 100) + bytes(96)),
    "two demos": with_checksum(header() + demo_bytes() + demo_bytes()),
    "too long": with_checksum(header() + struct.pack("<HH", 9, 4090) + bytes(4086)),
}


@pytest.mark.parametrize("data", MALFORMED.values(), ids=MALFORMED.keys())
def test_malformed_raises_navdata_error(data):
    with pytest.raises(NavdataError):
        decode_navdata(data)


def test_navdata_error_is_value_error():
    assert issubclass(NavdataError, ValueError)


def test_encoder_orders_options_and_validates():
    opts = (NavdataOption(26, b"ab"), empty_vision_detect_option(), NavdataOption(1, b"abcd"))
    nav = Navdata(DroneState(0), 3, demo=DemoOption(), options=opts)
    back = decode_navdata(encode_navdata(nav))
    assert [o.tag for o in back.options] == [1, 16, 26]
    for bad in (NavdataOption(0, b""), NavdataOption(0xFFFF, b"")):
        with pytest.raises(ValueError):
            Navdata(DroneState(0), 1, options=(bad,))
    with pytest.raises(ValueError):
        encode_navdata(Navdata(DroneState(0), 1, options=(NavdataOption(9, bytes(4070)),)))
    with pytest.raises(ValueError):
        Navdata(DroneState(0), 2**32)
    with pytest.raises(ValueError):
        Navdata(DroneState(0), 1, magic=0)
    with pytest.raises(ValueError):
        NavdataOption(1, bytes(0xFFFF))
    with pytest.raises(ValueError):
        DemoOption(battery_pct=-1)
    with pytest.raises(ValueError):
        DemoOption(theta_mdeg=1e39)
    with pytest.raises(ValueError):
        DemoOption(drone_camera_trans=(1.0, 2.0))


def test_max_size_packet_round_trips():
    nav = Navdata(DroneState(0), 1, options=(NavdataOption(9, bytes(NAVDATA_MAX_BYTES - 28)),))
    raw = encode_navdata(nav)
    assert len(raw) == NAVDATA_MAX_BYTES and decode_navdata(raw) == nav


def test_demo_from_si():
    d = DemoOption.from_si(ctrl_state=ctrl_state_value(CtrlMajor.FLYING), battery_pct=55,
                           pitch_deg=-3.25, roll_deg=1.5, yaw_deg=90.0, altitude_m=0.8005,
                           vx_body_mps=0.5, vy_body_mps=-0.25, vz_mps=0.125)
    assert (d.theta_mdeg, d.phi_mdeg, d.psi_mdeg) == (-3250.0, 1500.0, 90000.0)
    assert d.altitude_mm == 800 or d.altitude_mm == 801
    assert (d.vx_mmps, d.vy_mmps, d.vz_mmps) == (500.0, -250.0, 125.0)
    assert d.ctrl_major == CtrlMajor.FLYING


# ----------------------------------------------------------------------------- properties

F32 = st.one_of(st.floats(width=32, allow_nan=False), st.sampled_from([-0.0, 0.0]))
U32 = st.integers(0, 2**32 - 1)
DEMOS = st.builds(
    DemoOption, ctrl_state=U32, battery_pct=U32, theta_mdeg=F32, phi_mdeg=F32, psi_mdeg=F32,
    altitude_mm=st.integers(-(2**31), 2**31 - 1), vx_mmps=F32, vy_mmps=F32, vz_mmps=F32,
    num_frames=U32, detection_camera_rot=st.tuples(*[F32] * 9),
    detection_camera_trans=st.tuples(*[F32] * 3), detection_tag_index=U32,
    detection_camera_type=U32, drone_camera_rot=st.tuples(*[F32] * 9),
    drone_camera_trans=st.tuples(*[F32] * 3))
OPTIONS = st.lists(st.builds(NavdataOption, st.integers(1, 0xFFFE), st.binary(max_size=64)),
                   max_size=12).map(lambda os: tuple(sorted(os, key=lambda o: o.tag)))
PACKETS = st.builds(Navdata, st.builds(DroneState, U32), U32,
                    st.integers(-(2**31), 2**31 - 1), st.none() | DEMOS, OPTIONS,
                    st.sampled_from([NAVDATA_MAGIC, NAVDATA_MAGIC_ALT]))


def _float_bits(d: DemoOption) -> bytes:
    return struct.pack("<9f", d.theta_mdeg, d.phi_mdeg, d.psi_mdeg, d.vx_mmps, d.vy_mmps,
                       d.vz_mmps, *d.drone_camera_trans)


@PROPERTY
@given(PACKETS)
def test_round_trip(nav):
    raw = encode_navdata(nav)
    assert len(raw) <= NAVDATA_MAX_BYTES
    assert raw[-8:-4] == b"\xff\xff\x08\x00"
    assert struct.unpack("<I", raw[-4:])[0] == sum(raw[:-8]) & 0xFFFFFFFF
    back = decode_navdata(raw)
    assert back == nav
    if nav.demo is not None:
        assert _float_bits(back.demo) == _float_bits(nav.demo)     # −0.0 survives
    assert encode_navdata(back) == raw


@PROPERTY
@given(st.floats(width=32))
def test_demo_nan_survives_as_nan(x):
    d = decode_navdata(encode_navdata(Navdata(DroneState(0), 1, demo=DemoOption(vx_mmps=x))))
    assert (d.demo.vx_mmps != d.demo.vx_mmps) == (x != x)


def _decode_or_own_error(data: bytes) -> None:
    try:
        nav = decode_navdata(data)
    except NavdataError:
        return
    assert isinstance(nav, Navdata)
    decode_navdata(encode_navdata(nav))       # what decodes is representable


def _valid_pool() -> list[bytes]:
    rng = random.Random(4546)
    pool = [BOOTSTRAP, with_checksum(header() + demo_bytes() + struct.pack("<HH", 16, 328) +
                                     bytes(324))]
    for _ in range(200):
        demo = None if rng.random() < 0.3 else DemoOption(
            ctrl_state=rng.randrange(2**20), battery_pct=rng.randrange(101),
            theta_mdeg=rng.uniform(-3e4, 3e4), altitude_mm=rng.randrange(-10, 3000))
        opts = sorted((NavdataOption(rng.choice([1, 16, 22, 27, 28, 300, 0xFFFE]),
                                     rng.randbytes(rng.randrange(0, 40)))
                       for _ in range(rng.randrange(4))), key=lambda o: o.tag)
        pool.append(encode_navdata(Navdata(DroneState(rng.randrange(2**32)),
                                           rng.randrange(2**32), 0, demo, tuple(opts))))
    return pool


VALID = st.sampled_from(_valid_pool())


@FUZZ
@given(st.binary(max_size=NAVDATA_MAX_BYTES + 50))
def test_arbitrary_bytes(data):
    _decode_or_own_error(data)


@FUZZ
@given(st.binary(max_size=200))
def test_arbitrary_bytes_after_a_valid_header(data):
    _decode_or_own_error(header() + data)
    _decode_or_own_error(with_checksum(header() + data))


@FUZZ
@given(VALID, st.data())
def test_truncated_packets(raw, draw):
    cut = draw.draw(st.integers(0, len(raw) - 1))
    _decode_or_own_error(raw[:cut])


@FUZZ
@given(VALID, st.data())
def test_single_byte_corruptions(raw, draw):
    i = draw.draw(st.integers(0, len(raw) - 1))
    b = draw.draw(st.integers(0, 255))
    bad = raw[:i] + bytes([b]) + raw[i + 1:]
    _decode_or_own_error(bad)
    if b != raw[i] and i < len(raw) - 8:
        with pytest.raises(NavdataError):      # the checksum (or the structure) catches it
            decode_navdata(bad)


@FUZZ
@given(VALID, st.data())
def test_corruptions_with_a_fixed_checksum(raw, draw):
    """Corrupt the body, then rewrite a consistent checksum so the option walk is exercised."""
    i = draw.draw(st.integers(0, len(raw) - 9))
    b = draw.draw(st.one_of(st.integers(0, 255), st.sampled_from([0, 1, 3, 4, 0xFF])))
    body = raw[:i] + bytes([b]) + raw[i + 1:len(raw) - 8]
    _decode_or_own_error(with_checksum(body))


def test_demo_of_a_sample_round_trips_through_the_reader():
    """What the simulators send for a NavdataSample reads back as that sample (battery as a
    clamped whole percent, angles and speeds to the wire's float32, altitude to the mm)."""
    from ardrone_nmpc.links.drone_link import navdata_sample_of
    from dataclasses import replace

    from ardrone_nmpc.core.types import FlightMode, NavdataSample

    sample = NavdataSample(0.0, FlightMode.FLYING, 100.4, 1.5, -2.25, 30.0, 1.2346, 0.5,
                           -0.25, 0.125)
    demo = DemoOption.of_sample(sample, ctrl_state_value(CtrlMajor.FLYING))
    assert demo.battery_pct == 100
    assert DemoOption.of_sample(replace(sample, battery_pct=-3.0), 0).battery_pct == 0
    back = navdata_sample_of(Navdata(DroneState.FLY, 1, demo=demo), 2.0)
    assert back.mode is FlightMode.FLYING and back.battery_pct == 100.0
    assert back.altitude_m == pytest.approx(1.235, abs=1e-12)
    for name in ("roll_deg", "pitch_deg", "yaw_deg", "vx_body_mps", "vy_body_mps", "vz_mps"):
        assert getattr(back, name) == pytest.approx(getattr(sample, name), rel=1e-6), name


# ----------------------------------------------------------------------------- the drone's side
# Codes written from ARDroneLib Soft/Common/control_states.h (CTRL_STATES enum: DEFAULT 0,
# INIT 1, LANDED 2, FLYING 3, HOVERING 4, TEST 5, TRANS_TAKEOFF 6, TRANS_GOTOFIX 7,
# TRANS_LANDING 8, TRANS_LOOPING 9; FLYING_ALT_OUT_ZONE 3, HOVERING_ALT_OUT_ZONE 4,
# HOVERING_LOST_COM 8), independently of CtrlMajor.
from ardrone_nmpc.protocol.navdata import (  # noqa: E402
    DEFAULT_NAVDATA_OPTIONS,
    CtrlCodes,
    DroneStatus,
    encode_drone_navdata,
    time_option,
)


def test_drone_encoder_bootstrap_is_the_captured_packet():
    status = DroneStatus("landed", bootstrap=True, com_watchdog=True)
    assert encode_drone_navdata(status, 1) == BOOTSTRAP
    # the ACK after the first CONFIG adds bit 6 only (§3.2)
    acked = DroneStatus("landed", bootstrap=True, com_watchdog=True, ack=True)
    assert int(acked.state_bits()) == 0x4F800C50


@pytest.mark.parametrize("phase, kwargs, sdk, fw24", [
    ("landed", {}, (2, 0), (2, 0)),
    ("emergency", {}, (0, 0), (0, 0)),
    ("taking_off", {}, (6, 0), (7, 0)),
    ("landing", {}, (8, 0), (9, 0)),
    ("flying", {}, (4, 0), (4, 0)),
    ("flying", {"moving": True}, (3, 0), (3, 0)),
    ("flying", {"moving": True, "alt_out_zone": True}, (3, 3), (3, 3)),
    ("flying", {"alt_out_zone": True}, (4, 4), (4, 4)),
    ("flying", {"moving": True, "lost_com": True}, (4, 8), (4, 8)),
])
def test_drone_ctrl_state_codes(phase, kwargs, sdk, fw24):
    status = DroneStatus(phase, **kwargs)
    for codes, (major, minor) in ((CtrlCodes.SDK, sdk), (CtrlCodes.FIRMWARE_2_4, fw24)):
        assert status.ctrl_state(codes) == (major << 16) | minor, codes
    assert status.ctrl_state() == status.ctrl_state(CtrlCodes.SDK)


@pytest.mark.parametrize("phase, fly, emergency", [
    ("landed", False, False), ("taking_off", True, False), ("flying", True, False),
    ("landing", True, False), ("emergency", False, True)])
def test_drone_state_bits_follow_the_phase(phase, fly, emergency):
    bits = DroneStatus(phase, user_emergency=True).state_bits()
    assert (DroneState.FLY in bits) is fly
    assert (DroneState.EMERGENCY in bits) is emergency
    assert (DroneState.USER_EL in bits) is emergency    # only shown while in emergency
    assert DroneState.NAVDATA_DEMO in bits and DroneState.NAVDATA_BOOTSTRAP not in bits
    assert bits & 0x0F800010 == 0x0F800010              # always-on bits of the capture
    flags = DroneStatus(phase, start_button=True, com_lost=True, battery_low=True,
                        demo=False).state_bits()
    assert flags & ((1 << 5) | (1 << 13) | (1 << 15)) == (1 << 5) | (1 << 13) | (1 << 15)
    assert not flags & (1 << 10)
    with pytest.raises(ValueError, match="phase"):
        DroneStatus("hovering")


def _sample(**changes):
    from dataclasses import replace

    from ardrone_nmpc.core.types import FlightMode, NavdataSample

    return replace(NavdataSample(0.0, FlightMode.FLYING, 55.0, 1.0, -2.0, 30.0, 0.9, 0.1,
                                 -0.2, 0.05), **changes)


def test_drone_encoder_options_follow_the_mask():
    flying = DroneStatus("flying", moving=True)
    nav = decode_navdata(encode_drone_navdata(flying, 9, _sample()))
    assert DEFAULT_NAVDATA_OPTIONS == 65537
    assert nav.sequence == 9 and nav.demo is not None and nav.demo.ctrl_state == 3 << 16
    assert [o.tag for o in nav.options] == [16] and nav.options[0].size == 328
    assert nav.options[0].payload == bytes(324)                  # nb_detected = 0
    bare = decode_navdata(encode_drone_navdata(flying, 9, _sample(), options_mask=1))
    assert bare.demo is not None and bare.options == ()
    none = decode_navdata(encode_drone_navdata(flying, 9, _sample(), options_mask=0))
    assert none.demo is None and none.options == ()
    full = decode_navdata(encode_drone_navdata(DroneStatus("flying", demo=False), 9, _sample(),
                                               options_mask=0, t_s=3.25))
    assert full.demo is not None and [o.tag for o in full.options] == [1, 16]
    assert not full.state & DroneState.NAVDATA_DEMO
    # time: 11 bits of seconds over 21 bits of microseconds, packed here by hand
    assert full.option(1).payload == struct.pack("<I", (3 << 21) | 250000)
    assert time_option(2049.5).payload == struct.pack("<I", (1 << 21) | 500000)
    with pytest.raises(ValueError):
        time_option(float("nan"))


@settings(max_examples=200, deadline=None)
@given(angles=st.lists(st.floats(-400.0, 400.0), min_size=3, max_size=3),
       speeds=st.lists(st.floats(-50.0, 50.0), min_size=3, max_size=3),
       altitude=st.floats(0.0, 100.0), battery=st.floats(-5.0, 120.0),
       sequence=st.integers(1, 0xFFFFFFFF), demo=st.booleans(), t_s=st.floats(0.0, 5000.0))
def test_the_drones_packet_before_encoding_reads_as_its_bytes_decoded(
        angles, speeds, altitude, battery, sequence, demo, t_s):
    """``drone_navdata`` is what a receiver reads of ``encode_drone_navdata``'s bytes: the
    header's state and sequence, the demo option field for field (the lockstep's quiet ticks
    hand it over without the bytes)."""
    from ardrone_nmpc.protocol.navdata import drone_navdata

    status = DroneStatus("flying", moving=True, demo=demo, com_watchdog=True)
    sample = _sample(battery_pct=battery, roll_deg=angles[0], pitch_deg=angles[1],
                     yaw_deg=angles[2], altitude_m=altitude, vx_body_mps=speeds[0],
                     vy_body_mps=speeds[1], vz_mps=speeds[2])
    built = drone_navdata(status, sequence, sample, t_s=t_s)
    read = decode_navdata(encode_drone_navdata(status, sequence, sample, t_s=t_s))
    assert (read.state, read.sequence) == (built.state, built.sequence)
    assert _demo_values(read.demo) == _demo_values(built.demo)  # bit for bit (−0.0 too)
    assert [(o.tag, o.payload) for o in read.options] == [
        (o.tag, o.payload) for o in built.options]


def _demo_values(demo) -> bytes:
    """The demo option's fields as float64 bytes."""
    from dataclasses import astuple

    values = [float(v) for field in astuple(demo)
              for v in (field if isinstance(field, tuple) else (field,))]
    return struct.pack(f"<{len(values)}d", *values)


_FLOATS_ANY = st.floats(allow_nan=True, allow_infinity=True) | st.sampled_from(
    [3.4028235e35, 3.4028236e35, -3.5e35, 2147483.6474, 2147483.6476, -0.0, 5e-42])


@settings(max_examples=300, deadline=None)
@given(values=st.lists(_FLOATS_ANY, min_size=7, max_size=7), battery=_FLOATS_ANY,
       ctrl_state=st.integers(0, 0xFFFFFFFF))
def test_the_demo_option_of_a_sample_is_the_checked_one(values, battery, ctrl_state):
    """``of_sample`` (built without the per-field checks, its floats rounded in one pack) is,
    field for field, the option the checked constructor builds of the same values; a value
    the checks refuse (beyond float32 or int32, a non-finite altitude) raises as they do."""
    import math
    from dataclasses import fields

    roll, pitch, yaw, altitude, vx, vy, vz = values
    sample = _sample(battery_pct=battery, roll_deg=roll, pitch_deg=pitch, yaw_deg=yaw,
                     altitude_m=altitude, vx_body_mps=vx, vy_body_mps=vy, vz_mps=vz)

    def checked():  # every field through __post_init__'s one-field-at-a-time float32 rounding
        if not math.isfinite(altitude):
            raise ValueError("from_si refuses a non-finite altitude")
        alt_mm = round(altitude * 1000.0)  # (inf beyond 1.8e305 m: OverflowError)
        return DemoOption(ctrl_state=ctrl_state,
                          battery_pct=int(round(min(100.0, max(0.0, battery)))),
                          theta_mdeg=pitch * 1000.0, phi_mdeg=roll * 1000.0,
                          psi_mdeg=yaw * 1000.0, altitude_mm=alt_mm, vx_mmps=vx * 1000.0,
                          vy_mmps=vy * 1000.0, vz_mmps=vz * 1000.0)

    try:
        expected = checked()
    except (ValueError, OverflowError) as refused:
        with pytest.raises(type(refused)):
            DemoOption.of_sample(sample, ctrl_state)
        return
    built = DemoOption.of_sample(sample, ctrl_state)
    assert _demo_values(built) == _demo_values(expected)  # bit for bit (−0.0, NaN too)
    assert [type(getattr(built, f.name)) for f in fields(DemoOption)] == [
        type(getattr(expected, f.name)) for f in fields(DemoOption)]


@pytest.mark.parametrize("demo", [True, False])
def test_the_drones_packet_is_the_checked_navdata(demo):
    """``drone_navdata`` (built without Navdata's checks) equals the Navdata the checked
    constructor makes of its parts; a sequence beyond u32 is refused as it is there."""
    from ardrone_nmpc.protocol.navdata import drone_navdata

    status = DroneStatus("flying", moving=True, demo=demo, battery_low=True, faults=1 << 7)
    built = drone_navdata(status, 7, _sample(), t_s=12.5)
    expected = Navdata(DroneState(int(built.state)), 7, demo=built.demo,
                       options=tuple(NavdataOption(o.tag, o.payload) for o in built.options))
    assert built == expected and type(built.state) is DroneState
    assert int(built.state) == int(status.state_bits()) and built.state & DroneState.VBAT_LOW
    with pytest.raises(ValueError):
        drone_navdata(status, 2**32, _sample())
