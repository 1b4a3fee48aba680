"""The channels of :mod:`ardrone_nmpc.runs.channels` on a foxglove-sdk context: JSON channels
for the run's own records, the SDK's typed channels (protobuf) for poses, transforms and
paths — one code path for the MCAP export, ``fly --mcap`` and the live view.

The SDK logs through Python's ``logging`` (logger ``foxglove``): :func:`sdk` routes it, once
per process, to whoever listens (:func:`add_log_listener`: the live view turns it into the
run's events) and never to the terminal — without this the SDK prints each refused
WebSocket handshake on stderr.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable, Iterable
from types import ModuleType
from typing import Any

from ardrone_nmpc.core.extras import import_extra
from ardrone_nmpc.runs import channels as ch

__all__ = ["FoxgloveChannels", "LIVE_ONLY", "add_log_listener", "remove_log_listener", "sdk",
           "write_mcap_messages"]

#: Channel metadata of the live view's re-sent paths: an MCAP recording leaves them out and
#: writes each path once, whole, at the end (:meth:`FoxgloveChannels.reopen`).
LIVE_ONLY = {"ardrone_nmpc.live_only": "true"}
_SDK_LOGGER = "foxglove"

_listeners: list[Callable[[logging.LogRecord], None]] = []
_lock = threading.Lock()
_routed = False


class _Router(logging.Handler):
    """Hands each SDK log record to the listeners (none: the record is dropped)."""

    def emit(self, record: logging.LogRecord) -> None:
        with _lock:
            listeners = list(_listeners)
        for listener in listeners:
            try:
                listener(record)
            except Exception:  # noqa: BLE001 - a listener's bug must not reach the SDK thread
                pass


def add_log_listener(listener: Callable[[logging.LogRecord], None]) -> None:
    """Receive the SDK's log records (INFO and above) from now on, on the SDK's threads."""
    with _lock:
        _listeners.append(listener)


def remove_log_listener(listener: Callable[[logging.LogRecord], None]) -> None:
    with _lock:
        if listener in _listeners:
            _listeners.remove(listener)


def _route_sdk_logging(fg: ModuleType) -> None:
    """Send the SDK's logging to the listeners only. The SDK's ``enable_logging`` also calls
    ``logging.basicConfig`` (a stderr handler on the root logger): that handler is removed
    again, so the application's logging is as it was."""
    global _routed
    with _lock:
        if _routed:
            return
        _routed = True
    logger = logging.getLogger(_SDK_LOGGER)
    logger.addHandler(_Router())
    logger.propagate = False
    logger.setLevel(logging.INFO)
    root = logging.getLogger()
    before = list(root.handlers)
    fg._foxglove.enable_logging(logging.INFO)
    for handler in root.handlers[:]:
        if handler not in before:
            root.removeHandler(handler)


def sdk(purpose: str, extra: str = "foxglove") -> ModuleType:
    """``foxglove`` (foxglove-sdk, in the ``foxglove`` and ``mcap`` extras) with its logging
    routed (module docstring); :class:`~ardrone_nmpc.core.extras.MissingExtra` naming
    ``extra`` without it."""
    fg = import_extra("foxglove", extra, purpose)
    _route_sdk_logging(fg)
    return fg


def _timestamp(fg: ModuleType, log_ns: int):
    sec, nsec = divmod(int(log_ns), 1_000_000_000)
    return fg.Timestamp(sec=sec, nsec=nsec)


def _pose(m: ModuleType, pose: ch.Pose):
    return m.Pose(position=m.Vector3(x=pose.x_m, y=pose.y_m, z=pose.z_m),
                  orientation=m.Quaternion(x=pose.qx, y=pose.qy, z=pose.qz, w=pose.qw))


