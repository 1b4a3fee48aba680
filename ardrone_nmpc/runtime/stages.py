"""The stages of one control tick, each a small object that can be built and tested alone.

:class:`~ardrone_nmpc.runtime.tick.Tick` chains them (docs/architecture.md, "one tick"):
estimation → delay prediction → control → supervision → row, with the moving obstacles fed
from the second tracked object first. Each stage owns the state that carries over from one tick
to the next — the estimators, the inputs sent but not yet acting, the NMPC warm start, the
last command sent — and nothing else; the log row is built from their results by
:func:`~ardrone_nmpc.runs.log_columns.tick_row`. The estimation stage lives in
:mod:`ardrone_nmpc.runtime.estimate`, the supervision stage in
:mod:`ardrone_nmpc.runtime.supervision`; both are re-exported here.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ardrone_nmpc.control.kernels import rollout_rk4
from ardrone_nmpc.control.mapping import DroneLimits, vz_reference_mps
from ardrone_nmpc.control.obstacles import OBS_X, OBS_Z
from ardrone_nmpc.control.ocp import SolveResult, SolverStatus
from ardrone_nmpc.control.proportional import PGains, p_control
from ardrone_nmpc.core.types import (
    INPUT_DIM, IU_PHI, IU_PSIRATE, IU_THETA, IU_ZACC, IX_PSI, IX_VZ, IX_Z, STATE_DIM,
    AttitudeCommand, MocapPose, TickInputs,
)
from ardrone_nmpc.estimation.attitude_response import AttitudeResponseEstimator, warm_up_kernels
from ardrone_nmpc.estimation.response_kernels import CMD_RESTART, CMD_SEND
from ardrone_nmpc.estimation.disturbance import ReferenceIntegrator, frozen_axes
from ardrone_nmpc.reference.experiment import HoldStartThen
from ardrone_nmpc.reference.live import LiveTarget, TrackedObject
from ardrone_nmpc.runtime.estimate import Estimation, navdata_velocity_world
from ardrone_nmpc.runtime.p_tick import p_tick, p_work
from ardrone_nmpc.runtime.supervision import HOVER, Sent, Supervision
from ardrone_nmpc.runtime.tick_kernels import (fill_reference_table, nmpc_inputs, nmpc_work,
                                               nmpc_work_views)
from ardrone_nmpc.safety import Action

__all__ = ["HOVER", "OBSTACLE_VELOCITY_FILTER_S", "Control", "DelayPrediction", "Estimation",
           "MovingObstacles", "OffsetFree", "ResponseEstimation", "Sent", "Solution", "Supervision",
           "feedback_ages_ms", "navdata_velocity_world"]

OBSTACLE_VELOCITY_FILTER_S = 0.2  # first-order filter of a moving obstacle's velocity (s)

# enum members bound once: ``Action.CONTROL`` is a lookup through the enum's metaclass
# (~0.1 µs), and the tick makes a dozen
_CONTROL, _FALLBACK = Action.CONTROL, Action.FALLBACK
_OK, _MAX_ITERATIONS = SolverStatus.OK, SolverStatus.MAX_ITERATIONS
_NO_SHIFT = np.zeros(0)  # nmpc_inputs: no offset-free shift
_ALL_FROZEN = (True, True, True, True)  # OffsetFree: no axis integrates
_F64 = np.dtype(np.float64)
_X_SHAPE = (STATE_DIM,)
_REF_SHAPE = (1, STATE_DIM)
# a Solution from all its fields without the NamedTuple's Python ``__new__`` (a frame a tick)
_new_tuple = tuple.__new__


# ----------------------------------------------------------------------------- delay
class DelayPrediction:
    """The inputs sent but not yet acting, and the state they lead to.

    Parameters
    ----------
    delay_s : the command delay to compensate (s); rounded up to whole ticks.
    period_s : control period (s).
    max_delay_s : the largest delay :meth:`set_delay_s` may set later (s): the inputs sent
        over that span are kept.

    Attributes read every tick (kept by :meth:`push` and :meth:`set_delay_s`, no call):
    ``lead_s``, how far ahead of the measurement the next command takes effect (s);
    ``ring``, ``first``, ``count``: :meth:`pending`'s answer.
    """

    def __init__(self, delay_s: float, period_s: float, *, max_delay_s: float = 0.0) -> None:
        self.period_s = period_s
        self.delay_ticks = math.ceil(delay_s / period_s - 1e-9)
        capacity = max(self.delay_ticks, math.ceil(max_delay_s / period_s - 1e-9), 1)
        # the inputs sent, a ring written twice (rows i and i + capacity): the last
        # ``capacity`` are always one slice, oldest first; zeros (hover) before the first
        self._capacity = capacity
        self._sent = self.ring = np.zeros((2 * capacity, INPUT_DIM))
        self._bind_pairs()
        self._next = 0  # the row the next input goes to
        self._pushed = False
        # what pending() answers, kept by push and set_delay_s: the control stage reads
        # them every tick without a call (µs a tick)
        self.lead_s = self.delay_ticks * period_s
        self.first = self.count = 0

    def _bind_pairs(self) -> None:
        # rows i and i + capacity as one (2, 4) view each: a push is one assignment, not two
        capacity = self._capacity
        self._pairs = [self._sent[i::capacity] for i in range(capacity)]

    def __setstate__(self, state: dict) -> None:
        """A deep copy or unpickling: numpy copies each view apart from its array, so the
        pairs a push writes are made views of the copied ring again (else the copy's pushes
        would never reach the inputs it predicts from)."""
        self.__dict__.update(state)
        self._bind_pairs()

    def set_delay_s(self, delay_s: float) -> bool:
        """Compensate ``delay_s`` from now on, to the nearest whole tick (at most the
        capacity); True if the ticks changed."""
        ticks = min(max(int(round(delay_s / self.period_s)), 0), self._capacity)
        changed = ticks != self.delay_ticks
        self.delay_ticks = ticks
        self.lead_s = ticks * self.period_s
        self._note_pending()
        return changed

    def push(self, u_sent: np.ndarray) -> None:
        """Note the (4,) input just sent (zeros for a hover)."""
        self._pairs[self._next][...] = u_sent  # rows i and i + capacity
        self._advance()

    def _advance(self) -> None:
        """The ring's next row, and the pending window, after a row was written (by
        :meth:`push`, or by the nominal tick's compiled call, ``runtime/after_solve``)."""
        i = self._next + 1
        capacity = self._capacity
        self._next = i = 0 if i == capacity else i  # (i + 1) % capacity
        n = self.count
        if n:  # the pending window moves one row: _note_pending's, without its frame
            self.first = i + capacity - n
        elif not self._pushed:  # the first input sent: something is pending from now on
            self._pushed = True
            self._note_pending()

    def _note_pending(self) -> None:
        n = self.delay_ticks
        if n == 0 or not self._pushed:
            self.first = self.count = 0
        else:
            self.first, self.count = self._next + self._capacity - n, n

    def pending(self) -> tuple[np.ndarray, int, int]:
        """The ring of inputs sent, and the first row and number of those still pending
        (:meth:`predict`'s rollout; 0 when it returns ``x`` itself), for a compiled caller
        (also :attr:`first` and :attr:`count`)."""
        return self._sent, self.first, self.count

    def predict(self, x: np.ndarray) -> np.ndarray:
        """``x`` rolled forward through the pending inputs (model eq. 3.13, RK4 per control
        period) — the state the new command will meet; ``x`` itself if nothing is pending."""
        n = self.delay_ticks
        if n == 0 or not self._pushed:
            return x
        out = np.empty(STATE_DIM)
        end = self._next + self._capacity  # the newest is the row before
        rollout_rk4(x, self._sent[end - n:end], self.period_s, out)
        return out

    def warm_up(self, x: np.ndarray) -> None:
        """Load (or compile) the rollout kernel now, not on the first tick in the air."""
        if self.delay_ticks:
            rollout_rk4(x, self._sent[:self.delay_ticks], self.period_s, np.empty(STATE_DIM))


