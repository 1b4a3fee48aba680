"""The controller's stages before the NMPC's solve, on the nominal tick, in one compiled call.

Before the solve the usual tick made five Python calls and two numba dispatches — the
feedback's ages (``feedback_ages_ms``), the supervisor's look at them
(``Supervisor.check_feedback``), the estimate (``Estimation.update``: the Kalman step), the
supervisor's look at it (``Supervisor.check_state``) and the NMPC's inputs (``Control.solve``'s
waypoint path: ``nmpc_inputs``) —: ~2.9 µs a tick besides the solve, ~2.2 in one call
(issue 26; the call's 28 arguments cost most of what is left). :func:`before_solve` does their
arithmetic — the same expressions in the same order (the Kalman step and the NMPC's inputs are
the very kernels the stages call) — over the same arrays the Python stages use (the
estimator's state, the delay ring, the control stage's buffers), so either path can take any
tick. It steps the estimate on a copy, tests everything that makes the tick nominal and
answers :data:`NOT_NOMINAL`, with nothing written, when one fails: the caller then runs the
Python stages, which decide as they always did.

:class:`BeforeSolve` is the Python side: the preconditions (fresh pose and navdata, nothing
latched, the compiled estimator, a reference the control stage has packed: a waypoint one
or a table of a curve's states), the call, and the solve itself (``Control._solved``: the
solver and the tick's ``Solution``).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ardrone_nmpc.core.entry_points import ArrayKind, VettedCall
from ardrone_nmpc.core.kernel_cache import first_warm_up, flush_stale_caches
from ardrone_nmpc.core.numerics import INNER_KERNEL, OUTER_KERNEL
from ardrone_nmpc.core.python_floats import py_square
from ardrone_nmpc.core.types import STATE_DIM, FlightMode
from ardrone_nmpc.reference.experiment import HoldStartThen
from ardrone_nmpc.reference.live import LiveTarget
from ardrone_nmpc.runtime.estimate import Estimation, navdata_velocity_world
from ardrone_nmpc.runtime.stages import Control
from ardrone_nmpc.runtime.tick_kernels import (E_SIZE, E_STEP, E_X, ESTIMATED, W_KNOTS,
                                               estimate_step, fill_reference_table,
                                               nmpc_inputs, sample_waypoint_work, table_tick)
from ardrone_nmpc.safety import ALARM_BITS, Supervisor

__all__ = ["BeforeSolve", "NOT_NOMINAL", "before_solve", "warm_up_kernels"]

#: :func:`before_solve`'s code when the tick is not nominal (nothing written).
NOT_NOMINAL = -1

# the supervisor's limits the nominal tick is held to (Supervisor.cfg's, unpacked), then the
# estimator's scratch: one float64 array (:meth:`BeforeSolve._load_limits`)
L_BATTERY_FLOOR_PCT = 0
L_NAVDATA_LAND_MS = 1
L_MOCAP_NOMINAL_MS = 2  # the smallest mocap limit (-inf: none passes without the chain)
L_FENCE_LO = 3          # (3) x, y, z
L_FENCE_HI = 6          # (3)
L_MAX_SPEED_MPS = 9
L_TILT_CAP_DEG = 10
L_ALARM_BITS = 11       # the fault bits acted on (safety's mask: read, not compiled in)
L_TWO = 12              # 2.0, read at run time: the speed's squares are pow's (py_square)
L_SCRATCH = 13          # (E_STEP) what the estimator's step writes, as it was before
L_SIZE = L_SCRATCH + E_STEP

_EMERGENCY = FlightMode.EMERGENCY
_NDARRAY = np.ndarray
_FLOAT = float
_NO_SHIFT = np.zeros(0)  # nmpc_inputs: no offset-free shift


@njit(cache=True, **OUTER_KERNEL)
def before_solve(t_s, pose_rx_t_s, navdata_rx_t_s, state_bits, battery_pct, roll_deg,
                 pitch_deg, px, py, pz, psi_rad, pose_t_s, zacc_mps2, navdata_velocity,
                 nav_vx_mps, nav_vy_mps, est, limits, t_exp_s, sent, first, pending, lead_s,
                 x_solve, shift, states, work, rows):
    """The nominal tick's stages before the solve, over their state (module docstring).

    The tick's time and the feedback's receipt times (``t_s``, ``*_rx_t_s``); the navdata's
    fault bits (0: none reported), battery and tilt; the pose (``px`` … ``pose_t_s``), the z̈
    applied since the last (``zacc_mps2``) and, ``navdata_velocity`` set, ẋ, ẏ from navdata
    (rotated by the caller) for the estimator's state ``est`` (``estimate_step``'s);
    ``limits`` the supervisor's (``L_*``); then ``nmpc_inputs``' arguments.

    Returns (code, mocap age, navdata age) in ms; code :data:`NOT_NOMINAL` when the tick is
    not nominal, and then nothing was written."""
    mocap_ms = (t_s - pose_rx_t_s) * 1e3
    nav_ms = (t_s - navdata_rx_t_s) * 1e3
    nothing = (NOT_NOMINAL, mocap_ms, nav_ms)
    # check_feedback's usual tick (the emergency mode and the latch are the caller's tests)
    if not (state_bits & int(limits[L_ALARM_BITS]) == 0
            and battery_pct > limits[L_BATTERY_FLOOR_PCT] and nav_ms <= limits[L_NAVDATA_LAND_MS]
            and mocap_ms <= limits[L_MOCAP_NOMINAL_MS]):
        return nothing
    # a reference table without this tick's times (runtime/tick_kernels.table_tick): Python's
    if int(work[W_KNOTS]) == 0 and table_tick(t_exp_s, lead_s, work, rows) < 0:
        return nothing
    # Estimation.update, its state's written slots kept: put back unless the tick is nominal
    kept = limits[L_SCRATCH:L_SCRATCH + E_STEP]
    for i in range(E_STEP):
        kept[i] = est[i]
    if estimate_step(est, px, py, pz, psi_rad, pose_t_s, zacc_mps2, navdata_velocity,
                     nav_vx_mps, nav_vy_mps) != ESTIMATED:
        return nothing  # (it wrote nothing)
    if not _state_checked(est[E_X:E_X + STATE_DIM], roll_deg, pitch_deg, limits):
        for i in range(E_STEP):
            est[i] = kept[i]
        return nothing
    # --- nominal: from here on the stages' state is written
    nmpc_inputs(est[E_X:E_X + STATE_DIM], sent, first, pending, x_solve, t_exp_s, lead_s, shift,
                states, work, rows)
    return (0, mocap_ms, nav_ms)


@njit(cache=True, inline="always", **INNER_KERNEL)
def _state_checked(x, roll_deg, pitch_deg, limits) -> bool:
    """``Supervisor.check_state``'s nominal answer for the estimate ``x``."""
    # finite, inside the geofence, not too fast (Python's ``** 2``: the C library's pow, not
    # x · x, which differs in the last bit for ~0.1 % of x), not too tilted
    for i in range(STATE_DIM):
        if not math.isfinite(x[i]):
            return False
    for k in range(3):  # x, y, z: slots 0, 2, 4
        v = x[2 * k]
        if not (limits[L_FENCE_LO + k] <= v <= limits[L_FENCE_HI + k]):
            return False
    two = limits[L_TWO]
    speed = math.sqrt(py_square(x[1], two) + py_square(x[3], two) + py_square(x[5], two))
    if not speed <= limits[L_MAX_SPEED_MPS]:
        return False
    cap_deg = limits[L_TILT_CAP_DEG]
    return -cap_deg <= roll_deg <= cap_deg and -cap_deg <= pitch_deg <= cap_deg


