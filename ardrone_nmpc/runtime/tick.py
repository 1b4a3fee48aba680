"""The control tick of DESIGN.md §2 — the one function ``simulate``, ``fly`` and ``replay`` share.

Per tick: measurements (latest mocap pose, latest navdata) → state estimate (position and ψ
from mocap, ẋ/ẏ from navdata or differences, ż from the vertical-speed estimator) → horizon
reference → NMPC (or the thesis' P controller) → mapping to PCMD fractions. The caller owns
the clock and the links; :meth:`Tick.step` only needs what arrived and when.
"""

from __future__ import annotations

import math
import time
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from ardrone_nmpc.control.mapping import DroneLimits, PcmdCommand, map_to_pcmd, vz_reference_mps
from ardrone_nmpc.control.proportional import PGains, p_control
from ardrone_nmpc.estimation import BackwardDifference, make_vz_estimator
from ardrone_nmpc.reference.live import TrackedObject
from ardrone_nmpc.control.kernels import rollout_rk4
from ardrone_nmpc.control.obstacles import OBS_X, OBS_Z
from ardrone_nmpc.control.ocp import SolverStatus
from ardrone_nmpc.safety import NOMINAL, Action, Decision, Supervisor
from ardrone_nmpc.reference.trajectories import Trajectory
from ardrone_nmpc.core.types import AttitudeCommand, MocapPose, NavdataSample

OBSTACLE_VELOCITY_FILTER_S = 0.2  # first-order filter of a moving obstacle's velocity (s)
HOVER = PcmdCommand(0.0, 0.0, 0.0, 0.0, (False, False, False, False))


@dataclass(frozen=True, slots=True)
class TickInputs:
    """What the links hold at tick time ``t_s`` (s, the run's clock).

    ``pose``/``navdata`` are the newest received (None before the first); ``*_rx_t_s`` their
    receipt times on the same clock (ages are measured from those). ``target`` is the newest
    pose of the followed object (reference kind ``follow``; None otherwise).
    """

    t_s: float
    pose: MocapPose | None
    pose_rx_t_s: float
    navdata: NavdataSample | None
    navdata_rx_t_s: float
    target: MocapPose | None = None
    target_rx_t_s: float = -math.inf


@dataclass(frozen=True, slots=True)
class TickOutput:
    """The command to send, the log row of the tick and the supervisor's verdict.

    ``progressive`` False means "hover" (AT*PCMD flag 0: the drone holds position itself).
    ``action`` tells the runner what else to do: :attr:`Action.LAND` — land now;
    :attr:`Action.STOP` — the drone is in emergency: stop the loop and report. ``events`` are
    the supervisor's mode changes of this tick, for ``events.jsonl``.
    """

    pcmd: PcmdCommand
    progressive: bool
    row: dict
    action: Action = Action.CONTROL
    events: list = field(default_factory=list)


def navdata_velocity_world(nav: NavdataSample, psi_rad: float) -> tuple[float, float]:
    """Navdata body velocities (forward, right-positive) → world (ẋ, ẏ) at heading ψ (CCW)."""
    c, s = math.cos(psi_rad), math.sin(psi_rad)
    fwd, right = nav.vx_body_mps, nav.vy_body_mps
    return fwd * c + right * s, fwd * s - right * c


def measurement_columns(inputs: TickInputs) -> dict:
    """The raw measurements of ``inputs`` as log columns (replay feeds them back).

    ``mocap_t_s`` is the pose's own time stamp as the tick saw it (the link's clock: receipt
    time in ``fly``, plant time in simulation), bit for bit: the estimators difference it, and
    moved to the experiment clock it would carry the tick's offset (rounding; in ``fly`` its
    lateness) into those differences.
    """
    nav = inputs.navdata
    pose = inputs.pose
    return {
        "mocap_t_s": pose.t_s if pose is not None else math.nan,
        "battery_pct": nav.battery_pct if nav is not None else math.nan,
        "nav_vx_body_mps": nav.vx_body_mps if nav is not None else math.nan,
        "nav_vy_body_mps": nav.vy_body_mps if nav is not None else math.nan,
        "nav_mode": nav.mode.value if nav is not None else "",
        "nav_roll_deg": nav.roll_deg if nav is not None else math.nan,
        "nav_pitch_deg": nav.pitch_deg if nav is not None else math.nan,
    } | _target_columns(inputs)


