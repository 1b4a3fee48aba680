"""``MotionCaptureSource`` reading its library process, against a stand-in child that writes the
documented line protocol (``_motioncapture_child.py``'s docstring: ``{"connected": true}`` or
``{"error": …}`` first, then ``{"b": [[name, x, y, z, qw, qx, qy, qz], …]}`` or
``{"frame_error": …}`` per frame; it ends when it exits): frames after a bad line still
arrive, errors are counted with their text, a child that dies before connecting names its
exit code, and a library that raises an empty exception is named by its type."""

from __future__ import annotations

import io
import json
import math

import pytest

from ardrone_nmpc.links import motioncapture_source as mcs
from ardrone_nmpc.links.mocap_source import MocapConnectError
from ardrone_nmpc.links.motioncapture_source import MotionCaptureSource


class StandInChild:
    """A child process that has written ``lines`` and exited with ``code``."""

    def __init__(self, lines: list[bytes], code: int = 0) -> None:
        self.stdout = io.BytesIO(b"".join(lines))
        self.code = code

    def poll(self):
        return self.code

    def wait(self, timeout=None):
        return self.code

    def terminate(self):  # pragma: no cover - it has exited
        pass

    kill = terminate


def _line(record) -> bytes:
    return (json.dumps(record) + "\n").encode()


def _body(name, x, y, z, qw=1.0, qx=0.0, qy=0.0, qz=0.0):
    return [name, x, y, z, qw, qx, qy, qz]


@pytest.fixture
def child(monkeypatch):
    made = {}

    def popen(lines, code=0):
        monkeypatch.setattr(mcs.subprocess, "Popen",
                            lambda *a, **k: made.setdefault("child", StandInChild(lines, code)))
        return made

    return popen


def _started(lines, child, code=0) -> MotionCaptureSource:
    child(lines, code)
    ticks = iter(range(1, 1000))
    src = MotionCaptureSource("mock", {"hostname": "h"}, connect_timeout_s=10.0,
                              clock=lambda: float(next(ticks)), repeat_limit=None)
    src.start()
    src._thread.join(timeout=10.0)          # the stand-in's stream ends: so does the thread
    assert not src._thread.is_alive()
    return src


def test_frames_after_an_unreadable_line_still_arrive_and_errors_are_counted(child):
    junk = b"x" * 100 + b"\n"
    src = _started([_line({"connected": True}),
                    _line({"b": [_body("ardrone", 1.0, 2.0, 3.0)]}),
                    junk,
                    _line({"b": [_body("ardrone", 1.5, 2.0, 3.0)]}),
                    _line({"frame_error": "no frame"}),
                    _line({"b": [_body("ardrone", 2.0, -1.0, 0.5, 0.0, 0.0, 0.0, 1.0)]})],
                   child)
    assert src.poses == 3 and src.frame_errors == 2
    assert src.last_error == "mocap: mock@h: no frame"
    pose, rx_t = src.latest()
    assert pose.position_m.tolist() == [2.0, -1.0, 0.5]
    assert pose.psi_rad == pytest.approx(math.pi)        # (w, z) = (0, 1): half a turn
    assert rx_t == 6.0   # stamped on receipt: the clock read as its line (the 6th) arrives


def test_an_unreadable_line_is_reported_by_its_first_80_characters(child):
    junk = b"y" * 100 + b"\n"
    src = _started([_line({"connected": True}), junk], child)
    assert src.frame_errors == 1
    assert src.last_error == ("mocap: mock@h: unreadable line from the library process: "
                              f"{junk[:80]!r}")


def test_a_connection_error_line_fails_start_with_its_text(child):
    with pytest.raises(MocapConnectError,
                       match=r"^mocap: cannot connect to mock@h: Unknown host$"):
        _started([_line({"error": "Unknown host"})], child, code=2)


def test_a_child_that_ends_before_connecting_names_its_exit_code(child):
    with pytest.raises(MocapConnectError, match=r"the library process ended \(exit code 3\)"):
        _started([], child, code=3)


class _Raising:
    def connect(self, system, options):
        raise RuntimeError()


def test_a_library_raising_an_empty_error_is_named_by_its_type():
    src = MotionCaptureSource("vicon", {"hostname": "h"}, connect_timeout_s=10.0,
                              library=_Raising())
    with pytest.raises(MocapConnectError, match=r"^mocap: cannot connect to vicon@h: "
                                                r"RuntimeError$"):
        src.start()
