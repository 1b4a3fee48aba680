"""Tests of the mocap pose datagram encoder and decoder (ardrone_nmpc.protocol.mocap).

docs/mocap-stream.md gives the layout and the ``struct`` formats; the byte-exact fixture below
is written out by hand and cross-checked against those formats.
"""

from __future__ import annotations

import math
import random
import struct

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from ardrone_nmpc.protocol.mocap import (
    MOCAP_MAX_OBJECTS,
    POSE_ITEM_BYTES,
    MocapError,
    MocapFrame,
    MocapObjectPose,
    decode_mocap,
    encode_mocap,
    rotation_heading_rad,
)

FUZZ = settings(max_examples=2000, deadline=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
PROPERTY = settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])

# Frame 7, one object "ardrone" at (1000, −250, 500) mm, rotation (0, 0, π/2) rad.
EXAMPLE = bytes.fromhex(
    "07000000" "01"                                       # frame number, item count
    "00" "4800"                                           # item id 0, size 72
    "617264726f6e65" + "00" * 17 +                        # "ardrone", NUL-padded to 24
    "0000000000408f40" "0000000000406fc0" "0000000000407f40"   # 1000.0, −250.0, 500.0 mm
    "0000000000000000" "0000000000000000" "182d4454fb21f93f")  # 0, 0, π/2 rad


def pose_item(name: bytes, t, r, item_id=0, extra=b"") -> bytes:
    return struct.pack("<BH24s6d", item_id, 72 + len(extra), name, *t, *r) + extra


# ----------------------------------------------------------------------------- fixtures


def test_example_matches_spec_formats():
    assert len(EXAMPLE) == 80 == 5 + POSE_ITEM_BYTES
    assert EXAMPLE == struct.pack("<IB", 7, 1) + pose_item(b"ardrone", (1000.0, -250.0, 500.0),
                                                           (0.0, 0.0, math.pi / 2))


def test_example_decodes():
    for data in (EXAMPLE, EXAMPLE + bytes(176), EXAMPLE + bytes(432), EXAMPLE + bytes(944)):
        frame = decode_mocap(data)                  # unpadded, 256, 512, 1024 bytes
        assert frame.frame_number == 7 and list(frame.poses) == ["ardrone"]
        p = frame.poses["ardrone"]
        assert p.translation_mm == (1000.0, -250.0, 500.0)
        assert p.position_m == (1.0, -0.25, 0.5)
        assert p.rotation_xyz_rad == (0.0, 0.0, math.pi / 2)
        assert p.psi_rad == pytest.approx(math.pi / 2) and p.fresh


def test_example_encodes_byte_exact():
    frame = MocapFrame.of(7, [MocapObjectPose("ardrone", (1000.0, -250.0, 500.0),
                                              (0.0, 0.0, math.pi / 2))])
    assert encode_mocap(frame, pad=False) == EXAMPLE
    padded = encode_mocap(frame)
    assert len(padded) == 256 and padded == EXAMPLE + bytes(176)


def test_second_item_is_not_aligned():
    frame = MocapFrame.of(1, [MocapObjectPose("a", (1, 2, 3), (0, 0, 0)),
                              MocapObjectPose("b", (4, 5, 6), (0, 0, 0))])
    raw = encode_mocap(frame, pad=False)
    assert len(raw) == 5 + 2 * 75 and raw[80:83] == b"\x00\x48\x00" and raw[83:84] == b"b"


@pytest.mark.parametrize("n, size", [(0, 256), (1, 256), (3, 256), (4, 1024), (13, 1024)])
def test_padding_sizes(n, size):
    frame = MocapFrame.of(3, [MocapObjectPose(f"obj{i}", (i, 0, 0), (0, 0, 0)) for i in range(n)])
    assert len(encode_mocap(frame)) == size
    assert len(encode_mocap(frame, pad=False)) == 5 + 75 * n
    assert decode_mocap(encode_mocap(frame)) == frame


def test_too_many_objects():
    assert MOCAP_MAX_OBJECTS == 13
    frame = MocapFrame.of(3, [MocapObjectPose(f"o{i}", (0, 0, 1), (0, 0, 0)) for i in range(14)])
    with pytest.raises(ValueError):
        encode_mocap(frame)


@pytest.mark.parametrize("name", ["", "x" * 25, "drône", "a\0b"])
def test_encoder_rejects_bad_names(name):
    with pytest.raises(ValueError):
        encode_mocap(MocapFrame.of(0, [MocapObjectPose(name, (1, 1, 1), (0, 0, 0))]))


