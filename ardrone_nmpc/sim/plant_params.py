"""The airframe's parameters (:class:`PlantParams`): the ``drone`` limits, the ``sim.plant``
model constants, the on-board behaviour and the navdata biases of docs/plant.md, with the
right-hand side's coefficients derived once. Its own module so that
:mod:`~ardrone_nmpc.sim.plant` stays the plant's behaviour; imported from there too."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # config imports pydantic; the plant only reads attributes
    from ardrone_nmpc.config.schema import DroneConfig, SimConfig

__all__ = ["ATTITUDE_MODELS", "PlantParams"]

ATTITUDE_MODELS = ("lag", "second_order")


@dataclass(frozen=True, slots=True)
class PlantParams:
    """Parameters of :class:`AirframePlant` (SI units; docs/plant.md).

    The first three come from the ``drone`` config section (the limits written to the drone),
    the next ten from ``sim.plant``. The rest are fixed behaviour of the on-board controller
    and the navdata sensor biases of plant.md's noise table; they have no config key.
    """

    euler_angle_max_rad: float = 0.2094
    control_vz_max_mps: float = 0.7
    control_yaw_radps: float = 1.745
    command_delay_s: float = 0.26
    tau_tilt_s: float = 0.10
    tau_yaw_s: float = 0.10
    tau_vz_s: float = 0.5
    drag_per_s: float = 0.58
    integration_step_s: float = 0.005
    initial_position_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    initial_psi_rad: float = 0.0
    battery_start_pct: float = 100.0
    battery_drain_pct_per_min: float = 1.5
    # --- air turbulence (docs/plant-profiles.md): a horizontal Gauss–Markov wind, σ per axis
    turbulence_std_mps: float = 0.0
    turbulence_tau_s: float = 5.0
    # --- on-board behaviour (docs/protocol.md §5), no config key
    hover_tau_s: float = 0.5                 # optical-flow position hold: v_xy time constant
    takeoff_altitude_m: float = 0.9          # where the take-off climb settles
    takeoff_climb_mps: float = 0.5
    landing_speed_mps: float = 0.5
    takeoff_min_battery_pct: float = 20.0    # take-off refused below (node-ar-drone #6)
    # --- navdata biases (plant.md noise table), no config key; zero them for exact tests
    navdata_trim_bias_max_rad: float = math.radians(0.5)     # per flight, uniform ±
    navdata_yaw_drift_radps: float = math.radians(1.0) / 60.0  # per flight, random sign
    navdata_yaw_walk_rad_per_sqrt_s: float = math.radians(0.2) / math.sqrt(60.0)
    navdata_velocity_bias_std_mps: float = 0.02              # Gauss–Markov, stationary σ
    navdata_velocity_bias_tau_s: float = 30.0
    # --- disturbance options (sim section): vertical gain, its sag at 0 % battery, a bias
    vz_gain: float = 1.0
    battery_sag_frac: float = 0.0
    navdata_velocity_bias_mps: tuple[float, float] = (0.0, 0.0)  # (forward, right)
    # --- airframe deviations (sim.plant; docs/plant-profiles.md §4): tilt per unit command
    # relative to E, [roll, pitch]; the attitude loops' form; yaw rate per unit command
    # relative to Y
    attitude_gain: tuple[float, float] = (1.0, 1.0)
    attitude_model: str = "lag"              # "lag" (τ_a) or "second_order" (below)
    attitude_wn_radps: float = 3.45          # second order: natural frequency ω_n
    attitude_damping: float = 0.58           # second order: damping ratio ζ
    attitude_zero_s: float = 0.5             # second order: zero time constant T_z
    yaw_gain: float = 1.0
    # derived: extra damping of the position hold so that v_xy decays with τ = hover_tau_s
    hover_damping_per_s: float = field(init=False, repr=False)
    # derived: (E·gain_φ, G·V/τ_z, 1/τ_z, Y·gain_ψ/τ_r, 1/τ_r, 1/τ_a, k_d, hover damping,
    # E·gain_θ, a1, a0, b1, b0 of the second-order attitude form) for the RHS
    rhs_coefficients: tuple = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        for name in ("euler_angle_max_rad", "control_vz_max_mps", "control_yaw_radps",
                     "tau_tilt_s", "tau_yaw_s", "tau_vz_s", "integration_step_s", "hover_tau_s",
                     "takeoff_altitude_m", "takeoff_climb_mps", "landing_speed_mps",
                     "navdata_velocity_bias_tau_s", "turbulence_tau_s", "vz_gain",
                     "attitude_wn_radps", "attitude_damping", "yaw_gain"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"{name} must be finite and > 0, got {value!r}")
        for name in ("command_delay_s", "turbulence_std_mps", "attitude_zero_s"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f"{name} must be finite and >= 0, got {value!r}")
        gains = tuple(float(g) for g in self.attitude_gain)
        if len(gains) != 2 or not all(math.isfinite(g) and g > 0.0 for g in gains):
            raise ValueError(f"attitude_gain must be [roll, pitch], finite and > 0, "
                             f"got {self.attitude_gain!r}")
        object.__setattr__(self, "attitude_gain", gains)
        if self.attitude_model not in ATTITUDE_MODELS:
            raise ValueError(f"attitude_model must be one of {ATTITUDE_MODELS}, "
                             f"got {self.attitude_model!r}")
        if not 0.0 <= self.battery_sag_frac < 1.0:
            raise ValueError(f"battery_sag_frac must be in [0, 1), got {self.battery_sag_frac!r}")
        if len(self.initial_position_m) != 3 or self.initial_position_m[2] < 0.0:
            raise ValueError(f"initial_position_m must be [x, y, z] with z >= 0, "
                             f"got {self.initial_position_m!r}")
        object.__setattr__(self, "initial_position_m",
                           tuple(float(v) for v in self.initial_position_m))
        object.__setattr__(self, "navdata_velocity_bias_mps",
                           tuple(float(v) for v in self.navdata_velocity_bias_mps))
        damping = max(0.0, 1.0 / self.hover_tau_s - self.drag_per_s)
        object.__setattr__(self, "hover_damping_per_s", damping)
        wn, zeta = self.attitude_wn_radps, self.attitude_damping
        object.__setattr__(self, "rhs_coefficients", (
            self.euler_angle_max_rad * gains[0],
            self.vz_gain * self.control_vz_max_mps / self.tau_vz_s, 1.0 / self.tau_vz_s,
            self.control_yaw_radps * self.yaw_gain / self.tau_yaw_s, 1.0 / self.tau_yaw_s,
            1.0 / self.tau_tilt_s, self.drag_per_s, damping, self.euler_angle_max_rad * gains[1],
            2.0 * zeta * wn, wn * wn, wn * wn * self.attitude_zero_s, wn * wn))

    @property
    def second_order_attitude(self) -> bool:
        """The attitude loops are the second-order form with a zero (two more states)."""
        return self.attitude_model == "second_order"

    @classmethod
    def from_config(cls, sim_cfg: SimConfig, drone_cfg: DroneConfig, **overrides) -> PlantParams:
        """Build from the ``sim`` and ``drone`` config sections; ``overrides`` set any field."""
        plant = sim_cfg.plant
        return cls(
            euler_angle_max_rad=drone_cfg.euler_angle_max_rad,
            control_vz_max_mps=drone_cfg.control_vz_max_mps,
            control_yaw_radps=drone_cfg.control_yaw_radps,
            command_delay_s=plant.command_delay_s,
            tau_tilt_s=plant.tau_tilt_s,
            tau_yaw_s=plant.tau_yaw_s,
            tau_vz_s=plant.tau_vz_s,
            drag_per_s=plant.drag_per_s,
            integration_step_s=plant.integration_step_s,
            initial_position_m=tuple(plant.initial_position_m),
            initial_psi_rad=plant.initial_psi_rad,
            battery_start_pct=plant.battery_start_pct,
            battery_drain_pct_per_min=plant.battery_drain_pct_per_min,
            turbulence_std_mps=plant.turbulence_std_mps,
            turbulence_tau_s=plant.turbulence_tau_s,
            vz_gain=sim_cfg.vz_gain,
            battery_sag_frac=sim_cfg.battery_sag_frac,
            navdata_velocity_bias_mps=tuple(sim_cfg.navdata_velocity_bias_mps),
            attitude_gain=tuple(plant.attitude_gain),
            attitude_model=plant.attitude_model,
            attitude_wn_radps=plant.attitude_wn_radps,
            attitude_damping=plant.attitude_damping,
            attitude_zero_s=plant.attitude_zero_s,
            yaw_gain=plant.yaw_gain,
            **overrides,
        )

    @property
    def command_delay_steps(self) -> int:
        """Length of the command FIFO: round(command_delay_s / integration_step_s)."""
        return int(round(self.command_delay_s / self.integration_step_s))

    def vertical_gain(self, battery_pct: float) -> float:
        """G of the module docstring at ``battery_pct`` (%): vertical speed / commanded."""
        return self.vz_gain * (1.0 - self.battery_sag_frac
                               * (1.0 - min(max(battery_pct, 0.0), 100.0) / 100.0))

    def coefficients_at(self, battery_pct: float) -> tuple:
        """:attr:`rhs_coefficients` with the vertical gain sagged for ``battery_pct`` (%)."""
        k = self.rhs_coefficients
        if self.battery_sag_frac == 0.0:
            return k
        return (k[0], k[1] * self.vertical_gain(battery_pct) / self.vz_gain, *k[2:])

    def replace(self, **changes) -> PlantParams:
        """A copy with some fields changed (e.g. a command-delay fault)."""
        return replace(self, **changes)
