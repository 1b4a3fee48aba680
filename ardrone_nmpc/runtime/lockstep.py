"""Lockstep simulation: the real tick against the simulated AR.Drone on a manual clock.

No sockets and no sleeping: the runner drives the simulated drone through the interface of
the drone's link (:class:`~ardrone_nmpc.sim.lockstep_drone.LockstepDrone`: REF and PCMD to its
firmware, its navdata and mocap samples, its configuration port), advancing it to each tick,
and hands the tick exactly what the links would hold — the newest mocap pose (sampled at
``sim.mocap_rate_hz``, delivered ``noise.mocap_latency_ms`` later) and the newest navdata
(``sim.navdata_rate_hz``, body-frame velocities). The drone is the one ``fly --sim`` serves
over UDP, firmware (altitude cap, watchdogs, REF semantics) and injected faults included: this
runner knows of no fault. Sequence: take off (REF), hold the reference's start for
``sim.settle_s`` (rows with t_s < 0), fly the experiment for ``duration_s``, land (REF).
Deterministic for a seed.

Before take-off the limits are written to the simulated drone's configuration and read back,
and the session's own check refuses (:class:`TakeoffRefused`, a ``takeoff_refused`` event) a
drone that holds other values or whose control port does not answer — the
``FlightSession.configure`` of ``fly``, not a second copy. A drone that lands by itself
during the flight ends the run (``land-drone-landed-itself``): the link's take-off guard
drops the take-off bit, so nothing takes it off again.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from ardrone_nmpc.control.diverging import diverging_wrapper
from ardrone_nmpc.control.ocp import SolverStatus
from ardrone_nmpc.core import monotonic
from ardrone_nmpc.core.kernel_cache import load_cached
from ardrone_nmpc.core.types import FlightMode
from ardrone_nmpc.errors import UserError
from ardrone_nmpc.links.drone_config import LinkError
from ardrone_nmpc.reference.experiment import experiment_trajectory
from ardrone_nmpc.runs.block_rows import BlockRows
from ardrone_nmpc.runs.log_columns import (MODE_CELL, TRUTH_CELLS, p_cells_row, put_truth,
                                           put_truth_cells, target_cells_row)
from ardrone_nmpc.runs.verdict import VerdictTally
from ardrone_nmpc.runtime.after_solve import SATURATED_TEXT
from ardrone_nmpc.runtime.lockstep_block import (EXIT_AFTER_CONTROL, EXIT_AFTER_LEGS, EXIT_FIT,
                                                 EXIT_NONE, EXIT_SHORT, TickBlocks,
                                                 tick_block, tick_block_newton,
                                                 tick_block_newton_obstacles,
                                                 tick_block_obstacles, tick_block_p,
                                                 tick_block_wire)
from ardrone_nmpc.runtime.precompile import (background_compiles, join_child,
                                             release_block_lock, start_if_cold,
                                             take_block_lock)
from ardrone_nmpc.runtime.schedule import (LANDING_TIMEOUT_S, TAKEOFF_TIMEOUT_S, Schedule,
                                           phase, write_events)
from ardrone_nmpc.runtime.session import FlightSession, PreflightError
from ardrone_nmpc.runtime.signals import polled_signals
from ardrone_nmpc.runtime.tick import Tick
from ardrone_nmpc.safety import Action, takeoff_refusal
from ardrone_nmpc.sim.lockstep_drone import LockstepDrone


@dataclass
class SimResult:
    """What a lockstep run produced (the rows are also in the recorder, if one was given).

    ``ending`` says how the flight ended: ``"completed"`` (the experiment ran to its end and
    did its job), a failed verdict of :mod:`ardrone_nmpc.runs.verdict` (it ran to its end
    without tracking, or never saw the object it follows), ``"land-<reason>"`` (the
    supervisor landed it), ``"stop-<reason>"`` (the drone cut its motors, or reported a motor
    fault and was cut); ``final_mode`` is the drone's mode after the run.
    """

    ticks: int
    final_mode: FlightMode
    run_dir: Path | None
    loop_wall_s: float = math.nan  # wall time of the flight itself (JIT warm-up excluded)
    ending: str = "completed"
    end_t_s: float = math.nan  # experiment time when it ended: touch-down, or rest after a stop


class TakeoffRefused(UserError, RuntimeError):
    """The pre-flight check failed (battery at or below the floor, a fault bit, limits the
    drone does not hold or did not acknowledge, no configuration read back): nothing took
    off."""


#: The event of a refused take-off (``reason``: the one-line refusal); no flight follows.
REFUSED_EVENT = "takeoff_refused"
#: The ending of a run whose drone landed by itself (the supervisor's ``land-<reason>`` form).
SELF_LANDED = "land-drone-landed-itself"
_ENDS = (Action.LAND, Action.STOP)  # the verdicts that end the experiment's ticks
_CONTROL = Action.CONTROL  # bound once (the usual verdict: tested first, by identity)
#: The most ticks a block flies in one compiled call (``runtime/lockstep_block``; 0: none,
#: every tick its own calls): the rows are written, the progress told and a signal seen
#: after each block
BLOCK_TICKS = 32
_OK_TEXT = SolverStatus.OK._value_  # a block's rows' solver_status
_warming_up = False  # warm_up_blocks' flight: its blocks compile their kernel
_BLOCK_GOES_ON = (EXIT_NONE, EXIT_FIT, EXIT_SHORT)  # a block's ends before no Python tick
_FLYING_TEXT = FlightMode.FLYING._value_  # … and nav_mode


def _configure(cfg, drone: LockstepDrone, events: list) -> None:
    """Write the limits, read them back and refuse as ``fly`` does (TakeoffRefused)."""
    session = FlightSession(cfg, drone, None, event=lambda kind, **f: events.append((kind, f)),
                            warn=lambda message: None)  # the warning is in the events
    try:
        session.configure()
    except (PreflightError, LinkError) as err:
        raise TakeoffRefused(str(err)) from None


def run_lockstep(cfg, *, recorder=None, seed: int | None = None,
                 progress: Callable[[float], None] | None = None, plant=None,
                 trajectory=None) -> SimResult:
    """Fly ``cfg`` against the simulated drone; rows go to ``recorder.write_row``.

    ``trajectory``: ``experiment_trajectory(cfg)`` made already (a caller that checked the
    reference against the geofence: one made per flight, not two), default made here.

    ``plant`` flies another airframe than the one ``sim.plant`` configures (an object with
    :class:`~ardrone_nmpc.sim.plant.AirframePlant`'s interface, landed at time 0: the tests'
    emulators) inside the same simulated drone (firmware, sensors, faults); ``sim.plant`` is
    then unused.

    ``progress(fraction)`` is called every tick with the fraction of the run done. The
    supervisor's verdicts are obeyed as on the real drone: ``land`` lands (rows go on until
    touch-down), ``stop`` (emergency) ends the run. Events are stamped with experiment time.
    Raises :class:`TakeoffRefused` (after a :data:`REFUSED_EVENT`) when the battery is at or
    below ``safety.battery_floor_pct``, the drone reports a fault bit, or the configuration
    (written, acknowledged, read back) refuses (module doc),
    :class:`~ardrone_nmpc.runtime.schedule.ScheduleError` for times that give no tick count.
    A drone that lands by itself ends the run with :data:`SELF_LANDED`. A Ctrl-C or
    terminating signal ends it at the next tick (:func:`~ardrone_nmpc.runtime.signals.
    polled_signals`: raised from its handler, it could land inside a compiled call and be lost).
    """
    start_if_cold()  # the drone's kernels compiled by a child while this compiles the solver
    with polled_signals() as check_signals:
        return _fly(cfg, recorder, seed, progress, plant, check_signals, trajectory)


def _fly(cfg, recorder, seed: int | None, progress, plant, check_signals,
         trajectory=None) -> SimResult:
    """:func:`run_lockstep`'s flight; ``check_signals()`` raises a signal that arrived."""
    schedule = Schedule.from_config(cfg)
    seed = cfg.sim.seed if seed is None else seed
    drone = LockstepDrone(cfg, seed=seed, plant=plant)
    # (blocks compile their kernel themselves in a warm-up's flight, or with no background
    # compile to wait for: runtime/precompile; so does the P controller's compiled tick)
    compile_now = _warming_up or not background_compiles()
    tick = Tick(cfg, trajectory if trajectory is not None else experiment_trajectory(cfg),
                wrap_solver=diverging_wrapper(drone.sim.solver_divergence),
                compile_now=compile_now)
    join_child()  # the drone's kernels, compiled meanwhile, are cached before it takes off
    period = schedule.period_s
    write_event = recorder.event if recorder is not None else (lambda *a, **k: None)

    preflight_events: list[tuple[str, dict]] = []  # stamped once experiment time exists
    try:
        battery_pct = drone.truth.battery_pct
        if not battery_pct > cfg.safety.battery_floor_pct:  # NaN is no charge either
            raise TakeoffRefused(f"battery {battery_pct:.0f} % is at or below the floor "
                                 f"safety.battery_floor_pct = "
                                 f"{cfg.safety.battery_floor_pct:.0f} %: take-off refused")
        refusal = takeoff_refusal(drone.state_word)  # as fly's preflight
        if refusal is not None:
            raise TakeoffRefused(refusal)
        try:
            drone.connect()
        except LinkError as err:  # a session that ignores plain CONFIG
            raise TakeoffRefused(str(err)) from None
        _configure(cfg, drone, preflight_events)
    except TakeoffRefused as err:  # no experiment time: nothing took off
        for kind, fields in preflight_events:
            write_event(math.nan, kind, **fields)
        write_event(math.nan, REFUSED_EVENT, reason=str(err))
        raise
    t_takeoff = drone.truth.t_s
    drone.takeoff()
    mode, t_now_s = drone.climb_out(period, TAKEOFF_TIMEOUT_S, check_signals)
    if mode is not FlightMode.FLYING:
        raise RuntimeError(f"simulated take-off did not complete "
                           f"(mode {mode.value})")
    # The settle phase starts now, on whole ticks: experiment time 0 is n_settle ticks later.
    t_first = t_now_s
    t_start = t_first + schedule.settle_span_s  # experiment time 0 on the plant clock
    announced = drone.start_experiment(t_start)
    for kind, fields in preflight_events:
        write_event(t_takeoff - t_start, kind, **fields)
    write_event(t_takeoff - t_start, "takeoff")
    write_events(write_event, schedule.t_exp_s(0), announced)
    wall0 = time.perf_counter()
    ending, k, flown = "completed", 0, 0
    tally = VerdictTally(follow=tick.follow is not None)
    # the loop's own calls bound once (~1000 ticks a minute of flight): what each does is
    # what its name says, in this order, every tick
    # (the drone's take_events and inputs are its simulator's and its sensors': theirs bound)
    advance_to, take_events = drone.advance_to, drone.sim.take_events
    faulty = drone.sim.faults is not None  # (set when the drone is made, never after)
    inputs, step, set_command = drone.sensors.inputs, tick.step, drone.set_command
    truth_cells, tally_add, tally_tick = drone.truth_cells, tally.add, tally.add_tick
    write_cells = _sink(recorder, "write_cells")
    write_block = _block_sink(recorder) if write_cells is not None else None
    tick.cell_rows = recorder is None or write_cells is not None
    blocks = (TickBlocks(tick, drone, n_max=BLOCK_TICKS, n_settle=schedule.n_settle,
                         period_s=period, t_first_s=t_first, compile_now=compile_now)
              if BLOCK_TICKS > 0 and TickBlocks.takes(tick, drone, compile_now) else None)
    # a flight with a second object, or the P controller's: its blocks' rows are the
    # per-tick path's dicts
    write_dict_row = (recorder.write_row if blocks is not None
                      and (blocks.target or blocks.p) and recorder is not None else None)
    n_ticks, n_settle = schedule.n_ticks, schedule.n_settle
    k = 0
    t_exp_s = schedule.t_exp_s  # (k by k, or jumps of a block's ticks)
    while k < n_ticks:
        check_signals()
        t_exp = t_exp_s(k)
        mode = phase(t_exp)
        answer, spent_ns, legs_ran = None, 0, False
        if blocks is not None:  # the usual ticks, a block of them in one compiled call
            n, exit_, answer, spent_ns = blocks.fly(
                k, mode, min(BLOCK_TICKS, (n_settle if t_exp < 0 else n_ticks) - k))
            if n:
                _block_rows(blocks.table, n, mode, write_cells, write_block, tally,
                            write_dict_row, blocks.target, blocks.p, blocks.wire)
                if progress is not None:
                    for j in range(k, k + n):
                        progress(schedule.fraction_done(j))
                k = flown = k + n
            if exit_ in _BLOCK_GOES_ON:  # (the next tick is a block's again)
                if exit_ == EXIT_FIT and answer:  # the fit's events, at its tick (k − 1)
                    write_events(write_event, t_exp_s(k - 1), answer)
                continue
            if n:  # the tick it ended at (before the phase ends: its mode)
                t_exp = t_exp_s(k)
            legs_ran = exit_ == EXIT_AFTER_LEGS or exit_ == EXIT_AFTER_CONTROL
        t_plant = t_first + k * period
        if not legs_ran:
            if blocks is not None:  # (what an open chain of blocks left, written back)
                blocks.close()
            advance_to(t_plant, t_exp)
        if faulty:  # (a drone without injected faults has no events to take, ever)
            drone_events = take_events()
            if drone_events:
                _write_events_at(write_event, drone_events)
        if drone.self_landing and drone.navdata.mode is not FlightMode.EMERGENCY:
            # the drone's word: no command, no take-off again (an emergency is the
            # supervisor's to report, as in fly, where the tick sees it first)
            write_event(t_exp, "drone_landed_itself", drone_mode=drone.navdata.mode.value)
            ending = SELF_LANDED
            break
        flown = k + 1
        out = step(inputs(t_plant), t_exp_s=t_exp, mode=mode, answer=answer,
                   spent_ns=spent_ns)
        if out.events:
            write_events(write_event, t_exp, out.events)
        pcmd = out.pcmd
        set_command(pcmd.roll_frac, pcmd.pitch_frac, pcmd.gaz_frac, pcmd.yaw_frac,
                    progressive=out.progressive)
        cells = out.cells
        if cells is not None:  # the usual NMPC tick: its cells in column order, no dict
            if write_cells is not None:
                cells[TRUTH_CELLS] = truth_cells()  # put_truth_cells without its call
                write_cells(cells)
            label = cells[MODE_CELL]
            tally_tick(t_exp, label)  # (t_exp: the row's t_s) no target: no target_age_ms
        else:
            row = out.row
            _record(recorder, row, drone)
            tally_add(row)
            label = row["mode"]
        if progress is not None:
            progress(schedule.fraction_done(k))
        action = out.action
        if action is not _CONTROL and action in _ENDS:
            ending = label
            break
        k += 1
    if blocks is not None:
        blocks.close()
    ending = tally.verdict(ending)
    loop_wall_s = time.perf_counter() - wall0
    t_end = t_first + flown * period - t_start
    if ending.startswith("stop"):
        if drone.truth.mode is not FlightMode.EMERGENCY:  # a motor fault bit: the tool cuts
            drone.emergency()                             # (as the session does)
            write_event(t_end, "emergency", reason=ending)
        write_event(t_end, "stopped", reason=ending, drone_mode=drone.truth.mode.value)
        drone.advance_to(drone.truth.t_s + 3.0)  # let it come to rest: the truth shows the fall
    else:
        _land(cfg, tick, drone, recorder, write_event, t_first, t_start, flown,
              logged=ending.startswith("land"))
    final_mode, t_final_s = drone.mode_and_t()
    return SimResult(flown, final_mode, recorder.path if recorder is not None else None,
                     loop_wall_s, ending, t_final_s - t_start)