def test_full_length_name_without_nul():
    frame = MocapFrame.of(0, [MocapObjectPose("x" * 24, (1, 1, 1), (0, 0, 0))])
    assert decode_mocap(encode_mocap(frame)) == frame


def test_unknown_items_and_longer_pose_items_are_skipped_by_size():
    data = (struct.pack("<IB", 9, 4) + struct.pack("<BH", 5, 10) + b"\x01" * 10 +
            pose_item(b"ardrone", (1, 2, 3), (0, 0, 0.5), extra=b"\xEE" * 8) +
            struct.pack("<BH", 200, 0) + pose_item(b"other", (4, 5, 6), (0, 0, 0)))
    frame = decode_mocap(data + bytes(7))
    assert list(frame.poses) == ["ardrone", "other"]
    assert frame.poses["ardrone"].translation_mm == (1.0, 2.0, 3.0)
    assert frame.poses["other"].position_m == (0.004, 0.005, 0.006)


def test_no_fresh_pose_forms():
    zero = decode_mocap(struct.pack("<IB", 1, 1) + pose_item(b"ardrone", (0, 0, 0), (0, 0, 0)))
    assert zero.poses["ardrone"].fresh is False
    negzero = MocapObjectPose("a", (-0.0, 0.0, 0.0), (0.0, -0.0, 0.0))
    assert negzero.fresh is False
    nan = MocapObjectPose("a", (1.0, math.nan, 0.0), (0.0, 0.0, 0.0))
    assert nan.fresh is False
    assert MocapObjectPose("a", (0.0, 0.0, 0.0), (0.0, 0.0, 1e-9)).fresh is True
    inf = decode_mocap(struct.pack("<IB", 1, 1) + pose_item(b"a", (1, 1, 1), (0, 0, math.inf)))
    assert inf.poses["a"].fresh is False and math.isnan(inf.poses["a"].psi_rad)
    missing = decode_mocap(struct.pack("<IB", 2, 0) + bytes(251))
    assert "ardrone" not in missing.poses and missing.frame_number == 2


def test_non_ascii_name_never_raises():
    frame = decode_mocap(struct.pack("<IB", 1, 1) + pose_item(b"dr\xf4ne", (1, 1, 1), (0, 0, 0)))
    assert list(frame.poses) == ["dr\\xf4ne"]


MALFORMED = {
    "empty": b"",
    "short header": b"\x01\x00\x00\x00",
    "missing item": struct.pack("<IB", 1, 1),
    "truncated item header": struct.pack("<IB", 1, 1) + b"\x00\x48",
    "overrun": struct.pack("<IB", 1, 1) + pose_item(b"a", (1, 1, 1), (0, 0, 0))[:-1],
    "count beyond items": EXAMPLE[:4] + b"\x02" + EXAMPLE[5:],
    "short pose item": struct.pack("<IB", 1, 1) + struct.pack("<BH", 0, 40) + bytes(40),
    "unknown item overrun": struct.pack("<IB", 1, 1) + struct.pack("<BH", 7, 300) + bytes(100),
    "duplicate name": struct.pack("<IB", 1, 2) + pose_item(b"a", (1, 1, 1), (0, 0, 0)) * 2,
}


@pytest.mark.parametrize("data", MALFORMED.values(), ids=MALFORMED.keys())
def test_malformed_raises_mocap_error(data):
    with pytest.raises(MocapError):
        decode_mocap(data)


def test_mocap_error_is_value_error():
    assert issubclass(MocapError, ValueError)


def test_frame_validation():
    with pytest.raises(ValueError):
        MocapFrame(2**32)
    with pytest.raises(ValueError):
        MocapFrame(1, {"a": MocapObjectPose("b", (1, 1, 1), (0, 0, 0))})
    with pytest.raises(ValueError):
        MocapFrame.of(1, [MocapObjectPose("a", (1, 1, 1), (0, 0, 0))] * 2)
    with pytest.raises(ValueError):
        MocapObjectPose("a", (1, 1), (0, 0, 0))
    with pytest.raises(TypeError):
        MocapFrame.of(1, []).poses["x"] = None   # read-only mapping


# ----------------------------------------------------------------------------- heading

ANGLE = st.floats(-math.pi, math.pi, allow_nan=False)


@PROPERTY
@given(ANGLE, st.floats(-1.5, 1.5), ANGLE)
def test_heading_matches_scipy_xyz(rx, ry, rz):
    m = Rotation.from_euler("XYZ", [rx, ry, rz]).as_matrix()
    expected = math.atan2(m[1, 0], m[0, 0])
    psi = rotation_heading_rad(rx, ry, rz)
    assert -math.pi < psi <= math.pi
    assert math.remainder(psi - expected, 2 * math.pi) == pytest.approx(0.0, abs=1e-9)
    # R = Rx·Ry·Rz, not the aviation Z-Y-X sequence.
    rx_, ry_, rz_ = (Rotation.from_euler(a, v).as_matrix() for a, v in
                     (("x", rx), ("y", ry), ("z", rz)))
    np.testing.assert_allclose(rx_ @ ry_ @ rz_, m, atol=1e-12)


