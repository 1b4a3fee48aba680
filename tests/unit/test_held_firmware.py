"""The firmware's command state held by the compiled legs between runs (sim/lockstep_legs.py,
sim/held_state.py): while the tick's PCMD leaves it nominal, CompiledLegs.command and run
keep it in one tuple, out of the firmware's ``__dict__``; a read of any of it gives back
what the Python path's firmware holds, a write while held is kept and taken up — the same
flight as the Python path's, tick for tick."""

import copy

import pytest

from ardrone_nmpc.sim.drone_firmware import DroneFirmware
from ardrone_nmpc.sim.lockstep_legs import CompiledLegs
from tests.unit.test_held_state import CFG, _flying
from tests.unit.test_lockstep_legs import _snapshot

FW_HELD = ("pcmd", "_applied_pcmd", "applied", "alt_capped", "last_cmd_t", "last_seq",
           "link_lost", "lost_com_hover", "comwdg_latched")
PERIOD = CFG.loop.period_s


def _ticks(drone, first: int, last: int, command=(0.1, -0.05, 0.1, 0.02)) -> None:
    t0 = drone.sensors.t_zero_s
    for k in range(first, last):
        drone.advance_to(t0 + k * PERIOD)
        drone.set_command(*command)


def _pair():
    """Two drones flown alike, the second with the compiled legs holding the firmware's
    command state (asserted)."""
    python, compiled = _flying(False), _flying(True)
    for drone in (python, compiled):
        drone.start_experiment(drone.truth.t_s)
        _ticks(drone, 1, 6)
    legs, fw = compiled.sensors._legs, compiled.sim.firmware
    assert legs.fw_held is not None and fw._held_by is legs._fw_holder
    assert not set(FW_HELD) & set(vars(fw))
    return python, compiled


def test_the_command_state_stays_held_over_many_ticks():
    """Only the truth read between ticks: the state is never released, yet every attribute
    read at the end is the Python path's (and reading one gives them all back)."""
    python, compiled = _pair()
    legs, fw = compiled.sensors._legs, compiled.sim.firmware
    held = []  # the compiled drone's, after every tick
    for drone in (python, compiled):
        for k in range(6, 60):
            drone.advance_to(drone.sensors.t_zero_s + k * PERIOD)
            drone.truth_cells()
            drone.set_command(0.05 * (k % 3 - 1), 0.02, 0.1 if k < 30 else -0.1, 0.0)
            if drone is compiled:
                held.append(legs.held() and fw.__dict__.get("_held_by") is legs._fw_holder)
    assert all(held) and len(held) == 54
    assert fw.last_seq == python.sim.firmware.last_seq  # a read: all back
    assert legs.fw_held is None and set(FW_HELD) <= set(vars(fw)) and fw._held_by is None
    assert fw._applied_pcmd is fw.pcmd
    assert _snapshot(python, python.truth.t_s) == _snapshot(compiled, compiled.truth.t_s)


@pytest.mark.parametrize("name", FW_HELD)
def test_a_held_attribute_read_mid_flight_is_the_python_paths(name):
    python, compiled = _pair()
    assert getattr(compiled.sim.firmware, name) == getattr(python.sim.firmware, name)
    _ticks(python, 6, 12)
    _ticks(compiled, 6, 12)
    assert _snapshot(python, python.truth.t_s) == _snapshot(compiled, compiled.truth.t_s)


# writes without a read first, each changing what the firmware does next: a later PCMD
# refused as stale, the cap's flag (the Python path re-applies), the com-watchdog bit, a
# hover dropped in, a silence that has already timed the hover out
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
def test_a_held_attribute_written_mid_flight_is_taken_up(name):
    python, compiled = _pair()
    for drone in (python, compiled):
        setattr(drone.sim.firmware, name, WRITES[name])
        drone.advance_to(drone.sensors.t_zero_s + 6 * PERIOD)
        _ticks(drone, 7, 14, command=(-0.1, 0.05, 0.0, 0.01))
    assert _snapshot(python, python.truth.t_s) == _snapshot(compiled, compiled.truth.t_s)


def test_a_held_firmware_copies_with_its_command_state():
    python, compiled = _pair()
    clone = copy.copy(compiled.sim.firmware)
    for name in FW_HELD:
        assert getattr(clone, name) == getattr(python.sim.firmware, name)
    assert clone._held_by is None


def test_a_firmware_class_shadowing_a_held_attribute_keeps_the_pcmd_chain():
    """A class default of a held name would stand in for the held state's descriptor."""
    drone = _flying(True)
    assert CompiledLegs.commands_eligible(drone.sim)
    drone.sim.firmware.__class__ = type("Shadowing", (DroneFirmware,), {"alt_capped": False})
    assert not CompiledLegs.commands_eligible(drone.sim)


def test_a_ref_reads_the_firmwares_state_alone():
    """A REF (a landing holds one every tick) reads the sequence number: the firmware's state
    comes back, the plant's stays in the arrays."""
    python, compiled = _pair()
    legs = compiled.sensors._legs
    for drone in (python, compiled):
        drone.land()
    assert legs.fw_held is None and legs.held()
    for drone in (python, compiled):
        for k in range(6, 10):
            drone.advance_to(drone.sensors.t_zero_s + k * PERIOD)
            drone.land()
    assert _snapshot(python, python.truth.t_s) == _snapshot(compiled, compiled.truth.t_s)


def test_a_silence_latches_the_com_watchdog_bit_in_the_held_state():
    """No PCMD for two ticks (beyond ``comwdg_s``, short of the hover's timeout): the runs
    latch the bit in the held state, and the read gives the Python path's."""
    python, compiled = _pair()
    fw = compiled.sim.firmware
    assert PERIOD > fw.comwdg_s and 2 * PERIOD < fw.hover_after_s
    for drone in (python, compiled):
        for k in (6, 7):
            drone.advance_to(drone.sensors.t_zero_s + k * PERIOD)
            drone.truth_cells()
    assert compiled.sensors._legs.fw_held is not None  # held through the silence
    assert fw.comwdg_latched and python.sim.firmware.comwdg_latched
    assert _snapshot(python, python.truth.t_s) == _snapshot(compiled, compiled.truth.t_s)
