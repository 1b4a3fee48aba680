"""Poses from any system the libmotioncapture library speaks (``mocap.kind: motioncapture``).

libmotioncapture (PyPI ``motioncapture``, the ``mocap`` extra; the layer crazyswarm2 uses)
connects with ``connect(type, options)`` to Vicon (DataStream SDK), OptiTrack (NatNet),
Qualisys, VRPN, NOKOV, Motion Analysis, FZMotion, and ``mock`` (fixed rigid bodies from
``{"rigid_bodies": "name(x,y,z,qw,qx,qy,qz);…", "frequency": "100"}``). ``waitForNextFrame()``
blocks until the next frame (releasing the GIL); ``rigidBodies`` then maps name → body with
``position`` (metres, float32) and ``rotation`` (a quaternion ``w, x, y, z``). The library
leaves occluded bodies out of the frame (Vicon's occluded flag, OptiTrack's tracking-valid bit,
Qualisys' NaN), which the shared rules count as missing. The library runs in a child process
(its ``connect`` holds Python's GIL while it waits, which would freeze the tool, Ctrl-C
included); a receiver thread here reads its frames and stamps them on receipt.

Each frame is converted to :class:`~ardrone_nmpc.protocol.mocap.MocapObjectPose` records in
our world frame (x forward, y left, z up; rotation as intrinsic X→Y→Z angles, as the UDP
stream carries them) and handed to :meth:`MocapSource.accept_frame
<ardrone_nmpc.links.mocap_source.MocapSource.accept_frame>`. A Y-up system (OptiTrack Motive's
default) is turned into Z-up by a +90° rotation about x: (x, y, z) → (x, −z, y), for the
position and for the quaternion's vector part alike. docs/mocap-sources.md.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
import threading
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from ardrone_nmpc.core.extras import import_extra
from ardrone_nmpc.links.mocap_source import MocapConnectError, MocapSource
from ardrone_nmpc.links.udp import Clock
from ardrone_nmpc.protocol.mocap import MocapObjectPose

__all__ = ["MotionCaptureSource", "quaternion_to_xyz_rad", "rigid_body_pose",
           "library_options"]

_RETRY_S = 0.1            # after a failed frame read: the loop must not spin
_CLOSE_JOIN_S = 1.0       # waiting for the library process (then killed) and the thread


def quaternion_to_xyz_rad(w: float, x: float, y: float, z: float) -> tuple[float, float, float]:
    """Intrinsic X→Y→Z angles (rx, ry, rz) of the unit quaternion (w, x, y, z):
    R = Rx(rx)·Ry(ry)·Rz(rz), as the UDP pose stream and scipy's ``as_euler("XYZ")``.

    The quaternion is normalised first (float32 ones are off by ~1e-7); a zero or non-finite
    one gives NaN angles (a pose that is not fresh).
    """
    n = math.sqrt(w * w + x * x + y * y + z * z)
    if not (n > 0.0 and math.isfinite(n)):
        return math.nan, math.nan, math.nan
    w, x, y, z = w / n, x / n, y / n, z / n
    r00 = 1.0 - 2.0 * (y * y + z * z)
    r01 = 2.0 * (x * y - w * z)
    r02 = 2.0 * (x * z + w * y)
    r12 = 2.0 * (y * z - w * x)
    r22 = 1.0 - 2.0 * (x * x + y * y)
    return (math.atan2(-r12, r22), math.asin(max(-1.0, min(1.0, r02))),
            math.atan2(-r01, r00))


def rigid_body_pose(name: str, position_m, quaternion_wxyz, *, y_up: bool = False
                    ) -> MocapObjectPose:
    """One library rigid body as a wire pose record in our frame (x forward, y left, z up)."""
    px, py, pz = (float(v) for v in position_m)
    w, qx, qy, qz = (float(v) for v in quaternion_wxyz)
    if y_up:  # +90° about x: the vertical y becomes z; body axes turn with the world's
        px, py, pz = px, -pz, py
        qx, qy, qz = qx, -qz, qy
    return MocapObjectPose(name, (px * 1e3, py * 1e3, pz * 1e3),
                           quaternion_to_xyz_rad(w, qx, qy, qz))


def library_options(hostname: str, options: Mapping[str, Any]) -> dict[str, str]:
    """The library's ``Dict[str, str]``: ``options`` as text (booleans as ``true``/``false``,
    which its ``getBool`` reads) and ``hostname``."""
    def text(v: Any) -> str:
        return ("true" if v else "false") if isinstance(v, bool) else str(v)

    out = {str(k): text(v) for k, v in options.items()}
    out["hostname"] = hostname
    return out


class MotionCaptureSource(MocapSource):
    """The newest fresh pose of ``object_name`` from a libmotioncapture system.

    The library runs in a child process (``_motioncapture_child.py``; its ``connect`` holds
    the GIL while it waits) whose JSON lines a receiver thread here reads and stamps on
    receipt. A ``library`` stand-in (tests) runs in that thread instead, same path onwards.

    Parameters
    ----------
    system : the library's type (``vicon``, ``optitrack``, ``qualisys``, ``vrpn``, ``mock``, …).
    options : the library's options, text (``hostname`` included).
    y_up : the system streams a Y-up frame (convert it to Z-up).
    connect_timeout_s : :meth:`start` gives up after this long without a connection.
    library : an object with the library's ``connect(type, options)``, used in-process; None
        runs the installed ``motioncapture`` in the child process.
    Other parameters as :class:`~ardrone_nmpc.links.mocap_source.MocapSource`.
    """

    kind = "motioncapture"

    def __init__(self, system: str, options: Mapping[str, str] | None = None, *,
                 object_name: str = "ardrone", other_objects: tuple[str, ...] = (),
                 y_up: bool = False, connect_timeout_s: float = 5.0,
                 clock: Clock = time.monotonic, repeat_limit: int | None = 3,
                 library: Any = None) -> None:
        super().__init__(object_name=object_name, other_objects=other_objects, clock=clock,
                         repeat_limit=repeat_limit)
        self.system = system
        self.options = dict(options or {})
        self.y_up = bool(y_up)
        self.connect_timeout_s = float(connect_timeout_s)
        self._library = library
        self._child: subprocess.Popen | None = None
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._ready = threading.Event()
        self._connect_error: str | None = None
        self.frame_errors = 0
        """Frames the library failed to deliver (an exception from waitForNextFrame)."""

    @classmethod
    def from_config(cls, mocap_cfg, *, other_objects: tuple[str, ...] = (),
                    clock: Clock = time.monotonic, library: Any = None) -> MotionCaptureSource:
        """The source of a ``MocapConfig`` of kind ``motioncapture``. The ``mock`` system
        streams constant poses by design, so its repeats are accepted (no freeze detection)."""
        return cls(mocap_cfg.system, library_options(mocap_cfg.hostname, mocap_cfg.options),
                   object_name=mocap_cfg.object_name, other_objects=other_objects,
                   y_up=mocap_cfg.vertical_axis == "y",
                   connect_timeout_s=mocap_cfg.connect_timeout_s, clock=clock,
                   repeat_limit=None if mocap_cfg.system == "mock" else 3, library=library)

    @property
    def where(self) -> str:
        return f"{self.system}@{self.options.get('hostname', '?')}"

    # ----------------------------------------------------------------------------- lifecycle

    def start(self) -> None:
        """Connect and wait for it (``connect_timeout_s``); raises
        :class:`~ardrone_nmpc.links.mocap_source.MocapConnectError` when the connection
        fails or does not come, :class:`~ardrone_nmpc.core.extras.MissingExtra` without the
        library."""
        if self._thread is not None or self._stop.is_set():
            raise RuntimeError("MotionCaptureSource already started (or closed)")
        if self._library is None:
            import_extra("motioncapture", "mocap", "mocap.kind 'motioncapture'")
            self._child = subprocess.Popen(
                [sys.executable, str(Path(__file__).with_name("_motioncapture_child.py")),
                 self.system, json.dumps(self.options)],
                stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL)
        self._thread = threading.Thread(target=self._rx_loop, name="mocap-rx", daemon=True)
        self._thread.start()
        if not self._ready.wait(self.connect_timeout_s):
            self.close()
            raise MocapConnectError(f"mocap: no connection to {self.where} within "
                                    f"{self.connect_timeout_s:g} s (mocap.connect_timeout_s)")
        if self._connect_error is not None:
            self.close()
            raise MocapConnectError(self._connect_error)

    def close(self) -> None:
        """Stop the child process and the thread (idempotent)."""
        self._stop.set()
        child = self._child
        if child is not None and child.poll() is None:
            child.terminate()
            try:
                child.wait(timeout=_CLOSE_JOIN_S)
            except subprocess.TimeoutExpired:
                child.kill()
                child.wait()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout=_CLOSE_JOIN_S)
        if child is not None and child.stdout is not None:
            child.stdout.close()

    # ----------------------------------------------------------------------------- receiver

    def _rx_loop(self) -> None:
        frames = self._child_frames() if self._library is None else self._library_frames()
        for bodies, t_s in frames:
            if self._stop.is_set():
                return
            self.receive_bodies(bodies, t_s)

    def _connected(self, error: str | None) -> None:
        if error is not None:
            self._connect_error = f"mocap: cannot connect to {self.where}: {error}"
        self._ready.set()

    def _library_frames(self):
        try:
            mc = self._library.connect(self.system, self.options)
        except Exception as exc:  # noqa: BLE001 - the library raises RuntimeError and others
            self._connected(str(exc) or type(exc).__name__)
            return
        self._connected(None)
        yield from self.frames_from(mc)

    def frames_from(self, mc):
        """``(bodies, t_s)`` per frame of a connected library object ``mc``
        (``waitForNextFrame``, then ``rigidBodies``: name → ``position``, ``rotation.w/x/y/z``),
        stamped with the source clock, until the source is closed."""
        while not self._stop.is_set():
            try:
                mc.waitForNextFrame()
                t_s = self._clock()
                bodies = [(name, b.position, (b.rotation.w, b.rotation.x, b.rotation.y,
                                              b.rotation.z))
                          for name, b in mc.rigidBodies.items()]
            except Exception as exc:  # noqa: BLE001 - counted; the age grows meanwhile
                self._frame_error(str(exc))
                self._stop.wait(_RETRY_S)
                continue
            yield bodies, t_s

    def _child_frames(self):
        stream = self._child.stdout
        for line in stream:   # blocks without the GIL; ends when the child ends
            t_s = self._clock()
            try:
                record = json.loads(line)
            except ValueError:
                self._frame_error(f"unreadable line from the library process: {line[:80]!r}")
                continue
            if "b" in record:
                yield [(b[0], b[1:4], b[4:8]) for b in record["b"]], t_s
            elif "frame_error" in record:
                self._frame_error(record["frame_error"])
            elif not self._ready.is_set():
                self._connected(record.get("error"))
        if not self._ready.is_set():
            self._connected(f"the library process ended (exit code {self._child.wait()})")

    def _frame_error(self, message: str) -> None:
        self.frame_errors += 1
        self._last_error = f"mocap: {self.where}: {message}"

    def receive_bodies(self, bodies, t_s: float) -> None:
        """Handle one frame of ``(name, position_m, quaternion_wxyz)`` received at ``t_s``, as
        the receiver thread does; tests and simulators deliver frames this way."""
        stats = self.stats
        stats.record_datagram()
        stats.record_packet(t_s)
        poses = {}
        for name, position_m, q_wxyz in bodies:
            try:
                poses[name] = rigid_body_pose(name, position_m, q_wxyz, y_up=self.y_up)
            except (TypeError, ValueError) as exc:  # a malformed body: skipped, counted
                stats.record_malformed()
                self._last_error = f"mocap: body {name!r}: {exc}"
        self.accept_frame(poses, t_s)