# ----------------------------------------------------------------------------- obstacles
class MovingObstacles:
    """Obstacles centred on the second tracked object, moved in the NMPC every tick.

    The centre is the object's position predicted at its estimated (filtered) velocity by
    ``ahead_s`` — to the moment the command takes effect (the state the NMPC solves from is
    predicted there too) plus ``controller.obstacle_lookahead_s``; over the horizon it is held.

    Parameters
    ----------
    nmpc : the solver (``obstacles`` array and ``move_obstacles(centres_m)``).
    indices : rows of ``nmpc.obstacles`` that move.
    ahead_s : prediction time (s).
    """

    def __init__(self, nmpc, indices: list[int], ahead_s: float) -> None:
        self.nmpc = nmpc
        self.indices = indices
        self.ahead_s = ahead_s
        self.track = TrackedObject(OBSTACLE_VELOCITY_FILTER_S)

    def update(self, pose: MocapPose) -> None:
        track = self.track
        track.update(pose, pose.t_s)
        centres = self.nmpc.obstacles[:, OBS_X:OBS_Z + 1].copy()
        centres[self.indices] = track.position_m + track.velocity_mps * self.ahead_s
        self.nmpc.move_obstacles(centres)


# ----------------------------------------------------------------------------- control
class Solution(NamedTuple):
    """What the controller computed in one tick (logged whether or not it is flown); a
    NamedTuple: built every tick, ~3× cheaper than a frozen dataclass.

    ``result`` is None for the P controller, whose command is ``p_command``. ``u_flown`` is
    the NMPC input the supervisor judges, ``ok`` whether the solver may be trusted,
    ``status`` the ``solver_status`` column.
    """

    ref_now: np.ndarray
    x_solve: np.ndarray
    result: SolveResult | None = None
    u_flown: np.ndarray | None = None
    ok: bool = True
    status: str = ""
    p_command: AttitudeCommand | None = None
    ref_horizon: np.ndarray | None = None

    @property
    def zacc_mps2(self) -> float:
        """The NMPC's z̈ as solved (m/s²); NaN for the P controller."""
        return math.nan if self.result is None else self.result.u.item(IU_ZACC)


