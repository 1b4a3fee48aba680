"""Loopback AR.Drone 2.0: AT commands in, navdata out, over real UDP on 127.0.0.1.

Serves a :class:`~ardrone_nmpc.sim.drone.SimulatedDrone` (plant, firmware, injected faults —
the drone ``simulate`` flies in lockstep) with the drone's wire protocol (docs/protocol.md) so
that the project's own links — or an unmodified third-party client (python-ardrone,
node-ar-drone style) — fly it as they would fly the real drone. What the drone does with each
command is :mod:`~ardrone_nmpc.sim.drone_firmware`; its configuration
:mod:`~ardrone_nmpc.sim.drone_config`; this module owns the sockets and the threads, all sharing
:attr:`DroneServer.lock` (also with a :class:`~ardrone_nmpc.sim.mocap_server.MocapServer`
given the same lock):

* **physics** — advances the plant on the clock in ``step_s`` increments against absolute
  deadlines (a late wake-up advances every step due, so plant time never drifts from wall
  time), then the firmware's watchdogs and altitude cap.
* **AT receiver** (UDP ``at_port``) — each datagram to the firmware.
* **navdata** (UDP ``navdata_port``) — waits for a wake-up datagram, then streams to the
  source of the last datagram received on the port: bootstrap packets until
  ``general:navdata_demo`` is written, then demo packets at ``demo_rate_hz`` or full-rate ones
  at ``full_rate_hz``. It stops after ``navdata_timeout_s`` without any client datagram (AT or
  navdata port); a new wake-up restarts it, the sequence counting on.
* **control** (optional TCP ``control_port``, the drone's 5559) —
  :class:`~ardrone_nmpc.sim.control_port.ControlPort`; ``control_port_mode`` makes it answer
  nothing ("silent") or refuse connections ("refused").

Firmware-like options (also fault kinds, see :mod:`~ardrone_nmpc.sim.faults`): ``ctrl_codes``
(the transition codes of another firmware), ``session`` (left in another multiconfig session:
writes acknowledged, not applied; its own limits flown and reported), ``control_port_mode``
and :meth:`DroneServer.land_by_itself` (a REF still asking for take-off relaunches it).

Not simulated: video (TCP 5555), multicast navdata, animations and LEDs, magnetometer
calibration, the tilt / cut-out / motor emergencies, navdata options other than demo, time and
an empty vision_detect.
"""

from __future__ import annotations

import dataclasses
import math
import select
import socket
import threading
import time
from typing import Callable, Literal, Optional

from ardrone_nmpc.protocol.navdata import CtrlCodes, DroneState
from ardrone_nmpc.sim.addresses import is_loopback_peer, require_loopback_host
from ardrone_nmpc.sim.control_port import ControlPort
from ardrone_nmpc.sim.drone_config import EULER_ANGLE_MAX_LIMIT_RAD, HeldSession
from ardrone_nmpc.sim.drone import SimulatedDrone
from ardrone_nmpc.sim.drone_firmware import VBAT_LOW_PCT, DroneServerCounters
from ardrone_nmpc.sim.plant import AirframePlant

__all__ = ["DroneServer", "DroneServerCounters", "require_loopback_host",
           "EULER_ANGLE_MAX_LIMIT_RAD"]

_RECV_BYTES = 4096
_POLL_S = 0.05                            # socket timeout: shutdown latency of the threads


