"""Blocks of lockstep ticks in one compiled call: the drone's tick, the controller's and the
row's numbers, tick after tick, while each is the usual one.

The lockstep runner's tick makes two compiled calls — the drone's legs
(``sim/lockstep_legs``) and the controller's tick (``runtime/control_tick``) — with Python
around them: objects for the samples, the firmware's PCMD, the stages' written state, the
row. On the usual tick none of that Python decides anything. :func:`tick_block` flies up to
``n_max`` ticks without it: :func:`~ardrone_nmpc.sim.drone_block.drone_legs`,
:func:`~.control_tick.control_tick`, :func:`~ardrone_nmpc.sim.drone_block.drone_command`,
and a row of numbers a tick (``runs/block_row``); :class:`TickBlocks` writes back to the
Python objects what the last tick left — the same values the per-tick path leaves — and
the runner writes the rows (docs/architecture.md, runtime).

A second mocap object (``sim.target``: logged, a moving obstacle's centre, or followed: its
reference's table) is drawn in the block per frame the legs take and observed every tick
(``runtime/second_object``), its rows then the per-tick path's dicts
(``log_columns.target_cells_row``).

A tick that is not the usual one ends the block where Python must take over (``EXIT_*``):
before the tick (a watchdog due: nothing of it done), after its legs (a leg the kernel
leaves to Python, a mode change: the legs' own after-run code goes on), or after the
controller's call (not nominal, a command the firmware caps: the tick goes on in
``Tick.step`` from the call's answer). A response fit due after a tick and a block of the
drone's normals run short end a block too, and are made between two blocks.
"""

from __future__ import annotations

import math
import time

import numpy as np
from numba import njit

from ardrone_nmpc.core import monotonic
from ardrone_nmpc.core.entry_points import entry_point
from ardrone_nmpc.core.kernel_cache import flush_stale_caches, load_cached
from ardrone_nmpc.core.monotonic import monotonic_ns
from ardrone_nmpc.core.numerics import INNER_KERNEL, OUTER_KERNEL, kernel_twin
from ardrone_nmpc.core.types import IX_PSI, IX_VX, IX_VY, IX_VZ, IX_X, IX_Y, IX_Z, STATE_DIM
from ardrone_nmpc.runs import block_row as br
from ardrone_nmpc.runtime.control_tick import (control_tick, control_tick_newton,
                                               control_tick_newton_obstacles,
                                               control_tick_obstacles)
from ardrone_nmpc.runtime.control_tick_p import PControlTick, control_tick_p
from ardrone_nmpc.runtime.second_object import (O_FOLLOW, O_ON, O_PSI, O_RX, O_T, O_X,
                                                SecondObject, followed, take_frame)
from ardrone_nmpc.runtime.tick_kernels import E_X, TABLE_TICKS, fill_reference_table
from ardrone_nmpc.sim import drone_block as db
from ardrone_nmpc.sim import sensor_step as ks
from ardrone_nmpc.sim import wire_block

__all__ = ["EXIT_AFTER_CONTROL", "EXIT_AFTER_LEGS", "EXIT_BEFORE", "EXIT_FIT", "EXIT_NONE",
           "EXIT_SHORT", "TickBlocks", "tick_block", "tick_block_newton",
           "tick_block_newton_obstacles", "tick_block_obstacles", "tick_block_p",
           "tick_block_wire"]

#: :func:`tick_block`'s exits: all ``n_max`` ticks flown; the next tick is Python's from
#: its start; its legs ran (Python's after-run code goes on); the controller's call answered
#: (the tick goes on in ``Tick.step``); the last tick flown whole has a response fit due
#: after it; a block of the drone's normals ran short before the next tick's legs
(EXIT_NONE, EXIT_BEFORE, EXIT_AFTER_LEGS, EXIT_AFTER_CONTROL, EXIT_FIT,
 EXIT_SHORT) = range(6)