class Control:
    """NMPC or the thesis' P controller, and the attitude command of a verdict.

    Parameters
    ----------
    cfg : ExperimentConfig (``controller``, ``estimator.kind``, ``safety``, ``loop``).
    limits : what the drone is configured to do (mapping and ż clipping).
    nmpc : the solver (None: the P controller flies).
    delay : the delay predictor the NMPC solves from.
    """

    def __init__(self, cfg, limits: DroneLimits, nmpc, delay: DelayPrediction) -> None:
        ctl = cfg.controller
        self.nmpc = nmpc
        self.delay = delay
        self.limits = limits
        g = ctl.p_gains
        self.p_gains = PGains(g.k1_per_s, g.k2_rad_per_mps, g.k3_rad_per_mps, g.k4_per_s)
        self.vz_lead_s = ctl.vz_lead_s if ctl.vz_lead_s is not None else cfg.loop.period_s
        self.vz_from_commands = cfg.estimator.kind == "none"
        self.accept_max_iterations = cfg.safety.solver_accept_max_iterations
        self._vz_max_mps = limits.control_vz_max_mps
        self._p_args: tuple | None = None  # the waypoint_args _p_work was made of
        self._p_work: tuple | None = None  # p_tick's work and rows (None: Python's path)
        if nmpc is None:  # the P controller's compiled nominal tick's (runtime/control_tick_p):
            # the reference now (its Solution's: overwritten by the next tick) and a state
            # it does not predict (no input pending in its lookup)
            self._x_solve = np.empty(STATE_DIM)
            self._states = np.empty(_REF_SHAPE)
            self._ref_now, self._ref_horizon = self._states[0], self._states[1:]
        else:
            self._stage_index = np.arange(nmpc.spec.horizon_steps + 1, dtype=np.float64)
            self._offsets = np.zeros(nmpc.spec.horizon_steps + 2)
            self._offsets_dtau = math.nan  # the Δτ _offsets were made with
            self._states_shape = (self._offsets.size, STATE_DIM)
            # the one-call lookup's buffers and parameters (the offsets, its times and their
            # clamp at 0, the shifted horizon — read by the solver within the tick only —, the
            # period, the trajectory's arrays): two arrays, made at the first solve against
            # a waypoint trajectory (_pack)
            self._work: np.ndarray | None = None
            self._rows: np.ndarray | None = None
            self._work_args: tuple | None = None  # the waypoint_args it holds
            self._horizon: np.ndarray | None = None
            # the fast path's answer — the predicted state, and the reference now and over
            # the horizon (one array, its two views) —: the stage's own, overwritten by the
            # next solve like the estimate it solves from (the tick reads its Solution within
            # the tick, the log takes values): two allocations and two views less a tick
            self._x_solve = np.empty(STATE_DIM)
            self._states = np.empty(self._states_shape)
            self._ref_now, self._ref_horizon = self._states[0], self._states[1:]
            self._dtau_varies = True  # until the first solve asks the solver
            # the fast path's solve: without the checks its arrays pass by construction (a
            # solver without it solves with them)
            self._solve_prepared = getattr(nmpc, "solve_prepared", None) or getattr(
                nmpc, "solve", None)

    def __setstate__(self, state: dict) -> None:
        """A deep copy or unpickling: numpy copies each view apart from its array, so the
        views the fast path reads or writes — the reference now and over the horizon of
        ``_states``, the offsets and shifted horizon of ``_work`` — are made views of the
        copied arrays again (else the copy would log and solve against stale arrays)."""
        self.__dict__.update(state)
        self._ref_now, self._ref_horizon = self._states[0], self._states[1:]
        if self.nmpc is None:
            return
        if self._work is not None:
            self._offsets, _, _, self._horizon = nmpc_work_views(self._work)

    def warm_up(self) -> np.ndarray:
        """Load (or compile) the solver kernels now; returns the hover state it solved at."""
        hover = np.zeros(STATE_DIM)
        hover[IX_Z] = 1.0
        self.nmpc.solve(0.0, hover, np.tile(hover, (self.nmpc.spec.horizon_steps + 1, 1)))
        self.nmpc.reset()
        return hover

    def solve(self, t_exp_s: float, x: np.ndarray, traj, offset: OffsetFree | None = None
              ) -> Solution:
        """The controller's answer at experiment time ``t_exp_s`` for the estimate ``x``;
        ``offset`` shifts the NMPC's horizon reference (offset-free tracking; ``ref_now``,
        the logged reference, stays the experiment's).

        Against a waypoint reference the answer's ``ref_now``, ``x_solve`` and
        ``ref_horizon`` are the stage's own arrays, overwritten by the next call (as the
        estimate ``x`` is): copy them to keep them; ``result`` is the answer's own."""
        if self.nmpc is None:
            return self._p_solve(t_exp_s, x, traj)
        solver = self.nmpc
        delay = self.delay
        if self._dtau_varies:
            dtau = solver.stage_dtau_s(t_exp_s)
            # one lookup for the reference at t (logged against x(t)) and over the horizon
            # that starts when this command takes effect, t + lead
            if 1e-9 > dtau:  # max(dtau, 1e-9) without the builtin's call (a NaN stays)
                dtau = 1e-9
            if dtau != self._offsets_dtau:  # [0, Δτ·i …], kept while Δτ holds
                np.multiply(dtau, self._stage_index, out=self._offsets[1:])
                self._offsets_dtau = dtau
            # a Δτ fixed for good (no horizon ramp): the offsets are made, never asked again
            self._dtau_varies = solver.fixed_dtau_s is None
        kind = traj.__class__
        args = traj.waypoint_args if kind is HoldStartThen or kind is LiveTarget else None
        if (args is not None and x.__class__ is np.ndarray and x.dtype is _F64
                and x.shape == _X_SHAPE):
            # a waypoint reference (the square) or a curve's table: the delay prediction, the
            # horizon's times, the lookup and the offset-free shift in one call
            # (runtime/tick_kernels.py), then the solve without the checks its arrays pass by
            # construction
            if args is not self._work_args:  # once a flight: its arrays into the work vector
                self._pack(args)
            if traj.tabulated:  # a curve: its states at this tick's times into the table
                fill_reference_table(traj, np.array([t_exp_s]), delay.lead_s, self._work,
                                     self._rows)
            pending = delay.count
            x_solve = self._x_solve if pending else x
            ref_horizon = self._ref_horizon  # the logged horizon, unshifted
            if offset is None:
                shift = _NO_SHIFT
                horizon = ref_horizon
            else:
                shift = offset.integrator.shift
                horizon = self._horizon
            nmpc_inputs(x, delay.ring, delay.first, pending, x_solve, t_exp_s, delay.lead_s,
                        shift, self._states, self._work, self._rows)
            return self._solved(t_exp_s, x_solve, self._ref_now, horizon, ref_horizon,
                                self._solve_prepared)
        x_solve = delay.predict(x)
        times = np.add(t_exp_s + delay.lead_s, self._offsets)  # (t + lead) + Δτ·i
        times[0] = t_exp_s
        states = traj.state_at(times)
        ref_horizon = states[1:]
        horizon = ref_horizon if offset is None else offset.integrator.shifted(ref_horizon)
        return self._solved(t_exp_s, x_solve, states[0], horizon, ref_horizon, solver.solve)

    def _p_solve(self, t_exp_s: float, x, traj) -> Solution:
        """The P controller's answer: against a waypoint reference in one compiled call
        (runtime/p_tick.py, the same bits), else ``state_at`` and ``p_control``."""
        kind = traj.__class__
        args = traj.waypoint_args if kind is HoldStartThen or kind is LiveTarget else None
        # a heading not finite: p_control's answer (its NaN's sign) or its ValueError
        if (args is not None and x.__class__ is np.ndarray and x.dtype is _F64
                and x.shape == _X_SHAPE and math.isfinite(x[IX_PSI])):
            if args is not self._p_args:  # once a flight: its arrays into the work vector
                self._p_args, self._p_work = args, p_work(self.delay.period_s, args)
            if self._p_work is not None:
                g = self.p_gains
                ref = np.empty(_REF_SHAPE)  # the Solution's own (the Python path's too)
                vz, phi, theta, rate = p_tick(x, t_exp_s, g.k1_per_s, g.k2_rad_per_mps,
                                              g.k3_rad_per_mps, g.k4_per_s, ref,
                                              *self._p_work)
                return Solution(ref[0], x, p_command=AttitudeCommand(vz, phi, theta, rate))
        ref_now = traj.state_at(t_exp_s)[0]
        return Solution(ref_now, x, p_command=p_control(x, ref_now, self.p_gains))

    def _pack(self, args: tuple) -> None:
        """:func:`~ardrone_nmpc.runtime.tick_kernels.nmpc_work` of the waypoint trajectory's
        ``args``; the offsets as they are, from now on a view of it (the general path too)."""
        work, self._rows = nmpc_work(self.delay.period_s, self._offsets.size, args)
        offsets, _, _, self._horizon = nmpc_work_views(work)
        offsets[:] = self._offsets
        self._offsets = offsets
        self._work, self._work_args = work, args

    def _solved(self, t_exp_s: float, x_solve: np.ndarray, ref_now: np.ndarray,
                horizon: np.ndarray, ref_horizon: np.ndarray, solve) -> Solution:
        """``solve``'s answer against ``horizon`` and its :class:`Solution` (``ref_now``: the
        reference now, ``ref_horizon`` the unshifted horizon)."""
        return self.solution(ref_now, x_solve, solve(t_exp_s, x_solve, horizon), ref_horizon)

    def solution(self, ref_now: np.ndarray, x_solve: np.ndarray, result: SolveResult,
                 ref_horizon: np.ndarray) -> Solution:
        """The tick's :class:`Solution` of the solver's ``result``: trusted (``ok``) when it
        solved, or stopped at its iterations and the safety config accepts that."""
        status = result.status
        ok = status is _OK or (status is _MAX_ITERATIONS and self.accept_max_iterations)
        # ``_value_``: the member's value without the enum's descriptor (µs a tick)
        return _new_tuple(Solution, (ref_now, x_solve, result, result.u, ok, status._value_,
                                     None, ref_horizon))

    def command(self, action: Action, sol: Solution, x: np.ndarray,
                vz_ref_last_mps: float) -> AttitudeCommand | None:
        """The attitude command ``action`` flies (None for hold, hover, land, stop).

        ``vz_ref_last_mps`` is the ż reference last sent: without a ż estimate the NMPC's z̈
        is integrated from it. (The nominal tick's compiled twin: ``runtime/after_solve.py``.)
        """
        if action is _FALLBACK:
            return p_control(x, sol.ref_now, self.p_gains)
        if action is not _CONTROL:
            return None
        if sol.result is None:
            return sol.p_command
        u = sol.result.u.tolist()  # Python floats: float(u[i]) without numpy's scalars
        zacc, phi, theta, rate = u[IU_ZACC], u[IU_PHI], u[IU_THETA], u[IU_PSIRATE]
        # ż reference: the estimator's (predicted) ż plus this tick's z̈ (thesis end of §4.4).
        # Without an estimate the thesis could only integrate its own z̈ commands — the
        # integrator that winds up into fig. 3.2's overshoot.
        # ``item``: a Python float (numpy's scalar costs ~3× per operation; the same double)
        vz_base = (float(vz_ref_last_mps) if self.vz_from_commands
                   else sol.x_solve.item(IX_VZ))
        vz_max = self._vz_max_mps  # the drone clips beyond: no wind-up past it
        # vz_reference_mps' arithmetic without its checks: a finite result from a lead ≥ 0
        # means every input was finite (a non-finite ż or z̈ makes it NaN or ±inf, and so
        # does an infinite lead), which is all its checks ask; otherwise it is called, to
        # answer or raise as it does
        dt = self.vz_lead_s
        vz_ref = vz_base + zacc * dt
        if not (vz_ref - vz_ref == 0.0 and dt >= 0.0):
            vz_ref = vz_reference_mps(vz_base, zacc, dt)
        # min(max(v, −vz_max), vz_max) spelled out: Python's min and max keep their first
        # argument unless the second is strictly beyond it (a NaN stays)
        if -vz_max > vz_ref:
            vz_ref = -vz_max
        if vz_max < vz_ref:
            vz_ref = vz_max
        return AttitudeCommand.make(vz_ref, phi, theta, rate)  # the record, ~50 ns cheaper