def _block_rows(table, n: int, mode: str, write_cells, write_block,
                tally: VerdictTally, write_dict_row=None, target: bool = False,
                p: bool = False, wire: bool = False) -> None:
    """The rows of a block's ``n`` ticks (``table``'s numbers, ``runtime/lockstep_block``)
    as the per-tick path writes and counts them (their mode: the phase's, the supervisor's
    nominal label): the block itself to a recorder that takes blocks (``write_block``), the
    rows' cells to one that takes cells; none to write without a recorder. A flight with a
    second object (``target``) logs it in each row: the per-tick path's rows are then dicts
    (``tick_row``'s), so are these (``log_columns.target_cells_row``); so are the P
    controller's (``p``: ``p_cells_row``, its rows without the solver's cells) — each given
    to ``write_dict_row`` (the recorder's ``write_row``); ``wire``: a flight's whose samples
    come through the wire (``BlockRows.wire``)."""
    # (a block kept by its recorder owns its numbers: the table is the next block's)
    dicts = target or p
    copy = write_block is not None and not dicts
    rows = BlockRows(table[:n].copy() if copy else table[:n], mode,
                     SATURATED_TEXT, _OK_TEXT, _FLYING_TEXT, target, wire)
    if target:  # (VerdictTally.add of rows with a finite target_age_ms)
        tally.target_seen = True
    if dicts:
        if write_dict_row is not None:
            for cells in rows.cells():
                write_dict_row(p_cells_row(cells, target) if p else target_cells_row(cells))
    elif write_block is not None:
        write_block(rows)
    elif write_cells is not None:
        for cells in rows.cells():
            write_cells(cells)
    tally.add_ticks(rows.times_s(), mode)


