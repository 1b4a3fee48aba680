"""The controller's nominal tick in one compiled call: the stages before the solve, the
solver's update (C/GMRES', or the thesis' Newton/fdgmres), the solver's verdict on it and the
stages after it.

The usual NMPC tick made three compiled calls — :func:`~.before_solve.before_solve`, the
solver's kernel (``cgmres_step``), :func:`~.after_solve.after_solve` — with Python between
them: ``NmpcSolverBase.solve_prepared``'s status logic, the ``SolveResult`` and the
``Solution``, and the after-stages' preconditions (issue 26). :func:`control_tick` makes the
three calls from compiled code, over the same arrays (the stages' buffers, the solver's own
memory), and decides what ``solve_prepared`` decides on its usual tick: a solver that
answered ``FLAG_OK`` with ‖F‖ within ``divergence_residual`` is trusted — on a tick that is
not the first and without a horizon ramp C/GMRES' status is ``OK`` whatever the tolerance
says; the Newton scheme holds every tick to it, so its kernel's twin answers a flag of its own
where ‖F‖ stayed above it (:data:`FLAG_ABOVE_TOLERANCE`: ``MAX_ITERATIONS``, judged in Python).
It times the solver's kernel alone with the clock ``time.perf_counter_ns`` reads
(``core/monotonic``): the row's ``solve_us`` is what it was, the solve and nothing else.

It answers one of three codes, each leaving the stages' state as the Python path would:

* :data:`NOT_NOMINAL` — the stages before the solve found the tick not nominal: nothing was
  written, the tick is the Python stages' (or the two-call path's) from the start;
* :data:`SOLVED` — the stages before the solve and the solver's kernel ran, and then the
  solver's answer needs Python's judgement (a flag, a divergence: ``judged`` recovers) or
  the stages after it found the tick not nominal (nothing of theirs written): the tick
  continues in Python from the kernel's answer;
* 0 — the whole controller's tick done: the records are built from the answer.

:class:`ControlTick` is the Python side: the preconditions of the three calls (those of
:class:`~.before_solve.BeforeSolve` and :class:`~.after_solve.AfterSolve`, and a plain
:class:`~ardrone_nmpc.control.cgmres.CGMRESController` or
:class:`~ardrone_nmpc.control.newton.NewtonGMRESController` (with obstacles or without: a twin
each), past its first solve, unwrapped — or in a
:class:`~ardrone_nmpc.control.diverging.DivergingSolver`, on the ticks whose answer it does not
mark), the call, and the records the tick's row and the Python
state need.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ardrone_nmpc.control.cgmres import CGMRESController
from ardrone_nmpc.control.diverging import DivergingSolver
from ardrone_nmpc.control.kernels import FLAG_OK, cgmres_step
from ardrone_nmpc.control.kernels.steps import (cgmres_step_obstacles, newton_step,
                                                newton_step_obstacles)
from ardrone_nmpc.control.kernels.layout import NU, P_TOL, u_out_at, unpack
from ardrone_nmpc.control.newton import NewtonGMRESController
from ardrone_nmpc.control.ocp import SolverStatus, SolveResult
from ardrone_nmpc.core import monotonic
from ardrone_nmpc.core.entry_points import ArrayKind, VettedCall
from ardrone_nmpc.core.kernel_cache import first_warm_up, flush_stale_caches
from ardrone_nmpc.core.monotonic import monotonic_ns
from ardrone_nmpc.core.numerics import INNER_KERNEL, OUTER_KERNEL, kernel_twin
from ardrone_nmpc.core.types import IU_PHI, IU_PSIRATE, IU_THETA, IU_ZACC, IX_VZ, STATE_DIM
from ardrone_nmpc.runtime.after_solve import after_solve
from ardrone_nmpc.runtime.before_solve import _NUMBERS as _BEFORE_NUMBERS
from ardrone_nmpc.runtime.before_solve import L_SIZE, before_solve
from ardrone_nmpc.runtime.stages import Solution
from ardrone_nmpc.runtime.tick_kernels import E_X

__all__ = ["FLAG_ABOVE_TOLERANCE", "NOT_NOMINAL", "SOLVED", "ControlTick", "control_tick",
           "control_tick_newton", "control_tick_newton_obstacles", "control_tick_obstacles",
           "warm_up_kernels"]

#: :func:`control_tick`'s code when the tick is not nominal before the solve (nothing written)
NOT_NOMINAL = -1
#: … when the solver ran and the rest of the tick is Python's (module docstring)
SOLVED = 1
_N_BEFORE = 28  # before_solve's arguments, control_tick's first


@njit(cache=True, **OUTER_KERNEL)
def control_tick(t_s, pose_rx_t_s, navdata_rx_t_s, state_bits, battery_pct, roll_deg,
                 pitch_deg, px, py, pz, psi_rad, pose_t_s, zacc_mps2, navdata_velocity,
                 nav_vx_mps, nav_vy_mps, est, limits, t_exp_s, ring, first, pending, lead_s,
                 x_solve, shift, states, work, rows, vz_ref_last_mps, ring_row, mem, iprm,
                 horizon, step_arg, divergence_residual, vz_from_commands, vz_lead_s,
                 vz_max_mps, tilt_cap_rad, gain, e, v, y, response, has_nav, offset,
                 offset_flags):
    """The nominal tick's controller, over its state (module docstring).

    ``before_solve``'s 28 arguments; the two numbers of the tick ``after_solve`` takes (the
    last ż reference, the delay ring's next row); then what changes only when a writer
    changes it (``ControlTick``'s prepared tail): the solver's memory, settings, horizon (the
    reference it solves against: shifted by the offset-free stage, if any), the solver
    kernel's last argument ``step_arg`` (C/GMRES' ``initialise``, False on its usual tick;
    Newton's active set) and ``divergence_residual``; ``after_solve``'s other numbers (the
    ż base is the last ż reference with ``vz_from_commands``, else the predicted state's ż)
    and its buffers (``has_nav`` 1).

    Returns (code, mocap age ms, navdata age ms, the kernel's flag, solve µs, ‖F‖, GMRES and
    Newton iterations, the input z̈, φ, θ, ψ̇, then ``after_solve``'s ż ref, four PCMD
    fractions, saturation bits and feed answer)."""
    code, mocap_ms, nav_ms = before_solve(
        t_s, pose_rx_t_s, navdata_rx_t_s, state_bits, battery_pct, roll_deg, pitch_deg, px, py,
        pz, psi_rad, pose_t_s, zacc_mps2, navdata_velocity, nav_vx_mps, nav_vy_mps, est, limits,
        t_exp_s, ring, first, pending, lead_s, x_solve, shift, states, work, rows)
    if code != 0:
        return (NOT_NOMINAL, mocap_ms, nav_ms, 0, 0.0, 0.0, 0, 0, 0.0, 0.0, 0.0, 0.0, 0.0,
                0.0, 0.0, 0.0, 0.0, 0, 0)
    x = est[E_X:E_X + STATE_DIM]
    xs = x_solve if pending else x
    t0_ns = monotonic_ns()
    flag = cgmres_step(mem, xs, horizon, iprm, step_arg)
    solve_us = (monotonic_ns() - t0_ns) * 1e-3
    u = u_out_at(horizon.shape[0] - 1, iprm[0])  # the answer, read in place (no views)
    stats = u + NU
    norm = mem[stats + 3]
    gmres_it, newton_it = int(mem[stats + 1]), int(mem[stats])
    zacc, phi = mem[u + IU_ZACC], mem[u + IU_PHI]
    theta, rate = mem[u + IU_THETA], mem[u + IU_PSIRATE]
    # solve_prepared's verdict (``judged``): on a flag or a divergence it recovers, in Python
    if flag != FLAG_OK or norm > divergence_residual:
        return (SOLVED, mocap_ms, nav_ms, flag, solve_us, norm, gmres_it, newton_it, zacc, phi,
                theta, rate, 0.0, 0.0, 0.0, 0.0, 0.0, 0, 0)
    vz_base = vz_ref_last_mps if vz_from_commands else xs[IX_VZ]
    code, vz, roll, pitch, gaz, yaw, bits, fed = after_solve(
        zacc, phi, theta, rate, vz_base, vz_lead_s, vz_max_mps, tilt_cap_rad, gain, e, v, y,
        ring, ring_row, response, has_nav, navdata_rx_t_s, roll_deg, pitch_deg, t_s, x,
        states[0], states[1:], offset, offset_flags)
    return (SOLVED if code != 0 else 0, mocap_ms, nav_ms, flag, solve_us, norm, gmres_it,
            newton_it, zacc, phi, theta, rate, vz, roll, pitch, gaz, yaw, bits, fed)


#: A Newton tick's flag (:func:`newton_step_judged`) when it answered ``FLAG_OK`` with ‖F‖
#: above the tolerance: ``solve_prepared``'s status ``MAX_ITERATIONS``, Python's to judge
FLAG_ABOVE_TOLERANCE = 3


@njit(cache=True, **INNER_KERNEL)
def newton_step_judged(mem, x, ref, iprm, active):
    """``newton_step``'s tick (the thesis' Newton/fdgmres to tolerance, then eq. 3.25), its
    flag, or :data:`FLAG_ABOVE_TOLERANCE` where ``judged`` would find the status
    ``MAX_ITERATIONS`` (every Newton tick is held to the tolerance): the ‖F‖ its iterations
    ended at above the tolerance, both as the kernel left them in the memory."""
    flag = newton_step(mem, x, ref, iprm, active)
    _, _, _, stats, _, prm, _, _ = unpack(mem, ref.shape[0] - 1, iprm[0], iprm[4])
    if flag == FLAG_OK and stats[2] > prm[P_TOL]:
        return FLAG_ABOVE_TOLERANCE
    return flag


#: :func:`newton_step_judged` with the obstacle table (``newton_step_obstacles``)
newton_step_judged_obstacles = kernel_twin(newton_step_judged, "newton_step_judged_obstacles",
                                           newton_step=newton_step_obstacles)
#: :func:`control_tick` solving with the obstacle table (``cgmres_step_obstacles``): a
#: kernel of its own, so that the obstacle-free flights' compiles nothing more
control_tick_obstacles = kernel_twin(control_tick, "control_tick_obstacles",
                                     cgmres_step=cgmres_step_obstacles)
#: … and the thesis' Newton scheme's ticks (:func:`newton_step_judged`: ``step_arg`` is the
#: solver's active set), without obstacles and with
control_tick_newton = kernel_twin(control_tick, "control_tick_newton",
                                  cgmres_step=newton_step_judged)
control_tick_newton_obstacles = kernel_twin(control_tick, "control_tick_newton_obstacles",
                                            cgmres_step=newton_step_judged_obstacles)
#: the controller's call by the solver's kernel
KERNELS = {cgmres_step: control_tick, cgmres_step_obstacles: control_tick_obstacles,
           newton_step: control_tick_newton, newton_step_obstacles: control_tick_newton_obstacles}
#: the kernels whose ``step_arg`` is Newton's active set (an (N, 4) int8 array)
NEWTON_KERNELS = (control_tick_newton, control_tick_newton_obstacles)

_OK = SolverStatus.OK
_OK_TEXT = _OK._value_
_new_tuple = tuple.__new__
_UNSET = (object(),) * 9  # (ControlTick._key before its first tail: nothing is this object)


class ControlTick:
    """The Python side of :func:`control_tick` for one tick's stages (``Tick``'s), built on
    their :class:`~.before_solve.BeforeSolve` and :class:`~.after_solve.AfterSolve`."""

    #: its nominal row is cells (``Tick.step``'s ``nominal_cells``; the P controller's is
    #: its own row: ``runtime/control_tick_p``)
    cells = True

    @staticmethod
    def takes(tick) -> bool:
        """Whether the compiled call can take ``tick``'s nominal ticks: both halves can, and
        the solver is a plain C/GMRES or Newton one (not wrapped, not a subclass: their
        overrides are called) whose tick is one of :data:`KERNELS`' (with obstacles or
        without), solved by its own ``solve_prepared``
        — on a platform whose clock the kernel reads (``core/monotonic.SAME_CLOCK``: Linux;
        elsewhere the two calls around the solve, timed in Python, take the tick). A
        :class:`DivergingSolver` around such a solver is taken too: its unmarked answer is
        the inner solver's (:meth:`answer` leaves a marked tick to Python)."""
        nmpc = tick.control.nmpc
        step = _step_of(_solving(nmpc)[0])
        return (monotonic.SAME_CLOCK
                and tick.before_solve is not None and tick.after_solve is not None
                and step is not None and step[0] in KERNELS
                and tick.control._solve_prepared == nmpc.solve_prepared)

    def __init__(self, tick) -> None:
        self._stages(tick, tick.before_solve)
        # the solver that solves (its memory, its verdict), and when its answers are marked
        # (None: never)
        self.nmpc, self._marks = _solving(tick.control.nmpc)
        # the solve :meth:`takes` found the solver's own: a tick solved by another (a wrapper
        # bound later, as the two calls around the solve would call) is Python's
        self._solve = tick.control._solve_prepared
        #: the compiled call for the solver's kernel (:data:`KERNELS`) and its vetting
        self._newton = type(self.nmpc) is NewtonGMRESController
        self._step_kernel = _step_of(self.nmpc)[0]
        self.kernel = KERNELS[self._step_kernel]
        self._call = _CALLS[self.kernel]
        self._arrays_at = _ARRAYS_OF[self.kernel]  # (its array arguments' positions)

    def _stages(self, tick, before) -> None:
        """The tick's stages the call reads and writes (``before``: the stages before the
        solve's :class:`~.before_solve.BeforeSolve`), and the call's vetting and tail, not
        yet made — what every controller's compiled tick keeps (``runtime/control_tick_p``)."""
        self.before = before
        self.after = tick.after_solve
        self.control = tick.control
        self.supervisor = tick.supervisor
        self.supervision = tick.supervision
        self.delay = tick.delay
        self.offset = tick.offset
        # the kernel's call: its compiled entry point while the arrays are the ones vetted
        # for it, else the dispatcher (:meth:`_vet`)
        self._entry = None
        self._vetted: tuple = ()
        # the call's tail (:meth:`_prepare`) and the objects it was made of
        self._tail: tuple = ()
        self._key: tuple = _UNSET

    def __getstate__(self) -> dict:
        """Without what :meth:`_vet` and :meth:`_prepare` make (an entry point does not
        pickle; a copy's arrays and views are made its stages' own again on its first tick)."""
        state = self.__dict__.copy()
        state["_entry"], state["_vetted"] = None, ()
        state["_tail"], state["_key"] = (), _UNSET
        state["kernel"], state["_call"] = self.kernel.__name__, None  # (by name: KERNELS')
        return state

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        self.kernel = globals()[state["kernel"]]
        self._call = _CALLS[self.kernel]

    def nominal(self, inputs, t_exp_s: float, traj):
        """The nominal tick's feedback ages, estimate, :class:`Solution` and what the stages
        after the solve hand on: ``(sent, events)``, or False when those are Python's to take
        from the solution on (their compiled call would decline it too). Nothing done: None
        when a precondition of the call does not hold, False when the stages before the
        solve found the tick not nominal (their compiled call would decline it too)."""
        answer = self.answer(inputs, t_exp_s, traj)
        return None if answer is None else self.finish(inputs, t_exp_s, answer)

    def answer(self, inputs, t_exp_s: float, traj) -> tuple | None:
        """:func:`control_tick`'s answer for this tick (its code first), or None when a
        precondition of the call does not hold (nothing done). Its code 0 leaves the Python
        stages to write (:meth:`finish`, or ``AfterSolve.written`` for a row built from the
        answer's numbers). None too on a tick whose answer the solver's wrapper marks: the
        wrapper's own solve takes it."""
        marks = self._marks
        if marks is not None and marks(t_exp_s):
            return None
        tail = self.prepared()
        if tail is None:
            return None
        before = self.before.arguments(inputs, t_exp_s, traj)
        if before is None:
            return None
        vz_last = (float(self.supervision.vz_ref_mps) if self.control.vz_from_commands
                   else 0.0)
        call, vet = self._entry, self._vetted
        if (call is not None and before[16] is vet[0] and before[19] is vet[1]
                and before[23] is vet[2] and before[24] is vet[3] and before[25] is vet[4]
                and before[26] is vet[5] and before[27] is vet[6]):
            return call(*before, vz_last, self.delay._next, *tail)
        # the dispatcher (it looks at every argument's type), then the vetting
        self._entry = None
        args = (*before, vz_last, self.delay._next, *tail)
        answer = self.kernel(*args)
        self._vet(args)
        return answer

    def prepared(self) -> tuple | None:
        """The call's tail (:meth:`_prepare`: its arguments from the solver's memory on),
        or None when a precondition of the call that no tick's inputs change does not hold
        (nothing done): the solver past its first solve and its ramp, solved by its own
        ``solve_prepared``, trusted."""
        nmpc, control = self.nmpc, self.control
        if (nmpc._t0_s is None or nmpc._ramped  # (the first solve initialises: Python's)
                or control._solve_prepared is not self._solve
                or self.supervisor._solver_fallback):  # (check_solution's other verdicts)
            return None
        supervision = self.supervision
        horizon = control._ref_horizon if self.offset is None else control._horizon
        key = self._key  # the tail holds while what it was made of is the stages' still
        step = nmpc.newton_call if self._newton else nmpc._step
        if not (step is key[0] and horizon is key[1]
                and nmpc.divergence_residual is key[2] and control.vz_from_commands is key[3]
                and supervision.attitude_gain is key[4] and control.vz_lead_s is key[5]
                and control._vz_max_mps is key[6] and self.supervisor.max_tilt_rad is key[7]
                and supervision._scales is key[8]) and not self._prepare(horizon):
            return None
        return self._tail

    def finish(self, inputs, t_exp_s: float, answer: tuple):
        """:meth:`nominal`'s answer from :meth:`answer`'s (not None): the records of the tick
        (code 0), the solver's answer judged (SOLVED), or False (NOT_NOMINAL)."""
        (code, mocap_ms, nav_ms, flag, solve_us, norm, gmres_it, newton_it, zacc, phi, theta,
         rate, vz, roll, pitch, gaz, yaw, bits, fed) = answer
        if code == NOT_NOMINAL:
            return False
        control = self.control
        x = self.before.estimation._x
        # (the pending window the call was given: nothing between wrote it)
        x_solve = control._x_solve if self.delay.count else x
        if code:  # SOLVED: the solver's answer judged as solve_prepared judges it, on the
            # horizon the call was given (the one its prepared tail is of: answer's key) —
            # from the kernel's own flag (a Newton tick above its tolerance: FLAG_OK)
            if flag == FLAG_ABOVE_TOLERANCE:
                flag = FLAG_OK
            result = self.nmpc.judged(t_exp_s, x_solve, self._key[1], flag, solve_us, False)
            return ((mocap_ms, nav_ms), x,
                    control.solution(control._ref_now, x_solve, result, control._ref_horizon),
                    False)
        sent, events = self.after._records(inputs.t_s, zacc, phi, theta, rate, vz, roll, pitch,
                                           gaz, yaw, bits, fed)
        u = sent.u  # the input solved and sent (read-only): the result's own
        result = _new_tuple(SolveResult, (u, _OK, norm, gmres_it, solve_us, newton_it, False))
        sol = _new_tuple(Solution, (control._ref_now, x_solve, result, u, True, _OK_TEXT, None,
                                    control._ref_horizon))
        return (mocap_ms, nav_ms), x, sol, (sent, events)

    def _prepare(self, horizon) -> bool:
        """The call's tail (:func:`control_tick`'s arguments from the solver's memory on)
        from the stages' objects now — the solver's memory, ``horizon``, the settings
        (``AfterSolve.settings``), the after-stages' buffers —, kept with the objects it was
        made of: :meth:`nominal` takes it while each is still the stages' (the same object:
        the same value, already vetted), and makes it again when a writer has replaced one.
        False (nothing kept) when a precondition of the call does not hold."""
        nmpc, control, supervision, after = self.nmpc, self.control, self.supervision, self.after
        # read first: the settings are of these objects (and their class tested by settings)
        key = (_step_of(nmpc), horizon, nmpc.divergence_residual, control.vz_from_commands,
               supervision.attitude_gain, control.vz_lead_s, control._vz_max_mps,
               self.supervisor.max_tilt_rad, supervision._scales)
        settings = after.settings()
        if settings is None:
            return False
        gain, lead, vz_max, tilt_cap, e, v, y = settings
        step, mem, iprm, step_arg = key[0][0], key[0][1], key[0][2], _step_arg(key[0])
        if step is not self._step_kernel:  # (another kernel bound since: not the call's)
            return False
        offset, flags = after._offset
        self._tail = (mem, iprm, horizon, step_arg, key[2], key[3], lead, vz_max, tilt_cap, gain,
                      e, v, y, after._response_state, 1, offset, flags)
        self._key = key
        self._entry = None  # the tail's arrays vetted on the next call
        return True

    def _vet(self, args: tuple) -> None:
        """After a call through the dispatcher: the kernel's entry point for float numbers
        (each number made a float64, an int64 or a truth by its unboxing: the same value —
        not the kinds of this call's numbers, whose entry point would unbox a later tick's
        float heading by ``int()`` after an int one here), kept with the arrays of the call
        if each is of the one kind it is compiled for (``VettedCall.entry_for``); else the
        dispatcher stays (asked again next call). The tail's arrays are checked by
        :meth:`nominal`'s test of what the tail was made of (a new tail: vetted again)."""
        entry = self._call.entry_for(*(args[i] for i in self._arrays_at))  # (None: not yet)
        if entry is not None:
            self._entry = entry
            self._vetted = tuple(args[i] for i in (16, 19, 23, 24, 25, 26, 27))


