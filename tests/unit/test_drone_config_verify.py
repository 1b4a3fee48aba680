"""``verify_config`` against its documented contract (docs/protocol.md §3): a held number
within a relative 1e-3 of the written one is the same (float32 storage, a few printed digits),
anything beyond — the 5–10 % of a half-applied profile as much as the 60 % of the outdoor one —
is refused; TRUE/FALSE compare case-insensitively, other text exactly; a missing key or a
non-finite number is a mismatch. The limits' unit conversions (§3.1: mm/s, mm) against the
drone's key table."""

from __future__ import annotations

import math

import pytest

import re
from pathlib import Path

from ardrone_nmpc.links.drone_config import (
    ConfigMismatch,
    _number_text,
    check_config_id,
    check_positive,
    verify_config,
)

ROOT = Path(__file__).parents[2]

KEY = "control:euler_angle_max"


def _refused(written: str, held: str | None) -> bool:
    out = verify_config({KEY: written}, {} if held is None else {KEY: held})
    assert len(out) <= 1
    return bool(out)


@pytest.mark.parametrize("frac", [0.5, 0.1, 0.07, 0.05, 0.02, 0.01, 0.005, 0.002, 0.0011])
@pytest.mark.parametrize("value", [0.21, 0.52, 700.0, 2000.0, 6.11])
@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_a_held_number_off_by_more_than_a_part_in_a_thousand_is_refused(frac, value, sign):
    held = value * (1.0 + sign * frac)
    assert _refused(repr(value), repr(held))
    assert _refused(repr(held), repr(value))  # the tolerance is symmetric


@pytest.mark.parametrize("frac", [0.0, 1e-6, 1e-4, 5e-4, 0.0009])
@pytest.mark.parametrize("value", [0.2094, 0.52, 700.0, 2000.0, 6.11])
@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_a_held_number_within_a_part_in_a_thousand_is_the_same(frac, value, sign):
    held = value * (1.0 + sign * frac)
    assert not _refused(repr(value), repr(held))
    assert not _refused(repr(held), repr(value))


def test_exactly_a_part_in_a_thousand_of_the_larger_value_is_the_same_either_way():
    """The bound is inclusive and relative to the larger of the two, so the check does not
    depend on which side wrote: 999 and 1000 are a part in a thousand of 1000 apart."""
    assert not _refused("999", "1000") and not _refused("1000", "999")
    assert _refused("998.99", "1000") and _refused("1000", "998.99")


def test_the_firmwares_float32_printouts_are_the_values_written():
    """What the firmware prints back for a float32 key (docs/protocol.md §3) against the text
    written: the same value, whatever the digits."""
    import numpy as np

    for written in ("0.2094", "0.35", "0.52", "6.11", "1.7453293"):
        held = f"{float(np.float32(float(written))):.7e}"  # 0.2094 → "2.0940000e-01"
        assert not _refused(written, held)
    assert not _refused("700", "700.000000")
    assert not _refused("1000", " 1000 ")  # surrounding blanks are not a difference


def test_zero_against_zero_and_against_a_tiny_number():
    """The scale is max(|a|, |b|, 1e-9): 0 is 0.0, and a number 1e-13 away from 0 is 0, but
    1e-6 (a thousand times the floor) is not."""
    assert not _refused("0", "0.0")
    assert not _refused("0", "-0")
    assert not _refused("0", "1e-13")
    assert _refused("0", "1e-6")
    assert _refused("1e-6", "0")


@pytest.mark.parametrize("held", ["nan", "inf", "-inf", "NaN"])
def test_a_non_finite_number_is_never_the_same(held):
    assert _refused(held, held)
    assert _refused("0.52", held)
    assert _refused(held, "0.52")


@pytest.mark.parametrize("written, held, same", [
    ("TRUE", "TRUE", True), ("TRUE", "true", True), ("FALSE", "False", True),
    (" FALSE", "FALSE ", True), ("TRUE", "FALSE", False), ("FALSE", "TRUE", False),
    ("TRUE", "1", False), ("1", "TRUE", False), ("FALSE", "0", False), ("0", "false", False),
])
def test_booleans_compare_case_insensitively_and_never_as_numbers(written, held, same):
    assert _refused(written, held) is not same


@pytest.mark.parametrize("written, held, same", [
    ("ardrone2", "ardrone2", True), (" ardrone2 ", "ardrone2", True),
    ("ardrone2", "Ardrone2", False), ("ab12cd34", "ab12cd35", False), ("a", "", False),
])
def test_other_text_compares_exactly_but_for_blanks(written, held, same):
    assert _refused(written, held) is not same


