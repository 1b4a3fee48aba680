"""The simulated AR.Drone 2.0 closed loop, driven by PCMD fractions (docs/plant.md).

Model (per fixed RK4 step of ``integration_step_s``, commands delayed by ``command_delay_s``)::

    φ' = (c_roll·E − φ)/τ_a          θ' = (−c_pitch·E − θ)/τ_a        (world/model signs, below)
    r' = (−c_yaw·Y − r)/τ_r          ψ' = r
    v_z' = (G·c_gaz·V − v_z)/τ_z + k_d·w_z               z' = v_z
    forward = g·tan θ,  right = g·tan φ                  (body accelerations)
    v_x' =  cos ψ·forward + sin ψ·right − k_d·(v_x − w_x) [− d·v_x in position hold]
    v_y' =  sin ψ·forward − cos ψ·right − k_d·(v_y − w_y) [− d·v_y in position hold]

with c = the PCMD fractions ``command_delay_s`` ago, w = ``wind_mps`` (+ the turbulence, a
Gauss–Markov wind of ``turbulence_std_mps``) and d = max(0, 1/hover_tau_s − k_d), so that without
wind a hold damps v_xy with τ = hover_tau_s. This is the ``ardrone`` profile's backend; the
``thesis_kit`` one (:mod:`~ardrone_nmpc.sim.plant_kit`) replaces :meth:`_motors_on_step`
(docs/plant-profiles.md). G = ``vz_gain``·(1 − ``battery_sag_frac``·(1 − battery/100)): a
vertical gain mismatch and battery sag (``sim`` disturbance options, 1 nominally; constant
wind is ``faults.wind``, applied by :class:`~ardrone_nmpc.sim.faults.PlantFaults`).

Sign conventions
----------------
The plant's state uses the **world/model convention** of thesis eq. 3.13 (docs/design.md §4), so the
truth needs no conversion:

* world frame x forward, y left, z up; ψ counter-clockwise from +x, r = ψ̇ counter-clockwise;
* φ > 0 (right wing down) accelerates towards −y at ψ = 0 — the **same** sign as PCMD roll;
* θ > 0 (nose down) accelerates towards +x at ψ = 0 — the **opposite** sign of PCMD pitch
  (``θ_world = −θ_pcmd``; plant.md's ``θ' = (c_pitch·E − θ_pcmd)/τ_a`` and
  ``forward = −g·tan θ_pcmd`` become the lines above);
* PCMD yaw > 0 turns clockwise, so the yaw-rate reference is ``−c_yaw·Y`` (ψ decreases);
* PCMD gaz > 0 climbs.

The airframe's rotation (body → world) is ``R = Rz(ψ)·Ry(θ)·Rx(φ)`` about the body's
forward/left/up axes; its thrust axis ``R·e_z`` tilts exactly as eq. 3.13 (ẍ/z̈ ∝ tan θ,
ÿ/z̈ ∝ −tan φ / cos θ). The mocap stream reports the same R as intrinsic X→Y→Z angles.
Navdata reports the drone's own signs (see :class:`~ardrone_nmpc.core.types.NavdataSample`):
``roll_deg = deg(φ)``, ``pitch_deg = −deg(θ)``, ``yaw_deg = −deg(ψ) + offset + drift``, body
velocities forward / **right**, vertical speed **down** positive.

Flight modes
------------
``LANDED`` (motion frozen, PCMD ignored) → ``takeoff()`` → ``TAKING_OFF`` (on-board climb at
``takeoff_climb_mps`` with position hold; PCMD ignored) → ``FLYING`` once the climb will settle
at ``takeoff_altitude_m`` (≈ 0.9 m, about 2.5 s) → ``land()`` → ``LANDING`` (descent at
``landing_speed_mps`` with position hold) → ``LANDED`` at z = 0. ``emergency()`` cuts the
motors in any mode: the drone falls (g, horizontal drag only, tilt and yaw rate frozen), lies
on the ground and stays ``EMERGENCY`` until ``reset_emergency()`` on the ground. In ``FLYING`` the
delayed PCMD drives the loops; with the progressive flag at 0 the drone ignores all four
values (references 0) and its optical-flow position hold damps v_xy with τ = ``hover_tau_s``.
An initial altitude above 0 starts the plant ``FLYING`` (hovering). The battery drains at
``battery_drain_pct_per_min`` while the motors run (TAKING_OFF, FLYING, LANDING); at 0 % the
drone lands by itself. Take-off is refused below ``takeoff_min_battery_pct``.

Sensors
-------
Mocap (:meth:`AirframePlant.mocap_pose`): position + N(0, σ_p) per axis; the three XYZ angles
+ N(0, σ_a) each; ψ recomputed from the noisy angles. Navdata (:meth:`AirframePlant.navdata`):
roll/pitch + N(0, σ) + a per-flight trim bias uniform in ±0.5°; yaw + N(0, σ) + an offset
uniform in ±180° drawn at take-off + a drift of 1°/min (random sign per flight) with a small
random walk; ultrasound altitude + N(0, σ); body velocities + N(0, σ_v) + a Gauss–Markov bias
(σ 0.02 m/s, τ 30 s) + the constant ``navdata_velocity_bias_mps``; altitude and velocities read 0 with the motors off. The biases evolve in
:meth:`~AirframePlant.advance`; σ values come from ``sim.noise``, the bias sizes from
:class:`PlantParams` (zero them for exact tests).

Time
----
:meth:`AirframePlant.advance` integrates whole steps of ``integration_step_s``; a remainder
(more than 1e-9 s short of a whole step) is carried to the next call, so the plant's clock
``t_s`` = steps·h never runs ahead of the caller's and never drifts from it by ≥ one step.
"""