class FoxgloveChannels:
    """Every topic of :data:`~ardrone_nmpc.runs.channels.TOPICS` as a channel on ``context``.

    ``live_only_paths``: the path channels carry :data:`LIVE_ONLY` (a recording sink filters
    them out)."""

    def __init__(self, fg: ModuleType, context, *, live_only_paths: bool = False) -> None:
        from foxglove import channels as fc, messages

        self._fg = fg
        self._m = messages
        self._context = context
        self._typed = {ch.TOPIC_POSE: fc.PoseInFrameChannel, ch.TOPIC_REFERENCE:
                       fc.PoseInFrameChannel, ch.TOPIC_TF: fc.FrameTransformChannel,
                       ch.TOPIC_FLIGHT_PATH: fc.PosesInFrameChannel,
                       ch.TOPIC_REFERENCE_PATH: fc.PosesInFrameChannel}
        self._channels: dict[str, Any] = {}
        for topic, (name, schema) in ch.JSON_SCHEMAS.items():
            self._channels[topic] = fg.Channel(
                topic, message_encoding="json", context=context,
                schema=fg.Schema(name=name, encoding="jsonschema", data=schema))
        for topic in self._typed:
            live_only = live_only_paths and topic in (ch.TOPIC_FLIGHT_PATH,
                                                      ch.TOPIC_REFERENCE_PATH)
            self._open(topic, LIVE_ONLY if live_only else None)

    def _open(self, topic: str, metadata: dict[str, str] | None) -> None:
        self._channels[topic] = self._typed[topic](topic, context=self._context,
                                                   metadata=metadata)

    def reopen(self, topic: str) -> None:
        """Close ``topic``'s channel and open it again without metadata (for the sinks left)."""
        self._channels[topic].close()
        self._open(topic, None)

    @property
    def topics(self) -> list[str]:
        return list(self._channels)

    def path_builder(self) -> ch.PathBuilder:
        """A :class:`~ardrone_nmpc.runs.channels.PathBuilder` whose poses are foxglove-sdk
        poses already (a path is then logged without converting each pose again)."""
        return ch.PathBuilder(convert=lambda pose: _pose(self._m, pose))

    def log(self, topic: str, payload: Any, log_ns: int) -> None:
        """Log one message of :func:`~ardrone_nmpc.runs.channels.row_messages` (or a path, a
        ``/events`` or ``/config`` message) at ``log_ns`` (ns since the epoch)."""
        m = self._m
        if isinstance(payload, bytes):
            self._channels[topic].log(payload, log_time=log_ns)
            return
        stamp = _timestamp(m, log_ns)
        if isinstance(payload, ch.Transform):
            p = payload.pose
            message = m.FrameTransform(
                timestamp=stamp, parent_frame_id=payload.parent, child_frame_id=payload.child,
                translation=m.Vector3(x=p.x_m, y=p.y_m, z=p.z_m),
                rotation=m.Quaternion(x=p.qx, y=p.qy, z=p.qz, w=p.qw))
        elif isinstance(payload, ch.Pose):
            message = m.PoseInFrame(timestamp=stamp, frame_id=ch.WORLD_FRAME,
                                    pose=_pose(m, payload))
        else:  # a path: a list of poses (foxglove-sdk's, or ours)
            poses = [_pose(m, p) if isinstance(p, ch.Pose) else p for p in payload]
            message = m.PosesInFrame(timestamp=stamp, frame_id=ch.WORLD_FRAME, poses=poses)
        self._channels[topic].log(message, log_time=log_ns)

    def close(self) -> None:
        for channel in self._channels.values():
            channel.close()


class _WatchedStream:
    """A binary stream that remembers the first error its ``write`` raised: foxglove-sdk's
    writer turns an error inside its call back into Python (a Ctrl-C landing there) into an
    I/O error of its own, raised later — the interrupt itself would be lost."""

    def __init__(self, raw) -> None:
        self.raw = raw
        self.error: BaseException | None = None

    def write(self, data) -> int:
        try:
            return self.raw.write(data)
        except BaseException as err:
            self.error = self.error or err
            raise

    def seek(self, offset: int, whence: int = 0) -> int:
        return self.raw.seek(offset, whence)

    def tell(self) -> int:
        return self.raw.tell()

    def flush(self) -> None:
        self.raw.flush()


def write_mcap_messages(stream, messages: Iterable[tuple[int, str, Any]]) -> int:
    """Write ``(log ns, topic, payload)`` messages, in their order, as MCAP to the binary
    ``stream`` (seekable) with foxglove-sdk's writer; return how many. An error the stream
    raised (a Ctrl-C while writing) is raised as itself, not as the writer's I/O error."""
    fg = sdk("export --format mcap", extra="mcap")
    context = fg.Context()
    watched = _WatchedStream(stream)
    writer = fg.open_mcap(watched, context=context)
    channels = FoxgloveChannels(fg, context)
    n = 0
    try:
        for log_ns, topic, payload in messages:
            channels.log(topic, payload, log_ns)
            n += 1
    except BaseException as err:
        try:  # the writer may be failed by now: its own error must not replace this one
            writer.close()
            channels.close()
        except Exception:  # noqa: S110 - abandoned: the caller removes the partial file
            pass
        if watched.error is not None and watched.error is not err:
            raise watched.error from None
        raise
    try:
        writer.close()
        channels.close()
    except BaseException:
        if watched.error is not None:
            raise watched.error from None
        raise
    return n