class BeforeSolve:
    """The Python side of :func:`before_solve` for one tick's stages (``Tick``'s, an NMPC's)."""

    @staticmethod
    def takes(tick) -> bool:
        """Whether the compiled call can take ``tick``'s nominal ticks: an NMPC against a
        waypoint reference, a tabulated curve or a followed object (``LiveTarget``: a table
        too, filled a tick at a time), the compiled estimator, and the stages' own
        classes (a subclass' overrides are called: the Python stages take its ticks)."""
        traj = tick.trajectory
        kind = traj.__class__
        return (tick.control.nmpc is not None and (kind is HoldStartThen or kind is LiveTarget)
                and traj.waypoint_args is not None and tick.estimation.compiled
                and type(tick.supervisor) is Supervisor and type(tick.estimation) is Estimation
                and type(tick.control) is Control)

    def __init__(self, tick) -> None:
        self.supervisor = tick.supervisor
        self.estimation = tick.estimation
        self.supervision = tick.supervision
        self.control = tick.control
        self.delay = tick.control.delay
        self.offset = tick.offset
        #: the P controller's (``runtime/control_tick_p``: :meth:`arguments` only, its
        #: reference's lookup ``p_tick``'s)
        self._p = tick.control.nmpc is None
        self._limits = np.zeros(L_SIZE)
        self._cfg = None  # the safety config the limits are of
        # the kernel's call: its compiled entry point (core/entry_points) while the stages'
        # arrays are the ones vetted for it, else the dispatcher (:meth:`_vet`)
        self._entry = None
        self._vetted: tuple = ()

    def __getstate__(self) -> dict:
        """Without what :meth:`_vet` makes (an entry point does not pickle; the arrays it
        vetted are the stages', copied apart)."""
        state = self.__dict__.copy()
        state["_entry"], state["_vetted"] = None, ()
        return state

    def _load_limits(self) -> None:
        """The supervisor's limits (its own unpacked copies) into the kernel's array. A limit
        that is not a Python float or an int exact in a float64 (a numpy float32 among a
        copied config's, say) is compared in its own precision by the Python checks (NEP 50):
        then no tick passes the kernel (the mocap limit −inf) and the Python stages take them."""
        sup = self.supervisor
        lim = self._limits
        values = (sup._battery_floor_pct, sup._navdata_land_ms, sup._mocap_nominal_ms,
                  *sup._fence_lo, *sup._fence_hi, sup._max_speed_mps, sup._tilt_cap_deg)
        if all(v.__class__ is _FLOAT or (v.__class__ is int and abs(v) <= 2 ** 53)
               for v in values):
            lim[L_BATTERY_FLOOR_PCT:L_ALARM_BITS] = values
        else:
            lim[L_MOCAP_NOMINAL_MS] = -math.inf
        lim[L_ALARM_BITS] = ALARM_BITS  # (< 2**53: exact in a float64)
        lim[L_TWO] = 2.0
        self._cfg = sup._cfg

    def nominal(self, inputs, t_exp_s: float, traj):
        """The nominal tick's feedback ages, estimate and :class:`Solution`, every stage up
        to and including the solve done; None (nothing done) when the tick is not nominal."""
        args = self.arguments(inputs, t_exp_s, traj)
        if args is None:
            return None
        call, v = self._entry, self._vetted
        if not (call is not None and args[16] is v[0] and args[19] is v[1] and args[23] is v[2]
                and args[24] is v[3] and args[25] is v[4] and args[26] is v[5]
                and args[27] is v[6]):
            call = before_solve  # the dispatcher: it looks at every argument's type
            self._entry = None
        code, mocap_ms, nav_ms = call(*args)
        if call is before_solve:
            self._vet(args)
        if code:
            return None
        control = self.control
        x = self.estimation._x
        ref_horizon = control._ref_horizon  # the logged horizon, unshifted
        sol = control._solved(t_exp_s, control._x_solve if args[21] else x, control._ref_now,
                              ref_horizon if self.offset is None else control._horizon,
                              ref_horizon, control._solve_prepared)
        return (mocap_ms, nav_ms), x, sol

    def arguments(self, inputs, t_exp_s: float, traj) -> tuple | None:
        """:func:`before_solve`'s arguments for this tick, or None when a precondition of the
        compiled call does not hold (the tick is the Python stages')."""
        pose, nav = inputs.pose, inputs.navdata
        sup = self.supervisor
        if pose is None or nav is None or sup._latched is not None or nav.mode is _EMERGENCY:
            return None
        est, control = self.estimation, self.control
        kind = traj.__class__
        args = traj.waypoint_args if kind is HoldStartThen or kind is LiveTarget else None
        if self._p:  # the P controller's lookup: its first tick packs the waypoints (_p_solve)
            if args is None or args is not control._p_args or not est._compiled:
                return None
            work = control._p_work
            if work is None:
                return None  # (no knots: a table, the Python path's)
            work, rows = work
        elif (args is None or args is not control._work_args or control._dtau_varies
                or not est._compiled):
            return None  # (the first solve asks Δτ and packs the trajectory: Control.solve)
        else:
            work, rows = control._work, control._rows
        pos = pose.position_m
        t_s, pose_rx, nav_rx = inputs.t_s, inputs.pose_rx_t_s, inputs.navdata_rx_t_s
        battery, roll, pitch = nav.battery_pct, nav.roll_deg, nav.pitch_deg
        # the numbers check_feedback and check_state compute and compare with in Python as
        # Python floats (as the links give them): numpy's scalars answer numpy ages, float32
        # ones compare in float32 (NEP 50) — the Python stages' ticks, not the kernel's
        if not (pos.__class__ is _NDARRAY and t_s.__class__ is _FLOAT
                and pose.t_s.__class__ is _FLOAT
                and pose_rx.__class__ is _FLOAT and nav_rx.__class__ is _FLOAT
                and battery.__class__ is _FLOAT and roll.__class__ is _FLOAT
                and pitch.__class__ is _FLOAT):
            return None
        px, py, pz = pos.tolist()
        if sup._cfg is not self._cfg:
            self._load_limits()
        bits = nav.state_bits
        by_nav = est.velocity_from_navdata
        if by_nav:
            vx, vy = navdata_velocity_world(nav, pose.psi_rad)
        else:
            vx = vy = 0.0
        delay, offset = self.delay, self.offset
        shift = _NO_SHIFT if offset is None else offset.integrator.shift
        if traj.tabulated:  # the reference's states at this tick's times, for the call
            fill_reference_table(traj, np.array([t_exp_s]), delay.lead_s, control._work,
                                 control._rows)
        # the bits masked in Python (check_feedback's own ``bits & ALARM_BITS``): a word
        # beyond int64 would not unbox
        return (t_s, pose_rx, nav_rx, 0 if bits is None else bits & ALARM_BITS, battery, roll,
                pitch, px, py, pz, pose.psi_rad, pose.t_s, self.supervision.zacc_mps2, by_nav,
                vx, vy, est._state, self._limits, t_exp_s, delay.ring, delay.first, delay.count,
                delay.lead_s, control._x_solve, shift, control._states, work, rows)

    def _vet(self, args: tuple) -> None:
        """After a call through the dispatcher: the kernel's entry point for float numbers
        (each number is made a float64, an int64 or a truth by its unboxing, as a Python
        caller's numbers are by the dispatcher's specialisation for them: the same value),
        kept with the stages' arrays of the call if each is of the one kind it is compiled
        for (``VettedCall.entry_for``), so that the next calls with them skip the
        dispatcher's look at 28 arguments (~0.4 µs); else the dispatcher stays (asked again
        next call)."""
        entry = _CALL.entry_for(*(args[i] for i, _ in _ARRAYS))
        if entry is not None:
            self._entry = entry
            self._vetted = tuple(args[i] for i in (16, 19, 23, 24, 25, 26, 27))