# the warm-up's flights: a square (tick_block), an obstacle's step (tick_block_obstacles),
# the square by the thesis' Newton scheme (tick_block_newton), the obstacle's step by it
# (tick_block_newton_obstacles), the square by the P controller (tick_block_p), the square
# with a mocap dropout: its sensors through the wire (tick_block_wire)
_WARM_UP_SQUARE = {"name": "warm-up", "duration_s": 1.0, "reference": {"kind": "square"}}
_WARM_UP_NEWTON = {**_WARM_UP_SQUARE, "name": "warm-up-newton",
                   "controller": {"solver": {"method": "newton"}}}
_WARM_UP_OBSTACLE = {"name": "warm-up-obstacle", "duration_s": 1.0,
                     "reference": {"kind": "step", "target_m": [2.5, 0.0, 1.0]},
                     "controller": {"obstacles": [{"kind": "cylinder",
                                                   "center_m": [1.25, 0.0, 1.0],
                                                   "radius_m": 0.3, "margin_m": 0.3}]}}
_WARM_UP_NEWTON_OBSTACLE = {**_WARM_UP_OBSTACLE, "name": "warm-up-newton-obstacle",
                            "controller": {**_WARM_UP_OBSTACLE["controller"],
                                           **_WARM_UP_NEWTON["controller"]}}
