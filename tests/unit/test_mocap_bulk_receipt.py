"""A mocap link's bulk receipt of frames carrying its object alone
(``MocapLink.feed_object_frames``, on ``LinkStats.record_numbered`` and
``MocapSource.accept_object_frames``) leaves the link as ``feed_frame`` of each frame in turn
does — the reference — over random streams: repeated numbers, reordered and restarted ones,
silences past the restart and relock times, bit-identical, zero (±0.0) and non-finite poses,
and frames of other senders, objects and malformed datagrams in between."""

from __future__ import annotations

import math
import random

import pytest

from ardrone_nmpc.links.mocap_link import MocapLink
from ardrone_nmpc.links.udp import LinkStats
from ardrone_nmpc.protocol.mocap import MocapFrame, MocapObjectPose, encode_mocap
from tests.link_state import bits, link_state

NAME, OTHER = "ardrone", "car"
NUMBER_BETWEEN = 7  # the number of a frame received between two runs


def _pose(rng: random.Random, last):
    """A pose (position m, rotation rad): mostly new, often the last one again, sometimes
    zero (either sign), non-finite or with a zero rotation."""
    roll = rng.random()
    if last is not None and roll < 0.3:
        return last
    if roll < 0.38:
        z = rng.choice([0.0, -0.0])
        return [z, 0.0, z], [0.0, z, 0.0]
    if roll < 0.42:
        return [rng.uniform(-2, 2), math.nan, 1.0], [0.0, 0.0, rng.choice([math.inf, 0.1])]
    position = [rng.uniform(-2, 2) for _ in range(3)]
    return position, ([0.0, 0.0, 0.0] if roll < 0.46 else [rng.uniform(-3, 3) for _ in range(3)])


def _stream(rng: random.Random, n: int) -> list:
    """``n`` frames ``(number, t_s, position_m, rotation_xyz_rad)``, numbers and times as a
    faulty stream has them."""
    # (times of 1/128 s steps: a silence of exactly the restart time, 0.5 s, is one)
    frames, number, t_s, last = [], rng.randrange(0, 50), rng.randrange(128) / 128, None
    step = 1 / 128
    for _ in range(n):
        r = rng.random()
        number = (number + 1 if r < 0.6 else number if r < 0.7  # (next, duplicate)
                  else max(0, number - rng.randrange(1, 5)) if r < 0.8  # (reordered)
                  else number + rng.randrange(2, 6) if r < 0.95  # (a gap)
                  else rng.randrange(0, 3))  # (a restart)
        t_s += (rng.choice([step, 0.0, 2 * step, 0.5, 0.5 - step, 0.75, 2.0, 2.5])
                if rng.random() < 0.2 else step)
        last = _pose(rng, last)
        frames.append((number & 0xFFFFFFFF, t_s, list(last[0]), list(last[1])))
    return frames


def _frame(number: int, position_m, rotation) -> MocapFrame:
    return MocapFrame.of(number, [MocapObjectPose.from_si(NAME, position_m, rotation)])


def _between(rng: random.Random, t_s: float, kind: int | None = None):
    """Something else the link receives between two runs of frames (both links alike)."""
    kind = rng.randrange(4) if kind is None else kind
    if kind == 0:  # another sender (foreign, or taking over after a silence)
        return lambda link: link.feed_frame(_frame(NUMBER_BETWEEN, [1.0, 2.0, 3.0], [0, 0, 1]),
                                            t_s, ("10.0.0.9", 51001))
    if kind == 1:  # the object and the other one
        frame = MocapFrame.of(NUMBER_BETWEEN,
                              [MocapObjectPose.from_si(NAME, [0.5, 0, 1], [0, 0, 0]),
                               MocapObjectPose.from_si(OTHER, [3, 1, 0], [0, 0, 2])])
        return lambda link: link.feed_frame(frame, t_s)
    if kind == 2:  # a malformed datagram
        return lambda link: link.feed(b"\x01\x02", t_s)
    data = encode_mocap(_frame(NUMBER_BETWEEN, [0.1, 0.2, 0.3], [0.0, 0.1, 0.2]))
    return lambda link: link.feed(data, t_s)





