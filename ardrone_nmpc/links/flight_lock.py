"""One flight per drone: an advisory lock per drone address, held from before connecting
until the drone is down.

A second ``fly`` at a drone already flown from this machine would wake the navdata stream from
its own port — the drone then streams to the newcomer, and the first flight loses its feedback
mid-air. :class:`FlightLock` prevents that before a single datagram goes out: a ``flock`` on a
file named after the drone's address and AT port in the user's runtime directory
(``$XDG_RUNTIME_DIR/ardrone-nmpc``, else ``<tmp>/ardrone-nmpc-<uid>``). The kernel drops the
lock when its holder dies (even by SIGKILL), so a stale file never blocks a flight. The file
holds the holder's pid and command line, for the refusal message and for the operator's
``land``/``emergency``, which never take the lock (they must always go through) but tell the
holder to land (SIGTERM) — two clients sending opposite REF levels would fight.
"""

from __future__ import annotations

import fcntl
import os
import re
import socket
import sys
import tempfile
from pathlib import Path

from ardrone_nmpc.errors import UserError

__all__ = ["DroneBusy", "FlightLock", "lock_dir"]


class DroneBusy(UserError, RuntimeError):
    """Another process on this machine holds the drone's flight lock."""


def lock_dir() -> Path:
    """The directory of the lock files (created, mode 0700)."""
    runtime = os.environ.get("XDG_RUNTIME_DIR")
    base = (Path(runtime) / "ardrone-nmpc" if runtime
            else Path(tempfile.gettempdir()) / f"ardrone-nmpc-{os.getuid()}")
    base.mkdir(mode=0o700, parents=True, exist_ok=True)
    return base


def _address(host: str) -> str:
    try:  # 'localhost' and '127.0.0.1' are the same drone
        return socket.gethostbyname(host)
    except OSError:
        return host


class FlightLock:
    """The flight lock of the drone at ``host`` (AT port ``at_port``).

    :meth:`acquire` raises :class:`DroneBusy` (naming the holder) if another process holds it;
    it is idempotent for this object, as is :meth:`release`. :meth:`holder` reads the pid of a
    live holder without taking the lock. Context manager: acquire … release.
    """

    def __init__(self, host: str, at_port: int, *, directory: Path | None = None) -> None:
        self.host = host
        self.at_port = int(at_port)
        safe = re.sub(r"[^A-Za-z0-9.-]", "_", _address(host))[:100]
        self.path = (directory or lock_dir()) / f"drone-{safe}-{self.at_port}.lock"
        self._fd: int | None = None

    @property
    def held(self) -> bool:
        return self._fd is not None

    def acquire(self) -> None:
        if self._fd is not None:
            return
        fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o600)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            pid, command = self._read_holder()
            raise DroneBusy(
                f"the drone at {self.host}:{self.at_port} is being flown from this machine "
                f"(pid {pid or '?'}{': ' + command if command else ''}) — one flight per "
                "drone: wait for it to land, or land it with `ardrone-nmpc land`") from None
        except BaseException:
            os.close(fd)
            raise
        os.ftruncate(fd, 0)
        os.write(fd, f"{os.getpid()}\n{' '.join(sys.argv)[:400]}\n".encode(errors="replace"))
        self._fd = fd

    def release(self) -> None:
        fd, self._fd = self._fd, None
        if fd is not None:
            try:
                fcntl.flock(fd, fcntl.LOCK_UN)
            finally:
                os.close(fd)

    def holder(self) -> int | None:
        """The pid of the process holding the lock now (None if nobody does)."""
        if self._fd is not None:
            return os.getpid()
        try:
            fd = os.open(self.path, os.O_RDWR)
        except FileNotFoundError:
            return None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            return self._read_holder()[0]
        finally:
            os.close(fd)  # closing drops a lock taken just now
        return None

    def _read_holder(self) -> tuple[int | None, str]:
        try:
            lines = self.path.read_text(errors="replace").splitlines()
            return int(lines[0]), (lines[1] if len(lines) > 1 else "")
        except (OSError, ValueError, IndexError):
            return None, ""

    def __enter__(self) -> FlightLock:
        self.acquire()
        return self

    def __exit__(self, *exc) -> None:
        self.release()
