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

from ardrone_nmpc.config.controller import (ControllerConfig, ObstacleConfig, OffsetFreeConfig,
                                            PGainsConfig, SolverConfig)
from ardrone_nmpc.config.faults import FaultsConfig
from ardrone_nmpc.config.sim import (PLANT_PROFILE_DEFAULTS, NoiseConfig, PlantConfig, SimConfig,
                                     TargetConfig)
from ardrone_nmpc.config.fields import (
    CoordinateVec2, CoordinateVec3, Finite, Host, NonNegativeSpan, PathSize, PathSizeVec2, PathSizeVec3, PathSizeVec4, Port, Positive, PositiveVec2,
    Section, Span, ascii_name, invalid, require_increasing,
)
from ardrone_nmpc.config.limits import (FIRMWARE_TILT_MAX_RAD, KIT_PORT_LIMIT, MAX_LORENZ_TIME,
                                       MAX_NAME_CHARS)
from ardrone_nmpc.config.profiles import fill_profile_defaults
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
    "OffsetFreeConfig",
    "PGainsConfig",
    "PLANT_PROFILE_DEFAULTS",
    "PlantConfig",
    "ReferenceConfig",
    "SafetyConfig",
    "SimConfig",
    "SolverConfig",
    "TargetConfig",
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


class ExcitationConfig(Section):
    """Reference kind 'excitation': the identification flight (docs/identification.md §1) —
    pseudo-random steps of set points ±amplitude on x, then y, then z, then ψ around start_m,
    and sweeps at a constant speed on x and y."""

    amplitude_m: PathSizeVec3 = Field(
        (0.25, 0.25, 0.15), description="Step size on x, y, z (m): small, within the geofence.")
    amplitude_psi_rad: Positive = Field(0.4, le=math.pi, description="Step size on ψ (rad).")
    axis_s: Span = Field(10.0, description="Seconds of steps per axis.")
    bit_s: Positive = Field(
        1.2, ge=0.2, le=60.0, description="Seconds per bit of the pseudo-random sequence "
        "(0.2 … 60): long enough for the loop to answer, short enough to vary.")
    sweep_m: float = Field(
        0.4, ge=0.0, le=5.0, description="Reach of the x and y sweeps (m): the set point "
        "travels out to ±sweep_m and back at sweep_mps, so the drag shows; 0: no sweeps.")
    sweep_mps: Positive = Field(0.2, le=2.0, description="Speed of the sweeps (m/s).")
    rest_s: NonNegativeSpan = Field(2.0, description="Seconds at start_m after each axis.")