_WARM_UP_P = {**_WARM_UP_SQUARE, "name": "warm-up-p", "controller": {"kind": "p"}}
_WARM_UP_WIRE = {**_WARM_UP_SQUARE, "name": "warm-up-wire",
                 "faults": {"mocap_dropout": {"start_s": 0.5, "duration_s": 0.1}}}
#: each block kernel's warm-up flight (warm_up_blocks)
_WARM_UPS = ((tick_block, _WARM_UP_SQUARE), (tick_block_obstacles, _WARM_UP_OBSTACLE),
             (tick_block_newton, _WARM_UP_NEWTON),
             (tick_block_newton_obstacles, _WARM_UP_NEWTON_OBSTACLE),
             (tick_block_p, _WARM_UP_P), (tick_block_wire, _WARM_UP_WIRE))


def warm_up_blocks() -> None:
    """Blocks of ticks' kernels (``runtime/lockstep_block.tick_block``, then
    ``tick_block_obstacles`` for a solver with obstacles, ``tick_block_newton`` and
    ``tick_block_newton_obstacles`` for the thesis' Newton scheme, ``tick_block_p`` for the
    P controller, ``tick_block_wire`` for a fault on the sensors' bytes) loaded from numba's
    cache, or compiled now by a short flight each (:data:`_WARM_UPS`: the square's ~7 s on
    an empty cache): the precompile's background child, ``bench --tick`` and the tests call
    it; a flight does not wait for it (its ticks are then the per-tick path's: the same
    rows)."""
    global _warming_up
    if not monotonic.SAME_CLOCK:
        return  # (no blocks flown where the kernel does not read Python's clock: no compile)
    flights = [cfg for kernel, cfg in _WARM_UPS if not load_cached(kernel)]
    if not flights:
        return
    from ardrone_nmpc.config.schema import config_from_dict

    # the block compile's lock held meanwhile: the flight's start_if_cold (or its child)
    # starts no process to compile the kernel a second time (none taken: one runs already)
    locked = take_block_lock()
    _warming_up = True
    try:
        for cfg in flights:
            run_lockstep(config_from_dict(cfg))
    finally:
        _warming_up = False
        if locked:
            release_block_lock()