# :func:`before_solve`'s array arguments (position, dimensions): the estimator's state, the
# limits, the ring, x_solve, the shift, the reference states, work, rows; its numbers' kinds
# (the state bits, the pending window: int64; ẋ, ẏ from navdata: a truth; floats else)
_ARRAYS = ((16, 1), (17, 1), (19, 2), (23, 1), (24, 1), (25, 2), (26, 1), (27, 2))
_NUMBERS = tuple(0 if i in (3, 20, 21) else False if i == 13 else 0.0 for i in range(28))
_CALL = VettedCall(before_solve, *(ArrayKind(dict(_ARRAYS)[i]) if i in dict(_ARRAYS) else k
                                   for i, k in enumerate(_NUMBERS)))


def warm_up_kernels() -> None:
    """Load (or compile) :func:`before_solve` now — once per process —, its callees from the
    cache first (``core/kernel_cache.first_warm_up``), not on the first tick aloft."""
    if not first_warm_up(before_solve):
        return
    n, work, rows = sample_waypoint_work()
    limits = np.zeros(L_SIZE)
    limits[L_NAVDATA_LAND_MS] = limits[L_MOCAP_NOMINAL_MS] = 1.0
    limits[L_FENCE_LO:L_FENCE_LO + 3] = -1.0
    limits[L_FENCE_HI:L_FENCE_HI + 3] = limits[L_MAX_SPEED_MPS] = limits[L_TILT_CAP_DEG] = 1.0
    limits[L_TWO] = 2.0
    before_solve(1.0, 1.0, 1.0, 0, 50.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, False, 0.0,
                 0.0, np.zeros(E_SIZE), limits, 0.0, np.zeros((2, 4)), 0, 1, 0.0, np.zeros(7),
                 np.zeros(4), np.zeros((n, 7)), work, rows)


flush_stale_caches(__name__)  # kernels calling other files: core/kernel_cache.py