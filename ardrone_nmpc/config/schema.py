"""Experiment configuration: the pydantic schema of an experiment (loading is in ``config.io``).

An experiment is one YAML mapping whose top level has ``name``, ``duration_s`` and one section
per subsystem::

    name: step_x                 # used in run-directory names
    duration_s: 20.0
    controller: {kind, horizon_steps, dtau_s, q, r, q_terminal, u_min, u_max, solver: {…}, p_gains: {…},
                 obstacles: [{kind, center_m, radius_m, margin_m}, …], obstacle_weight, …}
    estimator:  {kind, kalman_q, kalman_r, kalman_p0, luenberger_lambda0_per_s, …}
    reference:  {kind, start_m, target_m, step_time_s, side_m, …, path_file}
    loop:       {period_s}
    drone:      {host, at_port, navdata_port, euler_angle_max_rad, control_vz_max_mps, …}
    mocap:      {kind, bind_host, port, system, hostname, options, up_axis, object_name, …}
    sim:        {seed, plant: {…}, noise: {…}, mocap_rate_hz, navdata_rate_hz}
    safety:     {geofence_min_m, geofence_max_m, max_tilt_rad, …, solver_fallback}
    faults:     {mocap_dropout: {start_s, duration_s}, …}   (simulation only; all off by default)

Every key is optional: a missing key takes its default, and the defaults are the values of the
thesis (``docs/thesis.md``), the AR.Drone SDK (``docs/protocol.md``) and the plant identification
(``docs/plant.md``). Unknown keys, NaN/inf, out-of-range values and vectors of the wrong length
are errors; durations, coordinates and the name are bounded (:mod:`ardrone_nmpc.config.limits`)
so that a valid config cannot crash a run later. Every field carries its unit in its name and a
description (``ExperimentConfig.model_json_schema()`` lists them all).

This module validates values only: it reads no file (the waypoint file of reference kind
'path' is read where the trajectory is built, by ``check``, and before a run directory is made).

Vectors are YAML lists, ordered like the thesis: states ``[x, ẋ, y, ẏ, z, ż, ψ]``, inputs
``[z̈, φ, θ, ψ̇]``, positions ``[x, y, z]`` in the world frame (x forward, y left, z up).

Errors are reported as a :class:`ConfigError` whose ``messages`` are ``field.path: message`` lines,
e.g. ``controller.solver.kmax: Input should be greater than or equal to 1``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any, Literal, Optional

from pydantic import Field, ValidationError, ValidationInfo, field_validator, model_validator

from ardrone_nmpc.config.faults import FaultsConfig
from ardrone_nmpc.config.fields import (
    CoordinateVec2, CoordinateVec3, Finite, NonNegative, NonNegativeSpan, NonNegativeVec4,
    NonNegativeVec7, PathSize, PathSizeVec2, PathSizeVec4, Port, Positive, PositiveVec2,
    PositiveVec4, Section, Span, Vec2, Vec4, ascii_name, invalid, require_increasing,
)
from ardrone_nmpc.config.limits import MAX_LORENZ_TIME, MAX_NAME_CHARS
from ardrone_nmpc.errors import UserError

from ardrone_nmpc.core import defaults

__all__ = [
    "ConfigError",
    "ControllerConfig",
    "DroneConfig",
    "EstimatorConfig",
    "ExperimentConfig",
    "FaultsConfig",
    "LoopConfig",
    "MocapConfig",
    "NoiseConfig",
    "ObstacleConfig",
    "PGainsConfig",
    "PlantConfig",
    "ReferenceConfig",
    "SafetyConfig",
    "SimConfig",
    "SolverConfig",
    "config_from_dict",
    "tracked_object",
]


class ConfigError(UserError):
    """Invalid configuration. ``messages`` are one-line ``field.path: message`` strings
    (exit code 1)."""

    def __init__(self, messages: str | Sequence[str]) -> None:
        self.messages: list[str] = [messages] if isinstance(messages, str) else list(messages)
        super().__init__(self.messages)

    def __str__(self) -> str:
        return "\n".join(self.messages)


# ----------------------------------------------------------------------------- controller


class SolverConfig(Section):
    """Numerical settings of the NMPC solvers (thesis §3.3, Algorithm 1; Ohtsuka's C/GMRES)."""

    method: Literal["cgmres", "newton"] = Field(
        "cgmres", description="'cgmres': continuation/GMRES, one GMRES solve per tick; "
        "'newton': the thesis' per-step Newton iterations with fdgmres.")
    kmax: int = Field(defaults.KMAX, ge=1, le=1000,
                      description="C/GMRES: Krylov-subspace dimension per solve (count).")
    newton_kmax: int = Field(
        defaults.NEWTON_KMAX, ge=1, le=1000, description="Method 'newton': Krylov dimension "
        "k_max of each Newton step (Algorithm 1; the thesis gives none). Its system is "
        "uncondensed (8 unknowns per stage): with 5, GMRES stops far above η and Newton stalls "
        "at ‖F‖ ≈ 0.1 (docs/thesis-reproduction.md).")
    zeta_per_s: Positive = Field(
        defaults.ZETA_PER_S, description="Continuation stabilisation gain ζ (1/s): dF/dt = −ζ F.")
    fd_step: Positive = Field(
        defaults.FD_STEP,
        description="Forward-difference step h of Jacobian-vector products (dimensionless).")
    gmres_rtol: float = Field(
        defaults.GMRES_RTOL, gt=0, lt=1,
        description="GMRES relative residual tolerance η (thesis Algorithm 1).")
    tolerance: Positive = Field(
        defaults.TOLERANCE,
        description="Target ‖F‖ of Newton solves (initial solve and method 'newton').")
    max_newton_iterations: int = Field(defaults.MAX_NEWTON_ITERATIONS, ge=1, le=1000,
                                       description="Newton iteration cap per solve.")
    dummy_weight: Positive = Field(
        defaults.DUMMY_WEIGHT,
        description="Linear cost weight of the dummy inputs that enforce the input bounds.")
    bound_epsilon: NonNegative = Field(
        defaults.BOUND_EPSILON,
        description="ε of thesis eq. 3.25: an active bound C < 0 becomes C − ε = 0 ('newton').")
    horizon_ramp_rate_per_s: NonNegative = Field(
        defaults.HORIZON_RAMP_RATE_PER_S,
        description="α (1/s) in T(t) = N·Δτ·(1 − e^(−αt)); 0 = fixed horizon as in the thesis.")
    divergence_residual: Positive = Field(
        defaults.DIVERGENCE_RESIDUAL,
        description="‖F‖ above which a solve counts as diverged and the solver re-initialises.")
    newton_trigger_residual: Positive = Field(
        defaults.NEWTON_TRIGGER_RESIDUAL,
        description="C/GMRES: ‖F‖ at a new measurement above which the tick first "
        "re-projects onto F = 0 by Newton/GMRES warm-started from the current solution (a "
        "reference jump is an impulse the continuation cannot follow).")
    condensed: bool = Field(
        defaults.CONDENSED,
        description="C/GMRES: eliminate the dummy inputs and multipliers per stage in closed "
        "form (4 unknowns per stage, not 12). Same equations; GMRES(5) stagnates on the "
        "uncondensed saddle-point system, so false is for comparison only.")


class PGainsConfig(Section):
    """Gains of the baseline proportional controller (thesis eq. 4.16; the thesis gives none)."""

    k1_per_s: Positive = Field(0.7, description="ż_ref = k1 (z_d − z), 1/s (tuned in "
                               "simulation: see control/proportional.py PGains).")
    k2_rad_per_mps: Positive = Field(
        0.2, description="Roll φ per m/s of lateral speed error, rad/(m/s).")
    k3_rad_per_mps: Positive = Field(
        0.2, description="Pitch θ per m/s of forward speed error, rad/(m/s).")
    k4_per_s: Positive = Field(1.0, description="ψ̇ = k4 (ψ_d − ψ), 1/s.")


class ObstacleConfig(Section):
    """A static obstacle the NMPC keeps out of: the constraint ‖p − c‖ ≥ d, d = radius + margin.

    A sphere measures the 3-D distance from its centre; a cylinder is vertical and unbounded
    in height and measures the horizontal distance only (its centre's z is ignored).
    """

    kind: Literal["sphere", "cylinder"] = Field(
        ..., description="'sphere' (3-D distance) or 'cylinder' (vertical; horizontal distance).")
    center_m: CoordinateVec3 = Field(
        ..., description="Centre [x, y, z] (m); z is ignored for a cylinder.")
    radius_m: PathSize = Field(..., description="Radius of the obstacle itself (m), ≤ 1000.")
    margin_m: NonNegative = Field(
        0.3, description="Safety margin added to the radius (m): the drone's half-size (≈ 0.26 m "
        "with the indoor hull) plus a buffer. The NMPC keeps the drone's centre d = radius + "
        "margin from the obstacle's centre.")
    mocap_object: Optional[str] = Field(
        None, min_length=1, max_length=24, description="A moving obstacle: the mocap object "
        "whose newest position is the centre each tick (center_m until it is first seen; the "
        "last position is kept when it goes stale). null: static.")


class OffsetFreeConfig(Section):
    """Offset-free tracking: integral action on the position/yaw error, fed to the NMPC as a
    shift of its reference (docs/solver-notes.md, "Offset-free tracking"). A constant wind, a
    vertical gain mismatch, battery sag or a navdata velocity bias then leave no steady error.
    Vectors are ordered [x, y, z, ψ]."""

    enabled: bool = Field(True, description="Integral action on (true) or off (false: the "
                          "NMPC tracks the reference itself, as in the thesis).")
    ki_per_s: NonNegativeVec4 = Field(
        (0.5, 0.5, 0.4, 0.15), description="Integral gain per axis (1/s): the reference shift "
        "moves by −ki·e per second while it learns, [x, y, z, ψ]; 0 switches an axis off.")
    kp: NonNegativeVec4 = Field(
        (0.0, 0.0, 1.0, 0.0), description="Proportional part of the shift while learning "
        "(dimensionless, m per m / rad per rad), [x, y, z, ψ]: stiffens a slow loop so the "
        "integrator settles without overshoot (velocity form: it never jumps the shift).")
    error_band: PositiveVec4 = Field(
        (0.5, 0.5, 0.5, 0.3), description="An axis learns only while |error| is below this "
        "[m, m, m, rad] (conditional integration: a step's transient does not wind up).")
    hold_s: NonNegativeVec4 = Field(
        (1.5, 1.5, 1.5, 2.0), description="It starts learning once the axis has been at rest "
        "inside its error band this long (s), and goes on until the error leaves the band or "
        "the reference moves: the tail of a step is the loop's own.")
    steady_band: PositiveVec4 = Field(
        (0.01, 0.01, 0.02, 0.01), description="'At rest' also needs the error steady: its "
        "range since the axis came to rest within this [m, m, m, rad] — a step's tail that "
        "still converges restarts the hold.")
    speed_band: PositiveVec4 = Field(
        (0.15, 0.15, 0.05, 0.3), description="'At rest': the estimated rate of the axis below "
        "this [m/s, m/s, m/s, rad/s].")
    release_speed: PositiveVec4 = Field(
        (0.3, 0.3, 0.3, 0.6), description="A learning axis stops (and needs a new hold) when "
        "its rate exceeds this [m/s, m/s, m/s, rad/s]: a gust is not a constant disturbance. "
        "Above speed_band, so the motion the shift itself causes does not stop it.")
    max_shift: PositiveVec4 = Field(
        (0.5, 0.5, 0.5, 0.3), description="Largest reference shift [m, m, m, rad]: a bad "
        "sensor cannot drag the drone further than this from the reference.")


class ControllerConfig(Section):
    """Controller choice and the optimal control problem (thesis eq. 3.14–3.16, 4.17)."""

    kind: Literal["nmpc", "p"] = Field(
        "nmpc", description="'nmpc': nonlinear MPC; 'p': proportional baseline (eq. 4.16).")
    horizon_steps: int = Field(defaults.HORIZON_STEPS, ge=1, le=1000,
                               description="Prediction horizon N (steps).")
    dtau_s: Positive = Field(defaults.DTAU_S, le=1.0,
                             description="Prediction step Δτ (s), ≤ 1; horizon T = N·Δτ.")
    q: NonNegativeVec7 = Field(
        defaults.Q_STATE,
        description="State weights diag q, order [x, ẋ, y, ẏ, z, ż, ψ] (thesis §4.4).")
    r: PositiveVec4 = Field(
        defaults.R_INPUT,
        description="Input weights diag r, order [z̈, φ, θ, ψ̇] (thesis 'Case 2').")
    q_terminal: NonNegativeVec7 = Field(
        defaults.Q_TERMINAL,
        description="Terminal state weights, order as q (the thesis has none).")
    u_min: Vec4 = Field(
        defaults.U_MIN,
        description="Input lower bounds [m/s², rad, rad, rad/s] (thesis eq. 4.17).")
    u_max: Vec4 = Field(
        defaults.U_MAX,
        description="Input upper bounds [m/s², rad, rad, rad/s]; each above u_min (eq. 4.17).")
    vz_lead_s: Optional[Positive] = Field(
        0.5, description="ż reference = ż estimate + z̈ · vz_lead_s (s). The drone's vertical "
        "loop is a first-order lag; this inverts it exactly when vz_lead_s is its time "
        "constant (0.5 s: docs/plant.md, sim.plant.tau_vz_s). null = one control period, the "
        "thesis' integration (end of §4.4), which assumes a new vertical speed within a tick "
        "and overshoots altitude steps by 6–7 % in simulation (2.3 % with 0.5).")
    delay_compensation_s: NonNegative = Field(
        0.26, le=2.0, description="Command delay (s, ≤ 2) the NMPC predicts through: the state "
        "is rolled forward through the commands already sent and the OCP solved for the moment "
        "the new command takes effect. 0.26 = the thesis simulator's delay (and sim.plant's); "
        "0 = the thesis' delay-free formulation, which limit-cycles (±0.3 m) against that delay.")
    solver: SolverConfig = Field(default_factory=SolverConfig, description="NMPC solver settings.")
    obstacles: tuple[ObstacleConfig, ...] = Field(
        (), max_length=32, description="Obstacles the NMPC avoids (exterior penalty on "
        "‖p − c‖² ≥ d², docs/solver-notes.md §7); none by default. The P controller ignores "
        "them.")
    obstacle_weight: Positive = Field(
        2000.0, description="Weight w of the obstacle penalty ½ w max(0, d² − ‖p − c‖²)² in the "
        "stage cost (1/m⁴, relative to q and r). Larger: less intrusion into the margin, a "
        "stiffer problem for GMRES.")
    obstacle_lookahead_s: NonNegative = Field(
        0.3, le=3.0, description="A moving obstacle (mocap_object) is placed where its "
        "estimated velocity takes it this long after the command takes effect; its motion over "
        "the horizon is not modelled, and this short look-ahead stands in for it (s; "
        "configs/moving_obstacle.yaml: 0 s → 31 ticks inside the margin, 0.3 s → none).")
    obstacle_tie_break_m: NonNegative = Field(
        0.05, description="Tie-break of head-on approaches (m): each tick the penalty's centre "
        "moves this far to the left of the line of sight from the drone, and d grows by as "
        "much (the penalised region still covers the obstacle). A drone within this distance "
        "of the line through the centre passes the obstacle on its right; 0 leaves the choice "
        "to noise.")
    obstacle_curvature: Literal["gauss-newton", "exact"] = Field(
        "gauss-newton", description="Curvature of the obstacle penalty in the solvers' "
        "Jacobian products: 'gauss-newton' drops the negative part, so the path through an "
        "obstacle's centre repels the continuation instead of attracting it; 'exact' is the "
        "true Hessian (for comparison).")
    p_gains: PGainsConfig = Field(
        default_factory=PGainsConfig, description="Gains of the 'p' controller.")
    offset_free: OffsetFreeConfig = Field(
        default_factory=OffsetFreeConfig, description="Offset-free tracking (integral action "
        "of the NMPC; the 'p' controller has none). true/false is short for "
        "{enabled: true/false} with the default gains.")

    _u_bounds = require_increasing("u_min", "u_max")

    @model_validator(mode="before")
    @classmethod
    def _offset_free_shorthand(cls, data: Any) -> Any:
        # controller.offset_free: false (a bool) → the section with enabled false
        if isinstance(data, Mapping) and isinstance(data.get("offset_free"), bool):
            data = {**data, "offset_free": {"enabled": data["offset_free"]}}
        return data


# ----------------------------------------------------------------------------- estimation


class EstimatorConfig(Section):
    """Velocity estimation (thesis ch. 4): ż from mocap z, ẋ/ẏ from navdata or differences."""

    kind: Literal["kalman", "luenberger", "difference", "none"] = Field(
        "kalman", description="ż estimator: Kalman filter (eq. 4.5–4.9), Luenberger observer "
        "(eq. 4.10–4.15), the raw finite difference of z, or none (ż ≡ 0: the thesis' first "
        "altitude experiment, fig. 3.2).")
    kalman_q: Positive = Field(
        2.8559e-4, description="Kalman process-noise variance Q, (m/s)² (thesis).")
    kalman_r: Positive = Field(
        3.2e-3, description="Kalman measurement-noise variance R of differenced z, (m/s)² (thesis).")
    kalman_p0: Positive = Field(1e-2, description="Initial Kalman error variance P0, (m/s)².")
    luenberger_lambda0_per_s: Positive = Field(
        5.0, le=1000.0, description="Observer double pole at −λ0 (1/s), ≤ 1000; gain K = "
        "[2λ0, λ0²].")
    luenberger_gain: Optional[PositiveVec2] = Field(
        None, description="Explicit observer gain [k1 (1/s), k2 (1/s²)], overriding λ0; both > 0 "
        "so that A − KC is Hurwitz. null = derive from λ0.")
    horizontal_velocity: Literal["navdata", "difference"] = Field(
        "difference", description="Source of ẋ, ẏ: finite differences of the mocap position "
        "(docs/design.md; in simulation the x step settles in 2.5 s) or the drone's optical-flow "
        "navdata as in the thesis (its bias leaves a ±3 cm wander: 12.7 s).")


# ----------------------------------------------------------------------------- reference


class FollowConfig(Section):
    """Reference kind 'follow': the drone follows a second object of the mocap stream."""

    object_name: str = Field(
        "car", min_length=1, max_length=24, description="Mocap name of the object to follow.")
    offset_m: CoordinateVec3 = Field(
        (0.0, 0.0, 1.0), description="Where the drone should be relative to the object (m).")
    offset_frame: Literal["world", "object"] = Field(
        "world", description="Frame of offset_m: the world's, or the object's (turns with it).")
    heading: Literal["fixed", "object"] = Field(
        "fixed", description="Drone heading: reference.start_psi_rad, or the object's heading.")
    predict: bool = Field(
        True, description="Extrapolate the object's velocity over the horizon (else the "
        "horizon holds its latest pose).")
    velocity_filter_s: Positive = Field(
        0.2, description="Time constant of the object's velocity estimate (s).")
    max_age_ms: Positive = Field(
        300.0, description="Object pose age (ms) beyond which the reference stops "
        "extrapolating and holds the last position.")

    _name = field_validator("object_name")(classmethod(lambda cls, v: ascii_name(v)))


class ReferenceConfig(Section):
    """The desired trajectory x_d(t), world frame, metres and radians."""

    kind: Literal["hover", "step", "square", "square_altitudes", "ellipse", "lorenz", "path",
                  "follow"] = (
        Field("hover", description="Trajectory type; the fields below apply as noted. "
              "'follow' takes it live from a second mocap object (see follow)."))
    follow: FollowConfig = Field(
        default_factory=FollowConfig, description="Reference kind 'follow' only; before the "
        "object is seen, the reference holds start_m.")
    start_m: CoordinateVec3 = Field((0.0, 0.0, 1.0), description="Start position [x, y, z] (m).")
    start_psi_rad: Finite = Field(0.0, description="Start heading ψ (rad, counter-clockwise).")
    target_m: CoordinateVec3 = Field(
        (0.0, 0.0, 1.0), description="Step target position [x, y, z] (m).")
    target_psi_rad: Finite = Field(0.0, description="Step target heading ψ (rad).")
    step_time_s: NonNegativeSpan = Field(
        1.0, description="Time of the step (s from start), ≤ 3600.")
    side_m: PathSize = Field(1.0, description="Square side length (m), ≤ 1000.")
    leg_duration_s: Span = Field(
        5.0, description="Time per side of 'square' and 'square_altitudes' (s), ≤ 3600.")
    altitudes_m: PathSizeVec4 = Field(
        (0.8, 1.0, 1.2, 1.4), description="Corner altitudes of 'square_altitudes' (m), ≤ 1000.")
    center_m: CoordinateVec2 = Field((0.0, 0.0), description="Ellipse centre [x, y] (m).")
    semi_axes_m: PathSizeVec2 = Field(
        (1.0, 0.6), description="Ellipse semi-axes [a_x, a_y] (m), ≤ 1000.")
    period_s: Span = Field(20.0, description="Time for one lap of the ellipse (s), ≤ 3600.")
    lorenz_scale_m: Positive = Field(
        0.05, le=1.0, description="Metres per Lorenz-system unit of the 'lorenz' path, ≤ 1.")
    lorenz_time_scale: Positive = Field(
        0.05, le=1.0, description="Lorenz-system time advanced per second of flight "
        "(dimensionless, ≤ 1); 0.05 keeps the scaled attractor under 1 m/s (peak ≈ 0.72 m/s at "
        "lorenz_scale_m 0.05).")
    path_file: Optional[str] = Field(
        None, validate_default=True, min_length=1, max_length=4096,
        description="CSV waypoint file (t_s,x_m,y_m,z_m,psi_rad) for 'path'; relative paths in a "
        "config file are relative to that file's directory. Resolved to an absolute path when "
        "loaded; a run directory holds its own copy (see docs/design.md). Its contents are "
        "checked by `check` and before a run starts (reference/waypoints.py: at most 10 000 "
        "waypoints, coordinates within ±1000 m).")

    @field_validator("path_file")
    @classmethod
    def _path_file_for_paths(cls, value: Optional[str], info: ValidationInfo) -> Optional[str]:
        if value is None and info.data.get("kind") == "path":
            raise invalid("required when kind is 'path'")
        return value


# ----------------------------------------------------------------------------- hardware


class LoopConfig(Section):
    """The control loop."""

    period_s: Positive = Field(
        defaults.LOOP_PERIOD_S, ge=0.001, le=1.0,
        description="Control period (s), 1 ms … 1 s; 65 ms in the thesis.")


class DroneConfig(Section):
    """The AR.Drone link and the limits written to its configuration at connect (protocol §3.1)."""

    host: str = Field("192.168.1.1", min_length=1, description="Drone IP address or host name.")
    at_port: Port = Field(5556, description="UDP port of AT commands.")
    navdata_port: Port = Field(5554, description="UDP port of navdata.")
    euler_angle_max_rad: float = Field(
        0.2094, gt=0, le=0.52, description="control:euler_angle_max (rad): tilt at PCMD ±1.")
    control_vz_max_mps: float = Field(
        0.7, ge=0.2, le=2.0, description="control:control_vz_max (m/s): climb rate at PCMD gaz ±1.")
    control_yaw_radps: float = Field(
        1.745, ge=0.7, le=6.11, description="control:control_yaw (rad/s): yaw rate at PCMD yaw ±1.")
    altitude_max_m: Positive = Field(
        3.0, le=100.0, description="control:altitude_max (m), ≤ 100 (the AR.Drone 2.0's cap).")
    navdata_demo: bool = Field(True, description="general:navdata_demo: 15 Hz demo packets if true.")
    keepalive_interval_s: float = Field(
        0.03, gt=0, le=0.03, description="Longest gap between AT commands (s); ≤ 30 ms (§2.6).")


MOCAP_SYSTEMS = ("vicon", "optitrack", "optitrack_closed_source", "qualisys", "vrpn", "nokov",
                 "motionanalysis", "fzmotion", "mock")
# Systems whose default world frame is Y-up (OptiTrack Motive streams Y up unless told otherwise).
_Y_UP_SYSTEMS = ("optitrack", "optitrack_closed_source")


class MocapConfig(Section):
    """The motion-capture source (docs/mocap-sources.md, docs/mocap-stream.md)."""

    kind: Literal["vicon_udp", "motioncapture"] = Field(
        "vicon_udp", description="'vicon_udp': Vicon Tracker's UDP object stream (bind_host, "
        "port); 'motioncapture': any system of the libmotioncapture library (system, hostname, "
        "options; the 'mocap' extra).")
    bind_host: str = Field("0.0.0.0", min_length=1, description="vicon_udp: local address to "
                           "listen on.")
    port: Port = Field(51001, description="vicon_udp: UDP port of the pose stream.")
    system: Literal[MOCAP_SYSTEMS] = Field(  # type: ignore[valid-type]
        "vicon", description="motioncapture: the library's system type (vicon = DataStream "
        "SDK, optitrack = NatNet, qualisys, vrpn, nokov, motionanalysis, fzmotion, mock).")
    hostname: str = Field("localhost", min_length=1, description="motioncapture: the mocap "
                          "server's address (the library's 'hostname' option).")
    options: dict[str, str | int | float | bool] = Field(
        default_factory=dict, description="motioncapture: more library options, passed through "
        "as strings (e.g. port_command, interface_ip; mock: rigid_bodies, frequency).")
    up_axis: Optional[Literal["z", "y"]] = Field(
        None, description="motioncapture: the system's vertical axis; 'y' turns a right-handed "
        "Y-up frame into ours (x, -z, y). null: 'y' for optitrack, 'z' otherwise (set 'z' when "
        "Motive streams Z up).")
    connect_timeout_s: Positive = Field(
        5.0, description="motioncapture: how long to wait for the connection (s).")
    object_name: str = Field(
        "ardrone", min_length=1, max_length=24, description="Tracked object name (≤ 24 ASCII).")

    @field_validator("object_name")
    @classmethod
    def _ascii_name(cls, value: str) -> str:
        if not value.isascii() or "\x00" in value:
            raise invalid("must be ASCII without NUL characters")
        return value

    @field_validator("options", mode="before")
    @classmethod
    def _scalar_options(cls, value: Any) -> Any:
        # the library takes text: one clear line rather than one per member of the union
        if isinstance(value, Mapping):
            for key, item in value.items():
                if not isinstance(item, (str, int, float, bool)):
                    raise invalid(f"{key}: expected a string, number or boolean, got "
                                   f"{type(item).__name__}")
        return value

    @property
    def vertical_axis(self) -> str:
        """The up axis in force: ``up_axis``, or the system's default."""
        if self.up_axis is not None:
            return self.up_axis
        return "y" if self.system in _Y_UP_SYSTEMS else "z"


# ----------------------------------------------------------------------------- simulation


#: What each ``sim.plant.profile`` sets where the config leaves a key out (docs/plant-profiles.md).
PLANT_PROFILE_DEFAULTS: dict[str, dict[str, float]] = {
    "ardrone": {},       # the defaults below: tum_ardrone dynamics with the thesis' 0.26 s delay
    # the kit's identified channels (sim/plant_kit.py) with its timeDelay and simDT
    "thesis_kit": {"command_delay_s": 0.26, "integration_step_s": 0.005},
    # the real drone as identified: tum_ardrone's ≈ 0.12 s delay and the turbulence calibrated
    # on the thesis' experimental square (docs/plant-profiles.md §3)
    "ardrone_lab": {"command_delay_s": 0.12, "turbulence_std_mps": 0.7},
}


class PlantConfig(Section):
    """The simulated AR.Drone closed loop (docs/plant.md, docs/plant-profiles.md)."""

    profile: Literal["ardrone", "thesis_kit", "ardrone_lab"] = Field(
        "ardrone", description="Plant backend and its defaults: 'ardrone' (tum_ardrone dynamics, "
        "firmware limits, the thesis' 0.26 s delay), 'thesis_kit' (the ARDrone Simulink "
        "Development Kit's linear identified channels; tau_*/drag_per_s unused), 'ardrone_lab' "
        "(ardrone with a 0.12 s delay and calibrated turbulence). docs/plant-profiles.md.")
    # Thesis simulator (ARDrone Simulink Development Kit) command delay block.
    command_delay_s: NonNegative = Field(
        0.26, le=2.0, description="Command transport delay T_d (s), ≤ 2.")
    # tum_ardrone EKF prediction model (Engel et al., IROS 2012).
    tau_tilt_s: Positive = Field(0.10, description="Roll/pitch first-order time constant τ_a (s).")
    # tum_ardrone EKF prediction model.
    tau_yaw_s: Positive = Field(0.10, description="Yaw-rate first-order time constant τ_r (s).")
    # Middle of the identifications bracketing it (0.17 s ROS simulator … 0.71 s tum_ardrone).
    tau_vz_s: Positive = Field(0.5, description="Vertical-speed time constant τ_z (s).")
    # tum_ardrone EKF constant c1 = 0.58.
    drag_per_s: NonNegative = Field(0.58, description="Horizontal linear drag k_d (1/s).")
    # docs/plant.md: fixed-step RK4 at 200 Hz for determinism.
    integration_step_s: float = Field(
        0.005, ge=1e-4, le=0.05, description="Fixed RK4 integration step (s), 0.1 … 50 ms; at "
        "most every time constant and 1 / drag_per_s (explicit RK4 is unstable beyond).")
    # Landed at the world origin.
    initial_position_m: CoordinateVec3 = Field(
        (0.0, 0.0, 0.0), description="Initial [x, y, z] (m), z ≥ 0.")
    initial_psi_rad: Finite = Field(0.0, description="Initial heading ψ (rad).")
    # A full battery.
    battery_start_pct: float = Field(100.0, ge=0, le=100, description="Initial battery (%).")
    # Project default, not identified: slow enough that long simulated runs are not cut short
    # by safety.battery_floor_pct (100 % → 20 % in ≈ 53 min).
    battery_drain_pct_per_min: NonNegative = Field(
        1.5, le=100.0, description="Battery drain while flying (% per minute), ≤ 100.")
    # 0 = still air; 'ardrone_lab' sets the value calibrated on the thesis' square.
    turbulence_std_mps: NonNegative = Field(
        0.0, le=5.0, description="Turbulence: σ (m/s) per horizontal axis of a Gauss–Markov "
        "wind added to sim faults' wind (0: none).")
    # Project choice (not identified): slow room-air drift, far slower than the tilt loops.
    turbulence_tau_s: Positive = Field(
        5.0, description="Turbulence correlation time τ (s) of the Gauss–Markov wind.")

    @model_validator(mode="before")
    @classmethod
    def _profile_defaults(cls, data: Any) -> Any:
        # a profile fills only the keys the config leaves out: explicit values win
        if isinstance(data, Mapping):
            defaults = PLANT_PROFILE_DEFAULTS.get(data.get("profile", "ardrone"), {})
            data = {**defaults, **data}
        return data

    @field_validator("initial_position_m")
    @classmethod
    def _above_ground(cls, value: tuple[float, ...]) -> tuple[float, ...]:
        if value[2] < 0:
            raise invalid("z must be ≥ 0 (the ground)")
        return value

    @field_validator("integration_step_s")
    @classmethod
    def _stable_step(cls, value: float, info: ValidationInfo) -> float:
        # h·λ ≤ 1 for every first-order mode (λ = 1/τ, drag): well inside RK4's stability
        # bound (2.79), where a tiny τ or a huge drag would make the plant blow up to NaN.
        for name in ("tau_tilt_s", "tau_yaw_s", "tau_vz_s"):
            tau = info.data.get(name)
            if tau is not None and value > tau:
                raise invalid(f"must be at most {name} ({value} > {tau})")
        drag = info.data.get("drag_per_s")
        if drag is not None and value * drag > 1.0:
            raise invalid(f"must be at most 1 / drag_per_s ({value} × {drag} > 1)")
        return value


class NoiseConfig(Section):
    """Simulated sensor noise, standard deviations (docs/plant.md table, docs/mocap-stream.md)."""

    # Upper bounds: far beyond any sensor (the reading is noise only), below float overflow.
    mocap_position_std_m: NonNegative = Field(
        0.0005, le=1.0, description="Mocap position σ per axis (m), ≤ 1.")
    mocap_angle_std_rad: NonNegative = Field(
        math.radians(0.1), le=math.pi, description="Mocap angle σ (rad), 0.1°; ≤ π.")
    mocap_latency_ms: float = Field(
        2.0, ge=0.0, le=50.0, description="Mocap stream latency (ms), 0–50: the lockstep runner "
        "samples only the newest frame a tick can see, which needs latency + frame period < "
        "the control period (65 ms); larger latencies would be silently capped.")
    navdata_attitude_std_rad: NonNegative = Field(
        math.radians(0.2), le=math.pi, description="Navdata roll/pitch σ (rad), 0.2°; ≤ π.")
    navdata_yaw_std_rad: NonNegative = Field(
        math.radians(0.3), le=math.pi, description="Navdata yaw σ (rad), 0.3°; ≤ π.")
    navdata_altitude_std_m: NonNegative = Field(
        0.010, le=10.0, description="Navdata ultrasound altitude σ (m), ≤ 10.")
    navdata_velocity_std_mps: NonNegative = Field(
        0.040, le=10.0, description="Navdata optical-flow vx, vy σ (m/s), ≤ 10.")


class TargetConfig(Section):
    """A scripted second object on the simulated mocap stream (e.g. a scale car on a loop),
    moving from the start of the simulation."""

    object_name: str = Field("car", min_length=1, max_length=24, description="Its mocap name.")
    path: Literal["circle", "figure8"] = Field("circle", description="The loop it drives.")
    center_m: CoordinateVec3 = Field(
        (0.0, 0.0, 0.0), description="Centre of the loop [x, y, z] (m).")
    radius_m: PathSize = Field(1.0, description="Circle radius / figure-8 half width (m).")
    speed_mps: NonNegative = Field(0.3, le=3.0, description="Speed along the loop (m/s).")

    _name = field_validator("object_name")(classmethod(lambda cls, v: ascii_name(v)))


class SimConfig(Section):
    """Simulation: seed, plant, sensor noise and stream rates."""

    seed: int = Field(0, ge=0, description="Seed of every random source of the simulation.")
    plant: PlantConfig = Field(default_factory=PlantConfig, description="Plant parameters.")
    noise: NoiseConfig = Field(default_factory=NoiseConfig, description="Sensor noise.")
    mocap_rate_hz: float = Field(
        100.0, ge=1.0, le=2000.0, description="Simulated mocap stream rate (Hz), 1 … 2000.")
    navdata_rate_hz: float = Field(
        15.0, ge=1.0, le=1000.0, description="Simulated navdata rate (Hz), 1 … 1000; 15 = demo.")
    target: Optional[TargetConfig] = Field(
        None, description="A scripted second object streamed on the mocap stream (null: none).")
    vz_gain: float = Field(
        1.0, gt=0.0, le=2.0, description="Disturbance: the plant's vertical speed is this times "
        "the commanded (a vertical gain mismatch, e.g. 0.7), full battery. Constant wind is "
        "faults.wind.")
    battery_sag_frac: float = Field(
        0.0, ge=0.0, lt=1.0, description="Disturbance: fraction of the vertical gain lost at "
        "0 % battery, linear in the discharge (battery sag: less thrust as it drains).")
    navdata_velocity_bias_mps: Vec2 = Field(
        (0.0, 0.0), description="Disturbance: constant bias of the navdata body velocities "
        "[forward, right] (m/s), on top of the drifting one.")
    settle_s: NonNegativeSpan = Field(
        4.0, description="Seconds the controller holds the reference's start point before t = 0 "
        "(logged with t_s < 0, mode 'settle'), so a step starts from rest as in the thesis; "
        "≤ 3600.")


# ----------------------------------------------------------------------------- safety


class SafetyConfig(Section):
    """Supervisor limits and policies (ardrone_nmpc/safety.py): outside them it holds the last
    command, falls back to the P controller, hovers or lands."""

    # z below the floor: a drone resting on it reads ±0.5 mm around 0, which is no breach.
    geofence_min_m: CoordinateVec3 = Field(
        (-3.0, -3.0, -0.2), description="Geofence lower corner [x, y, z] (m); z a little "
        "below the floor, so that mocap noise on the ground is no breach.")
    geofence_max_m: CoordinateVec3 = Field(
        (3.0, 3.0, 2.5), description="Geofence upper corner [x, y, z] (m).")
    geofence_action: Literal["land", "hover"] = Field(
        "land", description="What the drone does when its measured position leaves the geofence.")
    max_tilt_rad: Positive = Field(
        0.35, description="Largest roll/pitch (rad): commands are clipped to it, a measured "
        "(navdata) tilt beyond it makes the drone hover.")
    max_speed_mps: Positive = Field(
        2.0, description="Largest estimated speed (m/s); beyond it the drone hovers (brakes).")
    mocap_hold_ms: Positive = Field(
        100.0, description="Mocap pose age (ms) above which the last command is held.")
    mocap_hover_ms: Positive = Field(
        250.0, description="Mocap pose age (ms) above which the drone hovers; > mocap_hold_ms.")
    mocap_land_ms: Positive = Field(
        1000.0, description="Mocap pose age (ms) above which the drone lands; > mocap_hover_ms.")
    navdata_land_ms: Positive = Field(500.0, description="Navdata age (ms) above which it lands.")
    battery_floor_pct: float = Field(
        20.0, ge=0, le=100, description="Battery level (%) below which the drone lands.")
    solver_fallback: Literal["hold", "p", "hover"] = Field(
        "p", description="On solver failure, once solver_hold_ticks have passed: keep holding "
        "the last input (then hover after solver_hover_ticks), switch to the P controller, or "
        "hover.")
    solver_accept_max_iterations: bool = Field(
        True, description="Fly a solve that stopped at max_newton_iterations (its input is "
        "finite, bounded and better than its start guess; it happens on re-initialisation "
        "after a reference jump); false treats it as a failure.")
    solver_hold_ticks: int = Field(
        2, ge=0, le=20, description="Failed solves for which the last good command is held "
        "before the fallback (ticks).")
    solver_hover_ticks: int = Field(
        8, ge=1, le=200, description="With solver_fallback 'hold': failed solves before the "
        "drone hovers (ticks).")
    solver_recover_ticks: int = Field(
        3, ge=1, le=100, description="Consecutive good solves before the NMPC flies again "
        "(ticks).")

    _geofence = require_increasing("geofence_min_m", "geofence_max_m")
    _hover_after_hold = require_increasing("mocap_hold_ms", "mocap_hover_ms")
    _land_after_hover = require_increasing("mocap_hover_ms", "mocap_land_ms")


# ----------------------------------------------------------------------------- top level


class ExperimentConfig(Section):
    """One flight experiment."""

    name: str = Field(
        "experiment", pattern=r"^[A-Za-z0-9_.-]+$", max_length=MAX_NAME_CHARS,
        description="Experiment name, used in run directory names (letters, digits, '_', '.', "
        "'-'; at most 200, so that the directory name fits every file system).")
    duration_s: Span = Field(30.0, description="Length of the experiment (s), ≤ 3600.")
    controller: ControllerConfig = Field(default_factory=ControllerConfig, description="Controller.")
    estimator: EstimatorConfig = Field(default_factory=EstimatorConfig, description="Estimator.")
    reference: ReferenceConfig = Field(default_factory=ReferenceConfig, description="Reference.")
    loop: LoopConfig = Field(default_factory=LoopConfig, description="Control loop.")
    drone: DroneConfig = Field(default_factory=DroneConfig, description="Drone link and limits.")
    mocap: MocapConfig = Field(default_factory=MocapConfig, description="Mocap stream.")
    sim: SimConfig = Field(default_factory=SimConfig, description="Simulation.")
    safety: SafetyConfig = Field(default_factory=SafetyConfig, description="Supervisor limits.")
    faults: FaultsConfig = Field(default_factory=FaultsConfig, description="Injected faults (simulation).")

    @field_validator("reference")
    @classmethod
    def _lorenz_span(cls, value: ReferenceConfig, info: ValidationInfo) -> ReferenceConfig:
        duration_s = info.data.get("duration_s")
        if value.kind == "lorenz" and duration_s is not None:
            span = value.lorenz_time_scale * duration_s
            if span > MAX_LORENZ_TIME:
                raise invalid(f"lorenz_time_scale × duration_s is {span:g} Lorenz time units; "
                              f"at most {MAX_LORENZ_TIME:g} (the path is integrated over it)")
        return value

    @field_validator("reference")
    @classmethod
    def _start_outside_obstacles(cls, value: ReferenceConfig, info: ValidationInfo
                                 ) -> ReferenceConfig:
        """The experiment must not start inside an obstacle's constraint distance d, and it
        tracks at most one second mocap object (followed and/or a moving obstacle)."""
        controller = info.data.get("controller")
        if controller is None:  # reported on its own
            return value
        names = {o.mocap_object for o in controller.obstacles if o.mocap_object}
        if value.kind == "follow":
            names.add(value.follow.object_name)
        if len(names) > 1:
            raise invalid(f"one second mocap object per experiment, got {sorted(names)} "
                           "(follow.object_name and controller.obstacles.*.mocap_object)")
        for k, obs in enumerate(controller.obstacles):
            if obs.mocap_object:  # moving: where it starts is not known here
                continue
            offset = [p - c for p, c in zip(value.start_m, obs.center_m)]
            if obs.kind == "cylinder":
                offset[2] = 0.0
            distance = math.sqrt(sum(o * o for o in offset))
            d = obs.radius_m + obs.margin_m
            if distance < d:
                raise invalid(f"start_m {list(value.start_m)} is {distance:.3g} m from "
                               f"controller.obstacles.{k}, inside its radius + margin "
                               f"({d:.3g} m)")
        return value


# ----------------------------------------------------------------------------- validation


def _format_errors(exc: ValidationError) -> list[str]:
    messages = []
    for error in exc.errors():
        path = ".".join(str(part) for part in error["loc"]) or "(top level)"
        messages.append(f"{path}: {error['msg']}")
    return messages


def config_from_dict(data: Mapping[str, Any]) -> ExperimentConfig:
    """Validate a plain mapping (as YAML gives it). Raises :class:`ConfigError` listing every
    problem as a ``field.path: message`` line."""
    if not isinstance(data, Mapping):
        raise ConfigError(f"(top level): expected a mapping, got {type(data).__name__}")
    try:
        return ExperimentConfig.model_validate(dict(data))
    except ValidationError as exc:
        raise ConfigError(_format_errors(exc)) from None


def tracked_object(cfg: ExperimentConfig) -> str | None:
    """The second mocap object the experiment tracks (followed, or a moving obstacle), if any."""
    if cfg.reference.kind == "follow":
        return cfg.reference.follow.object_name
    return next((o.mocap_object for o in cfg.controller.obstacles if o.mocap_object), None)