# ----------------------------------------------------------------------------- offset-free
class OffsetFree:
    """Integral action of the NMPC (``controller.offset_free``): the reference shift that
    removes a constant disturbance's steady error (:mod:`ardrone_nmpc.estimation.disturbance`).

    Updated after each tick's verdict: it integrates only on a tick the NMPC flew
    (:attr:`Action.CONTROL`) — frozen while the supervisor holds, hovers, lands, stops or falls
    back to P — and, per axis, not while the command sent sits on the drone's limits.
    """

    def __init__(self, cfg, period_s: float) -> None:
        self.integrator = ReferenceIntegrator.from_config(cfg, period_s)

    def update(self, x: np.ndarray | None, sol: Solution | None, sent: Sent) -> None:
        if x is None or sol is None:  # nothing solved: nothing to learn from
            self.integrator.learning[:] = False
            return
        p = sent.pcmd
        if sent.decision.action is _CONTROL:
            frozen = frozen_axes((p.roll_frac, p.pitch_frac, p.gaz_frac, p.yaw_frac),
                                 sent.saturated)
        else:  # frozen, but it still sees the reference move and the drone come to rest
            frozen = _ALL_FROZEN
        # x, ref_now, ref_horizon are float64 arrays: the integrator's own step, without
        # its conversions (ReferenceIntegrator.update)
        self.integrator.step(x, sol.ref_now, frozen, sol.ref_horizon)