from __future__ import annotations

import math
import struct
from typing import TYPE_CHECKING, Optional

import numpy as np

from ardrone_nmpc.core.angles import wrap_angle_deg, wrap_angle_rad
from ardrone_nmpc.core.types import GRAVITY_MPS2, FlightMode, MocapPose, NavdataSample, PlantTruth
from ardrone_nmpc.sim.airframe import (N_STATE, _airframe_rhs, airframe_rk4, airframe_rk4_array,
                                       freefall_derivative, rk4_step)
from ardrone_nmpc.sim.command_fifo import CommandFifo
from ardrone_nmpc.sim.geometry import mocap_rotation_xyz_rad, rotation_heading_rad
from ardrone_nmpc.sim.held_state import holds_in_arrays
from ardrone_nmpc.sim.normal_blocks import NormalBlocks
from ardrone_nmpc.sim.plant_params import ATTITUDE_MODELS, PlantParams
from ardrone_nmpc.sim.plant_step import (AUTO_FLYING, AUTO_LANDED, AUTO_LANDING, AUTO_SAME,
                                         auto_steps, flying_advance)

if TYPE_CHECKING:  # config imports pydantic; the plant only reads attributes
    from ardrone_nmpc.config.schema import DroneConfig, NoiseConfig, SimConfig

__all__ = [
    "ATTITUDE_MODELS",
    "AirframePlant",
    "FlightMode",
    "PlantParams",
    "airframe_derivative",
    "freefall_derivative",
    "gauss_markov_step",
    "mocap_rotation_xyz_rad",
    "rk4_step",
    "rotation_heading_rad",
]

# State tuple layout: positions, world velocities, world/model tilt, heading and its rate.
STATE_NAMES = ("x_m", "y_m", "z_m", "vx_mps", "vy_mps", "vz_mps",
               "phi_rad", "theta_rad", "psi_rad", "psirate_radps")
# Command tuple layout: PCMD fractions (drone signs) and the position-hold flag.
COMMAND_NAMES = ("roll_frac", "pitch_frac", "gaz_frac", "yaw_frac", "position_hold")