def _target_columns(inputs: TickInputs) -> dict:
    target = inputs.target
    if target is None:
        return {}
    p = target.position_m
    return {"target_x_m": p[0], "target_y_m": p[1], "target_z_m": p[2],
            "target_psi_rad": target.psi_rad, "target_t_s": target.t_s,
            "target_age_ms": (inputs.t_s - inputs.target_rx_t_s) * 1e3}


def effective_controller(controller, limits: DroneLimits):
    """``controller`` with its input box intersected with what the drone is configured to do.

    The thesis bounds φ, θ and ψ̇ by ±1 (rad, rad/s), but the AR.Drone clips tilt to
    ``euler_angle_max`` (0.21 rad by default) and yaw rate to ``control_yaw``: planning beyond
    them plans the impossible, and every command then saturates behind the command delay.
    """
    lo = list(controller.u_min)
    hi = list(controller.u_max)
    for j, cap in ((1, limits.euler_angle_max_rad), (2, limits.euler_angle_max_rad),
                   (3, limits.control_yaw_radps)):
        lo[j], hi[j] = max(lo[j], -cap), min(hi[j], cap)
    return controller.model_copy(update={"u_min": tuple(lo), "u_max": tuple(hi)})


class Tick:
    """Estimator → reference → controller → mapping for one experiment.

    Parameters
    ----------
    cfg : ExperimentConfig.
    trajectory : the experiment's reference (time 0 = experiment start).
    """

    def __init__(self, cfg, trajectory: Trajectory):
        self.cfg = cfg
        self.trajectory = trajectory
        self.period_s = cfg.loop.period_s
        self.limits = DroneLimits(cfg.drone.euler_angle_max_rad, cfg.drone.control_vz_max_mps,
                                  cfg.drone.control_yaw_radps)
        ctl = cfg.controller
        self.use_nmpc = ctl.kind == "nmpc"
        if self.use_nmpc:
            from ardrone_nmpc.control.newton import make_nmpc

            self.nmpc = make_nmpc(effective_controller(ctl, self.limits), period_s=self.period_s)
            self._stage_index = np.arange(ctl.horizon_steps + 1, dtype=np.float64)
        g = ctl.p_gains
        self.p_gains = PGains(g.k1_per_s, g.k2_rad_per_mps, g.k3_rad_per_mps, g.k4_per_s)
        est = cfg.estimator
        self.vz_estimator = make_vz_estimator(
            est.kind, kalman_q=est.kalman_q, kalman_r=est.kalman_r, kalman_p0=est.kalman_p0,
            lambda0_per_s=est.luenberger_lambda0_per_s, gain=est.luenberger_gain)
        self.xy_difference = BackwardDifference(size=2)
        self._last_pose_t_s: float | None = None
        self._zacc_mps2 = 0.0  # z̈ applied over the last interval (KF/observer input)
        self._vz_ref_mps = 0.0  # the last ż reference sent
        self.vz_lead_s = ctl.vz_lead_s if ctl.vz_lead_s is not None else self.period_s
        self._state = np.zeros(7)
        self.supervisor = Supervisor(cfg.safety)
        self._live = trajectory if hasattr(trajectory, "observe") else None
        # moving obstacles: indices of those whose centre is the tracked object's position
        self._moving = [k for k, o in enumerate(ctl.obstacles) if o.mocap_object] \
            if self.use_nmpc else []
        self._last = None  # (pcmd, u) of the last command sent, for a hold
        self._moving_track = TrackedObject(OBSTACLE_VELOCITY_FILTER_S)
        diverge = cfg.faults.solver_diverge
        self._solver_fault = (None if diverge is None else
                              lambda t: diverge.start_s <= t < diverge.start_s + diverge.duration_s)
        # Delay compensation: the inputs sent but not yet acting (newest last).
        self.delay_ticks = math.ceil(ctl.delay_compensation_s / self.period_s - 1e-9)
        self._pending = deque(maxlen=max(self.delay_ticks, 1))
        self._sent = np.zeros((self.delay_ticks, 4))
        if self.use_nmpc:
            self._warm_up()

    def _warm_up(self) -> None:
        """Load (or compile) the solver kernels now, not on the first tick in the air."""
        hover = np.zeros(7)
        hover[4] = 1.0
        self.nmpc.solve(0.0, hover, np.tile(hover, (self.nmpc.spec.horizon_steps + 1, 1)))
        self.nmpc.reset()
        if self.delay_ticks:
            rollout_rk4(hover, self._sent, self.period_s, np.empty(7))

    # -- estimation ---------------------------------------------------------------------
    def _estimate(self, inputs: TickInputs) -> np.ndarray:
        pose = inputs.pose
        x = self._state
        if pose.t_s != self._last_pose_t_s:  # a new pose: update the estimators
            if self._last_pose_t_s is None:
                self.vz_estimator.reset(pose.position_m[2])
                self.xy_difference.reset()
                self.xy_difference.update(pose.position_m[:2], 1.0)
            else:
                dt = pose.t_s - self._last_pose_t_s
                self.vz_estimator.update(pose.position_m[2], self._zacc_mps2, dt)
                self.xy_difference.update(pose.position_m[:2], dt)
            self._last_pose_t_s = pose.t_s
        x[0], x[2], x[4] = pose.position_m
        x[6] = pose.psi_rad
        x[5] = self.vz_estimator.vz_mps
        if self.cfg.estimator.horizontal_velocity == "navdata" and inputs.navdata is not None:
            x[1], x[3] = navdata_velocity_world(inputs.navdata, pose.psi_rad)
        else:
            x[1], x[3] = self.xy_difference.velocity_mps
        return x

    # -- the tick -----------------------------------------------------------------------
    def step(self, inputs: TickInputs, *, t_exp_s: float, mode: str = "track",
             trajectory: Trajectory | None = None) -> TickOutput:
        """One tick at experiment time ``t_exp_s`` against ``trajectory`` (default: the
        experiment's). ``mode`` labels a nominal row ("track", "settle"); the supervisor's
        verdict replaces it otherwise (module :mod:`ardrone_nmpc.safety`)."""
        t0 = time.perf_counter_ns()
        traj = trajectory or self.trajectory
        mocap_age_ms = (inputs.t_s - inputs.pose_rx_t_s) * 1e3 if inputs.pose else math.inf
        navdata_age_ms = ((inputs.t_s - inputs.navdata_rx_t_s) * 1e3 if inputs.navdata
                          else math.inf)
        row = {"t_s": t_exp_s, "mocap_age_ms": mocap_age_ms, "navdata_age_ms": navdata_age_ms,
               "solver_status": "", "cmd_saturated": "0000"}
        row.update(measurement_columns(inputs))
        if self._live is not None:  # reference kind 'follow': the object's newest pose
            self._live.observe(inputs.target, t_pose_s=t_exp_s - (inputs.t_s - inputs.target_rx_t_s),
                               age_ms=(inputs.t_s - inputs.target_rx_t_s) * 1e3)
        if self._moving and inputs.target is not None:
            self._move_obstacles(inputs.target)
        sup = self.supervisor
        cmd = None
        decision = sup.check_feedback(mocap_age_ms=mocap_age_ms, navdata_age_ms=navdata_age_ms,
                                      navdata=inputs.navdata)
        if inputs.pose is not None:  # logged even when stale (mocap_age_ms says so)
            x = self._estimate(inputs)
            row.update(x_m=x[0], y_m=x[2], z_m=x[4], psi_rad=x[6], vx_mps=x[1], vy_mps=x[3],
                       vz_mps=x[5])
        if decision.action is Action.CONTROL:
            decision = sup.check_state(x, inputs.navdata)
            if decision.action is Action.CONTROL:
                cmd, decision = self._control(t_exp_s, x, traj, row)
        pcmd, progressive, decision = self._command_of(decision, cmd, row)
        row["mode"] = sup.record(decision, mode)
        row["compute_us"] = (time.perf_counter_ns() - t0) * 1e-3
        return TickOutput(pcmd, progressive, row, decision.action, sup.take_events())

    def _move_obstacles(self, pose) -> None:
        """Moving obstacles take the tracked object's position, predicted at its estimated
        velocity to the moment the command takes effect (the state the NMPC solves from is
        predicted there too) plus ``controller.obstacle_lookahead_s``, as their centre; over
        the horizon it is held."""
        track = self._moving_track
        track.update(pose, pose.t_s)
        centres = self.nmpc.obstacles[:, OBS_X:OBS_Z + 1].copy()
        ahead_s = self.delay_ticks * self.period_s + self.cfg.controller.obstacle_lookahead_s
        centres[self._moving] = track.position_m + track.velocity_mps * ahead_s
        self.nmpc.move_obstacles(centres)

    def _control(self, t_exp_s, x, traj, row):
        """The controller (NMPC or P) and the supervisor's verdict on its solution."""
        if not self.use_nmpc:
            ref_now = traj.state_at(t_exp_s)[0]
            cmd = p_control(x, ref_now, self.p_gains)
            row.update(x_ref_m=ref_now[0], y_ref_m=ref_now[2], z_ref_m=ref_now[4],
                       psi_ref_rad=ref_now[6], u_zacc_mps2=math.nan, u_phi_rad=cmd.phi_rad,
                       u_theta_rad=cmd.theta_rad, u_psirate_radps=cmd.psirate_radps)
            return cmd, NOMINAL
        x_solve, result, ref_now = self._nmpc(t_exp_s, x, traj, row)
        u = result.u
        if self._solver_fault is not None and self._solver_fault(t_exp_s):
            u = np.full(4, math.nan)  # injected: a diverged, non-finite solution
            row["solver_status"] = SolverStatus.DIVERGED.value
            ok = False
        else:
            ok = result.ok or (result.status is SolverStatus.MAX_ITERATIONS
                               and self.cfg.safety.solver_accept_max_iterations)
        decision = self.supervisor.check_solution(ok, u)
        if decision.action is Action.CONTROL:
            return self._apply_nmpc_input(u, x_solve), decision
        if decision.action is Action.FALLBACK:
            return p_control(x, ref_now, self.p_gains), decision
        return None, decision

    def _apply_nmpc_input(self, u, x_solve) -> AttitudeCommand:
        """The NMPC input ``u`` as an attitude command; its z̈ feeds the ż integrators."""
        # ż reference: the estimator's (predicted) ż plus this tick's z̈ (thesis end of §4.4).
        # Without an estimate the thesis could only integrate its own z̈ commands — the
        # integrator that winds up into fig. 3.2's overshoot.
        vz_base = self._vz_ref_mps if self.cfg.estimator.kind == "none" else x_solve[5]
        vz_max = self.limits.control_vz_max_mps  # the drone clips beyond: no wind-up past it
        vz_ref = min(max(vz_reference_mps(vz_base, u[0], self.vz_lead_s), -vz_max), vz_max)
        return AttitudeCommand(vz_ref, float(u[1]), float(u[2]), float(u[3]))

    def _command_of(self, decision: Decision, cmd: AttitudeCommand | None, row):
        """The command the decision flies, with the bookkeeping of what was sent (the ż
        integrators, the delay predictor's pending inputs, the last command for a hold)."""
        action = decision.action
        if action is Action.HOLD and self._last is not None:
            pcmd, u_sent = self._last
            return self._sent_output(pcmd, u_sent, True, decision, row)
        if cmd is not None and action in (Action.CONTROL, Action.FALLBACK):
            roll, roll_clipped = self.supervisor.clip_tilt_rad(cmd.phi_rad)
            pitch, pitch_clipped = self.supervisor.clip_tilt_rad(cmd.theta_rad)
            cmd = AttitudeCommand(cmd.vz_ref_mps, roll, pitch, cmd.psirate_radps)
            if all(map(math.isfinite, (cmd.vz_ref_mps, roll, pitch, cmd.psirate_radps))):
                pcmd = map_to_pcmd(cmd, self.limits)
                flags = (pcmd.saturated[0] or roll_clipped, pcmd.saturated[1] or pitch_clipped,
                         *pcmd.saturated[2:])
                zacc = row["u_zacc_mps2"] if action is Action.CONTROL else 0.0
                u_sent = np.array([zacc if math.isfinite(zacc) else 0.0, roll, pitch,
                                   cmd.psirate_radps])
                row.update(vz_ref_mps=cmd.vz_ref_mps,
                           cmd_saturated="".join("1" if f else "0" for f in flags))
                if action is Action.FALLBACK:
                    row.update(u_phi_rad=roll, u_theta_rad=pitch,
                               u_psirate_radps=cmd.psirate_radps)
                self._vz_ref_mps = cmd.vz_ref_mps
                self._last = (pcmd, u_sent)
                return self._sent_output(pcmd, u_sent, True, decision, row)
            decision = Decision(Action.HOVER, "nonfinite-command")  # never sent
        elif action is Action.HOLD:  # nothing sent yet that could be held
            decision = Decision(Action.HOVER, decision.reason)
        # hover, land, stop: the drone's own hover — no acceleration, for the delay predictor
        # and the integrators; the last NMPC input is never flown
        self._vz_ref_mps = 0.0
        self._last = None
        return self._sent_output(HOVER, np.zeros(4), False, decision, row)

    def _sent_output(self, pcmd, u_sent, progressive, decision, row):
        self._zacc_mps2 = float(u_sent[0])
        if self.delay_ticks:
            self._pending.append(u_sent)
        row.update(cmd_roll_frac=pcmd.roll_frac, cmd_pitch_frac=pcmd.pitch_frac,
                   cmd_gaz_frac=pcmd.gaz_frac, cmd_yaw_frac=pcmd.yaw_frac)
        return pcmd, progressive, decision

    def predict_through_delay(self, x: np.ndarray) -> np.ndarray:
        """``x`` rolled forward through the inputs already sent and not yet acting (model
        eq. 3.13, RK4 per control period) — the state the new command will meet."""
        if self.delay_ticks == 0 or not self._pending:
            return x
        sent = self._sent
        missing = self.delay_ticks - len(self._pending)  # start-up: hover for those
        sent[:missing] = 0.0
        for k, u in enumerate(self._pending):
            sent[missing + k] = u
        out = np.empty(7)
        rollout_rk4(x, sent, self.period_s, out)
        return out

    def _nmpc(self, t_exp_s, x, traj, row):
        solver = self.nmpc
        lead_s = self.delay_ticks * self.period_s
        x_solve = self.predict_through_delay(x)
        dtau = solver.stage_dtau_s(t_exp_s)
        # one lookup for the reference at t (logged against x(t)) and over the horizon that
        # starts when this command takes effect, t + lead
        times = np.empty(solver.spec.horizon_steps + 2)
        times[0] = t_exp_s
        times[1:] = t_exp_s + lead_s + max(dtau, 1e-9) * self._stage_index
        states = traj.state_at(times)
        ref_now, ref = states[0], states[1:]
        result = solver.solve(t_exp_s, x_solve, ref)
        u = result.u
        row.update(x_ref_m=ref_now[0], y_ref_m=ref_now[2], z_ref_m=ref_now[4],
                   psi_ref_rad=ref_now[6], u_zacc_mps2=u[0], u_phi_rad=u[1], u_theta_rad=u[2],
                   u_psirate_radps=u[3], solve_us=result.solve_time_us,
                   solver_status=result.status.value, residual_norm=result.residual_norm,
                   gmres_iterations=result.gmres_iterations,
                   newton_iterations=result.newton_iterations)
        return x_solve, result, ref_now