def _step_of(solver) -> tuple | None:
    """``(kernel, memory, settings[, active set])`` of ``solver``'s tick — a plain
    :class:`CGMRESController`'s bound call (``kernel(memory, x, ref, settings, initialise)``)
    or a plain :class:`NewtonGMRESController`'s (``…, active)``) —, None for any other
    (another class's tick, or an override, is its own)."""
    if type(solver) is CGMRESController:
        return solver._step
    if type(solver) is NewtonGMRESController:
        return solver.newton_call
    return None


def _step_arg(step: tuple):
    """:func:`control_tick`'s ``step_arg`` for the solver's call ``step`` (:func:`_step_of`):
    ``initialise`` False for C/GMRES' usual tick, Newton's active set."""
    return step[3] if len(step) > 3 else False


def _solving(nmpc) -> tuple:
    """``(the solver that solves, when its answers are marked)`` of the control stage's
    ``nmpc``: a :class:`DivergingSolver`'s inner solver and its ``marks``, else ``nmpc``
    itself and None (nothing marked)."""
    if type(nmpc) is DivergingSolver:
        return nmpc.inner, nmpc.marks
    return nmpc, None


# :func:`control_tick`'s array arguments (position: dimensions, dtype)
_F8, _I8, _B1 = np.dtype(np.float64), np.dtype(np.int64), np.dtype(np.bool_)
_ARRAYS = {16: (1, _F8), 17: (1, _F8), 19: (2, _F8), 23: (1, _F8), 24: (1, _F8),
           25: (2, _F8), 26: (1, _F8), 27: (2, _F8), 30: (1, _F8), 31: (1, _I8), 32: (2, _F8),
           43: (1, _F8), 45: (1, _F8), 46: (2, _B1)}
