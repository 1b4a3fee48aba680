"""Motion-capture sources behind one interface: the newest fresh pose of each tracked object.

``mocap.kind`` picks the source: ``vicon_udp`` (:class:`~ardrone_nmpc.links.mocap_link.MocapLink`,
Vicon Tracker's UDP object stream, decoded by this package) or ``motioncapture``
(:class:`~ardrone_nmpc.links.motioncapture_source.MotionCaptureSource`: every system the
libmotioncapture library speaks — Vicon DataStream SDK, OptiTrack, Qualisys, VRPN, NOKOV, …).
Each turns a frame into :class:`~ardrone_nmpc.protocol.mocap.MocapObjectPose` records in our
world frame (x forward, y left, z up, ψ counter-clockwise) and hands them to
:meth:`MocapSource.accept_frame`, so the freshness rules below, the readings the runner, the
session and the dashboard use, and therefore the log, are one code path for every system.

Not fresh — the last good pose is kept and its age grows (the supervisor acts on the age; a
zero pose never reaches the controller), see docs/mocap-stream.md:

* the object missing from the frame (``missing``);
* an all-zero (or non-finite) pose (``zero_poses``; ``MocapObjectPose.fresh`` is False);
* a bit-identical pose in ``repeat_limit`` (3) or more consecutive frames: the first two are
  accepted, the third and later are ignored (``repeats``) — real measurements are never
  bit-identical three frames running, a tracker holding an occluded object's pose is.

Every source receives on its own thread; the readings take a lock for a few attribute reads,
so the 65 ms loop never waits for the network or for the mocap system.
"""

from __future__ import annotations

import math
import struct
import threading
import time
from collections.abc import Mapping

import numpy as np

from ardrone_nmpc.core.types import MocapPose
from ardrone_nmpc.links.udp import Clock, LinkStats
from ardrone_nmpc.protocol.mocap import (
    _MM_PER_M,  # (MocapObjectPose's scale: _pose_of_floats)
    MocapObjectPose,
    rotation_heading_rad,
)

__all__ = ["MOCAP_KINDS", "MocapSource", "MocapConnectError", "mocap_pose_of"]

MOCAP_KINDS = ("vicon_udp", "motioncapture")
_POSE_BITS = struct.Struct("<6d")     # the six pose floats, to compare poses bit for bit


class MocapConnectError(RuntimeError):
    """The mocap system could not be reached (or its library is missing): one line to show."""


def _readonly(values) -> np.ndarray:
    a = np.array(values, dtype=np.float64)
    a.setflags(write=False)
    return a


def mocap_pose_of(pose: MocapObjectPose, t_s: float) -> MocapPose:
    """A decoded wire pose as the :class:`MocapPose` record stamped ``t_s`` (SI units)."""
    return MocapPose(t_s=t_s, position_m=_readonly(pose.position_m),
                     rotation_xyz_rad=_readonly(pose.rotation_xyz_rad), psi_rad=pose.psi_rad)


def _pose_of_floats(t_s: float, translation_mm, rotation_xyz_rad) -> MocapPose:
    """``mocap_pose_of(MocapObjectPose(name, translation_mm, rotation_xyz_rad), t_s)`` of two
    triples of floats, the wire pose not built (its checks and ``fresh`` are the caller's):
    :class:`MocapObjectPose`'s own conversions, metres = millimetres / 1000 and the heading of
    :func:`rotation_heading_rad` (a bulk receipt's newest pose)."""
    x, y, z = translation_mm
    return MocapPose(t_s=t_s, position_m=_readonly((x / _MM_PER_M, y / _MM_PER_M, z / _MM_PER_M)),
                     rotation_xyz_rad=_readonly(rotation_xyz_rad),
                     psi_rad=rotation_heading_rad(*rotation_xyz_rad))


