"""The ``sim`` section: the simulated AR.Drone (plant profile, disturbances, sensor noise,
stream rates, the scripted second object) — docs/plant.md, docs/plant-profiles.md."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Annotated, Any, Literal, Optional

from pydantic import BeforeValidator, Field, ValidationInfo, field_validator, model_validator

from ardrone_nmpc.config.fields import (
    CoordinateVec3, Finite, NonNegative, NonNegativeSpan, PathSize, Positive, Section, Vec2, ascii_name, invalid,
    vector,
)


#: What each ``sim.plant.profile`` sets where the config leaves a key out (docs/plant-profiles.md).
PLANT_PROFILE_DEFAULTS: dict[str, dict[str, float]] = {
    "ardrone": {},       # the defaults below: tum_ardrone dynamics with the thesis' 0.26 s delay
    # the kit's identified channels (sim/plant_kit.py) with its timeDelay and simDT
    "thesis_kit": {"command_delay_s": 0.26, "integration_step_s": 0.005},
    # the real drone as identified: tum_ardrone's ≈ 0.12 s delay and the turbulence calibrated
    # on the thesis' experimental square (docs/plant-profiles.md §3)
    "ardrone_lab": {"command_delay_s": 0.12, "turbulence_std_mps": 0.7},
}


def _both_axes(value: Any) -> Any:
    """A single number for both roll and pitch."""
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return (value, value)
    return value


AttitudeGain = Annotated[vector(Annotated[float, Field(ge=0.05, le=5.0, allow_inf_nan=False)], 2),
                         BeforeValidator(_both_axes)]


def is_profile_file(profile: str) -> bool:
    """A ``sim.plant.profile`` that names a file rather than a built-in profile."""
    return profile.lower().endswith((".yaml", ".yml"))


class PlantConfig(Section):
    """The simulated AR.Drone closed loop (docs/plant.md, docs/plant-profiles.md)."""

    profile: str = Field(
        "ardrone", min_length=1, max_length=4096, description="Plant backend and its defaults: "
        "'ardrone' (tum_ardrone dynamics, firmware limits, the thesis' 0.26 s delay), "
        "'thesis_kit' (the ARDrone Simulink Development Kit's linear identified channels; "
        "tau_*/drag_per_s unused), 'ardrone_lab' (ardrone with a 0.12 s delay and calibrated "
        "turbulence), or a profile file (*.yaml, e.g. written by `ardrone-nmpc identify`: the "
        "ardrone backend with the file's values; relative paths in a config file are relative "
        "to that file's directory). docs/plant-profiles.md.")
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
    # --- how this airframe differs from the nominal one (docs/plant-profiles.md §4): the
    # region a real drone can be in, and what `identify` measures
    attitude_gain: AttitudeGain = Field(
        (1.0, 1.0), description="Tilt per unit PCMD roll/pitch, relative to "
        "drone.euler_angle_max_rad, [roll, pitch] (a number sets both); 1 = the firmware's "
        "nominal gain, the Simulink kit identified [1.33, 1.95]; 0.05 … 5.")
    attitude_model: Literal["lag", "second_order"] = Field(
        "lag", description="Form of the attitude loops: 'lag' (first order, tau_tilt_s) or "
        "'second_order' (ω_n² (1 + T_z s)/(s² + 2ζω_n s + ω_n²), the kit's identified form: "
        "attitude_wn_radps, attitude_damping, attitude_zero_s).")
    attitude_wn_radps: Positive = Field(
        3.45, le=100.0, description="second_order: natural frequency ω_n (rad/s); kit pitch "
        "3.45.")
    attitude_damping: Positive = Field(
        0.58, le=10.0, description="second_order: damping ratio ζ; kit pitch 0.58.")
    attitude_zero_s: NonNegative = Field(
        0.5, le=10.0, description="second_order: zero time constant T_z (s); kit pitch 0.52.")
    yaw_gain: Positive = Field(
        1.0, ge=0.05, le=5.0, description="Yaw rate per unit PCMD yaw, relative to "
        "drone.control_yaw_radps; 0.05 … 5.")

    @field_validator("profile")
    @classmethod
    def _known_profile(cls, value: str) -> str:
        if value not in PLANT_PROFILE_DEFAULTS and not is_profile_file(value):
            raise invalid(f"expected one of {', '.join(PLANT_PROFILE_DEFAULTS)} or a profile "
                          f"file (*.yaml), got {value!r}")
        return value

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

    @field_validator("attitude_zero_s")
    @classmethod
    def _stable_second_order(cls, value: float, info: ValidationInfo) -> float:
        # the second-order loops' fastest mode must stay well inside RK4's stability bound
        wn, step = info.data.get("attitude_wn_radps"), info.data.get("integration_step_s")
        if info.data.get("attitude_model") == "second_order" and wn and step and step * wn > 0.5:
            raise invalid(f"integration_step_s × attitude_wn_radps must be at most 0.5 "
                          f"({step} × {wn})")
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