@pytest.mark.parametrize("seed", range(40))
def test_bulk_receipt_leaves_the_link_as_frame_by_frame(seed):
    rng = random.Random(seed)
    kwargs = {"object_name": NAME, "clock": lambda: 0.0}
    if seed % 4 == 1:
        kwargs["other_objects"] = (OTHER,)
    if seed % 4 == 2:
        kwargs["repeat_limit"] = rng.choice([2, 4, None])
    if seed % 8 == 3:
        kwargs["other_objects"] = (NAME,)  # (the object kept as another one, too)
    reference, bulk = MocapLink("127.0.0.1", 0, **kwargs), MocapLink("127.0.0.1", 0, **kwargs)
    frames = _stream(rng, rng.randrange(1, 120))
    if seed % 5 == 0:  # a foreign sender first: the link not locked yet, or onto it
        first = _between(rng, 0.0, kind=0)
        first(reference)
        first(bulk)
    at = 0
    while at < len(frames):
        run = frames[at:at + rng.randrange(0, 12)]
        at += len(run)
        for number, t_s, position_m, rotation in run:
            reference.feed_frame(_frame(number, position_m, rotation), t_s)
        bulk.feed_object_frames([(n, t, list(p), list(r)) for n, t, p, r in run])
        assert link_state(bulk) == link_state(reference)
        if rng.random() < 0.3:
            # (after a silence of the relock time: another sender takes over)
            other = _between(rng, (run[-1][1] if run else 0.0) + rng.choice([0.0, 2.0]))
            other(reference)
            other(bulk)
    assert link_state(bulk) == link_state(reference)
    assert bits(bulk.latest()) == bits(reference.latest())
    assert bulk.take_events() == reference.take_events()


def test_the_state_compared_tells_links_apart():
    """(The comparison above sees a frame's difference: a pose, a time, a number.)"""
    a, b = MocapLink("127.0.0.1", 0, object_name=NAME), MocapLink("127.0.0.1", 0,
                                                                 object_name=NAME)
    a.feed_object_frames([(1, 0.0, [1.0, 2.0, 3.0], [0.0, 0.0, 0.5])])
    for changed in [(1, 0.0, [1.0, 2.0, 3.0], [0.0, 0.0, 0.25]),
                    (1, 1e-9, [1.0, 2.0, 3.0], [0.0, 0.0, 0.5]),
                    (2, 0.0, [1.0, 2.0, 3.0], [0.0, 0.0, 0.5])]:
        b = MocapLink("127.0.0.1", 0, object_name=NAME)
        b.feed_frame(_frame(changed[0], changed[2], changed[3]), changed[1])
        assert link_state(a) != link_state(b)


@pytest.mark.parametrize("seed", range(20))
def test_record_numbered_leaves_the_stats_as_the_calls_one_by_one(seed):
    rng = random.Random(seed)
    reference, bulk = LinkStats(window_s=0.05), LinkStats(window_s=0.05, restart_backjump=100)
    t_s, numbered = 0.0, []
    for _ in range(rng.randrange(1, 80)):
        t_s += rng.choice([0.0, 0.01, 0.03, 0.2, -0.01])  # (even a time going back)
        numbered.append((rng.choice([rng.randrange(0, 300), len(numbered)]), t_s,
                         rng.random() < 0.1))
    accepted = []
    for seq, t, restart_ok in numbered:
        reference.record_datagram()
        accepted.append(reference.accept_sequence(seq, restart_ok=restart_ok))
        if accepted[-1]:
            reference.record_packet(t)
    cut = rng.randrange(len(numbered) + 1)
    assert bulk.record_numbered(numbered[:cut]) + bulk.record_numbered(numbered[cut:]) == accepted
    state = {k: bits(v) for k, v in vars(reference).items() if k != "_lock"}
    assert {k: bits(v) for k, v in vars(bulk).items() if k != "_lock"} == state
    assert True in accepted and reference.datagrams == len(numbered)


def _record_bits(record) -> tuple:
    return (bits(record.t_s), tuple(bits(v) for v in record.position_m),
            tuple(bits(v) for v in record.rotation_xyz_rad), bits(record.psi_rad),
            record.position_m.flags.writeable, record.rotation_xyz_rad.flags.writeable)


@pytest.mark.parametrize("seed", range(5))
def test_the_newest_pose_record_is_the_wire_poses_one(seed):
    """``_pose_of_floats`` (the bulk receipt's record, no wire pose built) is bit for bit
    ``mocap_pose_of`` of the :class:`MocapObjectPose` of the same floats."""
    from ardrone_nmpc.links.mocap_source import _pose_of_floats, mocap_pose_of

    rng = random.Random(seed)
    for _ in range(200):
        position_m, rotation = _pose(rng, None)
        translation_mm = tuple(float(v) * 1000.0 for v in position_m)
        rotation = tuple(float(v) for v in rotation)
        t_s = rng.uniform(0.0, 100.0)
        reference = mocap_pose_of(MocapObjectPose(NAME, translation_mm, rotation), t_s)
        assert _record_bits(_pose_of_floats(t_s, translation_mm, rotation)) == \
            _record_bits(reference)


def test_the_newest_pose_record_in_closed_form():
    """Metres are millimetres / 1000; a rotation about z alone is the heading."""
    from ardrone_nmpc.links.mocap_source import _pose_of_floats

    record = _pose_of_floats(2.5, (1500.0, -250.0, 1000.0), (0.0, 0.0, 0.5))
    assert record.t_s == 2.5
    assert list(record.position_m) == [1.5, -0.25, 1.0]
    assert list(record.rotation_xyz_rad) == [0.0, 0.0, 0.5]
    assert record.psi_rad == pytest.approx(0.5, abs=1e-15)
    assert not record.position_m.flags.writeable
