"""One sender per mocap stream (links/mocap_link.py), datagram by datagram through ``feed``:
lock onto the first sender of the object, ignore and report the others, relock only after a
silence, restart the numbering only after a silence."""

import pytest

from ardrone_nmpc.links.mocap_link import MocapLink
from ardrone_nmpc.protocol.mocap import MocapFrame, MocapObjectPose, encode_mocap

A, B, C = ("10.0.0.2", 51000), ("10.0.0.3", 40000), ("10.0.0.2", 51001)


def frame(k, x_mm, name="ardrone"):
    return encode_mocap(MocapFrame.of(k, [MocapObjectPose(name, (x_mm, 0.0, 1000.0),
                                                          (0.0, 0.0, 0.1))]))


def x_of(link):
    return link.latest()[0].position_m[0]


def test_the_first_sender_of_the_object_is_locked_and_others_never_move_the_pose():
    link = MocapLink(object_name="ardrone")
    link.feed(frame(1, 5.0, name="wand"), 0.00, B)       # not our object: no lock
    assert link.sender is None and link.latest()[0] is None
    link.feed(frame(7, 10.0), 0.01, A)
    assert link.sender == "10.0.0.2:51000" and x_of(link) == pytest.approx(0.010)
    for k in range(1, 50):                                  # a stale replay from frame 1
        link.feed(frame(k, 800.0 + k), 0.01 + k * 1e-3, B)
    link.feed(frame(1, 800.0), 0.2, C)                      # same host, another port
    assert x_of(link) == pytest.approx(0.010)
    assert link.foreign_senders == {"10.0.0.3:40000": 50, "10.0.0.2:51001": 1}
    assert link.frames_from("10.0.0.2:51000") == 1 and link.frames_from("x:1") == 0
    assert link.stats.foreign == 51 and link.stats.packets == 1 and link.stats.datagrams == 52
    link.feed(frame(8, 11.0), 0.21, A)                      # the live stream goes on
    assert x_of(link) == pytest.approx(0.011)
    events = link.take_events()
    assert [(e["kind"], e["sender"]) for e in events] == [
        ("mocap_foreign_sender", "10.0.0.3:40000"), ("mocap_sender", "10.0.0.2:51000"),
        ("mocap_foreign_sender", "10.0.0.2:51001")]
    assert events[0]["carries_object"] is False and events[0]["locked_sender"] is None
    assert events[1]["frame"] == 7                         # the frame it was locked on
    assert events[2]["carries_object"] is True and events[2]["locked_sender"] == \
        "10.0.0.2:51000" and events[2]["frame"] == 1
    assert link.take_events() == []


def test_a_sender_numbered_ahead_does_not_starve_the_live_stream():
    link = MocapLink(object_name="ardrone")
    link.feed(frame(1, 1.0), 0.00, A)
    link.feed(frame(90000, 900.0), 0.005, B)
    link.feed(frame(2, 2.0), 0.01, A)
    assert x_of(link) == pytest.approx(0.002) and link.stats.out_of_order == 0


def test_another_sender_takes_over_only_after_the_relock_silence():
    link = MocapLink(object_name="ardrone", relock_silence_s=2.0)
    link.feed(frame(100, 1.0), 0.0, A)
    link.feed(frame(1, 2.0), 1.99, B)                      # A silent 1.99 s: still A's
    assert x_of(link) == pytest.approx(0.001) and link.sender == "10.0.0.2:51000"
    link.feed(frame(2, 3.0), 2.0, B)                       # 2.0 s: B takes over
    assert x_of(link) == pytest.approx(0.003) and link.sender == "10.0.0.3:40000"
    link.feed(frame(3, 4.0), 2.01, B)
    assert x_of(link) == pytest.approx(0.004)
    link.feed(frame(101, 9.0), 2.02, A)                    # the old sender is foreign now
    assert x_of(link) == pytest.approx(0.004)
    kinds = [e["kind"] for e in link.take_events()]
    assert kinds == ["mocap_sender", "mocap_foreign_sender", "mocap_sender_changed"]


def test_the_numbering_restarts_only_after_a_silence():
    link = MocapLink(object_name="ardrone", restart_silence_s=0.5)
    link.feed(frame(500, 1.0), 0.0, A)
    link.feed(frame(3, 2.0), 0.49, A)                      # back-jump, no silence: dropped
    assert x_of(link) == pytest.approx(0.001) and link.stats.out_of_order == 1
    link.feed(frame(3, 3.0), 0.99, A)                      # 0.5 s silent: a restart
    assert x_of(link) == pytest.approx(0.003) and link.stats.restarts == 1
    link.feed(frame(4, 4.0), 1.0, A)
    assert x_of(link) == pytest.approx(0.004) and link.stats.lost == 0


def test_the_lockstep_feed_is_one_sender():
    link = MocapLink(object_name="ardrone")
    for k in range(1, 4):
        link.feed(frame(k, float(k)), k * 0.01)
    assert link.sender == "lockstep:0" and x_of(link) == pytest.approx(0.003)
    assert link.foreign_senders == {}


def test_a_foreign_sender_of_the_object_is_a_contender_and_one_of_other_objects_is_not():
    link = MocapLink(object_name="ardrone")
    assert link.contenders == []
    link.feed(frame(1, 1.0), 0.00, A)                      # locked
    link.feed(frame(1, 5.0, name="wand"), 0.01, C)         # another object: no contender
    assert link.contenders == []
    link.feed(frame(1, 800.0), 0.02, B)                    # the object again: a contender
    assert link.contenders == ["10.0.0.3:40000"] and x_of(link) == pytest.approx(0.001)


def test_the_defaults_are_the_documented_ones():
    """docs/mocap-stream.md: all interfaces, port 51001, relock after 2 s of silence, a pose
    frozen from its 3rd bit-identical frame."""
    link = MocapLink()
    assert link.where == "udp 0.0.0.0:51001" and link.object_name == "ardrone"
    link.feed(frame(100, 1.0), 0.0, A)
    link.feed(frame(1, 2.0), 1.99, B)
    assert x_of(link) == pytest.approx(0.001)
    link.feed(frame(2, 3.0), 2.0, B)
    assert x_of(link) == pytest.approx(0.003) and link.sender == "10.0.0.3:40000"
    events = link.take_events()
    assert events[-1] == {"kind": "mocap_sender_changed", "sender": "10.0.0.3:40000",
                          "frame": 2}


def test_repeat_limit_is_the_links_own():
    link = MocapLink(object_name="ardrone", repeat_limit=5)
    for k in range(1, 7):
        link.feed(frame(k, 1.0), 0.01 * k, A)              # bit-identical six frames running
    assert link.poses == 4 and link.repeats == 2
