"""The operator's ways in: terminating signals (runtime/signals.py), the keys on a terminal
(runtime/operator_input.py, driven through a pseudo-terminal) and the flight lock
(links/flight_lock.py, held by another process)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time

import pytest

from ardrone_nmpc.links.flight_lock import DroneBusy, FlightLock, lock_dir
from ardrone_nmpc.runtime.operator_input import KeyReader, OperatorRequests
from ardrone_nmpc.runtime.signals import (
    EMERGENCY_SIGNAL,
    LANDING_SIGNALS,
    EmergencyRequested,
    Terminated,
    exit_code_of,
    ignoring_emergency_signal,
    landing_signals,
)


# ----------------------------------------------------------------------------- signals

def test_exit_codes_are_128_plus_the_signal():
    assert exit_code_of(KeyboardInterrupt()) == 130
    assert exit_code_of(Terminated(signal.SIGHUP)) == 129
    assert exit_code_of(Terminated(signal.SIGPIPE)) == 141
    assert str(Terminated(signal.SIGQUIT)) == "SIGQUIT"
    assert isinstance(Terminated(15), KeyboardInterrupt)


@pytest.mark.parametrize("sig", LANDING_SIGNALS)
def test_each_landing_signal_raises_terminated_inside_and_nothing_after(sig):
    before = signal.getsignal(sig)
    with pytest.raises(Terminated) as err:
        with landing_signals():
            os.kill(os.getpid(), sig)
            for _ in range(1000):  # the handler runs between bytecodes
                time.sleep(0.001)
    assert err.value.signum == sig
    assert signal.getsignal(sig) == before


def test_the_emergency_signal_raises_its_own_terminated_inside_and_nothing_after():
    assert EMERGENCY_SIGNAL == signal.SIGUSR2 and EMERGENCY_SIGNAL not in LANDING_SIGNALS
    before = signal.getsignal(EMERGENCY_SIGNAL)
    with pytest.raises(EmergencyRequested) as err:
        with landing_signals():
            os.kill(os.getpid(), EMERGENCY_SIGNAL)
            for _ in range(1000):
                time.sleep(0.001)
    assert isinstance(err.value, Terminated) and exit_code_of(err.value) == 140
    assert str(err.value) == "the operator's `emergency` command (SIGUSR2)"
    assert signal.getsignal(EMERGENCY_SIGNAL) == before


def test_around_a_flight_a_late_emergency_signal_is_ignored_not_fatal():
    before = signal.getsignal(EMERGENCY_SIGNAL)
    with ignoring_emergency_signal():
        os.kill(os.getpid(), EMERGENCY_SIGNAL)          # the default action would kill us
        time.sleep(0.05)
        with pytest.raises(EmergencyRequested):
            with landing_signals():
                os.kill(os.getpid(), EMERGENCY_SIGNAL)
                for _ in range(1000):
                    time.sleep(0.001)
        assert signal.getsignal(EMERGENCY_SIGNAL) == signal.SIG_IGN
        os.kill(os.getpid(), EMERGENCY_SIGNAL)
        time.sleep(0.05)
    assert signal.getsignal(EMERGENCY_SIGNAL) == before


def test_sigint_raises_keyboard_interrupt_whatever_was_installed():
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        with pytest.raises(KeyboardInterrupt) as err:
            with landing_signals():
                os.kill(os.getpid(), signal.SIGINT)
                for _ in range(1000):
                    time.sleep(0.001)
        assert type(err.value) is KeyboardInterrupt
        assert signal.getsignal(signal.SIGINT) == signal.SIG_IGN
    finally:
        signal.signal(signal.SIGINT, previous)


def test_outside_the_main_thread_nothing_is_installed():
    seen = []

    def body():
        with landing_signals():
            seen.append(signal.getsignal(signal.SIGHUP))

    before = signal.getsignal(signal.SIGHUP)
    t = threading.Thread(target=body)
    t.start()
    t.join()
    assert seen == [before]


# ----------------------------------------------------------------------------- keys

@pytest.fixture
def terminal():
    master, slave = os.openpty()
    yield master, slave
    os.close(master)
    os.close(slave)


def run_keys(terminal, data: bytes, wait_for):
    master, slave = terminal
    requests = OperatorRequests()
    cut = []
    reader = KeyReader(slave, on_land=requests.request_land,
                       on_emergency=lambda: (cut.append(1), requests.request_emergency()))
    with reader:
        os.write(master, data)
        deadline = time.monotonic() + 3.0
        while time.monotonic() < deadline and not wait_for(requests):
            time.sleep(0.01)
        time.sleep(0.1)  # anything else it would do, it does now
    return requests, cut


@pytest.mark.timeout(10)
@pytest.mark.parametrize("key", [b" ", b"\r", b"\n"])
def test_space_or_enter_lands(terminal, key):
    requests, cut = run_keys(terminal, key, lambda r: r.land)
    assert requests.land and not requests.emergency and cut == []


@pytest.mark.timeout(10)
@pytest.mark.parametrize("key", [b"e", b"E", b"\x1b"])
def test_e_or_esc_cuts_the_motors(terminal, key):
    requests, cut = run_keys(terminal, key, lambda r: r.emergency)
    assert requests.emergency and requests.land and cut == [1]


@pytest.mark.timeout(10)
def test_an_arrow_key_is_not_an_esc_press(terminal):
    requests, cut = run_keys(terminal, b"\x1b[A", lambda r: False)
    assert not requests.land and cut == []


@pytest.mark.timeout(10)
def test_the_terminal_mode_is_restored(terminal):
    import termios

    master, slave = terminal
    before = termios.tcgetattr(slave)
    with KeyReader(slave, on_land=lambda: None, on_emergency=lambda: None):
        during = termios.tcgetattr(slave)
        assert not during[3] & termios.ICANON and not during[3] & termios.ECHO
    assert termios.tcgetattr(slave) == before


def test_no_terminal_no_keys():
    r, w = os.pipe()
    try:
        reader = KeyReader(r, on_land=lambda: None, on_emergency=lambda: None)
        reader.start()
        assert reader._thread is None
        reader.stop()
    finally:
        os.close(r)
        os.close(w)


# ----------------------------------------------------------------------------- flight lock

HOLD = """
import sys, time
from pathlib import Path
from ardrone_nmpc.links.flight_lock import FlightLock
lock = FlightLock("localhost", 5556, directory=Path(sys.argv[1]))
lock.acquire()
print("held", flush=True)
time.sleep(60)
"""


@pytest.mark.timeout(30)
def test_a_lock_held_by_another_process_refuses_and_dies_with_it(tmp_path):
    env = dict(os.environ, PYTHONPATH=os.getcwd())
    proc = subprocess.Popen([sys.executable, "-c", HOLD, str(tmp_path)], stdout=subprocess.PIPE,
                            text=True, env=env)
    try:
        assert proc.stdout.readline().strip() == "held"
        mine = FlightLock("127.0.0.1", 5556, directory=tmp_path)
        assert mine.holder() == proc.pid
        with pytest.raises(DroneBusy, match=rf"pid {proc.pid}: .*-c"):
            mine.acquire()
        assert not mine.held
        assert FlightLock("127.0.0.1", 5557, directory=tmp_path).holder() is None  # other drone
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=10)
        assert mine.holder() is None  # the kernel dropped it with its holder
        with mine:
            assert mine.held and mine.holder() == os.getpid()
            mine.acquire()  # idempotent
        assert not mine.held
        mine.release()  # idempotent
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def test_the_lock_directory_is_private_and_follows_xdg(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_RUNTIME_DIR", str(tmp_path))
    d = lock_dir()
    assert d == tmp_path / "ardrone-nmpc" and (d.stat().st_mode & 0o777) == 0o700
    monkeypatch.delenv("XDG_RUNTIME_DIR")
    assert lock_dir().name == f"ardrone-nmpc-{os.getuid()}"