# c: the controller's numbers a block carries from tick to tick — the input z̈ and ż
# reference sent last (Supervision's), the delay ring's next row and first pending row —
# and what it only reads — the pending count, the ring's capacity, the delay's lead, the
# next response fit's time (inf: none), the state bits, ẋ, ẏ from the navdata's speeds
# (1.0) or not —; whether a feed took a sample; the exit tick's call: its time (ns) and
# answer (19 numbers)
(C_ZACC, C_VZ_REF, C_NEXT, C_FIRST, C_COUNT, C_CAPACITY, C_LEAD_S, C_NEXT_FIT_S, C_BITS,
 C_BY_NAV, C_FED, C_SPENT_NS, C_ANSWER) = range(13)
C_SIZE = C_ANSWER + 19
# the answer's integer numbers (code, flag, GMRES and Newton iterations, bits, feed code)
_ANSWER_INTS = (0, 3, 6, 7, 17, 18)
_perf_counter_ns = time.perf_counter_ns


@njit(cache=True, **OUTER_KERNEL)
def tick_block(n_max, k0, t_first_s, period_s, n_settle, d, x, ring, buf, bias_n, gust_n,
               mocap_n, nav_n, c, table, est, limits, dring, x_solve, shift, states, work,
               rows, mem, iprm, horizon, step_arg, divergence_residual, vz_from_commands,
               vz_lead_s, vz_max_mps, tilt_cap_rad, gain, e, v, y, response, offset,
               offset_flags, o, o_normals, obstacles):
    """Ticks ``k0`` … of the lockstep schedule (plant time ``t_first_s + k·period_s``,
    experiment time ``(k − n_settle)·period_s``) while each is the usual one: returns how
    many it flew and its exit (``EXIT_*``). ``d``: the drone's numbers
    (``sim/drone_block``); the legs' arrays; ``c``: the controller's (``C_*``); ``table``:
    a row of numbers a tick (``BLOCK_ROW``); then :func:`control_tick`'s arrays and settings
    (its prepared tail's, ``has_nav`` 1); the second object's (``runtime/second_object``:
    ``o``, its normals, the solver's obstacle table)."""
    out = buf[ks.B_OUT:ks.B_IV]
    capacity, count = int(c[C_CAPACITY]), int(c[C_COUNT])
    bits = int(c[C_BITS])
    by_nav = c[C_BY_NAV] != 0.0
    for i in range(n_max):
        k = k0 + i
        t_s = t_first_s + k * period_s
        t_exp_s = (k - n_settle) * period_s
        t_pose = d[db.D_T_POSE]
        status = db.drone_legs(d, x, ring, buf, bias_n, gust_n, mocap_n, nav_n, t_s,
                               ks.MODE_FLYING, 0.0)
        t_new = d[db.D_T_POSE]  # (a frame taken: the sampler's took_pose draws the object)
        if o[O_ON] != 0.0 and t_new == t_new and t_new != t_pose:
            take_frame(o, o_normals, t_new, d[db.D_POSE_RX], obstacles)
        if status != db.LEGS_DONE:
            return i, (EXIT_AFTER_LEGS if status == db.LEGS_PARTIAL else
                       EXIT_SHORT if status == db.LEGS_SHORT else EXIT_BEFORE)
        t0_ns = monotonic_ns()
        if o[O_FOLLOW] != 0.0:  # (Tick.step's observe, then the reference's table)
            followed(o, t_s, t_exp_s, c[C_LEAD_S], work, rows)
        nxt = int(c[C_NEXT])
        vz_last = c[C_VZ_REF] if vz_from_commands else 0.0
        # (what the links hold: d's newest pose and navdata sample, and ẋ, ẏ from the
        # navdata's speeds if the estimate takes them)
        nav_vx, nav_vy = _navdata_velocity_world(d) if by_nav else (0.0, 0.0)
        answer = control_tick(
            t_s, d[db.D_POSE_RX], d[db.D_T_NAV], bits, d[db.D_BATTERY], d[db.D_NAV_ROLL],
            d[db.D_NAV_PITCH], d[db.D_PX], d[db.D_PY], d[db.D_PZ], d[db.D_PSI], d[db.D_POSE_T],
            c[C_ZACC], by_nav, nav_vx, nav_vy, est, limits, t_exp_s, dring, int(c[C_FIRST]),
            count, c[C_LEAD_S], x_solve, shift, states, work, rows, vz_last, nxt, mem, iprm,
            horizon, step_arg, divergence_residual, vz_from_commands, vz_lead_s, vz_max_mps,
            tilt_cap_rad, gain, e, v, y, response, 1, offset, offset_flags)
        (code, mocap_ms, nav_ms, flag, solve_us, norm, gmres_it, newton_it, zacc, phi, theta,
         rate, vz, roll, pitch, gaz, yaw, sat_bits, fed) = answer
        if code != 0 or not db.drone_command(d, out, roll, pitch, gaz, yaw):
            a = c[C_ANSWER:]
            a[0], a[1], a[2], a[3], a[4], a[5] = code, mocap_ms, nav_ms, flag, solve_us, norm
            a[6], a[7], a[8], a[9], a[10], a[11] = gmres_it, newton_it, zacc, phi, theta, rate
            a[12], a[13], a[14], a[15], a[16], a[17] = vz, roll, pitch, gaz, yaw, sat_bits
            a[18] = fed
            c[C_SPENT_NS] = monotonic_ns() - t0_ns
            return i, EXIT_AFTER_CONTROL
        # what AfterSolve.written keeps: Supervision's inputs, the delay ring's next row
        c[C_ZACC], c[C_VZ_REF] = zacc, vz
        nxt = 0 if nxt + 1 == capacity else nxt + 1
        c[C_NEXT] = nxt
        if count:
            c[C_FIRST] = nxt + capacity - count
        if fed:
            c[C_FED] = 1.0
        compute_us = (monotonic_ns() - t0_ns) * 1e-3
        _row(table[i], t_exp_s, est, states[0], zacc, phi, theta, rate, vz, roll, pitch,
             gaz, yaw, sat_bits, solve_us, norm, gmres_it, newton_it, mocap_ms, nav_ms, d,
             compute_us, out)
        if o[O_ON] != 0.0:  # (log_columns' target cells)
            row = table[i]
            row[br.BR_TARGET_X], row[br.BR_TARGET_Y] = o[O_X], o[O_X + 1]
            row[br.BR_TARGET_Z], row[br.BR_TARGET_PSI] = o[O_X + 2], o[O_PSI]
            row[br.BR_TARGET_T], row[br.BR_TARGET_AGE] = o[O_T], (t_s - o[O_RX]) * 1e3
        if not t_s < c[C_NEXT_FIT_S]:  # (AfterSolve.written's test: a fit due, in Python)
            return i + 1, EXIT_FIT
    return n_max, EXIT_NONE