# … and its numbers' kinds (:func:`warm_up_kernels`' call's; None: an array): before_solve's,
# then the ż base, the ring's row, step_arg, the divergence residual, vz_from_commands, lead
# and limit, the tilt cap, the gain, E, V, Y, has_nav
_NUMBERS = (*_BEFORE_NUMBERS, 0.0, 0, None, None, None, False, 0.0, False, 0.0, 0.0, 0.0, 0.0,
            0.0, 0.0, 0.0, None, 0, None, None)
assert len(_BEFORE_NUMBERS) == _N_BEFORE and len(_NUMBERS) == 47
_STEP_ARG = 33  # (``step_arg``: Newton's active set an array, C/GMRES' initialise a truth)


def _arrays(kernel) -> dict:
    """``kernel``'s array arguments (position: dimensions, dtype; in positions' order)."""
    if kernel not in NEWTON_KERNELS:
        return _ARRAYS
    return dict(sorted({**_ARRAYS, _STEP_ARG: (2, np.dtype(np.int8))}.items()))


def _kinds(kernel) -> tuple:
    arrays = _arrays(kernel)
    return tuple(ArrayKind(*arrays[i]) if i in arrays else k for i, k in enumerate(_NUMBERS))


#: the array arguments' positions, by kernel (``ControlTick._vet``)
_ARRAYS_OF = {kernel: tuple(_arrays(kernel)) for kernel in KERNELS.values()}
_KINDS = _kinds(control_tick)
_CALLS = {kernel: VettedCall(kernel, *_kinds(kernel)) for kernel in KERNELS.values()}