class ReferenceConfig(Section):
    """The desired trajectory x_d(t), world frame, metres and radians."""

    kind: Literal["hover", "step", "square", "square_altitudes", "ellipse", "lorenz", "path",
                  "follow", "excitation"] = (
        Field("hover", description="Trajectory type; the fields below apply as noted. "
              "'follow' takes it live from a second mocap object (see follow)."))
    follow: FollowConfig = Field(
        default_factory=FollowConfig, description="Reference kind 'follow' only; before the "
        "object is seen, the reference holds start_m.")
    excitation: ExcitationConfig = Field(
        default_factory=ExcitationConfig, description="Reference kind 'excitation' only: the "
        "identification flight's steps.")
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

    @property
    def stepped_axes(self) -> tuple[str, ...]:
        """A step's axes (``x``, ``y``, ``z``, ``psi``) whose target differs from their start;
        none for other kinds."""
        if self.kind != "step":
            return ()
        return tuple(a for a, y0, yf in zip(("x", "y", "z", "psi"),
                                            (*self.start_m, self.start_psi_rad),
                                            (*self.target_m, self.target_psi_rad)) if y0 != yf)

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
    """The AR.Drone link and the limits written to its configuration at connect (docs/protocol.md §3.1)."""

    host: Host = Field("192.168.1.1", description="Drone IP address or host name.")
    at_port: Port = Field(5556, description="UDP port of AT commands.")
    navdata_port: Port = Field(5554, description="UDP port of navdata.")
    euler_angle_max_rad: float = Field(
        0.2094, gt=0, le=0.52, description="control:euler_angle_max (rad): tilt at PCMD ±1.")
    control_vz_max_mps: float = Field(
        0.7, ge=0.2, le=2.0, description="control:control_vz_max (m/s): climb rate at PCMD gaz ±1.")
    control_yaw_radps: float = Field(
        1.745, ge=0.7, le=6.11, description="control:control_yaw (rad/s): yaw rate at PCMD yaw ±1.")
    command_convention: Literal["sdk", "kit"] = Field(
        "sdk", description="How a command becomes a PCMD fraction: 'sdk' — a fraction of the "
        "limits above (roll φ/euler_angle_max, gaz ż/control_vz_max, yaw −ψ̇/control_yaw; "
        "docs/design.md §4); 'kit' — the ARDrone Simulink Development Kit's: φ, θ in rad, ż in "
        "m/s, ψ̇ in rad/s written as the fraction itself, so the NMPC's bounds are ±1 (thesis "
        "eq. 4.17). The limits above still bound the drone. The thesis_kit profile sets 'kit' "
        "(docs/plant-profiles.md §2).")
    altitude_max_m: Positive = Field(
        3.0, le=100.0, description="control:altitude_max (m), ≤ 100 (the AR.Drone 2.0's cap).")
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
            raise invalid('quote ids made of digits only, e.g. "00000001" (YAML reads them '
                           "as numbers)")
        return value

    @field_validator("config_ids")
    @classmethod
    def _hex_ids(cls, value):
        if value is not None and not all(
                len(v) == 8 and all(c in "0123456789abcdefABCDEF" for c in v) for v in value):
            raise invalid("each id must be 8 hex digits, e.g. [d2e081a3, be27e2e4, d87f7e0c]")
        return value


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
    bind_host: Host = Field("0.0.0.0", description="vicon_udp: local address to listen on.")
    port: Port = Field(51001, description="vicon_udp: UDP port of the pose stream.")
    system: Literal[MOCAP_SYSTEMS] = Field(  # type: ignore[valid-type]
        "vicon", description="motioncapture: the library's system type (vicon = DataStream "
        "SDK, optitrack = NatNet, qualisys, vrpn, nokov, motionanalysis, fzmotion, mock).")
    hostname: Host = Field("localhost", description="motioncapture: the mocap server's "
                           "address (the library's 'hostname' option).")
    options: dict[str, str | int | float | bool] = Field(
        default_factory=dict, description="motioncapture: more library options, passed through "
        "as strings (e.g. port_command, interface_ip; mock: rigid_bodies, frequency).")
    up_axis: Optional[Literal["z", "y"]] = Field(
        None, description="motioncapture: the system's vertical axis; 'y' turns a right-handed "
        "Y-up frame into ours (x, -z, y). null: 'y' for optitrack, 'z' otherwise (set 'z' when "
        "Motive streams Z up).")
    connect_timeout_s: Positive = Field(
        5.0, le=60.0, description="motioncapture: how long to wait for the connection (s), "
        "≤ 60 (a longer wait would look like a hang).")
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
    # The limits below are bounded by the drone's physics and its firmware (docs/protocol.md
    # §2.6, §3.1, §5): a supervisor limit beyond them would never act.
    max_tilt_rad: float = Field(
        0.35, gt=0, le=KIT_PORT_LIMIT, description="Largest roll/pitch (rad), ≤ 0.52 (the "
        "firmware's euler_angle_max cap) under drone.command_convention 'sdk'; ≤ 1 (the "
        "port's saturation, in the port's units) under 'kit', which flies only simulated "
        "drones: commands are clipped to it, a measured (navdata) tilt beyond it makes the "
        "drone hover.")
    max_speed_mps: float = Field(
        2.0, gt=0, le=5.0, description="Largest estimated speed (m/s), ≤ 5 (the AR.Drone "
        "2.0's top speed); beyond it the drone hovers (brakes).")
    mocap_hold_ms: float = Field(
        100.0, gt=0, le=1000.0, description="Mocap pose age (ms) above which the last command "
        "is held; ≤ 1000.")
    mocap_hover_ms: float = Field(
        250.0, gt=0, le=2000.0, description="Mocap pose age (ms) above which the drone hovers; "
        "> mocap_hold_ms, ≤ 2000.")
    mocap_land_ms: float = Field(
        1000.0, gt=0, le=5000.0, description="Mocap pose age (ms) above which the drone lands; "
        "> mocap_hover_ms, ≤ 5000.")
    navdata_land_ms: float = Field(
        500.0, gt=0, le=2000.0, description="Navdata age (ms) above which it lands; ≤ 2000 "
        "(the drone itself declares the link lost after 2 s).")
    battery_floor_pct: float = Field(
        20.0, ge=20, le=100, description="Battery level (%) below which the drone lands; ≥ 20 "
        "(the firmware's own take-off threshold: a lower floor would never act).")
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

    @model_validator(mode="before")
    @classmethod
    def _profile_defaults(cls, data: Any) -> Any:
        # the plant profile's keys outside sim.plant (config/profiles.py); explicit values win
        return fill_profile_defaults(data)

    @field_validator("safety")
    @classmethod
    def _tilt_within_the_firmware(cls, value: SafetyConfig, info: ValidationInfo
                                  ) -> SafetyConfig:
        """Under the SDK's convention the tilt limit is a real angle the firmware caps at
        0.52 rad; the kit's convention (simulation only) measures it in the port's ±1."""
        drone = info.data.get("drone")
        if (drone is not None and drone.command_convention == "sdk"
                and value.max_tilt_rad > FIRMWARE_TILT_MAX_RAD):
            raise invalid(f"max_tilt_rad {value.max_tilt_rad:g} rad is beyond the firmware's "
                          f"euler_angle_max cap {FIRMWARE_TILT_MAX_RAD:g} rad (the "
                          "supervisor would never act); above it only under "
                          "drone.command_convention 'kit', in the port's units")
        return value

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
