"""polled_signals: a signal that would raise is raised at the caller's safe point.

Python raises a handler's exception between any two bytecodes; inside a numba dispatcher call
it comes out as a SystemError and in a finaliser it is dropped (a SIGTERM to an hour-long
``simulate`` was lost, and the flight flew on to exit 0). These tests hold the mechanism and
the lockstep flight that relies on it: it ends at the tick the signal arrived in."""

from __future__ import annotations

import os
import signal
from pathlib import Path

import pytest

from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.runtime.lockstep import run_lockstep
from ardrone_nmpc.runtime.signals import (EmergencyRequested, Terminated, landing_signals,
                                          polled_signals, stopping_signals)

ROOT = Path(__file__).resolve().parents[2]


def _arrive(sig: signal.Signals) -> None:
    """Send ``sig`` to this process and give its handler the bytecodes it needs to run."""
    os.kill(os.getpid(), sig)
    for _ in range(1000):
        pass


@pytest.mark.parametrize("sig, raised", [(signal.SIGINT, KeyboardInterrupt),
                                         (signal.SIGTERM, Terminated),
                                         (signal.SIGHUP, Terminated)])
def test_a_signal_waits_for_check_and_is_raised_by_the_handler_it_would_have_had(sig, raised):
    steps = []
    with stopping_signals():
        before = signal.getsignal(sig)
        with pytest.raises(raised) as caught:
            with polled_signals() as check:
                _arrive(sig)
                steps.append("the compiled call returned")
                check()
                steps.append("never")
        assert signal.getsignal(sig) is before
    assert steps == ["the compiled call returned"]
    if raised is Terminated:
        assert caught.value.signum == sig


def test_the_block_end_raises_what_check_was_not_asked_for():
    with stopping_signals():
        with pytest.raises(Terminated):
            with polled_signals():
                _arrive(signal.SIGTERM)
                finished = True
    assert finished


def test_the_emergency_signal_stays_an_emergency_in_a_flight():
    with landing_signals():
        with pytest.raises(EmergencyRequested):
            with polled_signals() as check:
                _arrive(signal.SIGUSR2)
                check()


def test_an_ignored_signal_stays_ignored_and_nothing_is_raised():
    previous = signal.signal(signal.SIGUSR1, signal.SIG_IGN)
    try:
        with polled_signals() as check:
            assert signal.getsignal(signal.SIGUSR1) is signal.SIG_IGN
            _arrive(signal.SIGUSR1)
            check()
        assert signal.getsignal(signal.SIGUSR1) is signal.SIG_IGN
    finally:
        signal.signal(signal.SIGUSR1, previous)


class _Rows:
    """The recorder interface run_lockstep writes to, kept in memory."""

    path = None

    def __init__(self) -> None:
        self.rows: list[dict] = []
        self.events: list[str] = []

    def write_row(self, row: dict) -> None:
        self.rows.append(row)

    def event(self, t_s: float, kind: str, **fields) -> None:
        self.events.append(kind)


@pytest.mark.parametrize("at_tick", [3, 40])
def test_a_lockstep_flight_ends_at_the_tick_the_signal_arrived_in(at_tick):
    cfg = load_config(ROOT / "configs" / "hover.yaml", ["duration_s=10"])
    rows = _Rows()
    returned = []

    def progress(fraction: float) -> None:  # called after each tick's row: inside the flight
        if len(rows.rows) == at_tick:
            _arrive(signal.SIGTERM)
            returned.append(at_tick)  # held back: nothing is raised inside the flight's calls

    with stopping_signals():
        with pytest.raises(Terminated) as caught:
            run_lockstep(cfg, recorder=rows, progress=progress)
    assert caught.value.signum == signal.SIGTERM
    assert returned == [at_tick]
    assert len(rows.rows) == at_tick  # not one tick flown after it
    assert "landed" not in rows.events
