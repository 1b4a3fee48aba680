"""A lockstep flight with a sensor fault whose mocap link's class overrides the receipt of the
bytes: the sampler hands that link bytes (its override runs), never the decoded frames that
would skip it, and the flight's rows are the plain link's; one that overrides ``feed_frame``
gets every frame through it (no bulk receipt), with the same rows."""

from __future__ import annotations

import math

import ardrone_nmpc.runtime.lockstep as lockstep
import ardrone_nmpc.sim.lockstep_drone as lockstep_drone
from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.links.mocap_link import MocapLink
from ardrone_nmpc.runs.memory import MemoryRecorder
from ardrone_nmpc.sim.sensors import LockstepSensors

OVERRIDES = ["duration_s=3", "sim.settle_s=1", "faults.mocap_dropout.start_s=1",
             "faults.mocap_dropout.duration_s=0.2"]


class _CountingLink(MocapLink):
    """A link whose ``feed`` (the bytes' receipt) counts its calls, then does what it did."""

    fed = 0

    def feed(self, data: bytes, t_s: float, sender=("lockstep", 0)) -> None:
        type(self).fed += 1
        super().feed(data, t_s, sender)


class _CountingSensors(LockstepSensors):
    def __init__(self, cfg, drone, on_navdata=None, t_zero_s=math.inf, **options):
        super().__init__(cfg, drone, on_navdata, t_zero_s, **options)
        link = self.mocap
        self.mocap = _CountingLink("127.0.0.1", 0, object_name=link.object_name,  # never
                                   other_objects=link.other_objects)              # opened


def _rows(cfg):
    recorder = MemoryRecorder()
    result = lockstep.run_lockstep(cfg, recorder=recorder)
    return result, [dict(r) for r in recorder.rows]


def test_an_overridden_receipt_gets_the_bytes_and_flies_the_same_rows(monkeypatch):
    cfg = load_config("configs/hover.yaml", OVERRIDES)
    plain, plain_rows = _rows(cfg)
    monkeypatch.setattr(lockstep_drone, "LockstepSensors", _CountingSensors)
    _CountingLink.fed = 0
    counted, counted_rows = _rows(cfg)
    # every frame sent arrives through feed: ~100 Hz over the flight, less the dropout
    assert _CountingLink.fed > 100
    assert counted.ticks == plain.ticks > 30
    skip = {"solve_us", "compute_us", "tick_late_ms"}
    assert [{k: repr(v) for k, v in r.items() if k not in skip} for r in counted_rows] == \
        [{k: repr(v) for k, v in r.items() if k not in skip} for r in plain_rows]


class _FrameCountingLink(MocapLink):
    """A link whose ``feed_frame`` (the decoded hand-over) counts its calls, then does what it
    did: the quiet ticks' bulk receipt (``feed_object_frames``) would skip it."""

    framed = 0

    def feed_frame(self, frame, t_s: float, sender=("lockstep", 0)) -> None:
        type(self).framed += 1
        super().feed_frame(frame, t_s, sender)


class _FrameCountingSensors(LockstepSensors):
    def __init__(self, cfg, drone, on_navdata=None, t_zero_s=math.inf, **options):
        super().__init__(cfg, drone, on_navdata, t_zero_s, **options)
        link = self.mocap
        self.mocap = _FrameCountingLink("127.0.0.1", 0, object_name=link.object_name,
                                        other_objects=link.other_objects)


def test_an_overridden_feed_frame_gets_every_frame_and_flies_the_same_rows(monkeypatch):
    cfg = load_config("configs/hover.yaml", OVERRIDES)
    plain, plain_rows = _rows(cfg)
    monkeypatch.setattr(lockstep_drone, "LockstepSensors", _FrameCountingSensors)
    _FrameCountingLink.framed = 0
    counted, counted_rows = _rows(cfg)
    # every frame sent — quiet ticks' included — arrives through feed_frame (~100 Hz over
    # the 4 s flight less the 0.2 s dropout; the bulk receipt would leave only the window's)
    assert _FrameCountingLink.framed > 300
    assert counted.ticks == plain.ticks > 30
    skip = {"solve_us", "compute_us", "tick_late_ms"}
    assert [{k: repr(v) for k, v in r.items() if k not in skip} for r in counted_rows] == \
        [{k: repr(v) for k, v in r.items() if k not in skip} for r in plain_rows]
