"""FlightSession landing paths with a fake drone: landing survives interrupts and failing logs."""

import pytest

from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.runtime.session import FlightSession
from ardrone_nmpc.core.types import FlightMode


class FakeNav:
    def __init__(self, mode):
        self.mode = mode
        self.battery_pct = 90.0


class FakeDrone:
    """Lands one poll after land(); raises the scripted interrupt on the first land()."""

    def __init__(self, interrupt_on_land=None, never_lands=False):
        self.calls = []
        self.navdata = FakeNav(FlightMode.FLYING)
        self._interrupt = interrupt_on_land
        self._never_lands = never_lands

    def land(self):
        self.calls.append("land")
        if self._interrupt is not None:
            err, self._interrupt = self._interrupt, None
            raise err
        if not self._never_lands:
            self.navdata = FakeNav(FlightMode.LANDED)

    def hover(self):
        self.calls.append("hover")


def _session(drone, events, clock=None):
    kwargs = {} if clock is None else {"clock": clock}
    return FlightSession(load_config(None), drone, mocap=None,
                         event=lambda kind, **f: events.append(kind), **kwargs)


def test_an_interrupt_during_landing_does_not_stop_it():
    drone, events = FakeDrone(interrupt_on_land=KeyboardInterrupt()), []
    session = _session(drone, events)
    with pytest.raises(KeyboardInterrupt):
        session.land()
    assert drone.calls.count("land") >= 2  # it tried again after the interrupt
    assert session.landed_cleanly is True and "landed" in events


def test_leaving_the_block_lands_even_when_logging_fails():
    drone = FakeDrone()

    def broken_event(kind, **fields):
        raise OSError("disk full")

    session = FlightSession(load_config(None), drone, mocap=None, event=broken_event)
    with pytest.raises(OSError):
        session.__exit__(None, None, None)
    assert "land" in drone.calls


def test_an_unconfirmed_landing_is_reported_not_hidden():
    t = [0.0]

    def clock():
        t[0] += 0.5  # time runs on: the landing wait times out quickly
        return t[0]

    drone, events = FakeDrone(never_lands=True), []
    session = _session(drone, events, clock=clock)
    assert session.land() is False
    assert session.landed_cleanly is False and "landing_failed" in events
