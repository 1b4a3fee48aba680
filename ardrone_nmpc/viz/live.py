"""Live view and flight recording: a flight's rows and events on a Foxglove WebSocket server
(``fly --foxglove``, ``simulate --foxglove``) and/or in an MCAP file written as it flies
(``fly --mcap FILE``), both sinks of one foxglove-sdk context (the ``foxglove`` extra).
docs/live-view.md.

The channels are those of the MCAP export (:mod:`ardrone_nmpc.runs.channels`). The control
thread only hands a row over — a dict copy appended to a bounded queue, a few microseconds —
and a publisher thread encodes and sends it; when the queue is full the row is dropped (and
counted), never waited for. The server binds 127.0.0.1 only: the protocol has no
authentication. What the SDK logs (a client connecting, a refused handshake) becomes the
run's events, never terminal output (:class:`SdkNotices`).
"""

from __future__ import annotations

import collections
import contextlib
import logging
import math
import re
import threading
import time
from pathlib import Path
from typing import Any

from ardrone_nmpc.errors import UserError
from ardrone_nmpc.runs import channels as ch
from ardrone_nmpc.runs import foxglove_channels as fox

__all__ = ["LiveView", "DEFAULT_PORT", "SdkNotices", "open_live_view"]

DEFAULT_PORT = 8765          # Foxglove's default WebSocket port
LOOPBACK = "127.0.0.1"
_PATHS_EVERY_S = 1.0         # /flight_path and /reference_path, re-sent as they grow
_PATH_POSES = 1500
_RECORDING_QUEUE = 4096      # with an MCAP file a row is worth more than a few kB of memory
#: What a refused client most likely is (the SDK speaks only ``foxglove.sdk.v1``).
REFUSED_HINT = ("the client does not speak the foxglove.sdk.v1 subprotocol (Foxglove Studio "
                "1.x, Lichtblick before 1.22): see docs/live-view.md")
_REFUSED = re.compile(r"Dropping client (\S+): handshake failed")
_CLIENT = re.compile(r"(Registered|Unregistered) client (\S+)")


class SdkNotices:
    """The SDK's log records as run events, deduplicated, for the control thread to write.

    * a refused handshake → one ``foxglove_refused`` event (the first; later ones are only
      counted in :attr:`refused`: a client retries every few seconds);
    * a client connecting or leaving → ``foxglove_client`` (``action``, ``client``);
    * any other warning or error → ``foxglove_sdk`` (``level``, ``message``), each distinct
      message once.
    """

    def __init__(self) -> None:
        self._pending: collections.deque = collections.deque(maxlen=256)
        self._seen: set[str] = set()
        self.refused = 0

    def __call__(self, record: logging.LogRecord) -> None:  # on the SDK's threads
        text = record.getMessage()
        if (m := _REFUSED.search(text)) is not None:
            self.refused += 1
            if self.refused == 1:
                self._pending.append(("foxglove_refused",
                                      {"client": m.group(1), "hint": REFUSED_HINT}))
            return
        if (m := _CLIENT.search(text)) is not None:
            action = "connected" if m.group(1) == "Registered" else "disconnected"
            self._pending.append(("foxglove_client", {"action": action, "client": m.group(2)}))
            return
        key = re.sub(r"\d+", "#", text)
        if record.levelno >= logging.WARNING and key not in self._seen:
            self._seen.add(key)
            self._pending.append(("foxglove_sdk", {"level": record.levelname.lower(),
                                                   "message": text}))

    def drain(self) -> list[tuple[str, dict[str, Any]]]:
        out = []
        while self._pending:
            out.append(self._pending.popleft())
        return out


class _Tee:
    """A run recorder that also hands every row and event to the live view, and writes the
    SDK's notices as events (on the recorder's thread, stamped with its clock)."""

    def __init__(self, recorder, view: LiveView):
        self._recorder = recorder
        self._view = view

    def _notices(self, t_s) -> None:
        for kind, fields in self._view.notices.drain():
            self._recorder.event(t_s, kind, **fields)
            self._view.event(t_s, kind, **fields)

    def write_row(self, row) -> None:
        self._notices(row.get("t_s", math.nan))
        self._recorder.write_row(row)
        self._view.row(row)

    def event(self, t_s: float, kind: str, **fields: Any) -> None:
        self._notices(t_s)
        self._recorder.event(t_s, kind, **fields)
        self._view.event(t_s, kind, **fields)

    def __getattr__(self, name: str):
        return getattr(self._recorder, name)


