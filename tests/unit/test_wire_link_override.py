"""A lockstep flight with a sensor fault whose mocap link's class overrides the receipt of the
bytes: the sampler hands that link bytes (its override runs), never the decoded frames that
would skip it, and the flight's rows are the plain link's; one that overrides ``feed_frame``
gets every frame through it (no bulk receipt), with the same rows."""

from __future__ import annotations

import math

import pytest

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

    calls = 0

    def feed(self, data: bytes, t_s: float, sender=("lockstep", 0)) -> None:
        type(self).calls += 1
        super().feed(data, t_s, sender)


class _FrameCountingLink(MocapLink):
    """A link whose ``feed_frame`` (the decoded hand-over) counts its calls, then does what it
    did: the quiet ticks' bulk receipt (``feed_object_frames``) would skip it."""

    calls = 0

    def feed_frame(self, frame, t_s: float, sender=("lockstep", 0)) -> None:
        type(self).calls += 1
        super().feed_frame(frame, t_s, sender)


def _sensors_with(link_class):
    """A sampler whose mocap link is a ``link_class`` (never opened) in the plain one's place."""

    class _Sensors(LockstepSensors):
        def __init__(self, cfg, drone, on_navdata=None, t_zero_s=math.inf, **options):
            super().__init__(cfg, drone, on_navdata, t_zero_s, **options)
            link = self.mocap
            self.mocap = link_class("127.0.0.1", 0, object_name=link.object_name,
                                    other_objects=link.other_objects)

    return _Sensors


def _rows(cfg):
    recorder = MemoryRecorder()
    result = lockstep.run_lockstep(cfg, recorder=recorder)
    return result, [dict(r) for r in recorder.rows]


# every frame sent arrives through the override: ~100 Hz over the 4 s flight, less the 0.2 s
# dropout (feed: more than 100; feed_frame: more than 300 — the bulk receipt would leave it
# only the Python path's, ~27)
@pytest.mark.parametrize("link_class, min_calls", [(_CountingLink, 100),
                                                   (_FrameCountingLink, 300)])
def test_an_overridden_receipt_gets_every_frame_and_flies_the_same_rows(monkeypatch, link_class,
                                                                         min_calls):
    cfg = load_config("configs/hover.yaml", OVERRIDES)
    plain, plain_rows = _rows(cfg)
    monkeypatch.setattr(lockstep_drone, "LockstepSensors", _sensors_with(link_class))
    link_class.calls = 0
    counted, counted_rows = _rows(cfg)
    assert link_class.calls > min_calls
    assert counted.ticks == plain.ticks > 30
    skip = {"solve_us", "compute_us", "tick_late_ms"}
    assert [{k: repr(v) for k, v in r.items() if k not in skip} for r in counted_rows] == \
        [{k: repr(v) for k, v in r.items() if k not in skip} for r in plain_rows]