@njit(cache=True, **INNER_KERNEL)
def _navdata_velocity_world(d):
    """``runtime/estimate.navdata_velocity_world`` of d's navdata sample at d's pose's ψ: the
    same expressions in the same order (cos and sin: the C library's, as Python's math)."""
    c, s = math.cos(d[db.D_PSI]), math.sin(d[db.D_PSI])
    fwd, right = d[db.D_NAV_VX], d[db.D_NAV_VY]
    return fwd * c + right * s, fwd * s - right * c


@njit(cache=True, **INNER_KERNEL)
def _row(row, t_exp_s, est, ref_now, zacc, phi, theta, rate, vz, roll, pitch, gaz, yaw,
         sat_bits, solve_us, norm, gmres_it, newton_it, mocap_ms, nav_ms, d, compute_us, out):
    """One tick's numbers in ``runs/block_row``'s order."""
    x = est[E_X:E_X + STATE_DIM]
    row[br.BR_T] = t_exp_s
    row[br.BR_X], row[br.BR_Y], row[br.BR_Z] = x[IX_X], x[IX_Y], x[IX_Z]
    row[br.BR_PSI], row[br.BR_VX], row[br.BR_VY] = x[IX_PSI], x[IX_VX], x[IX_VY]
    row[br.BR_VZ] = x[IX_VZ]
    row[br.BR_X_REF], row[br.BR_Y_REF] = ref_now[IX_X], ref_now[IX_Y]
    row[br.BR_Z_REF], row[br.BR_PSI_REF] = ref_now[IX_Z], ref_now[IX_PSI]
    row[br.BR_ZACC], row[br.BR_PHI], row[br.BR_THETA], row[br.BR_RATE] = zacc, phi, theta, rate
    row[br.BR_VZ_REF] = vz
    row[br.BR_ROLL], row[br.BR_PITCH], row[br.BR_GAZ], row[br.BR_YAW] = roll, pitch, gaz, yaw
    row[br.BR_SATURATED], row[br.BR_SOLVE_US], row[br.BR_NORM] = sat_bits, solve_us, norm
    row[br.BR_GMRES], row[br.BR_NEWTON] = gmres_it, newton_it
    row[br.BR_MOCAP_MS], row[br.BR_NAV_MS] = mocap_ms, nav_ms
    row[br.BR_BATTERY], row[br.BR_COMPUTE_US] = d[db.D_BATTERY], compute_us
    row[br.BR_MOCAP_T], row[br.BR_NAV_VX] = d[db.D_POSE_T], d[db.D_NAV_VX]
    row[br.BR_NAV_VY], row[br.BR_NAV_ROLL] = d[db.D_NAV_VY], d[db.D_NAV_ROLL]
    row[br.BR_NAV_PITCH] = d[db.D_NAV_PITCH]
    row[br.BR_TRUE_X], row[br.BR_TRUE_Y] = out[ks.O_STATE], out[ks.O_STATE + 1]
    row[br.BR_TRUE_Z], row[br.BR_TRUE_PSI] = out[ks.O_STATE + 2], out[ks.O_STATE + 8]
    row[br.BR_TRUE_VZ] = out[ks.O_STATE + 5]
    row[br.BR_NAV_STATE] = d[db.D_NAV_STATE]