class LiveView:
    """Serve a run live on ``ws://127.0.0.1:<port>`` and/or record it to an MCAP file
    (context manager: start … close).

    Parameters
    ----------
    port : TCP port (8765; 0 picks a free one, see :attr:`port`).
    config : the ExperimentConfig, published on ``/config``.
    seed : the run's seed, published with it.
    queue_size : rows and events waiting for the publisher; beyond, new ones are dropped
        (default 256, 4096 when recording).
    pace : sleep in :meth:`row` until the row's time has come on the wall clock (a lockstep
        simulation, faster than real time, then flies at real time for the viewer).
    serve : start the WebSocket server (False: only record).
    mcap : write every message to this MCAP file too (it must not exist).
    """

    def __init__(self, port: int = DEFAULT_PORT, *, config=None, seed: Any = None,
                 queue_size: int | None = None, pace: bool = False, serve: bool = True,
                 mcap: Path | None = None) -> None:
        if not 0 <= int(port) <= 65535:
            raise ValueError(f"--foxglove-port {port}: must be in 0..65535")
        self._requested_port = int(port)
        self._config = config
        self._seed = seed
        self._serve = serve
        self._mcap_path = Path(mcap) if mcap is not None else None
        self._queue: collections.deque = collections.deque()
        self._queue_size = int(queue_size if queue_size is not None else
                               _RECORDING_QUEUE if mcap is not None else 256)
        self._wake = threading.Event()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._server = None
        self._writer = None
        self._channels: Any = None
        self._pace = pace
        self._pace_origin: tuple[float, float] | None = None   # (wall s, run t_s)
        self._paths = ch.PathBuilder()   # foxglove-sdk poses once the channels exist
        self._first_log_ns: int | None = None
        self._config_due = config is not None
        self.notices = SdkNotices()
        """The SDK's log records, waiting to become the run's events."""
        self.rows_in = 0
        """Rows handed over by the runner."""
        self.published = 0
        """Rows published (``/log`` messages sent to the server)."""
        self.dropped = 0
        """Rows and events dropped because the queue was full."""

    # ----------------------------------------------------------------------------- lifecycle

    def __enter__(self) -> LiveView:
        self.start()
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def start(self) -> None:
        """Open the MCAP file, start the server on 127.0.0.1 and the publisher thread; raises
        :class:`~ardrone_nmpc.core.extras.MissingExtra` without foxglove-sdk."""
        fg = fox.sdk("--mcap" if not self._serve else "--foxglove")
        fox.add_log_listener(self.notices)
        context = fg.Context()  # channels close with their context
        if self._mcap_path is not None:
            try:
                self._mcap_path.parent.mkdir(parents=True, exist_ok=True)
                self._writer = fg.open_mcap(self._mcap_path, context=context,
                                            channel_filter=_recorded)
            except Exception as err:  # the SDK's errors name no file
                fox.remove_log_listener(self.notices)
                raise UserError(f"--mcap {self._mcap_path}: cannot write it: {err}") from None
        if self._serve:
            self._server = fg.start_server(name="ardrone-nmpc", host=LOOPBACK,
                                           port=self._requested_port, context=context,
                                           server_listener=_listener(self._config_wanted))
        self._channels = fox.FoxgloveChannels(fg, context, live_only_paths=self._serve)
        self._paths = self._channels.path_builder()
        self._thread = threading.Thread(target=self._publish_loop, name="live-view",
                                        daemon=True)
        self._thread.start()

    def close(self) -> None:
        """Publish what is queued, stop the thread and the server, finish the MCAP file with
        the whole paths (idempotent)."""
        self._stop.set()
        self._wake.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
            self._thread = None
        if self._server is not None:
            self._server.stop()
            self._server = None
        if self._writer is not None:
            self._record_paths()
            self._writer.close()
            self._writer = None
        fox.remove_log_listener(self.notices)

    @property
    def port(self) -> int:
        """The bound port (the actual one when 0 was requested)."""
        return self._server.port if self._server is not None else self._requested_port

    @property
    def url(self) -> str:
        return f"ws://{LOOPBACK}:{self.port}"

    # ----------------------------------------------------------------------------- runner side

    def tee(self, recorder) -> _Tee:
        """``recorder`` (``write_row``, ``event``, …) that also feeds this view."""
        return _Tee(recorder, self)

    def row(self, row) -> None:
        """Hand one log row over (control thread; never blocks unless ``pace``)."""
        self.rows_in += 1
        if self._pace:
            self._sleep_until(row.get("t_s"))
        self._put(("row", dict(row), time.time_ns()))

    def event(self, t_s: float, kind: str, **fields: Any) -> None:
        """Hand one event over (never blocks)."""
        self._put(("event", {"t_s": float(t_s), "kind": str(kind), **fields}, time.time_ns()))

    def _config_wanted(self) -> None:
        """A client subscribed to ``/config``: send it again (it has no history)."""
        self._config_due = self._config is not None
        self._wake.set()

    def _put(self, item) -> None:
        if len(self._queue) >= self._queue_size:
            self.dropped += 1
            return
        self._queue.append(item)
        self._wake.set()

    def _sleep_until(self, t_s) -> None:
        if not isinstance(t_s, (int, float)) or not math.isfinite(t_s):
            return
        now = time.monotonic()
        if self._pace_origin is None:
            self._pace_origin = (now, float(t_s))
        wall0, t0 = self._pace_origin
        delay = wall0 + (t_s - t0) - now
        if delay > 0:
            time.sleep(delay)

    # ----------------------------------------------------------------------------- publisher

    def _publish_loop(self) -> None:
        origin_ns: int | None = None      # epoch ns of the rows' t_s = 0 (from the first)
        next_paths = 0.0
        while True:
            self._wake.wait(0.5)
            self._wake.clear()
            now = time.monotonic()
            if self._config_due:
                self._config_due = False
                self._publish_config()
            if now >= next_paths and self._serve:
                self._publish_paths()
                next_paths = now + _PATHS_EVERY_S
            while self._queue:
                kind, payload, wall_ns = self._queue.popleft()
                if kind == "event":   # stamped when it happened: events use several clocks
                    self._channels.log(ch.TOPIC_EVENTS, ch.event_message(payload), wall_ns)
                    continue
                t = payload.get("t_s")
                t = float(t) if isinstance(t, (int, float)) else math.nan
                if origin_ns is None and math.isfinite(t):
                    origin_ns = wall_ns - round(t * 1e9)
                log_ns = ch.time_ns(origin_ns, t) if origin_ns is not None else wall_ns
                if self._first_log_ns is None:
                    self._first_log_ns = log_ns
                for topic, data in ch.row_messages(payload, self._paths):
                    self._channels.log(topic, data, log_ns)
                self.published += 1
            if self._stop.is_set() and not self._queue:
                if self._serve:
                    self._publish_paths()   # the whole flight, for a client still watching
                return

    def _publish_paths(self) -> None:
        """The paths so far, at most about ``_PATH_POSES`` poses each."""
        self._paths.every = 1 + len(self._paths.poses[ch.TOPIC_FLIGHT_PATH]) // _PATH_POSES
        now_ns = time.time_ns()
        for topic, poses in self._paths.messages():
            self._channels.log(topic, poses, now_ns)

    def _record_paths(self) -> None:
        """The recording's whole paths, once, at the first row's time (as the export)."""
        if self._serve:   # the live channels were left out of the file: new ones for it
            for topic in (ch.TOPIC_FLIGHT_PATH, ch.TOPIC_REFERENCE_PATH):
                self._channels.reopen(topic)
        self._paths.every = 1
        t0 = self._first_log_ns if self._first_log_ns is not None else time.time_ns()
        for topic, poses in self._paths.messages():
            self._channels.log(topic, poses, t0)

    def _publish_config(self) -> None:
        from ardrone_nmpc.config.io import config_to_dict

        from ardrone_nmpc import __version__

        data = ch.config_message(config_to_dict(self._config), seed=self._seed,
                                 version=__version__)
        self._channels.log(ch.TOPIC_CONFIG, data, time.time_ns())


