"""The simulated drone's usual tick as numbers (sim/drone_block.py) leaves the drone the
per-tick path leaves: two lockstep drones of one seed — one flown tick by tick through
``advance_to`` and ``set_command`` (``CompiledLegs.run`` and ``.command``), the other
through ``drone_legs`` and ``drone_command`` with its state taken by ``block_entry`` and
written back by ``after_block`` — hold the same samples, truth, plant, firmware state and
counters; a landing waited out by ``LockstepDrone.descend`` leaves what ``advance_to`` and
``land`` tick by tick leave; and a command the firmware caps or the plant clips is refused
with nothing changed (the Python path's)."""

import math

import numpy as np
import pytest

from ardrone_nmpc.config.schema import config_from_dict
from ardrone_nmpc.core.numerics import callable_from_python
from ardrone_nmpc.core.types import FlightMode
from ardrone_nmpc.sim import drone_block as db
from ardrone_nmpc.sim import lockstep_drone
from ardrone_nmpc.sim import sensor_step as ks
from ardrone_nmpc.sim.drone_firmware import _HOVER_CMD
from ardrone_nmpc.sim.lockstep_drone import LockstepDrone
from tests.unit.test_lockstep_legs import _light, _snapshot

PERIOD_S = 0.065
# the drone's tick as numbers, callable from Python (kernels only kernels call, else)
drone_legs = callable_from_python(db.drone_legs)
drone_command = callable_from_python(db.drone_command)
# a zig-zag of commands: climbs and descents, a repeated command (the firmware's applied
# one kept), a negative zero (equal to zero: not a new command)
COMMANDS = [(0.1, -0.05, 0.2, 0.0), (0.1, -0.05, 0.2, 0.0), (-0.2, 0.1, -0.1, 0.05),
            (0.0, 0.0, 0.0, 0.0), (-0.0, 0.0, 0.0, -0.0), (0.3, 0.2, 0.1, -0.1),
            (-0.3, -0.2, -0.3, 0.1)] * 3


def _flying(seed: int = 3, faults: dict | None = None, **sim) -> tuple[LockstepDrone, float]:
    """A lockstep drone taken off and flown a few ticks (the compiled legs hold its state),
    with injected ``faults`` (a config section) if given."""
    cfg = config_from_dict({"name": "t", "duration_s": 5.0, "sim": {"seed": seed, **sim},
                            "faults": faults or {}})
    drone = LockstepDrone(cfg, seed=seed)
    drone.connect()
    drone.takeoff()
    mode, t = drone.mode_and_t()
    while mode is not FlightMode.FLYING:
        drone.advance_to(t + PERIOD_S)
        mode, t = drone.mode_and_t()
    drone.start_experiment(t)
    for k in range(1, 6):
        drone.advance_to(t + k * PERIOD_S, k * PERIOD_S)
        drone.set_command(0.05, 0.0, 0.1, 0.0)
    return drone, t + 5 * PERIOD_S  # (its plant time now)


@pytest.mark.parametrize("sim", [{}, {"plant": {"turbulence_std_mps": 0.3}},
                                 {"navdata_rate_hz": 200.0}, {"mocap_rate_hz": 10.0}])
def test_ticks_as_numbers_leave_the_drone_the_per_tick_path_leaves(sim):
    a, t0 = _flying(**sim)
    b, _ = _flying(**sim)
    assert _snapshot(a, t0) == _snapshot(b, t0)  # (the same start)
    t0 += PERIOD_S  # a tick of each, the arrays holding the state again (a snapshot reads
    for drone in (a, b):  # the plant's attributes: they are given back)
        drone.advance_to(t0, t0)
        drone.set_command(0.05, 0.0, 0.1, 0.0)
    legs, d = b.sensors._legs, np.zeros(db.D_SIZE)
    assert db.block_entry(legs, d, b._seq + 1)
    out = legs.buf[ks.B_OUT:ks.B_IV]
    for k, cmd in enumerate(COMMANDS, start=1):
        t = t0 + k * PERIOD_S
        a.advance_to(t, t - t0)
        a.set_command(*cmd)
        assert drone_legs(d, *legs._args, t, ks.MODE_FLYING, 0.0) == db.LEGS_DONE
        assert drone_command(d, out, *cmd)
    n = len(COMMANDS)
    b._seq += n
    b.t_exp_s = t - t0
    db.after_block(legs, d, b._seq, True)
    assert d[db.D_COMMANDS] == n
    assert _snapshot(a, t) == _snapshot(b, t)


