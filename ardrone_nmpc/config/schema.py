"""Experiment configuration: the YAML schema, loading, ``--set`` overrides and dumping.

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
    mocap:      {bind_host, port, object_name, rate_hz}
    sim:        {seed, plant: {…}, noise: {…}, mocap_rate_hz, navdata_rate_hz}
    safety:     {geofence_min_m, geofence_max_m, max_tilt_rad, …, solver_fallback}
    faults:     {mocap_dropout: {start_s, duration_s}, …}   (simulation only; all off by default)

Every key is optional: a missing key takes its default, and the defaults are the values of the
thesis (``specs/thesis.md``), the AR.Drone SDK (``specs/ardrone-protocol.md`` §3.1) and the plant
identification (``specs/plant.md``). Unknown keys, NaN/inf, out-of-range values and vectors of the
wrong length are errors. Every field carries its unit in its name and a description
(``ExperimentConfig.model_json_schema()`` lists them all).

Vectors are YAML lists, ordered like the thesis: states ``[x, ẋ, y, ẏ, z, ż, ψ]``, inputs
``[z̈, φ, θ, ψ̇]``, positions ``[x, y, z]`` in the world frame (x forward, y left, z up).

Errors are reported as a :class:`ConfigError` whose ``messages`` are ``field.path: message`` lines,
e.g. ``controller.solver.kmax: Input should be greater than or equal to 1``.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Annotated, Any, Literal, Optional

import yaml
from pydantic import (
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    ValidationError,
    ValidationInfo,
    field_validator,
)
from pydantic_core import PydanticCustomError

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
    "apply_overrides",
    "config_from_dict",
    "config_to_dict",
    "dump_config",
    "load_config",
]


class ConfigError(Exception):
    """Invalid configuration. ``messages`` are one-line ``field.path: message`` strings."""

    def __init__(self, messages: str | Sequence[str]) -> None:
        self.messages: list[str] = [messages] if isinstance(messages, str) else list(messages)
        super().__init__(self.messages)

    def __str__(self) -> str:
        return "\n".join(self.messages)


def _invalid(message: str) -> PydanticCustomError:
    return PydanticCustomError("config", "{message}", {"message": message})


# ----------------------------------------------------------------------------- field types

Finite = Annotated[float, Field(allow_inf_nan=False)]
Positive = Annotated[float, Field(gt=0, allow_inf_nan=False)]
NonNegative = Annotated[float, Field(ge=0, allow_inf_nan=False)]


def _vector(item: Any, length: int) -> Any:
    """A fixed-length tuple of ``item``; accepts a YAML list. A wrong length is one error at the
    vector itself (not a cascade of per-item errors)."""

    def check_length(value: Any) -> Any:
        if isinstance(value, (list, tuple)) and len(value) != length:
            raise _invalid(f"expected {length} values, got {len(value)}")
        return value

    return Annotated[
        tuple[item, ...],
        BeforeValidator(check_length),
        Field(json_schema_extra={"minItems": length, "maxItems": length}),
    ]


Vec2 = _vector(Finite, 2)
Vec3 = _vector(Finite, 3)
Vec4 = _vector(Finite, 4)
PositiveVec2 = _vector(Positive, 2)
PositiveVec4 = _vector(Positive, 4)
# Sizes of a reference path: a kilometre is already far beyond any mocap volume, and the path
# is sampled at 2 cm for the deviation metrics (1e300 m would not fit in memory).
PathSize = Annotated[float, Field(gt=0, le=1000.0, allow_inf_nan=False)]
PathSizeVec2 = _vector(PathSize, 2)
PathSizeVec4 = _vector(PathSize, 4)
NonNegativeVec7 = _vector(NonNegative, 7)
Port = Annotated[int, Field(ge=1, le=65535)]


def _require_increasing(lower_name: str, upper_name: str) -> Callable[..., Any]:
    """Validator for ``upper_name`` that requires it to exceed ``lower_name`` (declared earlier)
    elementwise; the error is reported at ``upper_name``."""

    def check(cls: type, value: Any, info: ValidationInfo) -> Any:
        lower = info.data.get(lower_name)
        if lower is None:  # the lower field itself failed and is reported on its own
            return value
        lows = lower if isinstance(lower, tuple) else (lower,)
        highs = value if isinstance(value, tuple) else (value,)
        for i, (lo, hi) in enumerate(zip(lows, highs)):
            if not lo < hi:
                where = f" at index {i}" if isinstance(value, tuple) else ""
                raise _invalid(f"must be greater than {lower_name}{where} ({hi} <= {lo})")
        return value

    return field_validator(upper_name)(classmethod(check))  # type: ignore[arg-type]


def _type_words(annotation: Any) -> str:
    """What a field takes, for error messages ("an integer", "a list of numbers", …)."""
    text = str(annotation)
    if "tuple" in text:
        return "a list of numbers"
    for kind, words in ((int, "an integer"), (float, "a number"), (str, "a string")):
        if annotation is kind or (kind.__name__ in text and "Literal" not in text):
            return words
    return "a value of another type"


class _Section(BaseModel):
    # validate_default: defaults go through the same checks (cross-field ones included).
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False,
                              validate_default=True)

    @field_validator("*", mode="before")
    @classmethod
    def _no_booleans_as_numbers(cls, value: Any, info: ValidationInfo) -> Any:
        # Lax mode would take YAML true/false as 1/0 (horizon_steps: true → 1): a boolean is
        # valid only where the field is declared bool.
        annotation = cls.model_fields[info.field_name].annotation
        if annotation is bool:
            return value
        items = value if isinstance(value, (list, tuple)) else (value,)
        for i, item in enumerate(items):
            if isinstance(item, bool):
                where = f" at index {i}" if items is value else ""
                raise _invalid(f"expected {_type_words(annotation)}, got the boolean "
                               f"{str(item).lower()}{where}")
        return value


# ----------------------------------------------------------------------------- controller


class SolverConfig(_Section):
    """Numerical settings of the NMPC solvers (thesis §3.3, Algorithm 1; Ohtsuka's C/GMRES)."""

    method: Literal["cgmres", "newton"] = Field(
        "cgmres", description="'cgmres': continuation/GMRES, one GMRES solve per tick; "
        "'newton': the thesis' per-step Newton iterations with fdgmres.")
    kmax: int = Field(5, ge=1, le=1000,
                      description="GMRES Krylov-subspace dimension per solve (count).")
    zeta_per_s: Positive = Field(
        15.0, description="Continuation stabilisation gain ζ (1/s): dF/dt = −ζ F.")
    fd_step: Positive = Field(
        1e-6, description="Forward-difference step h of Jacobian-vector products (dimensionless).")
    gmres_rtol: float = Field(
        1e-3, gt=0, lt=1, description="GMRES relative residual tolerance η (thesis Algorithm 1).")
    tolerance: Positive = Field(
        1e-4, description="Target ‖F‖ of Newton solves (initial solve and method 'newton').")
    max_newton_iterations: int = Field(20, ge=1, description="Newton iteration cap per solve.")
    dummy_weight: Positive = Field(
        0.01, description="Linear cost weight of the dummy inputs that enforce the input bounds.")
    bound_epsilon: NonNegative = Field(
        1e-3, description="ε of thesis eq. 3.25: an active bound C < 0 becomes C − ε = 0 ('newton').")
    horizon_ramp_rate_per_s: NonNegative = Field(
        0.0, description="α (1/s) in T(t) = N·Δτ·(1 − e^(−αt)); 0 = fixed horizon as in the thesis.")
    divergence_residual: Positive = Field(
        1e3, description="‖F‖ above which a solve counts as diverged and the solver re-initialises.")
    newton_trigger_residual: Positive = Field(
        100.0, description="C/GMRES: ‖F‖ at a new measurement above which the tick first "
        "re-projects onto F = 0 by Newton/GMRES warm-started from the current solution (a "
        "reference jump is an impulse the continuation cannot follow).")
    condensed: bool = Field(
        True, description="C/GMRES: eliminate the dummy inputs and multipliers per stage in closed "
        "form (4 unknowns per stage, not 12). Same equations; GMRES(5) stagnates on the "
        "uncondensed saddle-point system, so false is for comparison only.")


class PGainsConfig(_Section):
    """Gains of the baseline proportional controller (thesis eq. 4.16; the thesis gives none)."""

    k1_per_s: Positive = Field(0.7, description="ż_ref = k1 (z_d − z), 1/s (tuned in "
                               "simulation: see control/proportional.py PGains).")
    k2_rad_per_mps: Positive = Field(
        0.2, description="Roll φ per m/s of lateral speed error, rad/(m/s).")
    k3_rad_per_mps: Positive = Field(
        0.2, description="Pitch θ per m/s of forward speed error, rad/(m/s).")
    k4_per_s: Positive = Field(1.0, description="ψ̇ = k4 (ψ_d − ψ), 1/s.")


class ObstacleConfig(_Section):
    """A static obstacle the NMPC keeps out of: the constraint ‖p − c‖ ≥ d, d = radius + margin.

    A sphere measures the 3-D distance from its centre; a cylinder is vertical and unbounded
    in height and measures the horizontal distance only (its centre's z is ignored).
    """

    kind: Literal["sphere", "cylinder"] = Field(
        ..., description="'sphere' (3-D distance) or 'cylinder' (vertical; horizontal distance).")
    center_m: Vec3 = Field(..., description="Centre [x, y, z] (m); z is ignored for a cylinder.")
    radius_m: Positive = Field(..., description="Radius of the obstacle itself (m).")
    margin_m: NonNegative = Field(
        0.3, description="Safety margin added to the radius (m): the drone's half-size (≈ 0.26 m "
        "with the indoor hull) plus a buffer. The NMPC keeps the drone's centre d = radius + "
        "margin from the obstacle's centre.")
    mocap_object: Optional[str] = Field(
        None, min_length=1, max_length=24, description="A moving obstacle: the mocap object "
        "whose newest position is the centre each tick (center_m until it is first seen; the "
        "last position is kept when it goes stale). null: static.")


class ControllerConfig(_Section):
    """Controller choice and the optimal control problem (thesis eq. 3.14–3.16, 4.17)."""

    kind: Literal["nmpc", "p"] = Field(
        "nmpc", description="'nmpc': nonlinear MPC; 'p': proportional baseline (eq. 4.16).")
    horizon_steps: int = Field(15, ge=1, le=1000, description="Prediction horizon N (steps).")
    dtau_s: Positive = Field(0.1, description="Prediction step Δτ (s); horizon T = N·Δτ.")
    q: NonNegativeVec7 = Field(
        (12.0, 2.0, 7.0, 2.0, 5.0, 10.0, 13.0),
        description="State weights diag q, order [x, ẋ, y, ẏ, z, ż, ψ] (thesis §4.4).")
    r: PositiveVec4 = Field(
        (4.0, 12.0, 12.0, 24.0),
        description="Input weights diag r, order [z̈, φ, θ, ψ̇] (thesis 'Case 2').")
    q_terminal: NonNegativeVec7 = Field(
        (0.0,) * 7, description="Terminal state weights, order as q (the thesis has none).")
    u_min: Vec4 = Field(
        (-1.0, -1.0, -1.0, -1.0),
        description="Input lower bounds [m/s², rad, rad, rad/s] (thesis eq. 4.17).")
    u_max: Vec4 = Field(
        (1.0, 1.0, 1.0, 1.0),
        description="Input upper bounds [m/s², rad, rad, rad/s]; each above u_min (eq. 4.17).")
    vz_lead_s: Optional[Positive] = Field(
        0.5, description="ż reference = ż estimate + z̈ · vz_lead_s (s). The drone's vertical "
        "loop is a first-order lag; this inverts it exactly when vz_lead_s is its time "
        "constant (0.5 s: specs/plant.md, sim.plant.tau_vz_s). null = one control period, the "
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

    _u_bounds = _require_increasing("u_min", "u_max")


# ----------------------------------------------------------------------------- estimation


class EstimatorConfig(_Section):
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
        "(DESIGN §2; in simulation the x step settles in 2.5 s) or the drone's optical-flow "
        "navdata as in the thesis (its bias leaves a ±3 cm wander: 12.7 s).")


# ----------------------------------------------------------------------------- reference


def _ascii_object_name(value: str) -> str:
    if not value.isascii() or "\x00" in value:
        raise _invalid("must be ASCII without NUL characters")
    return value


class FollowConfig(_Section):
    """Reference kind 'follow': the drone follows a second object of the mocap stream."""

    object_name: str = Field(
        "car", min_length=1, max_length=24, description="Mocap name of the object to follow.")
    offset_m: Vec3 = Field(
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

    _name = field_validator("object_name")(classmethod(lambda cls, v: _ascii_object_name(v)))


class ReferenceConfig(_Section):
    """The desired trajectory x_d(t), world frame, metres and radians."""

    kind: Literal["hover", "step", "square", "square_altitudes", "ellipse", "lorenz", "path",
                  "follow"] = (
        Field("hover", description="Trajectory type; the fields below apply as noted. "
              "'follow' takes it live from a second mocap object (see follow)."))
    follow: FollowConfig = Field(
        default_factory=FollowConfig, description="Reference kind 'follow' only; before the "
        "object is seen, the reference holds start_m.")
    start_m: Vec3 = Field((0.0, 0.0, 1.0), description="Start position [x, y, z] (m).")
    start_psi_rad: Finite = Field(0.0, description="Start heading ψ (rad, counter-clockwise).")
    target_m: Vec3 = Field((0.0, 0.0, 1.0), description="Step target position [x, y, z] (m).")
    target_psi_rad: Finite = Field(0.0, description="Step target heading ψ (rad).")
    step_time_s: NonNegative = Field(1.0, description="Time of the step (s from start).")
    side_m: PathSize = Field(1.0, description="Square side length (m), ≤ 1000.")
    leg_duration_s: Positive = Field(
        5.0, description="Time per side of 'square' and 'square_altitudes' (s).")
    altitudes_m: PathSizeVec4 = Field(
        (0.8, 1.0, 1.2, 1.4), description="Corner altitudes of 'square_altitudes' (m), ≤ 1000.")
    center_m: Vec2 = Field((0.0, 0.0), description="Ellipse centre [x, y] (m).")
    semi_axes_m: PathSizeVec2 = Field(
        (1.0, 0.6), description="Ellipse semi-axes [a_x, a_y] (m), ≤ 1000.")
    period_s: Positive = Field(20.0, description="Time for one lap of the ellipse (s).")
    lorenz_scale_m: Positive = Field(
        0.05, le=1.0, description="Metres per Lorenz-system unit of the 'lorenz' path, ≤ 1.")
    lorenz_time_scale: Positive = Field(
        0.05, le=1.0, description="Lorenz-system time advanced per second of flight "
        "(dimensionless, ≤ 1); 0.05 keeps the scaled attractor under 1 m/s (peak ≈ 0.72 m/s at "
        "lorenz_scale_m 0.05).")
    path_file: Optional[str] = Field(
        None, validate_default=True,
        description="CSV waypoint file (t_s,x_m,y_m,z_m,psi_rad) for 'path'; relative paths in a "
        "config file are relative to that file's directory. Stored as an absolute path.")

    @field_validator("path_file")
    @classmethod
    def _check_path_file(cls, value: Optional[str], info: ValidationInfo) -> Optional[str]:
        if value is None:
            if info.data.get("kind") == "path":
                raise _invalid("required when kind is 'path'")
            return None
        base = (info.context or {}).get("base_dir")
        path = Path(value).expanduser()
        if not path.is_absolute():
            path = Path(base or ".") / path
        path = path.resolve()
        if not path.is_file():
            raise _invalid(f"no such file: {path}")
        # Read it now, so that `check` rejects what `simulate` would (non-monotonic time, a
        # bad cell: "<file>:<line>: …"). Imported here: reference imports this module.
        from ardrone_nmpc.reference.trajectories import ReferenceError, load_waypoints_csv

        try:
            load_waypoints_csv(path)
        except ReferenceError as exc:
            raise _invalid(str(exc)) from None
        return str(path)


# ----------------------------------------------------------------------------- hardware


class LoopConfig(_Section):
    """The control loop."""

    period_s: Positive = Field(
        0.065, ge=0.001, le=1.0,
        description="Control period (s), 1 ms … 1 s; 65 ms in the thesis.")


class DroneConfig(_Section):
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
    altitude_max_m: Positive = Field(3.0, description="control:altitude_max (m).")
    navdata_demo: bool = Field(True, description="general:navdata_demo: 15 Hz demo packets if true.")
    keepalive_interval_s: float = Field(
        0.03, gt=0, le=0.03, description="Longest gap between AT commands (s); ≤ 30 ms (§2.6).")
    control_port: Port = Field(
        5559, description="TCP port the drone dumps its configuration on (read back to verify "
        "the limits before take-off).")
    verify_config: bool = Field(
        True, description="Refuse to take off unless the configuration read back from "
        "control_port holds what was written; false flies unverified (with a loud warning).")
    config_ids: Optional[tuple[str, str, str]] = Field(
        None, description="Multiconfiguration [session, profile, application] ids (8 hex "
        "digits each): switched to at connect, and AT*CONFIG_IDS precedes every AT*CONFIG; "
        "null stays in the default session.")
    hull: Literal["indoor", "outdoor"] = Field(
        "indoor", description="The hull fitted: written as control:flight_without_shell "
        "(TRUE for the outdoor hull).")

    @field_validator("config_ids", mode="before")
    @classmethod
    def _quoted_ids(cls, value):
        if isinstance(value, (list, tuple)) and any(isinstance(v, int) for v in value):
            raise _invalid('quote ids made of digits only, e.g. "00000001" (YAML reads them '
                           "as numbers)")
        return value

    @field_validator("config_ids")
    @classmethod
    def _hex_ids(cls, value):
        if value is not None and not all(
                len(v) == 8 and all(c in "0123456789abcdefABCDEF" for c in v) for v in value):
            raise _invalid("each id must be 8 hex digits, e.g. [d2e081a3, be27e2e4, d87f7e0c]")
        return value


class MocapConfig(_Section):
    """The motion-capture pose stream (specs/mocap-stream.md)."""

    bind_host: str = Field("0.0.0.0", min_length=1, description="Local address to listen on.")
    port: Port = Field(51001, description="UDP port of the pose stream.")
    object_name: str = Field(
        "ardrone", min_length=1, max_length=24, description="Tracked object name (≤ 24 ASCII).")
    rate_hz: Positive = Field(100.0, description="Expected pose rate (Hz).")

    @field_validator("object_name")
    @classmethod
    def _ascii_name(cls, value: str) -> str:
        if not value.isascii() or "\x00" in value:
            raise _invalid("must be ASCII without NUL characters")
        return value


# ----------------------------------------------------------------------------- simulation


class PlantConfig(_Section):
    """The simulated AR.Drone closed loop (specs/plant.md)."""

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
    # specs/plant.md: fixed-step RK4 at 200 Hz for determinism.
    integration_step_s: float = Field(
        0.005, ge=1e-4, le=0.05, description="Fixed RK4 integration step (s), 0.1 … 50 ms; at "
        "most every time constant and 1 / drag_per_s (explicit RK4 is unstable beyond).")
    # Landed at the world origin.
    initial_position_m: Vec3 = Field((0.0, 0.0, 0.0), description="Initial [x, y, z] (m), z ≥ 0.")
    initial_psi_rad: Finite = Field(0.0, description="Initial heading ψ (rad).")
    # A full battery.
    battery_start_pct: float = Field(100.0, ge=0, le=100, description="Initial battery (%).")
    # Project default, not identified: slow enough that long simulated runs are not cut short
    # by safety.battery_floor_pct (100 % → 20 % in ≈ 53 min).
    battery_drain_pct_per_min: NonNegative = Field(
        1.5, description="Battery drain while flying (% per minute).")

    @field_validator("initial_position_m")
    @classmethod
    def _above_ground(cls, value: tuple[float, ...]) -> tuple[float, ...]:
        if value[2] < 0:
            raise _invalid("z must be ≥ 0 (the ground)")
        return value

    @field_validator("integration_step_s")
    @classmethod
    def _stable_step(cls, value: float, info: ValidationInfo) -> float:
        # h·λ ≤ 1 for every first-order mode (λ = 1/τ, drag): well inside RK4's stability
        # bound (2.79), where a tiny τ or a huge drag would make the plant blow up to NaN.
        for name in ("tau_tilt_s", "tau_yaw_s", "tau_vz_s"):
            tau = info.data.get(name)
            if tau is not None and value > tau:
                raise _invalid(f"must be at most {name} ({value} > {tau})")
        drag = info.data.get("drag_per_s")
        if drag is not None and value * drag > 1.0:
            raise _invalid(f"must be at most 1 / drag_per_s ({value} × {drag} > 1)")
        return value


class NoiseConfig(_Section):
    """Simulated sensor noise, standard deviations (specs/plant.md table, mocap-stream.md)."""

    mocap_position_std_m: NonNegative = Field(0.0005, description="Mocap position σ per axis (m).")
    mocap_angle_std_rad: NonNegative = Field(
        math.radians(0.1), description="Mocap angle σ (rad), 0.1°.")
    mocap_latency_ms: float = Field(
        2.0, ge=0.0, le=50.0, description="Mocap stream latency (ms), 0–50: the lockstep runner "
        "samples only the newest frame a tick can see, which needs latency + frame period < "
        "the control period (65 ms); larger latencies would be silently capped.")
    navdata_attitude_std_rad: NonNegative = Field(
        math.radians(0.2), description="Navdata roll/pitch σ (rad), 0.2°.")
    navdata_yaw_std_rad: NonNegative = Field(
        math.radians(0.3), description="Navdata yaw σ (rad), 0.3°.")
    navdata_altitude_std_m: NonNegative = Field(
        0.010, description="Navdata ultrasound altitude σ (m).")
    navdata_velocity_std_mps: NonNegative = Field(
        0.040, description="Navdata optical-flow vx, vy σ (m/s).")


class TargetConfig(_Section):
    """A scripted second object on the simulated mocap stream (e.g. a scale car on a loop),
    moving from the start of the simulation."""

    object_name: str = Field("car", min_length=1, max_length=24, description="Its mocap name.")
    path: Literal["circle", "figure8"] = Field("circle", description="The loop it drives.")
    center_m: Vec3 = Field((0.0, 0.0, 0.0), description="Centre of the loop [x, y, z] (m).")
    radius_m: Positive = Field(1.0, description="Circle radius / figure-8 half width (m).")
    speed_mps: NonNegative = Field(0.3, le=3.0, description="Speed along the loop (m/s).")

    _name = field_validator("object_name")(classmethod(lambda cls, v: _ascii_object_name(v)))


class SimConfig(_Section):
    """Simulation: seed, plant, sensor noise and stream rates."""

    seed: int = Field(0, ge=0, description="Seed of every random source of the simulation.")
    plant: PlantConfig = Field(default_factory=PlantConfig, description="Plant parameters.")
    noise: NoiseConfig = Field(default_factory=NoiseConfig, description="Sensor noise.")
    mocap_rate_hz: Positive = Field(100.0, description="Simulated mocap stream rate (Hz).")
    navdata_rate_hz: Positive = Field(15.0, description="Simulated navdata rate (Hz); 15 = demo.")
    target: Optional[TargetConfig] = Field(
        None, description="A scripted second object streamed on the mocap stream (null: none).")
    settle_s: NonNegative = Field(
        4.0, description="Seconds the controller holds the reference's start point before t = 0 "
        "(logged with t_s < 0, mode 'settle'), so a step starts from rest as in the thesis.")


# ----------------------------------------------------------------------------- safety


class SafetyConfig(_Section):
    """Supervisor limits and policies (ardrone_nmpc/safety.py): outside them it holds the last
    command, falls back to the P controller, hovers or lands."""

    # z below the floor: a drone resting on it reads ±0.5 mm around 0, which is no breach.
    geofence_min_m: Vec3 = Field(
        (-3.0, -3.0, -0.2), description="Geofence lower corner [x, y, z] (m); z a little "
        "below the floor, so that mocap noise on the ground is no breach.")
    geofence_max_m: Vec3 = Field((3.0, 3.0, 2.5), description="Geofence upper corner [x, y, z] (m).")
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
    start_tolerance_m: Positive = Field(
        0.5, description="Largest horizontal distance (m) between the drone's mocap position "
        "on the ground and the experiment's start; farther, take-off is refused.")
    heading_tolerance_rad: Positive = Field(
        0.2, description="Largest disagreement (rad) between the mocap heading change and "
        "navdata's yaw change during take-off; beyond it the drone lands (wrong object frame).")
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

    _geofence = _require_increasing("geofence_min_m", "geofence_max_m")
    _hover_after_hold = _require_increasing("mocap_hold_ms", "mocap_hover_ms")
    _land_after_hover = _require_increasing("mocap_hover_ms", "mocap_land_ms")


# ----------------------------------------------------------------------------- faults


class _FaultWindow(_Section):
    """A fault active from ``start_s`` for ``duration_s`` (experiment time: 0 = the end of the
    settle phase, the first tick of the experiment)."""

    start_s: Finite = Field(5.0, description="When the fault starts (s, experiment time).")
    duration_s: Positive = Field(1.0, description="How long it lasts (s).")


class MocapDropoutFault(_FaultWindow):
    """No mocap datagram arrives (network loss or tracker stall)."""

    repeat_every_s: Optional[Positive] = Field(
        None, description="Repeat the burst with this period (s) until the end; null = once.")


class MocapOcclusionFault(_FaultWindow):
    """Datagrams arrive but the object is missing (markers occluded) or its pose is zero."""

    zero_pose: bool = Field(False, description="Send an all-zero pose instead of omitting it.")


class MocapLatencyFault(_FaultWindow):
    """Mocap datagrams sent during the window arrive ``extra_latency_ms`` late."""

    extra_latency_ms: Positive = Field(200.0, description="Added latency (ms).")


class NavdataLossFault(_FaultWindow):
    """No navdata arrives."""


class NavdataCorruptFault(_FaultWindow):
    """Every navdata packet of the window is corrupted on the wire."""

    kind: Literal["checksum", "truncated", "zero_option"] = Field(
        "checksum", description="Bad checksum, truncated packet, or an option of size 0.")


class DisorderFault(_FaultWindow):
    """Datagrams of one stream duplicated and reordered (swapped with the next)."""

    stream: Literal["mocap", "navdata"] = Field("mocap", description="Which stream.")
    duplicate_probability: float = Field(0.3, ge=0, le=1, description="Chance a datagram is sent twice.")
    reorder_probability: float = Field(0.3, ge=0, le=1, description="Chance a datagram is held back behind the next.")


class AtLossFault(_FaultWindow):
    """AT datagrams lost before the drone: it keeps flying its last command."""

    probability: float = Field(1.0, gt=0, le=1, description="Chance each command is lost.")


class SolverDivergeFault(_FaultWindow):
    """The NMPC returns a diverged, non-finite solution every tick of the window."""


class BatteryFloorFault(_Section):
    """The battery drops to ``level_pct`` at ``start_s``."""

    start_s: Finite = Field(5.0, description="When (s, experiment time).")
    level_pct: float = Field(19.0, ge=0, le=100, description="Battery level it drops to (%).")


class EmergencyFault(_Section):
    """The drone raises its emergency state (motors cut) at ``start_s``."""

    start_s: Finite = Field(5.0, description="When (s, experiment time).")


class WindGustFault(_FaultWindow):
    """Air moving at ``velocity_mps`` (world frame) during the window; drag pushes the drone."""

    velocity_mps: Vec3 = Field((1.5, 0.0, 0.0), description="Gust air velocity [x, y, z] (m/s).")


class WindFault(_Section):
    """Constant wind for the whole flight (take-off included)."""

    velocity_mps: Vec3 = Field((0.5, 0.0, 0.0), description="Air velocity [x, y, z] (m/s).")


class DelayJumpFault(_Section):
    """The command transport delay jumps to ``delay_s`` at ``start_s``."""

    start_s: Finite = Field(5.0, description="When (s, experiment time).")
    delay_s: NonNegative = Field(0.5, le=2.0, description="New command delay (s).")


class FaultsConfig(_Section):
    """Injected faults (simulation only: ``simulate`` and ``fly --sim``); each is off (null)
    unless given, e.g. ``--set faults.mocap_dropout.start_s=5``."""

    mocap_dropout: Optional[MocapDropoutFault] = Field(None, description="Mocap dropout bursts.")
    mocap_occlusion: Optional[MocapOcclusionFault] = Field(None, description="Object occluded.")
    mocap_latency: Optional[MocapLatencyFault] = Field(None, description="Mocap latency spike.")
    navdata_loss: Optional[NavdataLossFault] = Field(None, description="Navdata lost.")
    navdata_corrupt: Optional[NavdataCorruptFault] = Field(None, description="Navdata corrupted.")
    disorder: Optional[DisorderFault] = Field(None, description="Duplicated/reordered datagrams.")
    at_loss: Optional[AtLossFault] = Field(None, description="AT commands lost (drone side).")
    solver_diverge: Optional[SolverDivergeFault] = Field(None, description="Solver forced to diverge.")
    battery_floor: Optional[BatteryFloorFault] = Field(None, description="Battery at the floor.")
    emergency: Optional[EmergencyFault] = Field(None, description="Emergency triggered.")
    wind_gust: Optional[WindGustFault] = Field(None, description="Wind gust on the plant.")
    wind: Optional[WindFault] = Field(None, description="Constant wind on the plant.")
    delay_jump: Optional[DelayJumpFault] = Field(None, description="Command-delay jump.")

    def active(self) -> list[str]:
        """Names of the faults that are set."""
        return [name for name in type(self).model_fields if getattr(self, name) is not None]


# ----------------------------------------------------------------------------- top level


class ExperimentConfig(_Section):
    """One flight experiment."""

    name: str = Field(
        "experiment", pattern=r"^[A-Za-z0-9_.-]+$", description="Experiment name, used in run "
        "directory names (letters, digits, '_', '.', '-').")
    duration_s: Positive = Field(30.0, description="Length of the experiment (s).")
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
            raise _invalid(f"one second mocap object per experiment, got {sorted(names)} "
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
                raise _invalid(f"start_m {list(value.start_m)} is {distance:.3g} m from "
                               f"controller.obstacles.{k}, inside its radius + margin "
                               f"({d:.3g} m)")
        return value


# ----------------------------------------------------------------------------- loading


class _UniqueKeyLoader(yaml.SafeLoader):
    """``yaml.SafeLoader`` that rejects duplicate keys instead of keeping the last one."""

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict[Any, Any]:
        seen: set[Any] = set()
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=deep)
            try:
                duplicate = key in seen
            except TypeError:  # unhashable key: the base class reports it
                break
            if duplicate:
                raise yaml.constructor.ConstructorError(
                    "while constructing a mapping", node.start_mark,
                    f"duplicate key {key!r}", key_node.start_mark)
            seen.add(key)
        return super().construct_mapping(node, deep=deep)


def _format_errors(exc: ValidationError) -> list[str]:
    messages = []
    for error in exc.errors():
        path = ".".join(str(part) for part in error["loc"]) or "(top level)"
        messages.append(f"{path}: {error['msg']}")
    return messages


def apply_overrides(data: Mapping[str, Any], overrides: Sequence[str]) -> dict[str, Any]:
    """Return a copy of ``data`` with each ``dotted.path=value`` override set.

    The value is parsed as YAML (``5`` → int, ``0.1`` → float, ``[1, 2]`` → list, ``null`` →
    None, ``p`` → str); missing intermediate mappings are created. Raises :class:`ConfigError`
    listing every malformed override.
    """
    result = copy.deepcopy(dict(data))
    errors = []
    for override in overrides:
        path, sep, text = override.partition("=")
        keys = path.strip().split(".")
        if not sep or any(not key.strip() for key in keys):
            errors.append(f"override {override!r}: expected dotted.path=value")
            continue
        keys = [key.strip() for key in keys]
        try:
            value = yaml.safe_load(text)
        except yaml.YAMLError as exc:
            errors.append(f"override {override!r}: invalid YAML value: {exc}".replace("\n", " "))
            continue
        node = result
        for depth, key in enumerate(keys[:-1]):
            child = node.setdefault(key, {})
            if not isinstance(child, dict):
                errors.append(f"override {override!r}: "
                              f"{'.'.join(keys[:depth + 1])} is not a mapping")
                break
            node = child
        else:
            node[keys[-1]] = value
    if errors:
        raise ConfigError(errors)
    return result


def config_from_dict(data: Mapping[str, Any], base_dir: str | Path | None = None
                     ) -> ExperimentConfig:
    """Validate a plain mapping; relative ``reference.path_file`` is resolved against
    ``base_dir`` (default: the working directory). Raises :class:`ConfigError`."""
    if not isinstance(data, Mapping):
        raise ConfigError(f"(top level): expected a mapping, got {type(data).__name__}")
    try:
        return ExperimentConfig.model_validate(dict(data), context={"base_dir": base_dir})
    except ValidationError as exc:
        raise ConfigError(_format_errors(exc)) from None


def _read_yaml(path: Path) -> dict[str, Any]:
    if not path.exists():
        raise ConfigError(f"{path}: no such file")
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{path}: cannot read: {exc}") from None
    try:
        data = yaml.load(text, Loader=_UniqueKeyLoader)  # noqa: S506 - a SafeLoader subclass
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        line = f" (line {mark.line + 1})" if mark is not None else ""
        problem = exc.problem or exc.context or "syntax error"
        raise ConfigError(f"{path}: invalid YAML{line}: {problem}") from None
    except yaml.YAMLError as exc:
        raise ConfigError(f"{path}: invalid YAML: {exc}".replace("\n", " ")) from None
    if data is None:
        # Most likely a truncated or wrong file; flying the default experiment instead would
        # be a surprise. `{}` (or no config at all) asks for the defaults explicitly.
        raise ConfigError(f"{path}: empty file (no settings); write {{}} in it for an "
                          "experiment with every default")
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: the top level must be a mapping of section names to "
                          f"values, not a {type(data).__name__}")
    return data


def tracked_object(cfg: ExperimentConfig) -> str | None:
    """The second mocap object the experiment tracks (followed, or a moving obstacle), if any."""
    if cfg.reference.kind == "follow":
        return cfg.reference.follow.object_name
    return next((o.mocap_object for o in cfg.controller.obstacles if o.mocap_object), None)


def load_config(path: str | Path | None = None, overrides: Sequence[str] = ()
                ) -> ExperimentConfig:
    """Load and validate an experiment.

    ``path`` None means all defaults. ``overrides`` (``dotted.path=value``) are merged before
    validation. A relative ``reference.path_file`` written in the file is resolved against the
    file's directory; one given by an override, against the working directory.
    Raises :class:`ConfigError` with every problem found.
    """
    data: dict[str, Any] = {}
    if path is not None:
        path = Path(path)
        data = _read_yaml(path)
        reference = data.get("reference")
        if isinstance(reference, dict) and isinstance(reference.get("path_file"), str):
            path_file = Path(reference["path_file"]).expanduser()
            if not path_file.is_absolute():
                reference["path_file"] = str(path.parent / path_file)
    return config_from_dict(apply_overrides(data, overrides))


class _Dumper(yaml.SafeDumper):
    """Block-style mappings, vectors on one line (``q: [12.0, 2.0, …]``)."""


_Dumper.add_representer(
    list, lambda dumper, data: dumper.represent_sequence(
        "tag:yaml.org,2002:seq", data, flow_style=True))


def config_to_dict(cfg: ExperimentConfig) -> dict[str, Any]:
    """The configuration as plain JSON/YAML-safe data (tuples become lists), declared order."""
    return cfg.model_dump(mode="json")


def dump_config(cfg: ExperimentConfig, header: str | None = None) -> str:
    """The configuration as YAML, keys in declared order, loadable by :func:`load_config`.

    ``header`` (e.g. the tool version) is written as leading ``#`` comment lines.
    """
    body = yaml.dump(config_to_dict(cfg), Dumper=_Dumper, sort_keys=False,
                     default_flow_style=False, allow_unicode=True, width=100)
    if not header:
        return body
    comments = "".join(f"# {line}".rstrip() + "\n" for line in header.splitlines())
    return comments + body