def _landing_logged(tick, drone: LockstepDrone, recorder, write_event, t_first: float,
                    t_start: float, k: int, period: float,
                    deadline: float) -> tuple[FlightMode, float]:
    """A landing's ticks logged after a supervisor's landing (:func:`_land`): each tick
    stepped and recorded as ``landing`` until LANDED, an EMERGENCY or ``deadline``."""
    # the loop's calls bound once (~40 ticks of descent a flight), as in _fly's loop
    advance_to, take_events, land = drone.advance_to, drone.take_events, drone.land
    mode_and_t = drone.mode_and_t  # (the truth's, without building one each tick)
    landed, emergency = FlightMode.LANDED, FlightMode.EMERGENCY
    mode, t_now_s = mode_and_t()
    while mode is not landed and t_now_s < deadline:
        if mode is emergency:
            break
        t_plant = t_first + k * period
        advance_to(t_plant, t_plant - t_start)
        drone_events = take_events()  # the faults that started: mostly none
        if drone_events:
            _write_events_at(write_event, drone_events)
        land()  # REF land, held as the link's keepalive holds it
        out = tick.step(drone.inputs(t_plant), t_exp_s=t_plant - t_start)
        _record_out(recorder, out, drone, "landing")
        k += 1
        mode, t_now_s = mode_and_t()
    return mode, t_now_s