class DroneServer:
    """The simulated AR.Drone's network side (see the module docstring).

    Parameters
    ----------
    plant : the simulated drone; every call to it is made under :attr:`lock`.
    bind_host : loopback address to bind (ValueError otherwise).
    at_port, navdata_port : UDP ports; 0 picks free ports (see the properties for the actual).
    control_port : TCP configuration port (5559 on the drone); None = not served, 0 = free port.
    control_port_mode : "serve", or a port that does not answer: "silent" (accepts, never
        writes) or "refused" (bound, not listening).
    step_s : physics step (s) on the clock.
    demo_rate_hz, full_rate_hz, bootstrap_rate_hz : navdata rates of demo, full
        (``navdata_demo = FALSE``) and bootstrap streaming.
    comwdg_s, hover_after_s, link_loss_s, navdata_timeout_s : the watchdog times (s) (0.05,
        0.25, 2.0, 2.0); ``navdata_timeout_s=None`` streams forever.
    comwdg_clear : "any" — any accepted command clears state bit 30; "comwdg" — only
        ``AT*COMWDG`` does (latched).
    ctrl_codes : :class:`~ardrone_nmpc.protocol.navdata.CtrlCodes` (or its value): "sdk"
        (take-off 6, landing 8) or "fw2.4" (7, 9).
    altitude_max_m : initial ``control:altitude_max`` (m).
    vbat_low_pct : battery level (%) below which state bit 15 is set.
    session : a multiconfig session the drone was left in (:class:`HeldSession`), None =
        the default session.
    lock : the lock to share (default: a new ``threading.RLock``).
    clock : the time source (s), ``time.monotonic`` by default.
    faults : injected faults (:class:`~ardrone_nmpc.sim.fault_injection.ServerFaults`, None =
        none): plant faults each physics step, navdata packets lost / corrupted / disordered,
        AT datagrams lost on arrival; their experiment time runs on ``clock``.
    drone : the :class:`~ardrone_nmpc.sim.drone.SimulatedDrone` to serve (its plant is
        ``plant``); it brings its own firmware and faults, and the firmware options above
        (``comwdg_s`` … ``session``, ``faults``) are then not taken.
    """

    def __init__(self, plant: AirframePlant, *, bind_host: str = "127.0.0.1", at_port: int = 0,
                 navdata_port: int = 0, control_port: Optional[int] = None,
                 control_port_mode: Literal["serve", "silent", "refused"] = "serve",
                 step_s: float = 0.005, demo_rate_hz: float = 15.0, full_rate_hz: float = 200.0,
                 bootstrap_rate_hz: Optional[float] = None, comwdg_s: float = 0.05,
                 hover_after_s: float = 0.25, link_loss_s: float = 2.0,
                 navdata_timeout_s: Optional[float] = 2.0,
                 comwdg_clear: Literal["any", "comwdg"] = "any",
                 ctrl_codes: CtrlCodes | str = CtrlCodes.SDK,
                 altitude_max_m: float = 3.0, vbat_low_pct: float = VBAT_LOW_PCT,
                 session: Optional[HeldSession] = None, lock: Optional[threading.RLock] = None,
                 clock: Callable[[], float] = time.monotonic, faults=None,
                 drone: Optional[SimulatedDrone] = None) -> None:
        self.bind_host = require_loopback_host(bind_host, "bind address")
        for name, v in (("step_s", step_s), ("demo_rate_hz", demo_rate_hz),
                        ("full_rate_hz", full_rate_hz), ("comwdg_s", comwdg_s),
                        ("hover_after_s", hover_after_s), ("link_loss_s", link_loss_s),
                        ("altitude_max_m", altitude_max_m)):
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be finite and > 0, got {v!r}")
        if comwdg_clear not in ("any", "comwdg"):
            raise ValueError(f"comwdg_clear must be 'any' or 'comwdg', got {comwdg_clear!r}")
        self.plant = plant
        self.lock = lock if lock is not None else threading.RLock()
        self.step_s = float(step_s)
        self.demo_rate_hz = float(demo_rate_hz)
        self.full_rate_hz = float(full_rate_hz)
        self.bootstrap_rate_hz = float(bootstrap_rate_hz or demo_rate_hz)
        self.navdata_timeout_s = None if navdata_timeout_s is None else float(navdata_timeout_s)
        self._clock = clock
        if drone is None:
            drone = SimulatedDrone(
                plant, faults=faults, comwdg_s=float(comwdg_s),
                hover_after_s=float(hover_after_s), link_loss_s=float(link_loss_s),
                comwdg_clear=comwdg_clear, ctrl_codes=CtrlCodes(ctrl_codes),
                altitude_max_m=float(altitude_max_m), vbat_low_pct=float(vbat_low_pct),
                session=session)
        self._drone = drone
        self._counters = drone.counters
        self._firmware = drone.firmware

        # navdata stream (under self.lock)
        self._last_traffic_t: Optional[float] = None  # last datagram on either port
        self._nav_client: Optional[tuple] = None
        self._streaming = False

        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self._started = False
        self._closed = False
        self._at_sock = self._nav_sock = None
        self._control: Optional[ControlPort] = None
        try:
            self._at_sock = self._udp(at_port)
            self._nav_sock = self._udp(navdata_port)
            if control_port is not None:
                self._control = ControlPort(self.bind_host, control_port, lock=self.lock,
                                            counters=self._counters, mode=control_port_mode)
                self._firmware.dump_config = self._control.dump
        except BaseException:
            self._close_sockets()
            raise

    def _udp(self, port: int) -> socket.socket:
        s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            s.bind((self.bind_host, int(port)))
        except BaseException:
            s.close()
            raise
        s.settimeout(_POLL_S)
        return s

    # ------------------------------------------------------------------ public state

    @property
    def at_port(self) -> int:
        """The UDP port AT commands are read from."""
        return self._at_sock.getsockname()[1]

    @property
    def navdata_port(self) -> int:
        """The UDP port of navdata (wake-ups in, packets out)."""
        return self._nav_sock.getsockname()[1]

    @property
    def control_port(self) -> Optional[int]:
        """The TCP configuration port, or None when not served."""
        return None if self._control is None else self._control.port

    @property
    def ctrl_codes(self) -> CtrlCodes:
        """The transition codes navdata reports."""
        return self._firmware.ctrl_codes

    @property
    def altitude_max_m(self) -> float:
        """The altitude cap (m), ``control:altitude_max``."""
        with self.lock:
            return self._firmware.config.altitude_max_m

    @property
    def config(self) -> dict[str, str]:
        """The configuration keys written by ``AT*CONFIG`` (a copy), key → value text."""
        with self.lock:
            return dict(self._firmware.config.written)

    @property
    def config_ids(self) -> tuple[str, str, str]:
        """The last ``AT*CONFIG_IDS`` (session, profile, application)."""
        with self.lock:
            return self._firmware.config.config_ids

    @property
    def counters(self) -> DroneServerCounters:
        """A snapshot of the counters."""
        with self.lock:
            return dataclasses.replace(self._counters)

    @property
    def navdata_client(self) -> Optional[tuple]:
        """The (ip, port) navdata is sent to, or None before the first wake-up."""
        with self.lock:
            return self._nav_client

    @property
    def streaming(self) -> bool:
        """True while navdata is being streamed."""
        with self.lock:
            return self._streaming

    @property
    def bootstrap(self) -> bool:
        """True until ``general:navdata_demo`` is written."""
        with self.lock:
            return self._firmware.config.bootstrap

    @property
    def config_held(self) -> dict[str, str]:
        """The values the drone flies with, as its control port reports them."""
        with self.lock:
            return self._firmware.config.held()

    def land_by_itself(self) -> bool:
        """The drone lands on its own decision now (motor cut-out, low battery, firmware):
        landing, then landed. The client's REF is untouched: one still asking for take-off
        launches it again once it is down, as the firmware does. False if not in the air."""
        with self.lock:
            return self.plant.land()

    def state_bits(self) -> DroneState:
        """The drone state bits navdata would report now."""
        with self.lock:
            return self._firmware.status(self._clock()).state_bits()

    # ------------------------------------------------------------------ life cycle

    def start(self) -> DroneServer:
        """Start the threads (once)."""
        if self._closed:
            raise RuntimeError("DroneServer is closed")
        if self._started:
            raise RuntimeError("DroneServer already started")
        self._started = True
        for name, fn in (("physics", self._physics_loop), ("at", self._at_loop),
                         ("navdata", self._navdata_loop)):
            t = threading.Thread(target=fn, name=f"drone-server-{name}", daemon=True)
            self._threads.append(t)
        for t in self._threads:
            t.start()
        if self._control is not None:
            self._control.start()
        return self

    def stop(self, timeout_s: float = 2.0) -> None:
        """Stop and join the threads and close the sockets (idempotent)."""
        self._stop.set()
        for t in self._threads:
            t.join(timeout_s)
        self._threads.clear()
        self._close_sockets()
        self._closed = True

    close = stop

    def _close_sockets(self) -> None:
        if self._control is not None:
            self._control.stop()
        for s in (self._at_sock, self._nav_sock):
            if s is not None:
                try:
                    s.close()
                except OSError:  # pragma: no cover
                    pass

    def __enter__(self) -> DroneServer:
        if not self._started:
            self.start()
        return self

    def __exit__(self, *exc) -> None:
        self.stop()

    def __repr__(self) -> str:
        return (f"DroneServer({self.bind_host}, at={self.at_port}, navdata={self.navdata_port}"
                f"{'' if self._control is None else f', control={self.control_port}'})")

    # ------------------------------------------------------------------ physics

    def _physics_loop(self) -> None:
        clock, step = self._clock, self.step_s
        t0 = clock()
        done = 0
        while not self._stop.is_set():
            deadline = t0 + (done + 1) * step
            delay = deadline - clock()
            if delay > 0:
                self._stop.wait(delay)
                if self._stop.is_set():
                    break
            now = clock()
            due = int((now - t0) / step) - done
            if due <= 0:
                continue
            with self.lock:
                c = self._counters
                c.physics_max_lag_s = max(c.physics_max_lag_s, now - deadline)
                # plant faults (battery, emergency, delay jump, wind), physics, watchdogs, cap
                self._drone.advance(due * step, now)
                done += due
                c.physics_steps += due
                self._stream_watchdog(now)

    def _stream_watchdog(self, now: float) -> None:
        if (self._streaming and self.navdata_timeout_s is not None
                and (self._last_traffic_t is None
                     or now - self._last_traffic_t > self.navdata_timeout_s)):
            self._streaming = False
            self._counters.navdata_stream_stops += 1

    # ------------------------------------------------------------------ AT commands

    def _at_loop(self) -> None:
        sock = self._at_sock
        while not self._stop.is_set():
            try:
                data, addr = sock.recvfrom(_RECV_BYTES)
            except socket.timeout:
                continue
            except OSError:
                if self._stop.is_set():
                    break
                continue
            if not is_loopback_peer(addr):   # pragma: no cover - the socket is loopback-bound
                continue
            self.handle_at_datagram(data)

    def handle_at_datagram(self, data: bytes) -> None:
        """Apply one AT datagram (as received on the AT port)."""
        now = self._clock()
        with self.lock:   # one lost before the drone is no traffic for its watchdogs either
            if self._drone.receive_at(data, now):
                self._last_traffic_t = now

    # ------------------------------------------------------------------ navdata

    @property
    def navdata_period_s(self) -> float:
        """The navdata period the server streams at now (s): bootstrap, demo or full rate."""
        return self._navdata_period()

    def _navdata_period(self) -> float:
        config = self._firmware.config
        if config.bootstrap:
            return 1.0 / self.bootstrap_rate_hz
        return 1.0 / (self.demo_rate_hz if config.demo else self.full_rate_hz)

    def _packet(self, now: float) -> bytes:
        """The next navdata packet (under the lock)."""
        return self._firmware.packet(now)

    def _on_wakeup(self, addr, now: float) -> bool:
        """A datagram on the navdata port; True if it (re)starts the stream."""
        with self.lock:
            self._counters.navdata_datagrams_in += 1
            self._last_traffic_t = now
            self._nav_client = addr
            if self._streaming:
                return False
            self._streaming = True
            self._counters.navdata_stream_starts += 1
            return True

    def _navdata_loop(self) -> None:
        sock, clock = self._nav_sock, self._clock
        next_send = math.inf
        while not self._stop.is_set():
            now = clock()
            timeout = min(_POLL_S, max(0.0, next_send - now))
            try:
                readable, _, _ = select.select([sock], [], [], timeout)
            except (OSError, ValueError):
                if self._stop.is_set():
                    break
                continue
            if readable:
                try:
                    _, addr = sock.recvfrom(_RECV_BYTES)
                except OSError:
                    continue
                if is_loopback_peer(addr) and self._on_wakeup(addr, clock()):
                    next_send = clock()
                continue
            now = clock()
            with self.lock:
                if not self._streaming:
                    next_send = math.inf
                    continue
                if now < next_send:
                    continue
                target = self._nav_client
                period = self._navdata_period()
                # injected faults: none (lost), corrupted, duplicated or held back
                datagrams = self._drone.navdata_datagrams(now)
            self._send_navdata(sock, datagrams, target)
            next_send += period
            if next_send < now - period:   # fell behind by more than a period: re-anchor
                next_send = now + period

    def _send_navdata(self, sock: socket.socket, datagrams: list[bytes], target) -> None:
        for packet in datagrams:
            try:
                sock.sendto(packet, target)
                with self.lock:
                    self._counters.navdata_packets_out += 1
            except OSError:
                with self.lock:
                    self._counters.navdata_send_errors += 1