def _listener(config_wanted):
    """The server's listener: a subscription to ``/config`` asks for it again."""
    from foxglove.websocket import ServerListener

    class _Listener(ServerListener):
        def on_subscribe(self, client, channel) -> None:
            if channel.topic == ch.TOPIC_CONFIG:
                config_wanted()

    return _Listener()


def _recorded(channel) -> bool:
    """The MCAP sink's channel filter: everything but the live view's re-sent paths."""
    return channel.metadata.get(next(iter(fox.LIVE_ONLY))) != "true"


@contextlib.contextmanager
def open_live_view(enabled: bool, port: int = DEFAULT_PORT, *, cfg=None, seed: Any = None,
                   pace: bool = False, echo=print, mcap: Path | None = None):
    """A started :class:`LiveView` (None when neither ``enabled`` nor ``mcap``), its address
    and at the end its dropped rows reported through ``echo``; closed on exit."""
    if not enabled and mcap is None:
        yield None
        return
    if seed is None and cfg is not None:
        seed = cfg.sim.seed   # what the runner flies with when no --seed is given
    with LiveView(port, config=cfg, seed=seed, pace=pace, serve=enabled, mcap=mcap) as view:
        if enabled:
            echo(f"live view: {view.url} (Foxglove, or Lichtblick ≥ 1.22: Open connection → "
                 "Foxglove WebSocket; layout docs/foxglove-layout.json)")
        try:
            yield view
        finally:
            view.close()
            if view.dropped:
                echo(f"live view: {view.dropped} rows or events dropped, {view.published} of "
                     f"{view.rows_in} rows published (the flight was not delayed)")
            if mcap is not None:
                echo(f"recording: {mcap}")