#: :func:`tick_block` for solvers with obstacles (``control_tick_obstacles``' blocks)
tick_block_obstacles = kernel_twin(tick_block, "tick_block_obstacles",
                                   control_tick=control_tick_obstacles)
#: … for the thesis' Newton scheme (``control_tick_newton``'s blocks), without obstacles
#: and with
tick_block_newton = kernel_twin(tick_block, "tick_block_newton",
                                control_tick=control_tick_newton)
tick_block_newton_obstacles = kernel_twin(tick_block, "tick_block_newton_obstacles",
                                          control_tick=control_tick_newton_obstacles)
#: … for the P controller (``runtime/control_tick_p``: control_tick's arguments and answer)
tick_block_p = kernel_twin(tick_block, "tick_block_p", control_tick=control_tick_p)
#: … for a flight with a sensor fault: the wire's quiet ticks (``sim/wire_block``'s legs)
tick_block_wire = kernel_twin(tick_block, "tick_block_wire", db=wire_block)
#: the blocks' kernel by the controller's (``ControlTick.kernel``)
BLOCK_KERNELS = {control_tick: tick_block, control_tick_obstacles: tick_block_obstacles,
                 control_tick_newton: tick_block_newton,
                 control_tick_newton_obstacles: tick_block_newton_obstacles,
                 control_tick_p: tick_block_p}
#: … through the wire (a flight with a sensor fault: ``sim/wire_block``)
WIRE_BLOCK_KERNELS = {control_tick: tick_block_wire}