_HOVER = (0.0, 0.0, 0.0, 0.0, True)   # what the drone does with the progressive flag at 0
_NO_WIND = (0.0, 0.0, 0.0)
_TIME_TOL_S = 1e-9
_PACK = {n: struct.Struct(f"{n}d").pack for n in (3, 6)}
#: what auto_steps does in the plant's place: a backend overriding any of it keeps its steps
_AUTO = ("_substep", "_motors_on_step", "_auto_command", "_ground_contact", "_check_transitions",
         "_at_rest")
_AUTO_MODES = {AUTO_FLYING: FlightMode.FLYING, AUTO_LANDING: FlightMode.LANDING,
               AUTO_LANDED: FlightMode.LANDED}


# ----------------------------------------------------------------------------- dynamics


def airframe_derivative(state: tuple, command: tuple, params: PlantParams,
                        wind_mps: tuple = _NO_WIND) -> tuple:
    """Right-hand side of the motors-on plant (module docstring), pure.

    Parameters
    ----------
    state : 10-tuple ``(x, y, z, vx, vy, vz, φ, θ, ψ, r)`` (m, m/s, rad, rad/s; world/model signs).
    command : 5-tuple ``(roll, pitch, gaz, yaw, position_hold)``: the *delayed* PCMD fractions in
        drone signs and a bool. ``position_hold`` zeroes the tilt references and adds the hold
        damping; gaz and yaw still act (the plant passes zeros for a progressive flag of 0, and
        the automatic take-off/landing climb rate as gaz).
    params : PlantParams
    wind_mps : (wx, wy, wz) air velocity; drag acts on v − w, the vertical loop sees k_d·w_z.

    A 12-tuple state (the hidden states η_φ, η_θ appended) takes the second-order attitude
    form of ``params``; a 10-tuple the first-order lag.

    Returns
    -------
    tuple, the time derivative of ``state``.
    """
    roll, pitch, gaz, yaw, hold = command
    out = np.empty(len(state))
    _airframe_rhs(np.asarray(state, dtype=np.float64), float(roll), float(pitch), float(gaz),
                  float(yaw), bool(hold), params.rhs_coefficients,
                  tuple(float(w) for w in wind_mps), out)
    return tuple(out.tolist())


# ----------------------------------------------------------------------------- backends


def gauss_markov_step(values: tuple, std: float, tau_s: float, dt_s: float, normals) -> tuple:
    """Independent Gauss–Markov processes (stationary σ ``std``, correlation time ``tau_s``)
    advanced exactly over ``dt_s`` with standard normal draws ``normals``."""
    a = math.exp(-dt_s / tau_s)
    q = std * math.sqrt(1.0 - a * a)
    return tuple(a * v + q * n for v, n in zip(values, normals))


def _finite_frac(name: str, value: float) -> float:
    v = float(value)
    if not math.isfinite(v):
        raise ValueError(f"{name} must be finite, got {v!r}")
    return min(1.0, max(-1.0, v))


def _readonly(*values: float) -> np.ndarray:
    """A read-only float64 array: one over immutable bytes (half the cost of a flags call)."""
    return np.frombuffer(_PACK[len(values)](*values))


# ----------------------------------------------------------------------------- the plant


# what the lockstep's compiled legs may hold in their arrays between their runs (a read while
# they do writes them back first: sim/held_state.py)
@holds_in_arrays("_state", "_tilt_aux", "_steps", "_pending_s", "_battery", "_yaw_bias_deg",
                 "_vel_bias", "_gust_mps", "_current", "_fifo", "_bias_normals",
                 "_gust_normals", "_mocap_normals", "_nav_normals")
