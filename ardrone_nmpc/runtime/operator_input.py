"""The operator's keys during ``fly`` on a terminal: land now, or cut the motors.

:class:`KeyReader` reads the terminal in its own thread (never the control thread's time) with
the terminal in cbreak mode (keys arrive one by one, unechoed; Ctrl-C still interrupts):

* **space** or **Enter** — land now (:meth:`OperatorRequests.request_land`; the control loop
  leaves at its next tick and the session lands the drone);
* **e** or **Esc** — cut the motors (emergency) at once, from the reader thread itself.
  An escape *sequence* (arrow keys, function keys: Esc followed by more bytes within 30 ms) is
  not an Esc press and is ignored — a stray arrow key must not drop the drone.

:class:`OperatorRequests` is what the session and the loop look at; the reader only sets it.
"""

from __future__ import annotations

import os
import select
import termios
import threading
import tty
from collections.abc import Callable

from ardrone_nmpc.errors import UserError

__all__ = ["KEYS_HELP", "KeyReader", "OperatorAbort", "OperatorRequests"]

KEYS_HELP = "space/Enter: land now · e/Esc: cut motors (emergency) · Ctrl-C: land"
_LAND_KEYS = frozenset(b" \r\n")
_EMERGENCY_KEYS = frozenset(b"eE")
_ESC = 0x1B
_SEQUENCE_WAIT_S = 0.03


class OperatorAbort(UserError, RuntimeError):
    """The operator asked to land (or cut the motors): the flight ends here."""


class OperatorRequests:
    """Thread-safe flags the key reader sets and the session/loop read."""

    def __init__(self) -> None:
        self._land = threading.Event()
        self._emergency = threading.Event()

    def request_land(self) -> None:
        self._land.set()

    def request_emergency(self) -> None:
        self._emergency.set()
        self._land.set()  # an emergency also ends the flight

    @property
    def land(self) -> bool:
        return self._land.is_set()

    @property
    def emergency(self) -> bool:
        return self._emergency.is_set()


class KeyReader:
    """Reads keys from terminal ``fd`` until :meth:`stop`; calls ``on_land`` / ``on_emergency``
    from its thread. Context manager: start … stop (the terminal's mode is restored)."""

    def __init__(self, fd: int, *, on_land: Callable[[], None],
                 on_emergency: Callable[[], None]) -> None:
        self.fd = fd
        self.on_land = on_land
        self.on_emergency = on_emergency
        self._stop = threading.Event()
        self._saved = None
        self._thread: threading.Thread | None = None

    def start(self) -> None:
        try:
            self._saved = termios.tcgetattr(self.fd)
            tty.setcbreak(self.fd, termios.TCSANOW)
        except (termios.error, OSError):
            self._saved = None
            return  # not a terminal after all: no keys, the flight goes on
        self._thread = threading.Thread(target=self._loop, name="operator-keys", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout=1.0)
        if self._saved is not None:
            try:
                termios.tcsetattr(self.fd, termios.TCSADRAIN, self._saved)
            except (termios.error, OSError):  # the terminal is gone (SIGHUP)
                pass
            self._saved = None

    def __enter__(self) -> KeyReader:
        self.start()
        return self

    def __exit__(self, *exc) -> None:
        self.stop()

    def _read(self, timeout_s: float) -> bytes:
        ready, _, _ = select.select([self.fd], [], [], timeout_s)
        if not ready:
            return b""
        data = os.read(self.fd, 64)
        if not data:
            raise EOFError
        return data

    def _loop(self) -> None:
        while not self._stop.is_set():
            try:
                data = self._read(0.1)
                if data == bytes([_ESC]):  # alone, or the start of an escape sequence?
                    data += self._read(_SEQUENCE_WAIT_S)
            except (OSError, ValueError, EOFError):
                return  # the terminal closed: the signal handlers take it from here
            if not data:
                continue
            self.handle(data)

    def handle(self, data: bytes) -> None:
        """Act on one read's bytes (an escape sequence as a whole is ignored)."""
        if data[0] == _ESC:
            if len(data) == 1:
                self.on_emergency()
            return
        if any(b in _EMERGENCY_KEYS for b in data):
            self.on_emergency()
        elif any(b in _LAND_KEYS for b in data):
            self.on_land()