def test_a_capped_climb_or_a_clipped_fraction_is_refused_with_nothing_changed():
    drone, _ = _flying()
    legs, d = drone.sensors._legs, np.zeros(db.D_SIZE)
    assert db.block_entry(legs, d, drone._seq + 1)
    out = legs.buf[ks.B_OUT:ks.B_IV]
    before = d.tobytes()
    for cmd in [(1.5, 0.0, 0.0, 0.0), (0.0, -1.01, 0.0, 0.0), (0.0, 0.0, 0.0, math.nan),
                (0.0, 0.0, math.inf, 0.0)]:
        assert not drone_command(d, out, *cmd)
        assert d.tobytes() == before
    d[db.D_ALT_MAX] = out[ks.O_STATE + 2]  # the cap where the drone is: any climb reaches it
    before = d.tobytes()
    assert not drone_command(d, out, 0.0, 0.0, 0.1, 0.0)
    assert d.tobytes() == before
    assert drone_command(d, out, 0.0, 0.0, -0.1, 0.0)  # a descent is not capped


def test_block_entry_refuses_a_firmware_that_is_not_quiet():
    drone, _ = _flying()
    legs, d, fw = drone.sensors._legs, np.zeros(db.D_SIZE), drone.sim.firmware
    assert db.block_entry(legs, d, drone._seq + 1)
    assert not db.block_entry(legs, d, fw.last_seq)  # a stale number
    for name, value in (("alt_capped", True), ("link_lost", True), ("lost_com_hover", True)):
        setattr(fw, name, value)
        assert not db.block_entry(legs, d, drone._seq + 1), name
        setattr(fw, name, False)
    assert db.block_entry(legs, d, drone._seq + 1)


def _landing(drone: LockstepDrone, t0: float) -> tuple[float, int]:
    """The REF land, then the ticks up to the first the navdata shows LANDING."""
    drone.land()
    k = 0
    while drone.navdata.mode is not FlightMode.LANDING:
        k += 1
        t = t0 + k * PERIOD_S
        drone.advance_to(t, t - t0)
        drone.land()
    return t0, k


# faults in the landing (its experiment time from 0 again, _landing's): an AT-loss window
# and a gust, the descent's calls between them (the ticks at which one may act: the caller's)
LANDING_FAULTS = {"at_loss": {"start_s": 0.8, "duration_s": 0.4, "probability": 0.5},
                  "wind_gust": {"start_s": 1.5, "duration_s": 0.2}}


@pytest.mark.parametrize("chunk, faults", [(1, None), (7, None), (64, None),
                                           (7, LANDING_FAULTS), (64, LANDING_FAULTS)])
def test_a_landing_waited_out_in_one_call_leaves_what_the_ticks_leave(chunk, faults,
                                                                     monkeypatch):
    monkeypatch.setattr(lockstep_drone, "_DESCENT_TICKS", chunk)
    a, t0 = _flying(faults=faults)
    b, _ = _flying(faults=faults)
    _, k = _landing(a, t0)
    assert _landing(b, t0)[1] == k
    deadline = t0 + 30.0
    compiled = 0
    while b.mode_and_t()[0] is FlightMode.LANDING:
        n, legs_ran = b.descend(t0, k + 1, PERIOD_S, deadline, t0)
        compiled += n
        if n == 0 and not legs_ran:  # not one it flies: the caller's tick
            t = t0 + (k + 1) * PERIOD_S
            b.advance_to(t, t - t0)
            b.land()
            n = 1
        elif legs_ran:  # the tick whose legs it ran: its REF land is the caller's
            b.land()
            n += 1
        for j in range(k + 1, k + 1 + n):
            t = t0 + j * PERIOD_S
            a.advance_to(t, t - t0)
            a.land()
        k += n
        t = t0 + k * PERIOD_S  # (what a tick reads, the firmware's, the counters: the
        assert _held(a, t) == _held(b, t), k  # arrays keep holding the plant's state)
    assert a.mode_and_t()[0] is b.mode_and_t()[0] is FlightMode.LANDED
    assert _snapshot(a, t) == _snapshot(b, t)
    assert compiled > 10  # (the descent flown in the calls, not tick by tick)
    if faults is not None:  # the same draws, counters and events; the window's ticks not
        fa, fb = a.sim.faults, b.sim.faults  # flown in a call
        assert fa.counters == fb.counters and fa.counters.at_lost > 0
        assert fa.schedule.rng.bit_generator.state == fb.schedule.rng.bit_generator.state
        assert fa.events == fb.events and len(fa.events) == 2
        assert compiled < k - 6