def warm_up_kernels(kernel=control_tick) -> None:
    """Load (or compile) ``kernel`` (:func:`control_tick`, or its twin of :data:`KERNELS`)
    now — once per process —, its callees from the cache first
    (``core/kernel_cache.first_warm_up``), not on the first tick aloft: a call of the kinds a
    tick's is, on a battery below any floor (not nominal at its first test: nothing runs,
    nothing is written)."""
    if not first_warm_up(kernel):
        return
    f8 = np.zeros(1)
    step_arg = np.zeros((1, NU), np.int8) if kernel in NEWTON_KERNELS else False
    kernel(1.0, 1.0, 1.0, 0, -math.inf, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, False,
                 0.0, 0.0, f8, np.zeros(L_SIZE), 0.0, np.zeros((2, 4)), 0, 0, 0.0, f8, f8,
                 np.zeros((1, STATE_DIM)), f8, np.zeros((1, 1)), 0.0, 0, f8,
                 np.zeros(6, np.int64), np.zeros((1, STATE_DIM)), step_arg, 1.0, False, 0.065, 0.7,
                 0.3, 1.0, 1.0, 1.0, 1.0, f8, 1, f8, np.zeros((3, 0), np.bool_))


flush_stale_caches(__name__)  # kernels calling other files: core/kernel_cache.py
