"""A minimal AR.Drone 2.0 stand-in with a disturbed, first-order velocity plant.

Written for the offset-free tracking tests from the SDK's documented behaviour (docs/protocol.md
restates it: AT commands on UDP, ``\\r``-separated, floats as int32 bit patterns; REF bit 9
take-off/land; PCMD flag 0 = hover; navdata on UDP to the wake-up's source, bootstrap until a
``AT*CONFIG``, state bit 6 = config ACK cleared by ``AT*CTRL=…,5,0``; the 148-byte demo option and
the byte-sum checksum option) and a Vicon-style pose stream (docs/mocap-stream.md). It imports
nothing from ``ardrone_nmpc``: it is not our simulator, and its dynamics are deliberately other
than ``sim/plant.py``'s — first-order velocity channels with the gains of a published
identification of the AR.Drone (x: 6.154·0.21/(s + 0.665), y: 4.774·0.21/(s + 0.46), per unit
PCMD fraction, air-relative so a wind drags the drone), a vertical speed of ``vz_gain`` times
the commanded, and a 0.1 s command delay.

Loopback only: it binds and sends on 127.0.0.1.
"""

from __future__ import annotations

import math
import socket
import struct
import threading
import time
from collections import deque

import numpy as np

_HEADER = 0x55667788
_BIT_FLY, _BIT_ACK, _BIT_DEMO, _BIT_BOOTSTRAP = 1 << 0, 1 << 6, 1 << 10, 1 << 11
_LANDED, _FLYING, _HOVERING, _TAKEOFF, _LANDING = 2, 3, 4, 6, 8
_DEMO = struct.Struct("<HHIIfffifffI9f3fII9f3f")  # 148 bytes
_POSE = struct.Struct("<BH24s6d")


def _float_of(arg: str) -> float:
    return struct.unpack("<f", struct.pack("<i", int(arg)))[0]


