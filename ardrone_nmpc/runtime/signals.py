"""Nothing ends a flight without landing it: every catchable terminating signal lands.

A closed terminal (SIGHUP), Ctrl-\\ (SIGQUIT), ``kill`` (SIGTERM), SIGUSR1 and a write to a
closed pipe (SIGPIPE) would each end the process at once by default and leave the drone
hovering. Inside :func:`landing_signals` each raises :class:`Terminated` instead — a
``KeyboardInterrupt``, exactly like Ctrl-C (SIGINT), so no ``except Exception`` on the way can
swallow it and the flight session's exit lands the drone — and the process exits with
128 + the signal's number (:func:`exit_code_of`). :data:`EMERGENCY_SIGNAL` (SIGUSR2) is the
operator's ``emergency`` command reaching the flight that holds the drone: it raises
:class:`EmergencyRequested` (a :class:`Terminated`), and the session cuts the motors instead of
landing. SIGKILL and SIGSTOP cannot be caught; the drone's own watchdog then holds it hovering
(docs/first-flight.md says what to do).

Every other command runs inside :func:`stopping_signals` (the command line's handler), which
does the same for :data:`STOPPING_SIGNALS`: a ``simulate``, ``sweep`` or ``tune`` that is
sent SIGTERM or loses its terminal ends the way Ctrl-C ends it — its run directory says it
was interrupted, its files are consistent — instead of dying mid-write.
"""

from __future__ import annotations

import signal
import threading
from contextlib import contextmanager

__all__ = ["EMERGENCY_SIGNAL", "EmergencyRequested", "LANDING_SIGNALS", "STOPPING_SIGNALS",
           "Terminated", "deferred_signals", "exit_code_of", "ignoring_emergency_signal",
           "landing_signals", "polled_signals", "signal_name", "stopping_signals"]

#: Besides SIGINT (Python's own KeyboardInterrupt), the signals that land the drone.
LANDING_SIGNALS: tuple[signal.Signals, ...] = (
    signal.SIGHUP, signal.SIGQUIT, signal.SIGUSR1, signal.SIGPIPE, signal.SIGTERM)
#: The signal ``ardrone-nmpc emergency`` sends the flight holding the drone: cut the motors.
EMERGENCY_SIGNAL = signal.SIGUSR2
#: The signals :func:`stopping_signals` turns into :class:`Terminated` (SIGPIPE stays a
#: BrokenPipeError there: a closed pipe is no reason to stop a flight that is not flying).
STOPPING_SIGNALS: tuple[signal.Signals, ...] = (
    signal.SIGHUP, signal.SIGQUIT, signal.SIGUSR1, signal.SIGUSR2, signal.SIGTERM)


class Terminated(KeyboardInterrupt):
    """A terminating signal arrived: leave the loop and land, like Ctrl-C."""

    def __init__(self, signum: int) -> None:
        self.signum = int(signum)
        super().__init__(signal.Signals(self.signum).name)


class EmergencyRequested(Terminated):
    """:data:`EMERGENCY_SIGNAL` arrived: the operator's ``emergency`` command — cut the motors
    (the session does), do not land."""

    def __str__(self) -> str:
        return f"the operator's `emergency` command ({signal.Signals(self.signum).name})"


def exit_code_of(interrupt: BaseException) -> int:
    """The exit code of a flight ended by ``interrupt``: 128 + its signal (130 for Ctrl-C)."""
    if isinstance(interrupt, Terminated):
        return 128 + interrupt.signum
    return 128 + int(signal.SIGINT)


def signal_name(interrupt: BaseException) -> str:
    """The signal behind ``interrupt``: ``SIGTERM``, ``SIGHUP``, … (``SIGINT`` for Ctrl-C)."""
    if isinstance(interrupt, Terminated):
        return signal.Signals(interrupt.signum).name
    return signal.SIGINT.name


def _raise_terminated(signum, frame):
    raise Terminated(signum)


def _raise_emergency(signum, frame):
    raise EmergencyRequested(signum)