# ----------------------------------------------------------------------------- adaptation
class ResponseEstimation:
    """The flight's own measurement of the drone's command → attitude delay and gain
    (:mod:`ardrone_nmpc.estimation.attitude_response`), and what ``auto`` makes of it: the
    delay the prediction compensates and the gain the command mapping divides by, each once
    its estimate is confident, clipped to ``controller.adaptation``'s bounds.

    Fed after each tick's verdict: the roll/pitch sent (a hover starts the window again: the
    drone's own hover is not the commands' response) and each new navdata sample, at its
    receipt time. Built only when something is ``auto`` (the summary measures every flight
    from its log).
    """

    def __init__(self, ctl, limits: DroneLimits, delay: DelayPrediction,
                 supervision: Supervision, *, auto_gain: bool) -> None:
        a = ctl.adaptation
        self.cfg = a
        self.auto_delay = ctl.delay_compensation_s == "auto"
        self.auto_gain = auto_gain  # attitude_gain auto, and an NMPC whose commands it divides
        self.delay = delay
        self.supervision = supervision
        self.limits = limits
        self.estimator = AttitudeResponseEstimator(limits.euler_angle_max_rad,
                                                   window_s=a.window_s)
        self._next_fit_s = -math.inf

    def warm_up(self) -> None:
        """Load (or compile) the streaming fit's kernels now, not on the first tick aloft
        (:class:`~ardrone_nmpc.runtime.tick.Tick` calls it after the solver's warm-up: a cold
        start's background compile has them cached by then, ``runtime/precompile.py``)."""
        warm_up_kernels()

    def update(self, inputs: TickInputs, sent: Sent) -> list[dict]:
        """Feed this tick; returns its events (a new fit, a change of what auto uses)."""
        nav = inputs.navdata
        # the sample, then the command sent (a hover restarts the window): one compiled call
        if nav is not None:  # (each a name, no tuple built and unpacked)
            t_nav, roll_deg, pitch_deg = inputs.navdata_rx_t_s, nav.roll_deg, nav.pitch_deg
        else:
            t_nav, roll_deg, pitch_deg = None, 0.0, 0.0
        if not sent.progressive:
            self.estimator.feed(t_nav, roll_deg, pitch_deg, CMD_RESTART)
            return []
        p = sent.pcmd
        self.estimator.feed(t_nav, roll_deg, pitch_deg, CMD_SEND, inputs.t_s, p.roll_frac,
                            p.pitch_frac)
        return self.refit(inputs.t_s)

    def refit(self, t_s: float) -> list[dict]:
        """After the feed of the tick at ``t_s``: the fit, once every ``refit_s``, and what
        auto makes of it; returns its events."""
        if t_s < self._next_fit_s:
            return []
        self._next_fit_s = t_s + self.cfg.refit_s
        e = self.estimator.estimate
        if not math.isfinite(e.delay_s):
            return []
        delay_confident, gain_confident = e.delay_confident, e.gain_confident  # (once)
        events = [{"kind": "attitude_estimate", "delay_s": e.delay_s,
                   "delay_std_s": e.delay_std_s, "delay_contrast": e.delay_contrast,
                   "gain": e.gain_mean,
                   "gain_std": e.gain_mean_std, "lag_s": e.lag_s, "r2": e.r2,
                   "delay_confident": delay_confident,
                   "gain_confident": gain_confident}]
        self._apply(e, delay_confident, gain_confident, events)
        return events

    def _apply(self, e, delay_confident: bool, gain_confident: bool,
               events: list[dict]) -> None:
        """What auto makes of the estimate ``e`` (and its confidences): a new delay, a new
        gain, each with its event appended to ``events``."""
        a = self.cfg
        if self.auto_delay and delay_confident:
            before = self.delay.lead_s
            if self.delay.set_delay_s(min(max(e.delay_s, a.delay_min_s), a.delay_max_s)):
                events.append({"kind": "delay_compensation", "delay_s": self.delay.lead_s,
                               "previous_s": before, "estimate_s": e.delay_s,
                               "estimate_std_s": e.delay_std_s})
        if self.auto_gain and gain_confident:
            gain = min(max(e.gain_mean, a.gain_min), a.gain_max)
            before = self.supervision.attitude_gain
            if abs(gain - before) > max(2.0 * e.gain_mean_std, 0.05 * before):
                self.supervision.attitude_gain = gain
                events.append({"kind": "attitude_gain", "gain": gain, "previous": before,
                               "estimate": e.gain_mean, "estimate_std": e.gain_mean_std})


# ----------------------------------------------------------------------------- the row
def feedback_ages_ms(inputs: TickInputs) -> tuple[float, float]:
    """Ages of the newest mocap pose and navdata at tick time (ms; inf before the first).
    (The nominal tick's compiled twin: ``runtime/before_solve.py``.)"""
    mocap = (inputs.t_s - inputs.pose_rx_t_s) * 1e3 if inputs.pose is not None else math.inf
    nav = (inputs.t_s - inputs.navdata_rx_t_s) * 1e3 if inputs.navdata is not None else math.inf
    return mocap, nav