class MocapSource:
    """The newest fresh pose of ``object_name`` (and of ``other_objects``) from some system.

    Subclasses own the thread and the transport: they call :meth:`accept_frame` once per
    frame (after counting it in :attr:`stats`) and implement :meth:`start`, :meth:`close`
    and :attr:`where`.

    Parameters
    ----------
    object_name : the controlled object's name in the stream.
    other_objects : more objects to keep (the followed one, moving obstacles).
    clock : receipt stamps (seconds, monotonic).
    repeat_limit : consecutive bit-identical frames from which a pose stops being fresh
        (≥ 2), or None to accept repeats (a mock system whose poses never change).
    restart_backjump : a frame number this far below the last is a tracker restart.
    """

    kind = "?"

    def __init__(self, *, object_name: str = "ardrone", other_objects: tuple[str, ...] = (),
                 clock: Clock = time.monotonic, repeat_limit: int | None = 3,
                 restart_backjump: int = 1000) -> None:
        if not isinstance(object_name, str) or not object_name:
            raise ValueError("object_name must be a non-empty string")
        if repeat_limit is not None and repeat_limit < 2:
            raise ValueError(f"repeat_limit must be >= 2 (or None), got {repeat_limit}")
        self.object_name = object_name
        self.other_objects = tuple(other_objects)
        self.repeat_limit = None if repeat_limit is None else int(repeat_limit)
        self._clock = clock
        self._lock = threading.Lock()
        self._pose: MocapPose | None = None
        self._rx_t_s = -math.inf
        self._last_values: bytes | None = None
        self._same_count = 0
        self._missing = 0
        self._zero = 0
        self._repeats = 0
        self._poses = 0
        self._max_gap_s = 0.0
        self._last_error: str | None = None
        self._others: dict[str, tuple[MocapPose, float]] = {}
        self._fresh_counts: dict[str, int] = {}
        self._names_seen: tuple[str, ...] = ()
        self.stats = LinkStats(window_s=1.0, restart_backjump=restart_backjump)
        """Stream statistics: frame rate, frame-number gaps (``lost``), malformed, out of order."""

    # ----------------------------------------------------------------------------- lifecycle

    def __enter__(self) -> MocapSource:
        self.start()
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def start(self) -> None:  # pragma: no cover - abstract
        """Connect and start the receiver thread (once)."""
        raise NotImplementedError

    def close(self) -> None:  # pragma: no cover - abstract
        """Stop the thread and release the connection (idempotent)."""
        raise NotImplementedError

    @property
    def where(self) -> str:  # pragma: no cover - abstract
        """Where the poses come from, for messages (``udp 0.0.0.0:51001``, ``vicon@host``)."""
        raise NotImplementedError

    @property
    def port(self) -> int | None:
        """The UDP port listened on, for a UDP source; None otherwise."""
        return None

    @property
    def sender(self) -> str | None:
        """The network sender the poses are taken from (``address:port``), for a source that
        hears several (UDP); None otherwise."""
        return None

    @property
    def foreign_senders(self) -> dict[str, int]:
        """Datagrams from senders that are ignored (a UDP source locks onto one); none here."""
        return {}

    def take_events(self) -> list[dict]:
        """Source events since the last call (a UDP source's sender events); none here."""
        return []

    @property
    def contenders(self) -> list[str]:
        """Ignored senders that also carried the controlled object (a second stream of it: a
        stale ``replay --broadcast``, another tracker); none for a single-sender source."""
        return []

    # ----------------------------------------------------------------------------- readings

    def latest(self) -> tuple[MocapPose | None, float]:
        """``(pose, rx_t_s)``: the newest fresh pose and its receipt time (source clock);
        ``(None, -inf)`` before the first."""
        with self._lock:
            return self._pose, self._rx_t_s

    def latest_of(self, name: str) -> tuple[MocapPose | None, float]:
        """``(pose, rx_t_s)`` of another tracked object (``other_objects``); ``(None, -inf)``
        before its first fresh pose."""
        with self._lock:
            return self._others.get(name, (None, -math.inf))

    def age_ms(self, now_s: float) -> float:
        """Milliseconds since the newest fresh pose was received (inf before the first)."""
        return (now_s - self._rx_t_s) * 1e3

    def fresh_count(self, name: str) -> int:
        """Fresh poses accepted so far for ``name`` (the object or one of ``other_objects``)."""
        return self._fresh_counts.get(name, 0)

    @property
    def names_seen(self) -> tuple[str, ...]:
        """The object names of the newest frame (diagnostics: what the system streams)."""
        return self._names_seen

    @property
    def poses(self) -> int:
        """Fresh poses accepted."""
        return self._poses

    @property
    def missing(self) -> int:
        """Frames without the configured object."""
        return self._missing

    @property
    def zero_poses(self) -> int:
        """Frames carrying the object with an all-zero or non-finite pose."""
        return self._zero

    @property
    def max_gap_s(self) -> float:
        """The longest time between two fresh poses of the object (s; 0 before the second)."""
        return self._max_gap_s

    @property
    def repeats(self) -> int:
        """Frames ignored as a bit-identical repeat (``repeat_limit`` or more in a row)."""
        return self._repeats

    @property
    def last_error(self) -> str | None:
        """The latest receive or decode error message (diagnostics)."""
        return self._last_error

    # ----------------------------------------------------------------------------- frames

    def accept_frame(self, poses: Mapping[str, MocapObjectPose], t_s: float) -> None:
        """Apply the freshness rules to one frame received at ``t_s`` (source clock)."""
        self._names_seen = tuple(poses)
        counts = self._fresh_counts
        for name in self.other_objects:  # e.g. the object a 'follow' reference tracks
            other = poses.get(name)
            if other is not None and other.fresh:
                with self._lock:
                    self._others[name] = (mocap_pose_of(other, t_s), t_s)
                counts[name] = counts.get(name, 0) + 1
        pose = poses.get(self.object_name)
        if pose is None:
            self._missing += 1
            self._last_values, self._same_count = None, 0
            return
        if not pose.fresh:
            self._zero += 1
            self._last_values, self._same_count = None, 0
            return
        values = _POSE_BITS.pack(*pose.translation_mm, *pose.rotation_xyz_rad)
        if values == self._last_values:        # bit-identical (0.0 and -0.0 differ)
            self._same_count += 1
        else:
            self._last_values, self._same_count = values, 1
        if self.repeat_limit is not None and self._same_count >= self.repeat_limit:
            self._repeats += 1
            return
        record = mocap_pose_of(pose, t_s)
        if math.isfinite(self._rx_t_s):
            self._max_gap_s = max(self._max_gap_s, t_s - self._rx_t_s)
        with self._lock:
            self._pose = record
            self._rx_t_s = t_s
        self._poses += 1
        counts[self.object_name] = counts.get(self.object_name, 0) + 1

    def accept_object_frames(self, frames) -> None:
        """:meth:`accept_frame` of each frame of ``frames`` in turn, of frames carrying the
        object ``object_name`` alone: ``(t_s, translation_mm, rotation_xyz_rad)`` each (the
        :class:`MocapObjectPose`'s floats). The state left is the calls' one by one; only the
        newest fresh pose is made a record (a lockstep receiver's bulk receipt)."""
        if not frames:
            return
        name = self.object_name
        self._names_seen = (name,)
        limit = self.repeat_limit
        last_values, same = self._last_values, self._same_count
        rx_t, max_gap = self._rx_t_s, self._max_gap_s
        zero = repeats = fresh = 0
        newest = None
        isfinite = math.isfinite
        for t_s, translation_mm, rotation in frames:
            values = translation_mm + rotation
            a, b, c, d, e, f = values  # MocapObjectPose.fresh: any(values), all finite
            if not ((a or b or c or d or e or f) and isfinite(a) and isfinite(b)
                    and isfinite(c) and isfinite(d) and isfinite(e) and isfinite(f)):
                zero += 1
                last_values, same = None, 0
                continue
            bits = _POSE_BITS.pack(*values)
            if bits == last_values:
                same += 1
            else:
                last_values, same = bits, 1
            if limit is not None and same >= limit:
                repeats += 1
                continue
            if isfinite(rx_t):
                max_gap = max(max_gap, t_s - rx_t)
            rx_t, newest = t_s, (t_s, translation_mm, rotation)
            fresh += 1
        self._last_values, self._same_count = last_values, same
        self._zero += zero
        self._repeats += repeats
        self._max_gap_s = max_gap
        if newest is not None:
            t_s, translation_mm, rotation = newest
            record = _pose_of_floats(t_s, translation_mm, rotation)
            with self._lock:
                self._pose = record
                self._rx_t_s = t_s
            self._poses += fresh
            counts = self._fresh_counts
            counts[name] = counts.get(name, 0) + fresh