@contextmanager
def landing_signals(signals: tuple[signal.Signals, ...] = LANDING_SIGNALS, *,
                    emergency: bool = True):
    """Within the block, ``signals`` raise :class:`Terminated`, :data:`EMERGENCY_SIGNAL`
    :class:`EmergencyRequested` (if ``emergency``: a flight holding the drone), and SIGINT raises
    KeyboardInterrupt (whatever handler was set before); the previous handlers come back after.
    Outside the main thread (where Python delivers signals) it changes nothing."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {}
    try:
        previous[signal.SIGINT] = signal.signal(signal.SIGINT, signal.default_int_handler)
        for sig in signals:
            previous[sig] = signal.signal(sig, _raise_terminated)
        if emergency:
            previous[EMERGENCY_SIGNAL] = signal.signal(EMERGENCY_SIGNAL, _raise_emergency)
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


def stopping_signals():
    """:func:`landing_signals` for :data:`STOPPING_SIGNALS` (every command but ``fly``)."""
    return landing_signals(STOPPING_SIGNALS, emergency=False)


@contextmanager
def _held(handlers: dict[int, object]):
    """Within the block each signal of ``handlers`` is only noted; the yielded ``deliver()``
    hands the first one noted to its handler (``handlers[signum](signum, None)``), and the
    block's end does if ``deliver`` was not asked. The handlers in force before come back."""
    pending: list[int] = []

    def note(signum, frame):
        pending.append(signum)

    def deliver() -> None:
        if pending:
            signum = pending[0]
            pending.clear()
            handlers[signum](signum, None)

    previous = {}
    try:
        for sig in handlers:
            previous[sig] = signal.signal(sig, note)
        yield deliver
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    deliver()


@contextmanager
def deferred_signals():
    """Within the block, Ctrl-C and :data:`STOPPING_SIGNALS` wait: the first one is raised
    (as ``KeyboardInterrupt`` / :class:`Terminated`) when the block ends, so a write that must
    not be cut in half (a database transaction) completes. Outside the main thread it changes
    nothing."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    with _held({signal.SIGINT: signal.default_int_handler,
                **{sig: _raise_terminated for sig in STOPPING_SIGNALS}}):
        yield


#: Every signal :func:`polled_signals` may hold back (those whose handler is Python's).
_POLLABLE: tuple[signal.Signals, ...] = tuple(dict.fromkeys(
    (signal.SIGINT, *LANDING_SIGNALS, EMERGENCY_SIGNAL, *STOPPING_SIGNALS)))


@contextmanager
def polled_signals():
    """Within the block, a signal whose handler would raise (Ctrl-C, or one of the handlers
    above) is only noted; the yielded ``check()`` hands it to that handler — raising
    ``KeyboardInterrupt`` / :class:`Terminated` / :class:`EmergencyRequested` — at the
    caller's safe point, and the block's end does if ``check`` did not. Signals that are
    ignored or left to the system stay so (a pool worker ignores Ctrl-C).

    Why: Python runs a handler between any two bytecodes, and an exception raised there is
    not always an exception the caller sees. Inside a numba dispatcher call it comes out as
    ``SystemError: CPUDispatcher(...) returned a result with an exception set``; inside a
    finaliser it is printed and dropped. A lockstep flight is compiled calls from end to end:
    its ``kill`` became a failure, or was lost and the hour-long flight flew on to exit 0.
    A loop that calls ``check()`` once a tick ends at the tick the signal arrived in.
    Outside the main thread it changes nothing (``check`` does nothing)."""
    if threading.current_thread() is not threading.main_thread():
        yield lambda: None
        return
    current = {sig: signal.getsignal(sig) for sig in _POLLABLE}
    with _held({sig: h for sig, h in current.items() if callable(h)}) as check:
        yield check


@contextmanager
def ignoring_emergency_signal():
    """Within the block :data:`EMERGENCY_SIGNAL` is ignored, outside any inner
    :func:`landing_signals` (which raise on it): an operator's ``emergency`` that reaches a
    flight already past its landing — writing its summary — must not kill it (the default
    action) before its run directory is complete. Outside the main thread it changes nothing."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(EMERGENCY_SIGNAL, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(EMERGENCY_SIGNAL, previous)