class AirframePlant:
    """The AR.Drone 2.0 with its on-board controller, as the ground station sees it.

    Deterministic for a seed: the truth depends only on the calls made; the mocap, navdata and
    sensor-bias noise come from three independent streams spawned from
    ``np.random.default_rng(seed)``, so sampling one sensor more often does not change another.

    Attributes
    ----------
    params : PlantParams
    noise : NoiseConfig (or any object with its fields)
    wind_mps : (3,) ndarray, air velocity in the world frame (m/s), default zeros; for fault
        injection, read at the start of each :meth:`advance`.
    """

    def __init__(self, params: PlantParams, noise: Optional[NoiseConfig] = None, *,
                 seed: int = 0) -> None:
        if noise is None:
            from ardrone_nmpc.config.schema import NoiseConfig
            noise = NoiseConfig()
        self.params = params
        self.noise = noise
        self.wind_mps = np.zeros(3)
        self._held_by = None  # the compiled legs holding some attributes (sim/held_state.py)
        root = np.random.default_rng(seed)
        # a fourth stream for the turbulence: spawn(4)'s first three equal spawn(3)'s, so the
        # sensor noise of a seed does not depend on the turbulence setting
        self._mocap_rng, self._nav_rng, self._bias_rng, self._gust_rng = root.spawn(4)
        self._gust_mps = tuple(params.turbulence_std_mps * v
                               for v in self._gust_rng.standard_normal(2))
        x, y, z = params.initial_position_m
        psi = wrap_angle_rad(float(params.initial_psi_rad))
        self._state = (x, y, z, 0.0, 0.0, 0.0, 0.0, 0.0, psi, 0.0)
        self._mode = FlightMode.FLYING if z > 0.0 else FlightMode.LANDED
        self._battery = float(params.battery_start_pct)
        self._steps = 0
        self._pending_s = 0.0
        self._current = _HOVER
        self._fifo = CommandFifo([_HOVER] * params.command_delay_steps)
        self._tilt_aux = (0.0, 0.0)  # η_φ, η_θ of the second-order attitude form
        self._vel_bias = tuple(params.navdata_velocity_bias_std_mps * v
                               for v in self._bias_rng.standard_normal(2))
        # the per-sample and per-advance normals, drawn ahead a block at a time (the same
        # values in the same order: sim/normal_blocks.py)
        self._mocap_normals, self._nav_normals, self._bias_normals, self._gust_normals = (
            NormalBlocks(rng) for rng in (self._mocap_rng, self._nav_rng, self._bias_rng,
                                          self._gust_rng))
        self._new_flight_biases()

    @classmethod
    def from_config(cls, sim_cfg: SimConfig, drone_cfg: DroneConfig, *,
                    seed: int | None = None) -> AirframePlant:
        """The plant of an experiment's ``sim`` and ``drone`` sections, seeded by ``seed``
        (default ``sim.seed``). This class only: :func:`~ardrone_nmpc.sim.backends.make_plant`
        picks the backend ``sim.plant.profile`` names (docs/plant-profiles.md)."""
        return cls(PlantParams.from_config(sim_cfg, drone_cfg), sim_cfg.noise,
                   seed=sim_cfg.seed if seed is None else seed)

    # ------------------------------------------------------------------ commands and modes

    @property
    def mode(self) -> FlightMode:
        return self._mode

    @property
    def t_s(self) -> float:
        """Plant time (s): whole integration steps since construction."""
        return self._steps * self.params.integration_step_s

    @property
    def battery_pct(self) -> float:
        return self._battery

    @property
    def moving(self) -> bool:
        """The current PCMD is progressive with a non-zero value (the drone is *flying* a
        command rather than hovering; its navdata ctrl_state tells the two apart)."""
        return any(self._current[:4]) and not self._current[4]

    def command(self, roll_frac: float, pitch_frac: float, gaz_frac: float, yaw_frac: float,
                *, progressive: bool = True) -> None:
        """Set the current PCMD (drone signs), held until the next call.

        Each fraction is clipped to [−1, 1]; it reaches the loops ``command_delay_s`` later.
        ``progressive=False`` is the hover command: all four values are ignored.

        Raises
        ------
        ValueError
            If any fraction is not finite (nothing is changed).
        """
        values = (_finite_frac("roll_frac", roll_frac), _finite_frac("pitch_frac", pitch_frac),
                  _finite_frac("gaz_frac", gaz_frac), _finite_frac("yaw_frac", yaw_frac))
        self._current = (*values, False) if progressive else _HOVER

    def takeoff(self) -> bool:
        """LANDED → TAKING_OFF (refused below ``takeoff_min_battery_pct``). True if accepted."""
        if (self._mode is not FlightMode.LANDED
                or self._battery < self.params.takeoff_min_battery_pct):
            return False
        self._mode = FlightMode.TAKING_OFF
        self._new_flight_biases()
        self._tilt_aux = (0.0, 0.0)
        return True

    def land(self) -> bool:
        """TAKING_OFF or FLYING → LANDING. True if accepted."""
        if self._mode not in (FlightMode.TAKING_OFF, FlightMode.FLYING):
            return False
        self._mode = FlightMode.LANDING
        return True

    def emergency(self) -> bool:
        """Cut the motors (any mode but EMERGENCY). True if it changed the mode."""
        if self._mode is FlightMode.EMERGENCY:
            return False
        self._mode = FlightMode.EMERGENCY
        if self._state[2] <= 0.0:  # already on the ground: it stops where it is
            self._state = self._at_rest(self._state)
        return True

    def reset_emergency(self) -> bool:
        """EMERGENCY → LANDED, only once on the ground (z = 0). True if accepted."""
        if self._mode is not FlightMode.EMERGENCY or self._state[2] > 0.0:
            return False
        self._mode = FlightMode.LANDED
        self._state = self._at_rest(self._state)
        return True

    # ------------------------------------------------------------------ faults

    def set_battery_pct(self, level_pct: float) -> None:
        """Fault injection: the battery reads ``level_pct`` (%) from now on (then drains)."""
        if not (math.isfinite(level_pct) and 0.0 <= level_pct <= 100.0):
            raise ValueError(f"level_pct must be in [0, 100], got {level_pct!r}")
        self._battery = float(level_pct)

    def set_command_delay_s(self, delay_s: float) -> None:
        """Fault injection: the command transport delay becomes ``delay_s`` (s) now.

        A longer delay repeats the oldest queued command (the drone flies it longer); a
        shorter one drops the oldest queued commands (they never act).
        """
        if not (math.isfinite(delay_s) and delay_s >= 0.0):
            raise ValueError(f"delay_s must be finite and >= 0, got {delay_s!r}")
        self.params = self.params.replace(command_delay_s=float(delay_s))
        self._fifo = self._fifo.resized(self.params.command_delay_steps, self._current)

    # ------------------------------------------------------------------ time

    def advance(self, dt_s: float) -> None:
        """Advance plant time by ``dt_s`` (s) in whole RK4 steps; the remainder is carried.

        Raises
        ------
        ValueError
            If ``dt_s`` is negative or not finite.
        """
        dt = float(dt_s)
        if not (math.isfinite(dt) and dt >= 0.0):
            raise ValueError(f"dt_s must be finite and >= 0, got {dt_s!r}")
        h = self.params.integration_step_s
        pending = self._pending_s + dt
        n = int(math.floor((pending + _TIME_TOL_S) / h))
        self._pending_s = max(0.0, pending - n * h)
        if n == 0:
            return
        p = self.params
        wind = tuple(map(float, self.wind_mps))
        if p.turbulence_std_mps > 0.0:
            wind = (wind[0] + self._gust_mps[0], wind[1] + self._gust_mps[1], wind[2])
        normals = self._bias_normals.take(3)  # the biases' draws (their stream alone)
        mode = self._mode
        if mode is FlightMode.FLYING:
            done = self._flying_advance(n, h, wind, normals)
        else:
            done = self._auto_advance(n, h, wind) if mode.airborne else 0  # take-off, landing
        if done < n or mode is not FlightMode.FLYING:  # (all flown: _flying_advance did it)
            for _ in range(n - done):
                self._substep(h, wind)
            x, y, z, vx, vy, vz, phi, theta, psi, r = self._state
            self._state = (x, y, z, vx, vy, vz, phi, theta, wrap_angle_rad(psi), r)
            self._advance_biases(n * h, normals)
        if p.turbulence_std_mps > 0.0:  # docs/plant-profiles.md §3, held within one call
            self._gust_mps = gauss_markov_step(self._gust_mps, p.turbulence_std_mps,
                                               p.turbulence_tau_s, n * h,
                                               self._gust_normals.take(2))

    def _flying_advance(self, n: int, h: float, wind: tuple, normals: np.ndarray) -> int:
        """Up to ``n`` FLYING substeps in one compiled call (:func:`flying_advance`), the same
        arithmetic as :meth:`_substep`'s, without its per-step Python — the simulator's
        largest cost per tick — and, when all ``n`` were flown, the heading's wrap and
        :meth:`_advance_biases` too. Leaves to :meth:`_substep` the steps that would empty
        the battery (a mode change). Returns the steps done."""
        p = self.params
        # a backend with other dynamics (its own _motors_on_step) keeps the step-by-step path
        if type(self)._motors_on_step is not AirframePlant._motors_on_step:
            return 0
        fifo, (roll, pitch, gaz, yaw, hold) = self._fifo, self._current
        done, fifo.head, self._battery, x, yaw_bias, vb0, vb1 = flying_advance(
            self._state_array(), fifo.rows, fifo.head, roll, pitch, gaz, yaw, hold,
            p.rhs_coefficients, wind, h, n, self._battery,
            p.battery_drain_pct_per_min * h / 60.0, p.vz_gain, p.battery_sag_frac, normals,
            self._yaw_bias_deg,
            *self._vel_bias, self._yaw_drift_sign * p.navdata_yaw_drift_radps,
            p.navdata_yaw_walk_rad_per_sqrt_s, p.navdata_velocity_bias_std_mps,
            p.navdata_velocity_bias_tau_s)
        self._steps += done
        self._state = self._from_state_array(x)
        if done == n:
            self._yaw_bias_deg, self._vel_bias = yaw_bias, (vb0, vb1)
        return done

    def _auto_advance(self, n: int, h: float, wind: tuple) -> int:
        """Up to ``n`` substeps of the automatic take-off or landing in one compiled call
        (:func:`auto_steps`, :meth:`_substep`'s arithmetic), up to the mode change that ends
        them; the caller wraps the heading and advances the biases. Returns the steps done."""
        mode, kind = self._mode, type(self)
        if any(getattr(kind, name) is not getattr(AirframePlant, name) for name in _AUTO):
            return 0  # a backend's own steps (or a test's stepwise plant) keep them
        p, fifo, (roll, pitch, gaz, yaw, hold) = self.params, self._fifo, self._current
        done, fifo.head, self._battery, x, new_mode = auto_steps(
            self._state_array(), fifo.rows, fifo.head, roll, pitch, gaz, yaw, hold,
            mode is FlightMode.LANDING, self._auto_command(mode)[2], p.rhs_coefficients, wind,
            h, n, self._battery, p.battery_drain_pct_per_min * h / 60.0, p.vz_gain,
            p.battery_sag_frac, p.tau_vz_s, p.takeoff_altitude_m)
        self._steps += done
        self._state = self._from_state_array(x)
        if new_mode != AUTO_SAME:
            self._mode = _AUTO_MODES[new_mode]
        return done

    def _substep(self, h: float, wind: tuple) -> None:
        delayed = self._fifo.shift(self._current)  # the command of command_delay_steps ago
        self._steps += 1
        mode = self._mode
        if mode is FlightMode.FLYING:
            deriv, command = airframe_derivative, delayed
        elif mode is FlightMode.TAKING_OFF or mode is FlightMode.LANDING:
            deriv, command = airframe_derivative, self._auto_command(mode)
        elif mode is FlightMode.EMERGENCY and self._state[2] > 0.0:
            deriv, command = freefall_derivative, _HOVER
        else:
            return  # LANDED, or EMERGENCY lying on the ground: frozen
        if deriv is airframe_derivative:
            state = self._motors_on_step(command, h, wind)
        else:
            state = rk4_step(deriv, self._state, h, command, self.params, wind)
        self._state = state if state[2] > 0.0 else self._ground_contact(state)
        if deriv is airframe_derivative:  # motors on
            drain = self.params.battery_drain_pct_per_min * h / 60.0
            self._battery = max(0.0, self._battery - drain)
            if mode is not FlightMode.FLYING or self._battery <= 0.0:
                self._check_transitions()

    def _motors_on_step(self, command: tuple, h: float, wind: tuple) -> tuple:
        """One step of the motors-on dynamics from ``self._state`` (the backend's hook: a
        profile with other dynamics overrides this, the modes, sensors and faults stay)."""
        roll, pitch, gaz, yaw, hold = command  # the compiled twin of rk4_step(airframe_derivative)
        k = self.params.coefficients_at(self._battery)
        if self.params.second_order_attitude:
            x = airframe_rk4_array(self._state_array(), float(roll), float(pitch), float(gaz),
                                   float(yaw), bool(hold), k, tuple(map(float, wind)), h)
            return self._from_state_array(x)
        return airframe_rk4(self._state, float(roll), float(pitch), float(gaz), float(yaw),
                            bool(hold), k, tuple(map(float, wind)), h)

    def _state_array(self) -> np.ndarray:
        """The state as the kernels take it (with the second-order form's hidden states)."""
        if self.params.second_order_attitude:
            return np.array((*self._state, *self._tilt_aux), dtype=np.float64)
        return np.array(self._state, dtype=np.float64)

    def _from_state_array(self, x: np.ndarray) -> tuple:
        """The 10-tuple state of a kernel's array, its hidden states kept aside."""
        values = x.tolist()
        if len(values) > N_STATE:
            self._tilt_aux = (values[N_STATE], values[N_STATE + 1])
        return tuple(values[:N_STATE])

    def _auto_command(self, mode: FlightMode) -> tuple:
        p = self.params
        speed = p.takeoff_climb_mps if mode is FlightMode.TAKING_OFF else -p.landing_speed_mps
        return (0.0, 0.0, speed / p.control_vz_max_mps, 0.0, True)

    def _ground_contact(self, state: tuple) -> tuple:
        """z ≤ 0: LANDING touches down (→ LANDED), a falling drone comes to rest, a flying one
        stops at the floor."""
        if self._mode is FlightMode.LANDING:
            self._mode = FlightMode.LANDED
            return self._at_rest(state)
        if self._mode is FlightMode.EMERGENCY:
            return self._at_rest(state)
        x, y, _, vx, vy, vz, phi, theta, psi, r = state
        return (x, y, 0.0, vx, vy, max(vz, 0.0), phi, theta, psi, r)

    @staticmethod
    def _at_rest(state: tuple) -> tuple:
        x, y, _, _, _, _, _, _, psi, _ = state
        return (x, y, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, psi, 0.0)

    def _check_transitions(self) -> None:
        mode = self._mode
        if mode is FlightMode.TAKING_OFF:
            z, vz = self._state[2], self._state[5]
            # the vertical loop still rises vz·τ_z after its reference drops to 0
            if z + vz * self.params.tau_vz_s >= self.params.takeoff_altitude_m:
                self._mode = FlightMode.FLYING
        if self._battery <= 0.0 and self._mode in (FlightMode.TAKING_OFF, FlightMode.FLYING):
            self._mode = FlightMode.LANDING

    # ------------------------------------------------------------------ sensor biases

    def _new_flight_biases(self) -> None:
        """Per-flight navdata trims, yaw offset and yaw drift direction (drawn at take-off)."""
        p, rng = self.params, self._bias_rng
        self._bias_normals.sync()  # the stream where the normals drawn so far left it
        u = rng.uniform(-1.0, 1.0, 3)
        self._trim_bias_rad = (p.navdata_trim_bias_max_rad * u[0],
                               p.navdata_trim_bias_max_rad * u[1])
        self._yaw_bias_deg = 180.0 * u[2]
        self._yaw_drift_sign = 1.0 if rng.random() < 0.5 else -1.0

    def _advance_biases(self, dt: float, n: np.ndarray) -> None:
        """The yaw offset's drift and walk and the velocity biases over ``dt`` (s), with the
        standard normals ``n`` (3) (:func:`flying_advance` compiles the same arithmetic)."""
        p = self.params
        drift = self._yaw_drift_sign * p.navdata_yaw_drift_radps * dt
        walk = p.navdata_yaw_walk_rad_per_sqrt_s * math.sqrt(dt) * n[0]
        self._yaw_bias_deg = wrap_angle_deg(self._yaw_bias_deg + math.degrees(drift + walk))
        self._vel_bias = gauss_markov_step(self._vel_bias, p.navdata_velocity_bias_std_mps,
                                           p.navdata_velocity_bias_tau_s, dt, n[1:])

    # ------------------------------------------------------------------ outputs

    @property
    def truth(self) -> PlantTruth:
        """The true state now (world/model signs, see module docstring)."""
        state = self._state
        motion = _readonly(*state[:6])  # position and velocity, read-only views of one
        return PlantTruth(t_s=self.t_s, position_m=motion[:3], velocity_mps=motion[3:],
                          roll_rad=state[6], pitch_rad=state[7], psi_rad=wrap_angle_rad(state[8]),
                          psi_rate_radps=state[9], mode=self._mode, battery_pct=self._battery)

    @property
    def altitude_m_and_rate_mps(self) -> tuple[float, float]:
        """(z, ż) now, without building :attr:`truth`: the firmware's altitude cap reads them
        whenever time passes or a command arrives."""
        state = self._state
        return state[2], state[5]

    def mocap_pose(self) -> MocapPose:
        """A mocap pose now: position + N(0, σ_p) per axis, each XYZ angle + N(0, σ_a)."""
        x, y, z, _, _, _, phi, theta, psi, _ = self._state
        n = self._mocap_normals.take(6)
        sp, sa = self.noise.mocap_position_std_m, self.noise.mocap_angle_std_rad
        rx, ry, rz = mocap_rotation_xyz_rad(phi, theta, psi)
        rx, ry = wrap_angle_rad(rx + sa * n[3]), ry + sa * n[4]
        rz = wrap_angle_rad(rz + sa * n[5])
        return MocapPose(
            t_s=self.t_s,
            position_m=_readonly(x + sp * n[0], y + sp * n[1], z + sp * n[2]),
            rotation_xyz_rad=_readonly(rx, ry, rz),
            psi_rad=rotation_heading_rad(rx, ry, rz))

    def navdata(self) -> NavdataSample:
        """A navdata demo sample now, in the drone's signs (see NavdataSample)."""
        x, y, z, vx, vy, vz, phi, theta, psi, _ = self._state
        nz = self.noise
        n = self._nav_normals.take(7)
        roll = math.degrees(phi + self._trim_bias_rad[0] + nz.navdata_attitude_std_rad * n[0])
        pitch = math.degrees(-theta + self._trim_bias_rad[1] + nz.navdata_attitude_std_rad * n[1])
        yaw = wrap_angle_deg(math.degrees(-psi + nz.navdata_yaw_std_rad * n[2])
                             + self._yaw_bias_deg)
        if self._mode.airborne:
            c, s = math.cos(psi), math.sin(psi)
            sv = nz.navdata_velocity_std_mps
            altitude = max(0.0, z + nz.navdata_altitude_std_m * n[3])
            bias = self.params.navdata_velocity_bias_mps
            forward = c * vx + s * vy + self._vel_bias[0] + bias[0] + sv * n[4]
            right = s * vx - c * vy + self._vel_bias[1] + bias[1] + sv * n[5]
            down = -vz + sv * n[6]
        else:  # motors off: ultrasound and optical flow report nothing
            altitude = forward = right = down = 0.0
        return NavdataSample(
            t_s=self.t_s, mode=self._mode, battery_pct=self._battery, roll_deg=roll,
            pitch_deg=pitch, yaw_deg=yaw, altitude_m=altitude, vx_body_mps=forward,
            vy_body_mps=right, vz_mps=down)
