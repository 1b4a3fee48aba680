"""Live view: a flight's rows and events on a Foxglove WebSocket server (``fly --foxglove``,
``simulate --foxglove``; the ``foxglove`` extra, foxglove-sdk). docs/live-view.md.

The channels are those of the MCAP export (:mod:`ardrone_nmpc.runs.channels`: ``/log``,
``/events``, ``/config``, ``/pose``, ``/reference``, ``/flight_path``, ``/reference_path``). The control thread only hands a row over
— a dict copy appended to a bounded queue, a few microseconds — and a publisher thread encodes
and sends it; when the queue is full the row is dropped (and counted), never waited for. The
server binds 127.0.0.1 only: the protocol has no authentication.
"""

from __future__ import annotations

import collections
import contextlib
import math
import threading
import time
from typing import Any

from ardrone_nmpc.core.extras import import_extra
from ardrone_nmpc.errors import UserError
from ardrone_nmpc.runs import channels as ch

__all__ = ["LiveView", "LiveViewError", "DEFAULT_PORT", "open_live_view"]

DEFAULT_PORT = 8765          # Foxglove's default WebSocket port
LOOPBACK = "127.0.0.1"
_CONFIG_EVERY_S = 2.0        # /config is re-sent so that a late client sees it too
_PATHS_EVERY_S = 1.0         # /flight_path and /reference_path, re-sent as they grow
_PATH_POSES = 1500


class LiveViewError(UserError):
    """The live view cannot start (its port is taken): one line, exit 1."""


class _Tee:
    """A run recorder that also hands every row and event to the live view."""

    def __init__(self, recorder, view: LiveView):
        self._recorder = recorder
        self._view = view

    def write_row(self, row) -> None:
        self._recorder.write_row(row)
        self._view.row(row)

    def event(self, t_s: float, kind: str, **fields: Any) -> None:
        self._recorder.event(t_s, kind, **fields)
        self._view.event(t_s, kind, **fields)

    def __getattr__(self, name: str):
        return getattr(self._recorder, name)


class LiveView:
    """Serve a run live on ``ws://127.0.0.1:<port>`` (context manager: start … close).

    Parameters
    ----------
    port : TCP port (8765; 0 picks a free one, see :attr:`port`).
    config : the ExperimentConfig, published on ``/config``.
    seed : the run's seed, published with it.
    queue_size : rows and events waiting for the publisher; beyond, new ones are dropped.
    pace : sleep in :meth:`row` until the row's time has come on the wall clock (a lockstep
        simulation, faster than real time, then flies at real time for the viewer).
    """

    def __init__(self, port: int = DEFAULT_PORT, *, config=None, seed: Any = None,
                 queue_size: int = 256, pace: bool = False) -> None:
        if not 0 <= int(port) <= 65535:
            raise ValueError(f"--foxglove-port {port}: must be in 0..65535")
        self._requested_port = int(port)
        self._config = config
        self._seed = seed
        self._queue: collections.deque = collections.deque()
        self._queue_size = int(queue_size)
        self._wake = threading.Event()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._server = None
        self._channels: dict[str, Any] = {}
        self._context = None
        self._pace = pace
        self._pace_origin: tuple[float, float] | None = None   # (wall s, run t_s)
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
        """Start the server on 127.0.0.1 and the publisher thread; raises
        :class:`~ardrone_nmpc.core.extras.MissingExtra` without foxglove-sdk, and
        :class:`LiveViewError` when the port cannot be bound."""
        fg = import_extra("foxglove", "foxglove", "--foxglove")
        context = self._context = fg.Context()  # channels close with their context
        try:
            self._server = fg.start_server(name="ardrone-nmpc", host=LOOPBACK,
                                           port=self._requested_port, context=context)
        except RuntimeError as err:  # the SDK reports a bind failure as FoxgloveError text
            text = " ".join(str(err).split()).removeprefix("FoxgloveError: ")
            raise LiveViewError(f"--foxglove-port {self._requested_port}: {text} (another "
                                "port, or 0 for a free one)") from None
        for topic, (name, schema) in ch.SCHEMAS.items():
            self._channels[topic] = fg.Channel(
                topic, message_encoding="json", context=context,
                schema=fg.Schema(name=name, encoding="jsonschema", data=schema))
        self._thread = threading.Thread(target=self._publish_loop, name="live-view",
                                        daemon=True)
        self._thread.start()

    def close(self) -> None:
        """Publish what is queued, stop the thread and the server (idempotent)."""
        self._stop.set()
        self._wake.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
        if self._server is not None:
            self._server.stop()
            self._server = None

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
        next_config = next_paths = 0.0
        paths = ch.PathBuilder()
        while True:
            self._wake.wait(0.5)
            self._wake.clear()
            now = time.monotonic()
            if now >= next_config and self._config is not None:
                self._publish_config()
                next_config = now + _CONFIG_EVERY_S
            if now >= next_paths:
                self._publish_paths(paths)
                next_paths = now + _PATHS_EVERY_S
            while self._queue:
                kind, payload, wall_ns = self._queue.popleft()
                if kind == "event":   # stamped when it happened: events use several clocks
                    self._channels[ch.TOPIC_EVENTS].log(ch.event_message(payload),
                                                        log_time=wall_ns)
                    continue
                t = payload.get("t_s")
                t = float(t) if isinstance(t, (int, float)) else math.nan
                if origin_ns is None and math.isfinite(t):
                    origin_ns = wall_ns - round(t * 1e9)
                log_ns = ch.time_ns(origin_ns, t) if origin_ns is not None else wall_ns
                for topic, data in ch.row_messages(payload, log_ns, paths):
                    self._channels[topic].log(data, log_time=log_ns)
                self.published += 1
            if self._stop.is_set() and not self._queue:
                self._publish_paths(paths)   # the whole flight, for a client still watching
                return

    def _publish_paths(self, paths: ch.PathBuilder) -> None:
        """The paths so far, at most about ``_PATH_POSES`` poses each."""
        paths.every = 1 + len(paths.poses[ch.TOPIC_FLIGHT_PATH]) // _PATH_POSES
        now_ns = time.time_ns()
        for topic, data in paths.messages(now_ns):
            self._channels[topic].log(data, log_time=now_ns)

    def _publish_config(self) -> None:
        from ardrone_nmpc.config.io import config_to_dict

        from ardrone_nmpc import __version__

        data = ch.config_message(config_to_dict(self._config), seed=self._seed,
                                 version=__version__)
        self._channels[ch.TOPIC_CONFIG].log(data, log_time=time.time_ns())


@contextlib.contextmanager
def open_live_view(enabled: bool, port: int = DEFAULT_PORT, *, cfg=None, seed: Any = None,
                   pace: bool = False, echo=print):
    """A started :class:`LiveView` (None when not ``enabled``), its address and at the end
    its dropped rows reported through ``echo``; closed on exit."""
    if not enabled:
        yield None
        return
    if seed is None and cfg is not None:
        seed = cfg.sim.seed   # what the runner flies with when no --seed is given
    with LiveView(port, config=cfg, seed=seed, pace=pace) as view:
        echo(f"live view: {view.url} (Foxglove: Open connection → Foxglove WebSocket; "
             "layout in docs/live-view.md)")
        try:
            yield view
        finally:
            if view.dropped:
                echo(f"live view: {view.dropped} rows or events dropped, {view.published} of "
                     f"{view.rows_in} rows published (the flight was not delayed)")