class TickBlocks:
    """The Python side of :func:`tick_block` for one lockstep flight's tick and drone: what
    a block starts from, and what it leaves written back (module docstring).

    Blocks follow one another while nothing but a response fit or new normals comes
    between (:data:`EXIT_FIT`, :data:`EXIT_SHORT`, a full block): the chain stays *open* —
    the drone's state and the stages' written numbers are the kernel's (``d``, ``c``),
    the delay ring's written back only for the fit — and :meth:`close` writes them back
    before anything else reads them (a Python tick, the landing)."""

    @staticmethod
    def takes(tick, drone, compile_now: bool) -> bool:
        """Whether blocks may fly some of this flight's ticks: its controller's nominal tick
        is one compiled call whose rows are cells, with a second object only where the
        kernel draws it (:meth:`SecondObject.takes`), and its drone's ticks are the compiled
        legs' (on a platform whose clock the kernel reads: ``core/monotonic.SAME_CLOCK``; a
        drone with something injected that
        leaves the sensors alone: the ticks at which nothing acts, :meth:`fly`) — and
        :func:`tick_block` has machine code (compiled, or in numba's cache: loaded), unless
        the blocks may compile it (``compile_now``): the obstacles' and the Newton scheme's
        kernels as the usual one (:func:`~.lockstep.warm_up_blocks` compiles the usual one,
        the obstacles' and Newton's)."""
        legs = drone._legs
        if not (monotonic.SAME_CLOCK and tick.control_tick is not None and tick.cell_rows
                and SecondObject.takes(tick, drone.sensors) and legs is not None
                and legs.stands_in):
            return False
        kernel = _kernels(drone).get(tick.control_tick.kernel)
        return kernel is not None and (compile_now or load_cached(kernel))

    def __init__(self, tick, drone, *, n_max: int, n_settle: int, period_s: float,
                 t_first_s: float, compile_now: bool) -> None:
        self.tick, self.drone = tick, drone
        #: the kernel of this flight's blocks (:data:`BLOCK_KERNELS`)
        self.kernel = _kernels(drone)[tick.control_tick.kernel]
        #: the sensors' datagrams through the wire (a sensor fault: ``sim/wire_block``)
        self.wire = drone.sensors.wire
        #: the second mocap object's numbers (logged, a moving obstacle's centre, followed)
        self.second = SecondObject(tick, drone.sensors)
        #: the rows have the object's cells
        self.target = drone.sensors.target_cfg is not None
        #: the P controller's rows (``runtime/control_tick_p``): the per-tick path's dicts,
        #: without the solver's cells (``log_columns.p_cells_row``)
        self.p = isinstance(tick.control_tick, PControlTick)
        #: compile :func:`tick_block` when a block finds no machine code for its arguments;
        #: else that block is not flown — its ticks are the per-tick path's, which leaves the
        #: same rows (a first flight on an empty cache does not wait ~7 s for it:
        #: ``runtime/precompile`` compiles it meanwhile)
        self.compile_now = compile_now
        self.n_max, self.n_settle = n_max, n_settle
        self.period_s, self.t_first_s = period_s, t_first_s
        #: the first tick at or after the last one asked at which the drone may not be
        #: plain (:meth:`_plain_ticks`; inf: never)
        self._unplain_k: float = 0
        self.d = (wire_block.wire_d(wire_block.row_capacity(drone.sensors, n_max, period_s))
                  if self.wire else np.zeros(db.D_SIZE))
        self.c = np.zeros(C_SIZE)
        #: the rows of the last block (``runs/block_row``: BLOCK_ROW numbers a tick)
        self.table = np.zeros((n_max, br.BLOCK_ROW))
        self._open = False
        self._last: list | None = None  # the open chain's last tick's row, its t_exp
        self._last_t_exp = math.nan
        self._ran = False  # a run of the open chain did legs
        # the last call: its arguments and entry point, the legs' arrays and the
        # controller's tail they were made with
        self._args: tuple = ()
        self._call = None
        self._legs_args = self._tail = None

    def fly(self, k: int, mode: str, n_max: int) -> tuple[int, int, object, int]:
        """Up to ``n_max`` ticks from tick ``k`` (all of phase ``mode``): ``(n, exit,
        more, spent_ns)`` — the ticks flown (their rows: :attr:`table`'s first ``n``),
        how the block ended (``EXIT_*``: 0 ticks and EXIT_BEFORE when it could not
        start); for EXIT_AFTER_CONTROL the controller's call's answer and time (ns) for
        ``Tick.step`` to go on from, for EXIT_FIT the fit's events (at the last tick).
        Unless the exit goes on with a block (:data:`EXIT_FIT`, :data:`EXIT_SHORT`,
        :data:`EXIT_NONE`), everything is written back (:meth:`close`). A tick at which
        the drone may not be plain (``LockstepDrone.plain_until_s``: something injected
        acts) is never a block's, nor are its legs begun in one."""
        n_max = min(n_max, self._plain_ticks(k))
        if n_max <= 0:
            self.close()
            return 0, EXIT_BEFORE, None, 0
        call = self._chained(k, mode, n_max) if self._open else None
        if call is None:
            self.close()
            call = self._entered(k, mode, n_max)
            if call is None:
                return 0, EXIT_BEFORE, None, 0
        second = self.second
        second.drawn(self._args[0])
        n, exit_ = call(*self._args, second.o, second.normals, second.obstacles)
        second.consumed()
        self._open = True
        period_s, n_settle = self.period_s, self.n_settle
        if n:
            self._last = self.table[n - 1].tolist()
            self._last_t_exp = (k + n - 1 - n_settle) * period_s
            self._ran = True
        if self.wire and (exit_ == EXIT_FIT or exit_ == EXIT_SHORT  # (a chain that goes on:
                          or exit_ == EXIT_NONE):                # the links' state first)
            self.drone.blocks_sent(self.d)
        if exit_ == EXIT_FIT:  # the fit AfterSolve.written makes after the last tick
            return n, exit_, self._fit(self.t_first_s + (k + n - 1) * period_s, n), 0
        if exit_ == EXIT_SHORT:  # new blocks of normals; the next tick's a block's again
            legs = self.drone._legs
            if self.wire:  # (as many as the tick's frames and packets take)
                legs.refill(wire_block.normals_short(legs))
            else:
                legs.refill()
        if exit_ == EXIT_SHORT or exit_ == EXIT_NONE:
            return n, exit_, None, 0
        legs_ran = exit_ == EXIT_AFTER_LEGS or exit_ == EXIT_AFTER_CONTROL
        if legs_ran:  # (the tick it ended at)
            self._ran, self._last_t_exp = True, (k + n - n_settle) * period_s
        self.close()
        if not legs_ran:
            return n, exit_, None, 0
        # (the object's pose of the tick's frame: the kernel's, written back by close)
        self.drone.block_ran_to(self.t_first_s + (k + n) * period_s,
                                target_drawn=self.target)
        if exit_ == EXIT_AFTER_LEGS:
            return n, exit_, None, 0
        numbers = self.c[C_ANSWER:].tolist()
        for i in _ANSWER_INTS:
            numbers[i] = int(numbers[i])
        return n, exit_, tuple(numbers), int(self.c[C_SPENT_NS])

    def _plain_ticks(self, k: int) -> float:
        """How many ticks from tick ``k`` on the drone is plain at (inf: all): the ticks
        before the first whose experiment time — the runner's, as ``Schedule.t_exp_s``
        makes it — reaches ``LockstepDrone.plain_until_s``. Kept until tick ``k`` reaches
        that tick: plain ticks change nothing injected."""
        if k < self._unplain_k:
            return self._unplain_k - k
        period_s, n_settle = self.period_s, self.n_settle
        t_exp_s = (k - n_settle) * period_s
        bound = self.drone.plain_until_s(t_exp_s)
        if not bound > t_exp_s:  # (not plain at tick k)
            self._unplain_k = k
            return 0
        if bound == math.inf:
            self._unplain_k = math.inf
            return math.inf
        j = k + math.ceil((bound - t_exp_s) / period_s)
        while j > k and (j - 1 - n_settle) * period_s >= bound:
            j -= 1
        while (j - n_settle) * period_s < bound:
            j += 1
        self._unplain_k = j
        return j - k

    def close(self) -> None:
        """Write back what the open chain of blocks left (the drone's state, the stages'
        numbers of its last tick); nothing when none is open."""
        if not self._open:
            return
        self._open = False
        self.drone.after_block(self.d, self._ran, self._last_t_exp)
        self.second.written()
        if self._last is not None:
            self._written()
        self._last, self._ran = None, False

    def _entered(self, k: int, mode: str, n_max: int):
        """A block's start from the Python objects: ``d`` and ``c`` filled and the call's
        arguments made (:attr:`_args`); its entry point, or None — no block (the tick is
        not one a block flies, or no machine code for its arguments' kinds)."""
        tick, drone, c = self.tick, self.drone, self.c
        ct, sup = tick.control_tick, tick.supervisor
        if sup.label != mode or sup.events or not tick.delay._pushed:
            return None  # (a label to note; the first input unsent)
        tail = ct.prepared()
        if (tail is None or not self.second.entered()
                or not drone.block_entry(self.d, second_object=self.target)):
            return None
        period_s, n_settle = self.period_s, self.n_settle
        t_s = self.t_first_s + k * period_s
        before = ct.before.arguments(drone.sensors.inputs(t_s), (k - n_settle) * period_s,
                                     tick.trajectory)
        if before is None:
            return None
        delay, response = tick.delay, tick.response
        vz_last = (float(tick.supervision.vz_ref_mps) if tick.control.vz_from_commands
                   else 0.0)
        c[:C_SPENT_NS] = (before[12], vz_last, delay._next, before[20], before[21],
                          delay._capacity, before[22],
                          math.inf if response is None else response._next_fit_s, before[3],
                          float(before[13]), 0.0)
        legs_args = drone._legs._args
        n_max = self._tabulated(k, n_max)
        self._args = (n_max, k, self.t_first_s, period_s, n_settle, self.d, *legs_args, c,
                      self.table, before[16], before[17], before[19], before[23], before[24],
                      before[25], before[26], before[27], *_tail_args(tail))
        return self._vetted(legs_args, tail)

    def _chained(self, k: int, mode: str, n_max: int):
        """The next block of an open chain (the Python objects not written back): its entry
        point with :attr:`_args` made for it, or None — the chain ends here (a label to
        note; a precondition of the controller's call gone)."""
        if self.tick.supervisor.label != mode:
            return None
        tail = self.tick.control_tick.prepared()
        if tail is None:
            return None
        legs_args = self.drone._legs._args
        n_max = self._tabulated(k, n_max)
        if legs_args is self._legs_args and tail is self._tail:
            self._args = (n_max, k, *self._args[2:])
            return self._call
        args = self._args
        n_legs = len(legs_args)
        at = 6 + n_legs + 10  # (the legs' arrays, then c … the stages' eight arrays)
        self._args = (n_max, k, *args[2:6], *legs_args, *args[6 + n_legs:at],
                      *_tail_args(tail))
        return self._vetted(legs_args, tail)

    def _tabulated(self, k: int, n_max: int) -> int:
        """The block's length from tick ``k``: ``n_max``, or for a curve's reference (read
        from a table: ``runtime/tick_kernels.fill_reference_table``) at most the table's
        ticks, its states filled at each one's horizon times — the delay's lead is the
        block's (a fit that moves it ends a block)."""
        tick = self.tick
        if not tick.trajectory.tabulated or tick.follow is not None:
            return n_max  # (a followed object's: the kernel's, a tick at a time)
        control = tick.control
        n_max = min(n_max, TABLE_TICKS)
        t_exp_s = (np.arange(k, k + n_max) - self.n_settle) * self.period_s  # tick_block's
        fill_reference_table(tick.trajectory, t_exp_s, tick.delay.lead_s, control._work,
                             control._rows)
        return n_max

    def _vetted(self, legs_args: tuple, tail: tuple):
        """:attr:`_args`' entry point (kept with the legs' arrays and the tail it is for),
        or the dispatcher when blocks compile (``compile_now``), else None."""
        kernel, second = self.kernel, self.second
        call = entry_point(kernel, *self._args, second.o, second.normals,  # (its machine
                           second.obstacles)                               # code for these)
        if call is None and self.compile_now:
            call = kernel  # the dispatcher: compiles them
        self._call = call
        self._legs_args, self._tail = (legs_args, tail) if call is not kernel else (
            None, None)  # (vetted again after the compile)
        return call

    def _fit(self, t_s: float, n: int) -> list[dict]:
        """AfterSolve.written's fit after the tick at plant time ``t_s`` (the block's last,
        its row the table's ``n``-th): the delay ring written back first (a new delay
        moves its pending window), the estimate refitted if a feed took a sample; then
        the chain's numbers of the delay and the next fit. Its time goes to the tick's
        ``compute_us``, as the per-tick path's."""
        c, delay, response = self.c, self.tick.delay, self.tick.response
        self._ring_and_feed_written()
        t0_ns = _perf_counter_ns()
        events = response.refit(t_s)
        self.table[n - 1, br.BR_COMPUTE_US] += (_perf_counter_ns() - t0_ns) * 1e-3
        c[C_FIRST], c[C_COUNT], c[C_LEAD_S] = delay.first, delay.count, delay.lead_s
        c[C_NEXT_FIT_S] = response._next_fit_s
        return events

    def _written(self) -> None:
        """What the stages keep after the chain's last tick (``AfterSolve.written``'s: the
        supervisor's and Supervision's, the delay ring's next row, the response's
        estimate to refit when read)."""
        tick, v = self.tick, self._last
        tick.after_solve.kept(v[br.BR_ZACC], v[br.BR_PHI], v[br.BR_THETA], v[br.BR_RATE],
                              v[br.BR_VZ_REF], v[br.BR_ROLL], v[br.BR_PITCH], v[br.BR_GAZ],
                              v[br.BR_YAW], int(v[br.BR_SATURATED]))
        self._ring_and_feed_written()

    def _ring_and_feed_written(self) -> None:
        """The delay ring's next and first pending rows written back, and the response's
        estimate refitted when next read if a feed took a sample since (its flag cleared):
        what :meth:`_fit` and :meth:`_written` both owe ``AfterSolve.written``."""
        tick, c = self.tick, self.c
        tick.delay._next, tick.delay.first = int(c[C_NEXT]), int(c[C_FIRST])
        if c[C_FED] != 0.0:
            tick.response.estimator._estimate = None
            c[C_FED] = 0.0


def _kernels(drone) -> dict:
    """The block kernels by the controller's for ``drone``'s sensors (through the wire:
    the usual controller's alone)."""
    return WIRE_BLOCK_KERNELS if drone.sensors.wire else BLOCK_KERNELS


def _tail_args(tail: tuple) -> tuple:
    """:func:`tick_block`'s arguments of the controller's prepared tail (``ControlTick``'s:
    without ``has_nav``, 1 in a block)."""
    (mem, iprm, horizon, step_arg, residual, from_commands, lead, vz_max, tilt_cap, gain, e, v,
     y, response_state, _, offset, flags) = tail
    return (mem, iprm, horizon, step_arg, residual, from_commands, lead, vz_max, tilt_cap,
            gain, e, v, y, response_state, offset, flags)


flush_stale_caches(__name__)  # kernels calling other files: core/kernel_cache.py