def test_heading_pure_yaw_and_wrap():
    assert rotation_heading_rad(0.0, 0.0, 1.0) == pytest.approx(1.0)
    assert rotation_heading_rad(0.0, 0.0, -math.pi) == pytest.approx(math.pi)
    assert rotation_heading_rad(0.0, 0.0, 0.0) == 0.0
    # Large roll and pitch: ψ is not rz.
    assert abs(rotation_heading_rad(0.8, 0.6, 0.3) - 0.3) > 0.05


# ----------------------------------------------------------------------------- properties

F64 = st.one_of(st.floats(allow_nan=False), st.sampled_from([-0.0, 0.0]))
NAME = st.text(alphabet=st.characters(min_codepoint=1, max_codepoint=127), min_size=1,
               max_size=24)
POSES = st.builds(MocapObjectPose, NAME, st.tuples(F64, F64, F64), st.tuples(F64, F64, F64))
FRAMES = st.builds(MocapFrame.of, st.integers(0, 2**32 - 1),
                   st.lists(POSES, max_size=MOCAP_MAX_OBJECTS, unique_by=lambda p: p.name))


@PROPERTY
@given(FRAMES, st.booleans())
def test_round_trip(frame, pad):
    raw = encode_mocap(frame, pad=pad)
    assert len(raw) <= 1024
    if pad:
        assert len(raw) in (256, 1024)
    back = decode_mocap(raw)
    assert back == frame and list(back.poses) == list(frame.poses)
    assert encode_mocap(back, pad=pad) == raw        # bit-exact, −0.0 included
    for p in back.poses.values():
        assert p.fresh == (any(p.translation_mm + p.rotation_xyz_rad) and
                           all(map(math.isfinite, p.translation_mm + p.rotation_xyz_rad)))


def _decode_or_own_error(data: bytes) -> None:
    try:
        frame = decode_mocap(data)
    except MocapError:
        return
    assert isinstance(frame, MocapFrame)
    for name, p in frame.poses.items():
        assert p.name == name and isinstance(p.fresh, bool)


def _valid_pool() -> list[bytes]:
    rng = random.Random(51001)
    pool = [EXAMPLE, EXAMPLE + bytes(176)]
    for _ in range(200):
        poses = [MocapObjectPose(f"obj{i}", tuple(rng.uniform(-5e3, 5e3) for _ in range(3)),
                                 tuple(rng.uniform(-3, 3) for _ in range(3)))
                 for i in range(rng.randrange(0, 6))]
        pool.append(encode_mocap(MocapFrame.of(rng.randrange(2**32), poses),
                                 pad=rng.random() < 0.5))
    return pool


VALID = st.sampled_from(_valid_pool())


@FUZZ
@given(st.binary(max_size=1100))
def test_arbitrary_bytes(data):
    _decode_or_own_error(data)


@FUZZ
@given(st.binary(max_size=300))
def test_arbitrary_items_after_a_header(data):
    for count in (1, 2, 255):
        _decode_or_own_error(struct.pack("<IB", 5, count) + data)


@FUZZ
@given(VALID, st.data())
def test_truncated_datagrams(raw, draw):
    cut = draw.draw(st.integers(0, len(raw) - 1))
    _decode_or_own_error(raw[:cut])


@FUZZ
@given(VALID, st.data())
def test_single_byte_corruptions(raw, draw):
    i = draw.draw(st.integers(0, len(raw) - 1))
    b = draw.draw(st.one_of(st.integers(0, 255), st.sampled_from([0, 1, 2, 72, 75, 0x80, 0xFF])))
    _decode_or_own_error(raw[:i] + bytes([b]) + raw[i + 1:])


def test_from_si_converts_metres_to_the_wire_millimetres():
    pose = MocapObjectPose.from_si("car", np.array([1.2, -0.5, 0.75]), (0.1, 0.2, 0.3))
    assert pose.translation_mm == (1200.0, -500.0, 750.0)
    assert pose.rotation_xyz_rad == (0.1, 0.2, 0.3)
    decoded = decode_mocap(encode_mocap(MocapFrame.of(1, [pose]))).poses["car"]
    np.testing.assert_allclose(decoded.position_m, [1.2, -0.5, 0.75], atol=1e-12)