def _write_events_at(write_event, events: list[tuple[float, dict]]) -> None:
    """``(experiment time, event)`` pairs, each at its time."""
    for t_exp, event in events:
        write_events(write_event, t_exp, [event])


def _sink(recorder, name: str):
    """The recorder's ``name`` method — ``write_cells`` (rows as cells in ``LOG_COLUMNS``
    order, no dict: RunRecorder, MemoryRecorder), ``write_block`` (a block of rows:
    ``runs/block_rows.BlockRows``) — or None: a recorder that does not take them. Looked up
    on its class: a wrapper that forwards other attributes (the live view's tee) must see
    every row through its own ``write_row``."""
    if recorder is None or getattr(type(recorder), name, None) is None:
        return None
    return getattr(recorder, name)


def _block_sink(recorder):
    """The recorder's ``write_block``, unless a class below the one that defines it
    overrides ``write_cells`` (a subclass that watches each row's cells must see a block's
    rows through its own ``write_cells``): then None, the rows go one by one."""
    mro = type(recorder).__mro__
    cells_at = next(i for i, kind in enumerate(mro) if "write_cells" in kind.__dict__)
    block_at = next((i for i, kind in enumerate(mro) if "write_block" in kind.__dict__), None)
    if block_at is None or block_at > cells_at:
        return None
    return recorder.write_block


def _record(recorder, row: dict, drone: LockstepDrone) -> None:
    if recorder is not None:
        put_truth(row, drone.truth_cells())
        recorder.write_row(row)


def _record_out(recorder, out, drone: LockstepDrone, mode: str) -> None:
    """Record a tick's output (its cells or its dict row) labelled ``mode``; a tick hands
    cells only when the recorder takes them, or there is none (``_fly``)."""
    cells = out.cells
    if cells is None:
        out.row["mode"] = mode
        _record(recorder, out.row, drone)
    elif recorder is not None:
        cells[MODE_CELL] = mode
        put_truth_cells(cells, drone.truth_cells())
        recorder.write_cells(cells)


def _land(cfg, tick, drone: LockstepDrone, recorder, write_event, t_first, t_start,
          k0, *, logged: bool) -> None:
    """Land and wait for touch-down. After a supervisor landing the ticks go on (logged, the
    supervisor hovering the link) so the log shows the descent; after a completed experiment
    only the events are written."""
    period = cfg.loop.period_s
    drone.land()
    write_event(t_first + k0 * period - t_start, "land")
    deadline = drone.truth.t_s + LANDING_TIMEOUT_S
    if not logged:  # (the descent's usual ticks in one compiled call)
        mode, t_now_s = drone.touch_down(
            t_first, k0, period, deadline, t_start,
            lambda events: _write_events_at(write_event, events))
    else:
        mode, t_now_s = _landing_logged(tick, drone, recorder, write_event, t_first, t_start,
                                        k0, period, deadline)
    write_event(t_now_s - t_start, "landed" if mode is FlightMode.LANDED else "not-landed",
                drone_mode=mode.value)
