"""The control tick — the one function ``simulate``, ``fly`` and ``replay`` share.

Per tick: measurements (newest mocap pose, newest navdata, newest pose of a second object) →
state estimate → delay prediction → NMPC (or the thesis' P controller) → the supervisor's
verdict → PCMD fractions, and one log row. The stages live in :mod:`ardrone_nmpc.runtime.stages`;
this module chains them. The caller owns the clock and the links: :meth:`Tick.step` only
needs what arrived and when.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Callable

from ardrone_nmpc.control.mapping import DroneLimits, PcmdCommand, command_scales
from ardrone_nmpc.control.ocp import SolverStatus
from ardrone_nmpc.core.kernel_cache import load_cached
from ardrone_nmpc.core.types import IU_PHI, IU_PSIRATE, IU_THETA, TickInputs, slot_init
from ardrone_nmpc.reference.experiment import HoldStartThen
from ardrone_nmpc.reference.live import LiveTarget
from ardrone_nmpc.reference.trajectories import Trajectory
from ardrone_nmpc.runs.log_columns import nominal_cells, tick_cells, tick_row
from ardrone_nmpc.runtime.after_solve import SATURATED_TEXT, AfterSolve
from ardrone_nmpc.runtime.after_solve import warm_up_kernels as warm_up_after_solve
from ardrone_nmpc.runtime.before_solve import BeforeSolve
from ardrone_nmpc.runtime.before_solve import warm_up_kernels as warm_up_before_solve
from ardrone_nmpc.runtime.control_tick import ControlTick
from ardrone_nmpc.runtime.control_tick import warm_up_kernels as warm_up_control_tick
from ardrone_nmpc.runtime.control_tick_p import PControlTick, control_tick_p
from ardrone_nmpc.runtime.p_tick import warm_up_kernels as warm_up_p_tick
from ardrone_nmpc.runtime.stages import (
    HOVER, OBSTACLE_VELOCITY_FILTER_S, Control, DelayPrediction, Estimation, MovingObstacles,
    OffsetFree, ResponseEstimation, Supervision, feedback_ages_ms, navdata_velocity_world,
)
from ardrone_nmpc.runtime.tick_kernels import warm_up_kernels as warm_up_tick_kernels
from ardrone_nmpc.safety import NOMINAL, Action, Supervisor

__all__ = ["HOVER", "OBSTACLE_VELOCITY_FILTER_S", "Tick", "TickOutput",
           "effective_controller", "navdata_velocity_world"]

_CONTROL = Action.CONTROL  # bound once: an enum member's lookup costs ~0.1 µs
_OK_TEXT = SolverStatus.OK._value_  # the nominal row's solver_status
_perf_counter_ns = time.perf_counter_ns


@slot_init  # one a tick (core/types.py)
@dataclass(frozen=True, slots=True)
class TickOutput:
    """The command to send, the log row of the tick and the supervisor's verdict.

    ``progressive`` False means "hover" (AT*PCMD flag 0: the drone holds position itself).
    ``action`` tells the runner what else to do: :attr:`Action.LAND` — land now;
    :attr:`Action.STOP` — the drone is in emergency: stop the loop and report. ``events`` are
    the supervisor's mode changes of this tick, for ``events.jsonl``. ``cells``: the row as
    its cells in ``LOG_COLUMNS`` order (:func:`~ardrone_nmpc.runs.log_columns.tick_cells`),
    only from a tick whose :attr:`Tick.cell_rows` is set, and then ``row`` is None.
    """

    pcmd: PcmdCommand
    progressive: bool
    row: dict | None
    action: Action = Action.CONTROL
    events: list = field(default_factory=list)
    cells: list | None = None


def effective_controller(controller, limits: DroneLimits):
    """``controller`` with its input box intersected with what the drone is configured to do.

    The thesis bounds φ, θ and ψ̇ by ±1 (rad, rad/s), but the AR.Drone clips tilt to
    ``euler_angle_max`` (0.21 rad by default) and yaw rate to ``control_yaw``: planning beyond
    them plans the impossible, and every command then saturates behind the command delay.
    The NMPC plans roll and pitch up to ``planned_tilt_frac`` of ``euler_angle_max`` only: a
    drone that tilts less per unit command (``attitude_gain`` divides it out) still reaches it,
    one that tilts more stays under ``safety.max_tilt_rad`` before its gain is measured
    (docs/solver-notes.md §10).
    """
    lo = list(controller.u_min)
    hi = list(controller.u_max)
    tilt = limits.euler_angle_max_rad * controller.planned_tilt_frac
    for j, cap in ((IU_PHI, tilt), (IU_THETA, tilt), (IU_PSIRATE, limits.control_yaw_radps)):
        lo[j], hi[j] = max(lo[j], -cap), min(hi[j], cap)
    return controller.model_copy(update={"u_min": tuple(lo), "u_max": tuple(hi)})


def _p_tick_ready(tick, compile_now: bool) -> bool:
    """The P controller's compiled tick takes ``tick``'s (``PControlTick.takes``) and has
    machine code — numba's cache holds it, or ``compile_now`` (then its warm-up compiles it,
    as the NMPC's): the lockstep runner's first P flight on an empty cache flies ``p_tick``'s
    one call a tick (the same rows) and leaves the compile to the background block compile
    (``runtime/precompile``: ``lockstep.warm_up_blocks``), not to its start."""
    return PControlTick.takes(tick) and (compile_now or load_cached(control_tick_p))


class Tick:
    """The stages of one experiment's tick, with their state.

    Parameters
    ----------
    cfg : ExperimentConfig.
    trajectory : the experiment's reference (time 0 = experiment start); a
        :class:`~ardrone_nmpc.reference.live.LiveTarget` (kind ``follow``) is fed the second
        object's pose every tick.
    wrap_solver : what the runner wraps the NMPC solver in (a simulation's injected
        divergence, :class:`~ardrone_nmpc.control.diverging.DivergingSolver`); None: nothing.
    compile_now : compile the P controller's compiled tick now if numba's cache lacks it
        (False: the lockstep runner's, when a background compile makes it: ``_p_tick_ready``).
    """

    def __init__(self, cfg, trajectory: Trajectory, *,
                 wrap_solver: Callable | None = None, compile_now: bool = True):
        self.cfg = cfg
        self.trajectory = trajectory
        #: Hand the usual NMPC tick's row as cells in column order (``TickOutput.cells``, no
        #: dict): the lockstep runner's recorder takes them as they are.
        self.cell_rows = False
        self.period_s = cfg.loop.period_s
        self.limits = command_scales(cfg.drone)  # the command at PCMD ±1
        ctl = cfg.controller
        nmpc = None
        if ctl.kind == "nmpc":
            from ardrone_nmpc.control.solver import make_nmpc

            nmpc = make_nmpc(effective_controller(ctl, self.limits), period_s=self.period_s)
            if wrap_solver is not None:
                nmpc = wrap_solver(nmpc)
        self.supervisor = Supervisor(cfg.safety)
        self.follow = trajectory if isinstance(trajectory, LiveTarget) else None
        self.estimation = Estimation(cfg.estimator)
        adapt = ctl.adaptation
        auto_delay = ctl.delay_compensation_s == "auto"
        self.delay = DelayPrediction(adapt.delay_prior_s if auto_delay
                                     else ctl.delay_compensation_s, self.period_s,
                                     max_delay_s=adapt.delay_max_s if auto_delay else 0.0)
        self.control = Control(cfg, self.limits, nmpc, self.delay)
        # the attitude gain divides the NMPC's commands (its model's tilt per unit command is
        # the nominal one); the P controller's gains are chosen on the plant (eq. 4.16)
        auto_gain = ctl.attitude_gain == "auto" and nmpc is not None
        gain = (adapt.gain_prior if auto_gain else
                1.0 if nmpc is None else ctl.attitude_gain)
        self.supervision = Supervision(self.supervisor, self.limits, gain)
        # the flight's own delay and gain, for what is 'auto' (docs/solver-notes.md §10)
        self.response = (ResponseEstimation(ctl, self.limits, self.delay, self.supervision,
                                            auto_gain=auto_gain)
                         if auto_delay or auto_gain else None)
        self.offset = (OffsetFree(ctl.offset_free, self.period_s)
                       if nmpc is not None and ctl.offset_free.enabled else None)
        moving = [k for k, o in enumerate(ctl.obstacles) if o.mocap_object]
        ahead_s = self.delay.lead_s + ctl.obstacle_lookahead_s
        self.obstacles = (MovingObstacles(nmpc, moving, ahead_s)
                          if nmpc is not None and moving else None)
        #: The stages after the solve in one compiled call on the nominal tick (the NMPC's;
        #: the P controller's within its whole tick's call, ``runtime/control_tick_p``)
        self.after_solve = AfterSolve(self)
        #: The stages before the solve, likewise (None: the P controller's, or a flight whose
        #: estimator, reference or stages the compiled call does not take)
        self.before_solve = BeforeSolve(self) if BeforeSolve.takes(self) else None
        #: The controller's whole nominal tick — both, and the solve (or P's law) between —
        #: in one compiled call (None: a flight or solver it does not take)
        self.control_tick = (ControlTick(self) if ControlTick.takes(self) else
                             PControlTick(self) if _p_tick_ready(self, compile_now) else None)
        if nmpc is not None:  # load (or compile) the kernels now, not on the first tick aloft
            self.delay.warm_up(self.control.warm_up())
        # the stages' own (runtime/tick_kernels): those this flight calls
        waypoints = ((trajectory.__class__ is HoldStartThen
                      and trajectory.waypoint_args is not None)
                     or trajectory.__class__ is LiveTarget)  # (a table of its states)
        warm_up_tick_kernels(estimate=self.estimation.compiled,
                             nmpc=nmpc is not None and waypoints)
        if nmpc is None and waypoints:  # the P controller's tick (runtime/p_tick.py)
            warm_up_p_tick()
        if self.response is not None:  # after the solver's (runtime/precompile.py)
            self.response.warm_up()
        if nmpc is not None:  # last: its callees (the feed's) are loaded or compiled by now
            warm_up_after_solve()
        if self.before_solve is not None:  # after its callees' (tick_kernels')
            warm_up_before_solve()
        if self.control_tick is not None:  # after its callees' (the solver's, both halves)
            warm_up_control_tick(self.control_tick.kernel)

    def step(self, inputs: TickInputs, *, t_exp_s: float, mode: str = "track",
             trajectory: Trajectory | None = None, answer: tuple | None = None,
             spent_ns: int = 0) -> TickOutput:
        """One tick at experiment time ``t_exp_s`` against ``trajectory`` (default: the
        experiment's). ``mode`` labels a nominal row ("track", "settle"); the supervisor's
        verdict replaces it otherwise (module :mod:`ardrone_nmpc.safety`). ``answer``: the
        compiled controller's answer for this tick made already (``ControlTick.answer``'s,
        by a block of ticks: ``runtime/lockstep_block``), in ``spent_ns``."""
        t0 = _perf_counter_ns() - spent_ns
        traj = self.trajectory if trajectory is None else trajectory
        if self.follow is not None:  # reference kind 'follow': the object's newest pose
            target_age_s = inputs.t_s - inputs.target_rx_t_s
            self.follow.observe(inputs.target, t_pose_s=t_exp_s - target_age_s,
                                age_ms=target_age_s * 1e3)
        if self.obstacles is not None and inputs.target is not None:
            self.obstacles.update(inputs.target)
        sup = self.supervisor
        # the nominal tick: the controller in one compiled call (None, False: not nominal;
        # False: the two calls around the solve would not take it either)
        whole = None
        ct = self.control_tick
        if ct is not None:
            if answer is None:
                answer = ct.answer(inputs, t_exp_s, traj)
            if answer is not None:
                if not answer[0] and self.cell_rows and inputs.target is None and ct.cells:
                    return self._nominal_cells(inputs, t_exp_s, mode, answer, t0)
                whole = ct.finish(inputs, t_exp_s, answer)
        if whole:
            ages_ms, x, solution, done = whole  # (done False: the stages after, in Python)
            decision = NOMINAL
        else:
            before = self.before_solve if whole is None else None
            # the stages up to the solve in one compiled call (None: not nominal)
            done = before.nominal(inputs, t_exp_s, traj) if before is not None else None
            if done is not None:
                ages_ms, x, solution = done
                decision = NOMINAL
            else:
                ages_ms, decision, x, solution = self._before(inputs, t_exp_s, traj)
            done = None
        cmd = None
        if not done and solution is not None:  # the verdict was CONTROL: it solved
            if done is None and solution.result is not None and self.after_solve is not None:
                # the nominal tick: the stages below in one compiled call (None: not nominal)
                done = self.after_solve.nominal(inputs, x, solution)
            if not done:
                if solution.result is not None:  # the NMPC's answer is judged; P's is not
                    decision = sup.check_solution(solution.ok, solution.u_flown)
                cmd = self.control.command(decision.action, solution, x,
                                           self.supervision.vz_ref_mps)
        sent, adapted = done if done else self._after(inputs, decision, x, solution, cmd)
        verdict = sent.decision
        label = sup.record(verdict, mode)  # (the usual tick: its nominal case, noting nothing)
        compute_us = (_perf_counter_ns() - t0) * 1e-3
        # a list of its own (extended, not copied); the usual tick has none to take
        events = sup.take_events() if sup.events else []
        if adapted:
            events += adapted
        if self.cell_rows:  # (positional: the same arguments as tick_row's, in its order)
            cells = tick_cells(t_exp_s, inputs, ages_ms, x, solution, sent, label, compute_us)
            if cells is not None:
                return TickOutput.make(sent.pcmd, sent.progressive, None, verdict.action,
                                       events, cells)
        row = tick_row(t_exp_s=t_exp_s, inputs=inputs, ages_ms=ages_ms, x=x, solution=solution,
                       sent=sent, mode=label, compute_us=compute_us)
        return TickOutput.make(sent.pcmd, sent.progressive, row, verdict.action, events)

    def _nominal_cells(self, inputs: TickInputs, t_exp_s: float, mode: str, answer: tuple,
                       t0: int) -> TickOutput:
        """:meth:`step`'s rest on a tick the compiled call did whole (code 0) whose row is
        cells (``tick_cells``' usual row: no target): the Python stages' state written
        (``AfterSolve.written``), the row built from the answer's numbers — not from the
        ``Sent``, ``Solution`` and ``SolveResult`` :meth:`ControlTick.finish` makes for a row
        that reads them (the same values: the input sent is the one solved)."""
        (_, mocap_ms, nav_ms, _, solve_us, norm, gmres_it, newton_it, zacc, phi, theta, rate,
         vz, roll, pitch, gaz, yaw, bits, fed) = answer
        pcmd, _, adapted = self.after_solve.written(inputs.t_s, zacc, phi, theta, rate, vz,
                                                    roll, pitch, gaz, yaw, bits, fed)
        sup = self.supervisor
        label = sup.record(NOMINAL, mode)
        compute_us = (_perf_counter_ns() - t0) * 1e-3
        events = sup.take_events() if sup.events else []
        if adapted:
            events += adapted
        ct = self.control_tick
        cells = nominal_cells(t_exp_s, ct.before.estimation._x, ct.control._ref_now, zacc, phi,
                              theta, rate, vz, pcmd, SATURATED_TEXT[bits], solve_us,
                              _OK_TEXT, norm, gmres_it, newton_it, label, mocap_ms, nav_ms,
                              inputs.navdata, compute_us, inputs.pose.t_s)
        return TickOutput.make(pcmd, True, None, _CONTROL, events, cells)

    def _before(self, inputs: TickInputs, t_exp_s: float, traj: Trajectory) -> tuple:
        """The stages up to the solve, one by one (every tick the compiled call did not take,
        ``runtime/before_solve``): the feedback's ages, the verdict, the estimate and the
        controller's solution (None unless the verdict is to control)."""
        sup = self.supervisor
        ages_ms = feedback_ages_ms(inputs)
        decision = sup.check_feedback(mocap_age_ms=ages_ms[0], navdata_age_ms=ages_ms[1],
                                      navdata=inputs.navdata)
        x = solution = None
        if inputs.pose is not None:  # estimated even when stale (the row logs it)
            x = self.estimation.update(inputs.pose, inputs.navdata, self.supervision.zacc_mps2)
        if decision.action is _CONTROL:
            decision = sup.check_state(x, inputs.navdata)
        if decision.action is _CONTROL:
            solution = self.control.solve(t_exp_s, x, traj, self.offset)
        return ages_ms, decision, x, solution

    def _after(self, inputs: TickInputs, decision, x, solution, cmd) -> tuple:
        """The stages after the verdict, one by one (every tick the compiled call did not
        take, ``runtime/after_solve``): the command sent, and the response fit's events."""
        sent = self.supervision.command(
            decision, cmd, solution.zacc_mps2 if solution is not None else math.nan)
        self.delay.push(sent.u)
        adapted = self.response.update(inputs, sent) if self.response is not None else []
        if self.offset is not None:  # integrates after the verdict: frozen unless flown
            self.offset.update(x, solution, sent)
        return sent, adapted
