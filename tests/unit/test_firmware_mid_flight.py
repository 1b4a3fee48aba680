"""The firmware's command state mid-flight with the compiled legs (sim/lockstep_legs.py:
CompiledLegs.command in the PCMD chain's place, CompiledLegs.run checking the firmware and
latching its com-watchdog bit while the arrays hold the plant's state): a read of any of it
gives what the Python path's firmware holds, a write is taken up — a stale sequence number,
the cap's flag, a hover dropped in, a timed-out silence — the same flight as the Python
path's, tick for tick (the pins of any later shortcut of the firmware's state)."""

import copy

import pytest

from tests.unit.test_held_state import CFG, _flying
from tests.unit.test_lockstep_legs import _snapshot

# what the tick's PCMD writes (DroneFirmware._accept, apply_command) and run() reads
COMMAND_STATE = ("pcmd", "_applied_pcmd", "applied", "alt_capped", "last_cmd_t", "last_seq",
                 "link_lost", "lost_com_hover", "comwdg_latched")
PERIOD = CFG.loop.period_s


def _ticks(drone, first: int, last: int, command=(0.1, -0.05, 0.1, 0.02)) -> None:
    t0 = drone.sensors.t_zero_s
    for k in range(first, last):
        drone.advance_to(t0 + k * PERIOD)
        drone.set_command(*command)


def _pair():
    """Two drones flown alike, the second with the compiled legs holding the plant's state
    and taking the PCMDs (asserted)."""
    python, compiled = _flying(False), _flying(True)
    for drone in (python, compiled):
        drone.start_experiment(drone.truth.t_s)
        _ticks(drone, 1, 6)
    legs = compiled.sensors._legs
    assert legs.takes_commands and legs.held() and legs.live_out is not None
    return python, compiled


def _same(python, compiled) -> None:
    assert _snapshot(python, python.truth.t_s) == _snapshot(compiled, compiled.truth.t_s)


def test_the_command_state_over_many_held_ticks():
    """Only the truth read between ticks (the plant's state never released): every
    attribute read at the end is the Python path's."""
    python, compiled = _pair()
    legs = compiled.sensors._legs
    held = []  # the compiled drone's, after every tick
    for drone in (python, compiled):
        for k in range(6, 60):
            drone.advance_to(drone.sensors.t_zero_s + k * PERIOD)
            drone.truth_cells()
            drone.set_command(0.05 * (k % 3 - 1), 0.02, 0.1 if k < 30 else -0.1, 0.0)
            if drone is compiled:
                held.append(legs.held())
    assert all(held) and len(held) == 54
    fw = compiled.sim.firmware
    for name in COMMAND_STATE:
        assert getattr(fw, name) == getattr(python.sim.firmware, name)
    assert fw._applied_pcmd is fw.pcmd
    _same(python, compiled)


@pytest.mark.parametrize("name", COMMAND_STATE)
def test_an_attribute_read_mid_flight_is_the_python_paths(name):
    python, compiled = _pair()
    assert getattr(compiled.sim.firmware, name) == getattr(python.sim.firmware, name)
    _ticks(python, 6, 12)
    _ticks(compiled, 6, 12)
    _same(python, compiled)


# writes without a read first, each changing what the firmware does next: a later PCMD
# refused as stale, the cap's flag (the Python path re-applies), the com-watchdog bit, a
# hover dropped in, a silence that has already timed the hover out, nothing applied
WRITES = {
    "last_seq": 10 ** 6,
    "alt_capped": True,
    "comwdg_latched": True,
    "pcmd": (0, 0.0, 0.0, 0.0, 0.0),
    "lost_com_hover": True,
    "last_cmd_t": 0.0,
    "applied": None,
}


@pytest.mark.parametrize("name", sorted(WRITES))
def test_an_attribute_written_mid_flight_is_taken_up(name):
    python, compiled = _pair()
    for drone in (python, compiled):
        setattr(drone.sim.firmware, name, WRITES[name])
        drone.advance_to(drone.sensors.t_zero_s + 6 * PERIOD)
        _ticks(drone, 7, 14, command=(-0.1, 0.05, 0.0, 0.01))
    _same(python, compiled)


def test_a_firmware_copied_mid_flight_has_its_command_state():
    python, compiled = _pair()
    clone = copy.copy(compiled.sim.firmware)
    for name in COMMAND_STATE:
        assert getattr(clone, name) == getattr(python.sim.firmware, name)


def test_a_ref_mid_flight_leaves_the_plants_state_held():
    """A REF (a landing holds one every tick) reads and writes the firmware's state alone:
    the plant's stays in the arrays, and the landing is the Python path's."""
    python, compiled = _pair()
    legs = compiled.sensors._legs
    for drone in (python, compiled):
        drone.land()
    assert legs.held()
    for drone in (python, compiled):
        for k in range(6, 10):
            drone.advance_to(drone.sensors.t_zero_s + k * PERIOD)
            drone.land()
    _same(python, compiled)


def test_a_silence_latches_the_com_watchdog_bit_as_the_python_path_does():
    """No PCMD for two ticks (beyond ``comwdg_s``, short of the hover's timeout): the runs
    latch the bit, and the read gives the Python path's."""
    python, compiled = _pair()
    fw = compiled.sim.firmware
    assert PERIOD > fw.comwdg_s and 2 * PERIOD < fw.hover_after_s
    for drone in (python, compiled):
        for k in (6, 7):
            drone.advance_to(drone.sensors.t_zero_s + k * PERIOD)
            drone.truth_cells()
    assert compiled.sensors._legs.held()  # the compiled runs' latch, not the Python legs'
    assert fw.comwdg_latched and python.sim.firmware.comwdg_latched
    _same(python, compiled)