class OffsetEmulator:
    """The stand-in drone: ``with OffsetEmulator(mocap_port=p, ...) as emu:`` then fly against
    ``127.0.0.1:emu.at_port`` / ``emu.navdata_port``; poses go to ``127.0.0.1:mocap_port``.

    Parameters
    ----------
    mocap_port : where the pose stream is sent (the ground station's mocap port).
    vz_gain : vertical speed = vz_gain × gaz × control_vz_max.
    wind_mps : (wx, wy) air velocity, world frame.
    sink_mps : a constant sink of the vertical loop (m/s; a thrust deficit it does not
        reject), 0 by default.
    """

    X_GAIN, X_POLE = 6.154 * 0.21, 0.665   # (m/s²) per unit pitch fraction, 1/s
    Y_GAIN, Y_POLE = 4.774 * 0.21, 0.46
    TAU_VZ_S = 0.3
    DELAY_S = 0.1
    STEP_S = 0.005
    HOLD_TAU_S = 0.5       # optical-flow position hold (PCMD flag 0): ground speed → 0
    TAKEOFF_ALT_M = 0.8

    def __init__(self, *, mocap_port: int, vz_gain: float = 0.7,
                 wind_mps: tuple[float, float] = (0.3, 0.2), sink_mps: float = 0.0,
                 object_name: str = "ardrone", seed: int = 0) -> None:
        self.sink_mps = sink_mps
        self.mocap_port = mocap_port
        self.vz_gain = vz_gain
        self.wind = np.array(wind_mps, dtype=float)
        self.object_name = object_name.encode()
        self.rng = np.random.default_rng(seed)
        self.pos = np.zeros(3)       # world x forward, y left, z up (m)
        self.vel = np.zeros(3)
        self.psi = 0.0               # counter-clockwise (rad)
        self.major = _LANDED
        self.vz_max_mps, self.yaw_max_radps = 0.7, 1.745
        self.ack = False
        self.bootstrap = True
        self.pcmd = (0, 0.0, 0.0, 0.0, 0.0)
        self.fifo: deque = deque([self.pcmd] * round(self.DELAY_S / self.STEP_S))
        self.takeoff_bit = False
        self.last_seq = 0
        self.nav_dest = None
        self.lock = threading.Lock()
        self.stop = threading.Event()
        self.at_sock = self._udp()
        self.nav_sock = self._udp()
        self.out_sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.at_port = self.at_sock.getsockname()[1]
        self.navdata_port = self.nav_sock.getsockname()[1]
        self.threads = [threading.Thread(target=f, daemon=True)
                        for f in (self._at_loop, self._nav_rx_loop, self._run)]

    @staticmethod
    def _udp() -> socket.socket:
        s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        s.bind(("127.0.0.1", 0))
        s.settimeout(0.05)
        return s

    def __enter__(self) -> OffsetEmulator:
        for t in self.threads:
            t.start()
        return self

    def __exit__(self, *exc) -> None:
        self.stop.set()
        for t in self.threads:
            t.join(timeout=2.0)
        for s in (self.at_sock, self.nav_sock, self.out_sock):
            s.close()

    # ------------------------------------------------------------------ AT commands
    def _at_loop(self) -> None:
        while not self.stop.is_set():
            try:
                data = self.at_sock.recv(2048)
            except (TimeoutError, socket.timeout):
                continue
            except OSError:
                return
            for line in data.decode("ascii", "replace").split("\r"):
                line = line.strip("\n")
                if line.startswith("AT*") and "=" in line:
                    name, _, rest = line[3:].partition("=")
                    with self.lock:
                        self._command(name, rest.split(","))

    def _command(self, name: str, args: list[str]) -> None:
        seq = int(args[0])
        if not (seq == 1 or seq > self.last_seq):
            return
        self.last_seq = seq
        if name in ("PCMD", "PCMD_MAG"):
            self.pcmd = (int(args[1]), *(_float_of(a) for a in args[2:6]))
        elif name == "REF":
            self.takeoff_bit = bool(int(args[1]) & 512)
        elif name == "CONFIG":
            key, value = args[1].strip('"'), args[2].strip('"')
            if key == "control:control_vz_max":
                self.vz_max_mps = float(value) / 1000.0
            elif key == "control:control_yaw":
                self.yaw_max_radps = float(value)
            self.bootstrap = False
            self.ack = True
        elif name == "CTRL" and args[1] == "5":
            self.ack = False

    # ------------------------------------------------------------------ navdata
    def _nav_rx_loop(self) -> None:
        while not self.stop.is_set():
            try:
                _, addr = self.nav_sock.recvfrom(64)
            except (TimeoutError, socket.timeout):
                continue
            except OSError:
                return
            with self.lock:
                self.nav_dest = addr  # unicast to the wake-up's source

    def _navdata(self, seq: int) -> bytes:
        state = (_BIT_FLY if self.major not in (_LANDED,) else 0) | (_BIT_ACK if self.ack else 0)
        if self.bootstrap:
            body = struct.pack("<IIII", _HEADER, state | _BIT_BOOTSTRAP, seq, 0)
        else:
            c, s = math.cos(self.psi), math.sin(self.psi)
            forward = c * self.vel[0] + s * self.vel[1]
            right = s * self.vel[0] - c * self.vel[1]
            demo = _DEMO.pack(0, _DEMO.size, self.major << 16, 80, 0.0, 0.0,
                              -math.degrees(self.psi) * 1e3, int(self.pos[2] * 1e3),
                              forward * 1e3, right * 1e3, -self.vel[2] * 1e3, 0,
                              *([0.0] * 9), *([0.0] * 3), 0, 3, *([0.0] * 9), *([0.0] * 3))
            body = struct.pack("<IIII", _HEADER, state | _BIT_DEMO, seq, 0) + demo
        return body + struct.pack("<HHI", 0xFFFF, 8, sum(body) & 0xFFFFFFFF)

    def _pose(self, frame: int) -> bytes:
        p = (self.pos + self.rng.normal(0.0, 0.0003, 3)) * 1e3  # noise: never bit-identical
        item = _POSE.pack(0, 72, self.object_name, *p, 0.0, 0.0, self.psi)
        return struct.pack("<IB", frame, 1) + item

    # ------------------------------------------------------------------ the plant
    def _run(self) -> None:
        t0 = time.monotonic()
        k = 0
        while not self.stop.is_set():
            k += 1
            target = t0 + k * self.STEP_S
            delay = target - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            with self.lock:
                self._step()
                nav = self._navdata(k) if k % 13 == 0 and self.nav_dest else None  # ≈ 15 Hz
                dest = self.nav_dest
                pose = self._pose(k // 2) if k % 2 == 0 else None                   # 100 Hz
            try:
                if nav is not None:
                    self.out_sock.sendto(nav, dest)
                if pose is not None:
                    self.out_sock.sendto(pose, ("127.0.0.1", self.mocap_port))
            except OSError:
                return

    def _step(self) -> None:
        h = self.STEP_S
        self.fifo.append(self.pcmd)
        flag, roll, pitch, gaz, yaw = self.fifo.popleft()
        if self.major == _LANDED:
            if self.takeoff_bit:
                self.major = _TAKEOFF
            return
        if not self.takeoff_bit and self.major != _LANDING:
            self.major = _LANDING
        if self.major in (_TAKEOFF, _LANDING):
            vz_ref = 0.6 if self.major == _TAKEOFF else -0.5
            flag = 0
        else:
            vz_ref = self.vz_gain * max(-1.0, min(1.0, gaz)) * self.vz_max_mps - self.sink_mps
        acc = -self.vel[:2] / self.HOLD_TAU_S
        if flag & 1:  # the four values act; tilt → air-relative velocity, first order
            c, s = math.cos(self.psi), math.sin(self.psi)
            air = self.vel[:2] - self.wind
            a_fwd = -self.X_GAIN * pitch - self.X_POLE * (c * air[0] + s * air[1])
            a_left = -self.Y_GAIN * roll - self.Y_POLE * (-s * air[0] + c * air[1])
            acc = np.array([c * a_fwd - s * a_left, s * a_fwd + c * a_left])
            self.psi += -max(-1.0, min(1.0, yaw)) * self.yaw_max_radps * h
            self.major = _FLYING
        elif self.major == _FLYING:
            self.major = _HOVERING
        self.vel[:2] += acc * h
        self.vel[2] += (vz_ref - self.vel[2]) / self.TAU_VZ_S * h
        self.pos += self.vel * h
        if self.major == _TAKEOFF and self.pos[2] >= self.TAKEOFF_ALT_M:
            self.major = _HOVERING
        if self.pos[2] <= 0.0 and self.major == _LANDING:
            self.pos[2] = 0.0
            self.vel[:] = 0.0
            self.major = _LANDED
        self.pos[2] = max(self.pos[2], 0.0)