def _held(drone: LockstepDrone, t_s: float) -> tuple:
    """``_light`` and the firmware's and counters' state, read without the plant's
    attributes."""
    fw = drone.sim.firmware
    return (_light(drone, t_s), fw.pcmd, fw._applied_pcmd, fw.applied, fw.last_seq,
            fw.last_cmd_t, fw.link_lost, fw.lost_com_hover, fw.alt_capped, fw.ref_start,
            fw.ref_emergency, tuple(vars(drone.sim.counters).items()), drone._seq,
            drone.mode_and_t())


def test_a_watchdog_due_is_left_to_the_per_tick_path_with_nothing_run():
    """A tick by whose time the hover watchdog or the link loss would act (no command for
    ``hover_after_s``, ``link_loss_s``) is not the kernel's: ``LEGS_NOT_QUIET``, and neither
    ``d`` nor the legs' arrays changed (the Python path's ``CompiledLegs.run`` flies it)."""
    drone, _ = _flying()
    legs, d, fw = drone.sensors._legs, np.zeros(db.D_SIZE), drone.sim.firmware
    assert db.block_entry(legs, d, drone._seq + 1)
    arrays = [a.tobytes() for a in legs._args]
    before = d.tobytes()
    late_s = d[db.D_LAST_CMD_T] + fw.hover_after_s + PERIOD_S
    assert drone_legs(d, *legs._args, late_s, ks.MODE_FLYING, 0.0) == db.LEGS_NOT_QUIET
    d[db.D_HOVER_AFTER_S] = math.inf  # (the link loss alone)
    lost_s = d[db.D_LAST_CMD_T] + fw.link_loss_s + PERIOD_S
    assert drone_legs(d, *legs._args, lost_s, ks.MODE_FLYING, 0.0) == db.LEGS_NOT_QUIET
    d[db.D_HOVER_AFTER_S] = fw.hover_after_s
    assert d.tobytes() == before
    assert [a.tobytes() for a in legs._args] == arrays
    # the next tick on time is the kernel's
    assert drone_legs(d, *legs._args, d[db.D_LAST_CMD_T] + PERIOD_S,
                      ks.MODE_FLYING, 0.0) == db.LEGS_DONE


@pytest.mark.parametrize("chunk", [1, 5, 64])
def test_a_take_off_waited_out_in_one_call_leaves_what_the_ticks_leave(chunk, monkeypatch):
    """``LockstepDrone.ascend`` (``drone_ascent``: the hover watchdog due on the way, the
    climb's end) against ``advance_to`` tick by tick, as the runner waits a take-off out."""
    monkeypatch.setattr(lockstep_drone, "_DESCENT_TICKS", chunk)
    cfg = config_from_dict({"name": "t", "duration_s": 5.0, "sim": {"seed": 3}})
    a, b = LockstepDrone(cfg, seed=3), LockstepDrone(cfg, seed=3)
    for drone in (a, b):
        drone.connect()
        drone.takeoff()
    compiled = 0
    while b.mode_and_t()[0] is not FlightMode.FLYING:
        n = b.ascend(PERIOD_S, 30.0)
        compiled += n
        if n == 0:
            b.advance_to(b.mode_and_t()[1] + PERIOD_S)
            n = 1
        for _ in range(n):
            a.advance_to(a.mode_and_t()[1] + PERIOD_S)
        t = a.mode_and_t()[1]
        assert _held(a, t) == _held(b, t)
    assert a.mode_and_t()[0] is FlightMode.FLYING
    assert _snapshot(a, t) == _snapshot(b, t)
    assert a.sim.firmware.lost_com_hover  # (the hover watchdog came due on the way: it holds
    assert b.sim.firmware.pcmd is a.sim.firmware.pcmd is _HOVER_CMD  # the firmware's hover)
    assert compiled > 10
