"""The ``thesis_kit`` plant: the ARDrone Simulink Development Kit's linear identified channels.

The thesis simulated with the kit (docs/plant.md §4): PCMD fractions pass a 0.26 s delay, then
linear identified channels, integrated at 5 ms. In the kit's (drone) signs, with c the delayed
PCMD fractions::

    roll  c_roll  → φ      ssRoll    (1.4834 s + 3.5236)/(s² + 4.2683 s + 12.6865)
          φ       → v      ssRoll2V  4.7737/(s + 0.4596)        v: body speed to the right
    pitch c_pitch → θ_k    ssPitch   (2.5139 s + 4.8661)/(s² + 3.9784 s + 11.9184)
          θ_k     → u      ssPitch2U −6.1543/(s + 0.6650)       u: body speed forward
    gaz   c_gaz   → z      Gzc       (0.1526 s + 5.153)/(s (s + 5.82))
    yaw   c_yaw   → ψ_k    ssYaw     1.265/(s + 0.0059)         ψ_k clockwise

θ_k > 0 is nose up (the PCMD sign), so a positive pitch fraction flies backwards; ψ_k is the
kit's heading change since take-off, clockwise. Into the world frame of docs/design.md §4
(x forward, y left, z up, ψ counter-clockwise): θ = −θ_k, ψ̇ = −ψ̇_k, and the body speeds turn
with ψ: ẋ = cos ψ·u + sin ψ·v, ẏ = sin ψ·u − cos ψ·v.

What the kit does not model, and this backend adds so that the rest of the simulator works
unchanged (the modes, take-off/landing, ground, battery, sensors and faults are
:class:`~ardrone_nmpc.sim.plant.AirframePlant`'s): the speed poles act on the air-relative speed
(so wind and ``turbulence_std_mps`` push the drone as drag does in the ``ardrone`` profile); with
the progressive flag at 0 the tilt commands are 0 and the position hold adds damping so that
u, v decay with ``hover_tau_s``; the automatic take-off and landing command the climb rate
through the kit's vertical gain. The firmware limits (``drone.euler_angle_max_rad`` …) are part
of the identified gains and do not act separately. As the kit's block, it draws no navdata
trims, yaw drift or velocity bias; the profile sets the sensor noise to 0 (config/profiles.py),
and ``sim.noise`` adds it back where set. Constants and sources: docs/plant-profiles.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numba import njit

from ardrone_nmpc.core.kernel_cache import flush_stale_caches
from ardrone_nmpc.core.numerics import INNER_KERNEL, OUTER_KERNEL
from ardrone_nmpc.core.types import FlightMode
from ardrone_nmpc.core.angle_kernels import wrap_half_turn
from ardrone_nmpc.sim.airframe import floor_and_drain, sagged_vz_gain, shift_ring
from ardrone_nmpc.sim.held_state import holds_in_arrays
from ardrone_nmpc.sim.plant import AirframePlant, PlantParams
from ardrone_nmpc.sim.plant_step import AUTO_LANDED, AUTO_SAME, advance_biases, auto_step_end

if TYPE_CHECKING:
    from ardrone_nmpc.config.schema import DroneConfig, SimConfig

__all__ = ["KIT", "N_KIT", "KitModel", "KitPlant", "kit_auto_steps", "kit_flying_steps",
           "kit_rk4"]

N_KIT = 12   # x, y, z, ψ (world) + roll (2), pitch (2), u, v, vertical (1), ψ_k states
NO_SENSOR_BIASES = {"navdata_trim_bias_max_rad": 0.0, "navdata_yaw_drift_radps": 0.0,
                    "navdata_yaw_walk_rad_per_sqrt_s": 0.0, "navdata_velocity_bias_std_mps": 0.0}


@dataclass(frozen=True, slots=True)
class KitModel:
    """The kit's identified state-space channels, as stored in its ``ss*`` objects
    (docs/plant.md §4; A, B, C per channel, D = 0) and its ``Gzc`` transfer function."""

    roll_a: tuple = ((-4.2683, -3.171628), (4.0, 0.0))
    roll_b: tuple = (2.0, 0.0)
    roll_c: tuple = (0.741691, 0.440455)
    pitch_a: tuple = ((-3.978376, -2.9796), (4.0, 0.0))
    pitch_b: tuple = (2.0, 0.0)
    pitch_c: tuple = (1.256933, 0.608257)
    roll2v_abc: tuple = (-0.459552, 2.0, 2.386839)
    pitch2u_abc: tuple = (-0.665041, 2.0, -3.07716)
    yaw_abc: tuple = (-0.005879, 1.0, 1.265268)
    # Gzc = (gz_num1 s + gz_num0) / (s (s + gz_pole)): gaz → z
    gz_num1: float = 0.1526
    gz_num0: float = 5.153
    gz_pole: float = 5.82

    @property
    def vz_per_frac_mps(self) -> float:
        """Steady climb rate per unit gaz (m/s): Gzc·s at s = 0."""
        return self.gz_num0 / self.gz_pole

    def coefficients(self, hover_tau_s: float) -> tuple:
        """The flat tuple :func:`kit_rk4` reads (its order is the kernel's unpacking)."""
        (ra11, ra12), (ra21, ra22) = self.roll_a
        (pa11, pa12), (pa21, pa22) = self.pitch_a
        av, bv, cv = self.roll2v_abc
        au, bu, cu = self.pitch2u_abc
        ay, by, cy = self.yaw_abc
        hold_u = max(0.0, 1.0 / hover_tau_s + au)   # au < 0: the pole's own damping
        hold_v = max(0.0, 1.0 / hover_tau_s + av)
        return (ra11, ra12, ra21, ra22, self.roll_b[0], self.roll_b[1], self.roll_c[0],
                self.roll_c[1], pa11, pa12, pa21, pa22, self.pitch_b[0], self.pitch_b[1],
                self.pitch_c[0], self.pitch_c[1], av, bv * cv, au, bu * cu, ay, by * cy,
                self.gz_num1, self.gz_num0 - self.gz_num1 * self.gz_pole, self.gz_pole,
                hold_u, hold_v)


KIT = KitModel()


@njit(cache=True, **INNER_KERNEL)
def _kit_rhs(x, roll, pitch, gaz, yaw, hold, k, w):
    """Derivative of the kit state ``x`` (N_KIT values, a tuple) as a tuple, and the outputs
    (vx, vy, vz, φ, θ_k, ψ̇_k). On values, not arrays: :func:`_kit_rk4_into` holds its
    stages in tuples (no array made per stage)."""
    (ra11, ra12, ra21, ra22, rb1, rb2, rc1, rc2, pa11, pa12, pa21, pa22, pb1, pb2, pc1, pc2,
     av, gv, au, gu, ay, gy, gz_feed, gz_in, gz_pole, hold_u, hold_v) = k
    psi = x[3]
    c = math.cos(psi)
    s = math.sin(psi)
    phi = rc1 * x[4] + rc2 * x[5]
    theta_k = pc1 * x[6] + pc2 * x[7]
    u, v = x[8], x[9]
    w_u = c * w[0] + s * w[1]          # wind along body forward / right
    w_v = s * w[0] - c * w[1]
    vz = gz_feed * gaz + x[10]
    psi_k_rate = ay * x[11] + gy * yaw
    vx = c * u + s * v
    vy = s * u - c * v
    du = au * (u - w_u) + gu * theta_k
    dv = av * (v - w_v) + gv * phi
    if hold:
        du -= hold_u * u
        dv -= hold_v * v
    # world ψ is counter-clockwise (its rate −ψ̇_k), the kit's clockwise
    return ((vx, vy, vz, -psi_k_rate,
             ra11 * x[4] + ra12 * x[5] + rb1 * roll, ra21 * x[4] + ra22 * x[5] + rb2 * roll,
             pa11 * x[6] + pa12 * x[7] + pb1 * pitch, pa21 * x[6] + pa22 * x[7] + pb2 * pitch,
             du, dv, -gz_pole * x[10] + gz_in * gaz, psi_k_rate),
            (vx, vy, vz, phi, theta_k, psi_k_rate))


@njit(cache=True, inline="always", **INNER_KERNEL)
def _kit_values(x):
    """The kit state array ``x`` (N_KIT) as a tuple."""
    return (x[0], x[1], x[2], x[3], x[4], x[5], x[6], x[7], x[8], x[9], x[10], x[11])


@njit(cache=True, inline="always", **INNER_KERNEL)
def _kit_stage(q, f, d):
    """An RK4 stage: q + f·d element by element (tuples)."""
    return (q[0] + f * d[0], q[1] + f * d[1], q[2] + f * d[2], q[3] + f * d[3],
            q[4] + f * d[4], q[5] + f * d[5], q[6] + f * d[6], q[7] + f * d[7],
            q[8] + f * d[8], q[9] + f * d[9], q[10] + f * d[10], q[11] + f * d[11])


@njit(cache=True, **INNER_KERNEL)
def _kit_rk4_into(x0, roll, pitch, gaz, yaw, hold, k, w, h, out):
    """:func:`kit_rk4` from the array ``x0`` into ``out`` (``out`` may be ``x0``); returns
    the outputs."""
    if hold:
        roll = 0.0
        pitch = 0.0
    hh = 0.5 * h
    q = _kit_values(x0)
    a = _kit_rhs(q, roll, pitch, gaz, yaw, hold, k, w)[0]
    b = _kit_rhs(_kit_stage(q, hh, a), roll, pitch, gaz, yaw, hold, k, w)[0]
    c = _kit_rhs(_kit_stage(q, hh, b), roll, pitch, gaz, yaw, hold, k, w)[0]
    d = _kit_rhs(_kit_stage(q, h, c), roll, pitch, gaz, yaw, hold, k, w)[0]
    h6 = h / 6.0
    for i in range(N_KIT):
        out[i] = q[i] + h6 * (a[i] + 2.0 * (b[i] + c[i]) + d[i])
    return _kit_rhs(_kit_values(out), roll, pitch, gaz, yaw, hold, k, w)[1]


@njit(cache=True, **OUTER_KERNEL)
def kit_rk4(x0, roll, pitch, gaz, yaw, hold, k, w, h):
    """One classical RK4 step of the kit over ``h`` (the commands held); returns the new state
    and the outputs (vx, vy, vz, φ, θ_k, ψ̇_k) at its end. ``hold`` zeroes roll and pitch."""
    x = np.empty(N_KIT)
    outputs = _kit_rk4_into(x0, roll, pitch, gaz, yaw, hold, k, w, h, x)
    return x, outputs


@njit(cache=True, inline="always", **INNER_KERNEL)
def _kit_motors_on(state, kit, roll, pitch, gaz, yaw, hold, k, w, h):
    """:meth:`KitPlant._motors_on_step` on arrays (``gaz`` times the vertical gain already):
    the kit's channels ``kit`` (12) take x, y, z, ψ of the plant's ``state`` (10, or more:
    its first 10), one :func:`kit_rk4` step, written into both in place."""
    kit[0], kit[1], kit[2], kit[3] = state[0], state[1], state[2], state[8]
    vx, vy, vz, phi, theta_k, psi_k_rate = _kit_rk4_into(kit, roll, pitch, gaz, yaw, hold, k,
                                                         w, h, kit)
    state[0], state[1], state[2], state[3], state[4] = kit[0], kit[1], kit[2], vx, vy
    state[5], state[6], state[7], state[8], state[9] = vz, phi, -theta_k, kit[3], -psi_k_rate


@njit(cache=True, **OUTER_KERNEL)
def kit_flying_advance(state, kit, ring, head, roll, pitch, gaz, yaw, hold, k, w, h, n,
                       battery, drain, vz_gain, sag, normals, yaw_bias_deg, vel_bias_0,
                       vel_bias_1, yaw_drift_radps, yaw_walk, vel_bias_std, vel_bias_tau_s):
    """Up to ``n`` FLYING steps of :class:`KitPlant` in one call (:func:`kit_flying_steps`
    on a copy of the plant's ``state`` (10) and on its channels ``kit``, in place). If all
    ``n`` were flown, ψ is wrapped and the biases advanced
    (:func:`~ardrone_nmpc.sim.plant_step.advance_biases`). Returns (steps done, head,
    battery, state, kit state, yaw offset °, velocity bias 0, velocity bias 1)."""
    state = state.copy()
    done, head, battery = kit_flying_steps(state, kit, ring, head, roll, pitch, gaz, yaw,
                                           hold, k, w, h, n, battery, drain, vz_gain, sag)
    if done < n:
        return done, head, battery, state, kit, yaw_bias_deg, vel_bias_0, vel_bias_1
    state[8] = wrap_half_turn(state[8], math.pi)
    yaw_bias_deg, vel_bias_0, vel_bias_1 = advance_biases(
        n * h, normals, yaw_bias_deg, vel_bias_0, vel_bias_1, yaw_drift_radps, yaw_walk,
        vel_bias_std, vel_bias_tau_s)
    return n, head, battery, state, kit, yaw_bias_deg, vel_bias_0, vel_bias_1


@njit(cache=True, **INNER_KERNEL)
def kit_flying_steps(state, kit, ring, head, roll, pitch, gaz, yaw, hold, k, w, h, n, battery,
                     drain, vz_gain, sag):
    """Up to ``n`` FLYING steps of :class:`KitPlant` on ``state`` and ``kit`` in place — each
    :meth:`~ardrone_nmpc.sim.plant.AirframePlant._substep`'s arithmetic in its order: the
    command ``roll`` … ``hold`` queued in the delay ring ``ring`` (oldest at ``head``) and the
    oldest flown (:func:`_kit_motors_on`, gaz times the vertical gain at the battery level),
    the floor, the drain — stopping before a step whose drain would empty the battery (a mode
    change, the plant's). Returns (steps done, head, battery)."""
    for i in range(n):
        if not battery - drain > 0.0:
            return i, head, battery
        r, p, g, y, hd, head = shift_ring(ring, head, roll, pitch, gaz, yaw, hold)
        _kit_motors_on(state, kit, r, p, g * sagged_vz_gain(vz_gain, sag, battery), y, hd, k,
                       w, h)
        battery = floor_and_drain(state, battery, drain)
    return n, head, battery


@njit(cache=True, **INNER_KERNEL)
def kit_auto_steps(state, kit, ring, head, roll, pitch, gaz, yaw, hold, landing, gaz_auto, k,
                   w, h, n, battery, drain, vz_gain, sag, tau_vz_s, takeoff_altitude_m):
    """Up to ``n`` steps of :class:`KitPlant`'s automatic take-off (``landing`` False) or
    landing on ``state`` and ``kit`` in place — :meth:`~ardrone_nmpc.sim.plant.AirframePlant.
    _substep`'s arithmetic in its order, as :func:`~ardrone_nmpc.sim.plant_step.auto_steps`
    for the airframe: the command queued and ignored, one step of the automatic climb or
    descent (:meth:`KitPlant._auto_command`'s gaz ``gaz_auto`` times the vertical gain,
    position hold), the floor — a landing touches down at rest, the channels at 0
    (:meth:`KitPlant._at_rest`) —, the drain, the mode's transitions. Stops after the step
    that changes the mode. Returns (steps done, head, battery, the mode then: ``AUTO_*``)."""
    auto_hold = landing or not landing  # a bool, not a literal (auto_steps' note)
    for i in range(n):
        head = shift_ring(ring, head, roll, pitch, gaz, yaw, hold)[5]
        _kit_motors_on(state, kit, 0.0, 0.0, gaz_auto * sagged_vz_gain(vz_gain, sag, battery),
                       0.0, auto_hold, k, w, h)
        battery, mode = auto_step_end(state, battery, drain, landing, tau_vz_s,
                                      takeoff_altitude_m)
        if mode == AUTO_LANDED:  # at rest, the channels too (KitPlant._at_rest)
            for j in range(N_KIT):
                kit[j] = 0.0
        if mode != AUTO_SAME:
            return i + 1, head, battery, mode
    return n, head, battery, AUTO_SAME


# the channels' state too, in the lockstep's compiled legs (sim/lockstep_legs: after the
# plant's 10-state in their state array)
@holds_in_arrays("_kit")
class KitPlant(AirframePlant):
    """:class:`~ardrone_nmpc.sim.plant.AirframePlant` with the kit's channels in flight.

    ``params`` keeps the shared fields (delay, step, take-off, battery, sensor biases); its
    ``tau_vz_s`` is the kit's vertical time constant 1/5.82 s (the take-off hand-over and the
    firmware's altitude cap read it). ``model`` holds the identified channels.
    """

    def __init__(self, params: PlantParams, noise=None, *, seed: int = 0,
                 model: KitModel = KIT) -> None:
        # the kit's block outputs its states as they are: no navdata trims, drift or bias
        # (the constant sim.navdata_velocity_bias_mps, a disturbance option, still acts)
        params = params.replace(tau_vz_s=1.0 / model.gz_pole, **NO_SENSOR_BIASES)
        super().__init__(params, noise, seed=seed)
        self.model = model
        self._coefficients = model.coefficients(params.hover_tau_s)
        self._kit = np.zeros(N_KIT)

    @classmethod
    def from_config(cls, sim_cfg: SimConfig, drone_cfg: DroneConfig, *,
                    seed: int | None = None) -> KitPlant:
        """The kit plant of an experiment's ``sim`` and ``drone`` sections (``tau_*`` and
        ``drag_per_s`` of ``sim.plant`` are not used)."""
        return cls(PlantParams.from_config(sim_cfg, drone_cfg), sim_cfg.noise,
                   seed=sim_cfg.seed if seed is None else seed)

    def _flying_advance(self, n: int, h: float, wind: tuple, normals: np.ndarray) -> int:
        """Up to ``n`` FLYING steps in one compiled call (:func:`kit_flying_advance`), as
        the airframe's; returns the steps done (the rest are the step-by-step path's)."""
        if type(self)._motors_on_step is not KitPlant._motors_on_step:
            return 0  # a backend with other dynamics still
        p, fifo, (roll, pitch, gaz, yaw, hold) = self.params, self._fifo, self._current
        done, fifo.head, self._battery, state, self._kit, yaw_bias, vb0, vb1 = \
            kit_flying_advance(
                np.array(self._state, dtype=np.float64), self._kit, fifo.rows, fifo.head, roll,
                pitch, gaz, yaw, hold, self._coefficients, wind, h, n, self._battery,
                p.battery_drain_pct_per_min * h / 60.0, p.vz_gain, p.battery_sag_frac, normals,
                self._yaw_bias_deg, *self._vel_bias, self._yaw_drift_sign
                * p.navdata_yaw_drift_radps, p.navdata_yaw_walk_rad_per_sqrt_s,
                p.navdata_velocity_bias_std_mps, p.navdata_velocity_bias_tau_s)
        self._steps += done
        self._state = tuple(state.tolist())
        if done == n:
            self._yaw_bias_deg, self._vel_bias = yaw_bias, (vb0, vb1)
        return done

    def _motors_on_step(self, command: tuple, h: float, wind: tuple) -> tuple:
        roll, pitch, gaz, yaw, hold = command
        kit = self._kit
        x, y, z, *_rest = self._state
        kit[0], kit[1], kit[2], kit[3] = x, y, z, self._state[8]
        gaz = float(gaz) * self.params.vertical_gain(self._battery)  # sim disturbance options
        kit, (vx, vy, vz, phi, theta_k, psi_k_rate) = kit_rk4(
            kit, float(roll), float(pitch), gaz, float(yaw), bool(hold),
            self._coefficients, wind, h)
        self._kit = kit
        return (kit[0], kit[1], kit[2], vx, vy, vz, phi, -theta_k, kit[3], -psi_k_rate)

    def _auto_command(self, mode: FlightMode) -> tuple:
        p = self.params
        speed = p.takeoff_climb_mps if mode is FlightMode.TAKING_OFF else -p.landing_speed_mps
        return (0.0, 0.0, speed / self.model.vz_per_frac_mps, 0.0, True)

    def _at_rest(self, state: tuple) -> tuple:
        """At rest on the ground, the kit's channels rest too (a new flight starts from 0)."""
        self._kit = np.zeros(N_KIT)
        return AirframePlant._at_rest(state)


flush_stale_caches(__name__)  # kernels calling other files: core/kernel_cache.py