def test_a_missing_key_is_a_mismatch_holding_none_and_order_is_the_written_order():
    written = {"control:outdoor": "FALSE", "control:altitude_max": "3000",
               "control:control_vz_max": "700", "control:control_yaw": "1.75"}
    held = {"control:outdoor": "TRUE", "control:control_vz_max": "700.000000",
            "control:control_yaw": "1.9", "other:key": "1"}
    out = verify_config(written, held)
    assert out == [ConfigMismatch("control:outdoor", "FALSE", "TRUE"),
                   ConfigMismatch("control:altitude_max", "3000", None),
                   ConfigMismatch("control:control_yaw", "1.75", "1.9")]
    assert verify_config(written, dict(held, **{"control:outdoor": "FALSE",
                                                "control:altitude_max": "3000.0",
                                                "control:control_yaw": "1.75"})) == []
    assert verify_config({}, held) == []


def test_written_values_that_are_not_text_are_compared_as_their_text():
    assert verify_config({KEY: 0.52}, {KEY: "0.5200"}) == []
    assert verify_config({KEY: 0.52}, {KEY: "0.55"}) == [ConfigMismatch(KEY, "0.52", "0.55")]


def test_a_mismatch_line_names_the_key_both_values_and_the_way_out():
    line = ConfigMismatch(KEY, "0.21", "0.35").line()
    assert KEY in line and "'0.35'" in line and "'0.21'" in line
    # the way out: the session whose limits the drone holds, and where to read its ids
    assert "drone.config_ids" in line and "ardrone-nmpc status" in line
    missing = ConfigMismatch(KEY, "0.21", None).line()
    assert "nothing (key missing)" in missing and "None" not in missing
    # the same sentence, "nothing (key missing)" where the held value would stand
    assert missing == line.replace("'0.35'", "nothing (key missing)")


def test_a_mismatch_line_is_the_one_docs_first_flight_lists():
    """docs/first-flight.md's table of refusals quotes the line's start (up to its "…") for
    its example, and gives the way out: set drone.config_ids, `ardrone-nmpc status` shows
    the ids."""
    table = (ROOT / "docs" / "first-flight.md").read_text()
    row = next(r for r in table.splitlines() if r.startswith("| `the drone holds "))
    quoted = re.match(r"\| `(.*) …` \|", row).group(1)
    key, held, written = re.match(r"the drone holds (\S+) = '(.*)', not the '(.*)' written",
                                  quoted).groups()
    line = ConfigMismatch(key, written, held).line()
    assert line.startswith(quoted + " ")
    assert "set drone.config_ids to that session (`ardrone-nmpc status` shows its ids" in line
    assert "\n" not in line and line.endswith("then retry")


@pytest.mark.parametrize("good", ["d2e081a3", "D2E081A3", "00000000", "aBcDeF09"])
def test_a_config_id_is_eight_hex_digits_of_either_case(good):
    """docs/protocol.md §3.3: 8 hex digits each."""
    assert check_config_id(good) == good


@pytest.mark.parametrize("bad", ["d2e081a", "d2e081a3f", "", "abc", "g2e081a3", "XXXXXXXX",
                                 "d2e081a ", "0x2e081a", 12345678, None])
def test_anything_but_eight_hex_digits_is_no_config_id(bad):
    with pytest.raises(ValueError, match="config ids must be 8 hex digits"):
        check_config_id(bad)


@pytest.mark.parametrize("bad", [0.0, -0.0, -1.0, math.nan, math.inf, -math.inf])
def test_check_positive_refuses_what_is_not_finite_and_positive(bad):
    with pytest.raises(ValueError, match="altitude_max_m must be finite and > 0"):
        check_positive("altitude_max_m", bad)


@pytest.mark.parametrize("good", [1e-12, 0.2, 1.0, 3000.0])
def test_check_positive_returns_the_value_as_a_float(good):
    out = check_positive("x", good)
    assert out == good and type(out) is float
    assert type(check_positive("x", 3)) is float


@pytest.mark.parametrize("x, text", [(1000.0, "1000"), (700.0, "700"), (0.0, "0"),
                                     (699.9999999, "700"), (0.35, "0.35"), (1234.5, "1234.5")])
def test_whole_numbers_go_out_as_integers(x, text):
    """§3.1: control_vz_max in mm/s; a whole value written ``1000``, not ``1000.0``."""
    out = _number_text(x)
    assert str(out) == text
    assert isinstance(out, int) is ("." not in text)
