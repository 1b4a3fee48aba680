"""An AR.Drone 2.0 airframe emulator, written apart from ``sim/plant.py`` to fly the controller
against a drone that is not our model.

Written from the documented behaviour of the drone and its firmware (docs/protocol.md: PCMD
fractions of ``euler_angle_max`` / ``control_vz_max`` / ``control_yaw``, the progressive flag 0
= optical-flow position hold, the automatic take-off to about a metre; navdata in the drone's
signs) and the forms the ARDrone Simulink Development Kit identified for the real drone
(docs/plant-profiles.md §2: a tilt response of second order with a zero per axis, a first-order
speed pole, a first-order climb rate). What a real drone varies is configurable: the command
delay, the tilt per unit command (relative to ``euler_angle_max``), the attitude lag or the
kit's second-order form, the vertical gain and time constant, the drag pole and a steady wind.

It differs from our plant on purpose in everything else: the delay is a time-stamped command
queue (not a FIFO of integration steps); the body is a thrust vector along the rotated body z
axis, whose magnitude the vertical loop sets (not g·tan θ); the integration is semi-implicit
Euler at 1 ms (not RK4 at 5 ms); the drag pole, the yaw and vertical time constants and the
hold damping are other numbers. It imports nothing of ``ardrone_nmpc`` but the records the
runner exchanges with any plant (``core.types``).

The lockstep runner flies it through ``run_lockstep(cfg, plant=AirframeEmulator(...))``: the
interface is the one the runner and the simulated control port use (``command``, ``advance``,
``takeoff``, ``land``, ``emergency``, ``mocap_pose``, ``navdata``, ``truth``,
``altitude_m_and_rate_mps``, ``mode``, ``t_s``, ``battery_pct``, ``wind_mps``, ``params``:
``ardrone_nmpc.sim.backends.Airframe``).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, replace

import numpy as np
from scipy.spatial.transform import Rotation

from ardrone_nmpc.core.types import FlightMode, MocapPose, NavdataSample, PlantTruth

G = 9.80665
# The kit's identified tilt responses per unit command (docs/plant-profiles.md §2), made of
# unit steady gain here: (b1, b0, a1, a0) of (b1 s + b0)/(s² + a1 s + a0).
KIT_ROLL = (1.4834 / (3.5236 / 12.6865), 3.5236 / (3.5236 / 12.6865), 4.2683, 12.6865)
KIT_PITCH = (2.5139 / (4.8661 / 11.9184), 4.8661 / (4.8661 / 11.9184), 3.9784, 11.9184)


@dataclass(frozen=True)
class EmulatorLimits:
    """The limits the drone holds (written over the control port at connect), and the delay
    and climb lag a simulated firmware's altitude cap leads by (sim.backends.Airframe)."""

    euler_angle_max_rad: float = 0.2094
    control_vz_max_mps: float = 0.7
    control_yaw_radps: float = 1.745
    command_delay_s: float = 0.0
    tau_vz_s: float = 0.0

    def replace(self, **changes) -> EmulatorLimits:
        return replace(self, **changes)


class AirframeEmulator:
    """The emulated drone.

    Parameters
    ----------
    command_delay_s : PCMD → airframe delay (s).
    attitude_gain : tilt per unit PCMD roll/pitch relative to ``euler_angle_max`` (one number
        for both, or (roll, pitch)).
    attitude_lag_s : first-order tilt lag (s); None selects the kit's second-order form.
    vz_gain : climb rate per unit gaz relative to ``control_vz_max``.
    tau_vz_s : climb-rate time constant (s).
    drag_per_s : horizontal drag pole on the air-relative speed (1/s).
    wind_mps : steady wind (x, y) (m/s), world frame.
    yaw_gain, tau_yaw_s : yaw rate per unit PCMD yaw relative to ``control_yaw``, its lag (s).
    seed : sensor noise.
    """

    STEP_S = 0.001
    HOLD_TAU_S = 0.6           # optical-flow hold: ground speed decays with this
    TAKEOFF_CLIMB_MPS = 0.6
    TAKEOFF_ALT_M = 0.85
    LANDING_MPS = 0.5

    def __init__(self, *, command_delay_s: float = 0.26, attitude_gain=1.0,
                 attitude_lag_s: float | None = 0.1, vz_gain: float = 1.0,
                 tau_vz_s: float = 0.3, drag_per_s: float = 0.5,
                 wind_mps: tuple[float, float] = (0.0, 0.0), yaw_gain: float = 1.0,
                 tau_yaw_s: float = 0.07, seed: int = 0) -> None:
        gains = attitude_gain if isinstance(attitude_gain, (tuple, list)) else (attitude_gain,) * 2
        self.attitude_gain = tuple(float(g) for g in gains)
        self.attitude_lag_s = attitude_lag_s
        self.command_delay_s = float(command_delay_s)
        self.vz_gain, self.tau_vz_s = float(vz_gain), float(tau_vz_s)
        self.drag_per_s = float(drag_per_s)
        self.yaw_gain, self.tau_yaw_s = float(yaw_gain), float(tau_yaw_s)
        self.wind_mps = np.array([wind_mps[0], wind_mps[1], 0.0])
        self.params = EmulatorLimits(command_delay_s=self.command_delay_s,
                                     tau_vz_s=self.tau_vz_s)
        self._rng = np.random.default_rng(seed)
        self._t = 0.0
        self._pos = np.zeros(3)
        self._vel = np.zeros(3)
        self._tilt = np.zeros(2)        # φ, θ (world/model signs)
        self._tilt_rate = np.zeros(2)   # hidden states of the second-order form
        self._psi = 0.0
        self._psi_rate = 0.0
        self._mode = FlightMode.LANDED
        self._battery = 90.0
        self._queue: deque = deque()    # (time sent, command)
        self._active = (0.0, 0.0, 0.0, 0.0, False)
        self._yaw_offset_deg = float(self._rng.uniform(-180.0, 180.0))

    # --------------------------------------------------------------- what the runner calls
    @property
    def mode(self) -> FlightMode:
        return self._mode

    @property
    def t_s(self) -> float:
        return self._t

    @property
    def battery_pct(self) -> float:
        return self._battery

    @property
    def moving(self) -> bool:
        return any(self._active[:4]) and self._active[4]

    def command(self, roll: float, pitch: float, gaz: float, yaw: float, *,
                progressive: bool = True) -> None:
        clip = lambda v: min(1.0, max(-1.0, float(v)))  # noqa: E731
        cmd = (clip(roll), clip(pitch), clip(gaz), clip(yaw), bool(progressive))
        self._queue.append((self._t, cmd))

    def takeoff(self) -> bool:
        if self._mode is not FlightMode.LANDED:
            return False
        self._mode = FlightMode.TAKING_OFF
        return True

    def land(self) -> bool:
        if self._mode not in (FlightMode.TAKING_OFF, FlightMode.FLYING):
            return False
        self._mode = FlightMode.LANDING
        return True

    def emergency(self) -> bool:
        self._mode = FlightMode.EMERGENCY
        return True

    def advance(self, dt_s: float) -> None:
        n = int(math.floor(dt_s / self.STEP_S + 1e-6))
        for _ in range(n):
            self._step()

    # --------------------------------------------------------------- physics
    def _due_command(self) -> tuple:
        """The newest command sent at least ``command_delay_s`` ago."""
        while self._queue and self._queue[0][0] <= self._t - self.command_delay_s + 1e-9:
            self._active = self._queue.popleft()[1]
        return self._active

    def _tilt_step(self, ref: np.ndarray, h: float) -> None:
        if self.attitude_lag_s is not None:
            self._tilt += (ref - self._tilt) * (h / self.attitude_lag_s)
            return
        for i, (b1, b0, a1, a0) in enumerate((KIT_ROLL, KIT_PITCH)):
            # observable canonical form: y' = −a1 y + w + b1 u, w' = −a0 y + b0 u
            w = self._tilt_rate[i] + h * (-a0 * self._tilt[i] + b0 * ref[i])
            self._tilt[i] += h * (-a1 * self._tilt[i] + w + b1 * ref[i])
            self._tilt_rate[i] = w

    def _step(self) -> None:
        h = self.STEP_S
        self._t += h
        roll, pitch, gaz, yaw, progressive = self._due_command()
        if self._mode in (FlightMode.LANDED, FlightMode.EMERGENCY):
            return
        p = self.params
        hold = not progressive or self._mode is not FlightMode.FLYING
        if self._mode is FlightMode.TAKING_OFF:
            vz_ref = self.TAKEOFF_CLIMB_MPS
        elif self._mode is FlightMode.LANDING:
            vz_ref = -self.LANDING_MPS
        else:
            vz_ref = self.vz_gain * gaz * p.control_vz_max_mps if progressive else 0.0
        e = p.euler_angle_max_rad
        ref = np.zeros(2) if hold else np.array([self.attitude_gain[0] * roll * e,
                                                 -self.attitude_gain[1] * pitch * e])
        self._tilt_step(ref, h)
        rate_ref = 0.0 if hold else -self.yaw_gain * yaw * p.control_yaw_radps
        self._psi_rate += (rate_ref - self._psi_rate) * (h / self.tau_yaw_s)
        self._psi = math.remainder(self._psi + self._psi_rate * h, 2.0 * math.pi)
        # thrust along the body z axis, its magnitude what the vertical loop asks for
        phi, theta = self._tilt
        az_wanted = (vz_ref - self._vel[2]) / self.tau_vz_s
        axis = self._body_z(phi, theta, self._psi)
        thrust = (G + az_wanted) / max(axis[2], 0.5)
        acc = thrust * axis - np.array([0.0, 0.0, G])
        air = self._vel - self.wind_mps
        acc[:2] -= self.drag_per_s * air[:2]
        if hold:
            acc[:2] -= self._vel[:2] / self.HOLD_TAU_S
        self._vel += acc * h
        self._pos += self._vel * h
        self._battery = max(0.0, self._battery - 0.02 * h)
        if self._mode is FlightMode.TAKING_OFF and self._pos[2] >= self.TAKEOFF_ALT_M:
            self._mode = FlightMode.FLYING
            self._vel[2] = 0.0
        if self._pos[2] <= 0.0:
            self._pos[2] = 0.0
            self._vel[:] = 0.0
            if self._mode is FlightMode.LANDING:
                self._mode = FlightMode.LANDED

    @staticmethod
    def _body_z(phi: float, theta: float, psi: float) -> np.ndarray:
        """The thrust axis: body z of R = Rz(ψ)·Ry(θ)·Rx(φ) (φ > 0 tilts it to −y, θ > 0 to
        +x at ψ = 0)."""
        c, s = math.cos(psi), math.sin(psi)
        tx = math.cos(phi) * math.sin(theta)
        ty = -math.sin(phi)
        return np.array([c * tx - s * ty, s * tx + c * ty, math.cos(phi) * math.cos(theta)])

    # --------------------------------------------------------------- sensors
    @property
    def truth(self) -> PlantTruth:
        return PlantTruth(t_s=self._t, position_m=self._pos.copy(),
                          velocity_mps=self._vel.copy(), roll_rad=float(self._tilt[0]),
                          pitch_rad=float(self._tilt[1]), psi_rad=self._psi,
                          psi_rate_radps=self._psi_rate, mode=self._mode,
                          battery_pct=self._battery)

    @property
    def altitude_m_and_rate_mps(self) -> tuple[float, float]:
        """(z, ż) now: what the firmware's altitude cap reads."""
        return float(self._pos[2]), float(self._vel[2])

    def mocap_pose(self) -> MocapPose:
        phi, theta = self._tilt
        r = Rotation.from_euler("ZYX", [self._psi, theta, phi])
        rx, ry, rz = r.as_euler("XYZ")
        return MocapPose(t_s=self._t, position_m=self._pos + self._rng.normal(0.0, 5e-4, 3),
                         rotation_xyz_rad=np.array([rx, ry, rz]), psi_rad=self._psi)

    def navdata(self) -> NavdataSample:
        phi, theta = self._tilt
        n = self._rng.normal(0.0, 1.0, 6)
        c, s = math.cos(self._psi), math.sin(self._psi)
        airborne = self._mode in (FlightMode.TAKING_OFF, FlightMode.FLYING,
                                  FlightMode.LANDING)
        forward = c * self._vel[0] + s * self._vel[1] + 0.04 * n[2]
        right = s * self._vel[0] - c * self._vel[1] + 0.04 * n[3]
        yaw = math.remainder(-math.degrees(self._psi) + self._yaw_offset_deg, 360.0)
        return NavdataSample(
            t_s=self._t, mode=self._mode, battery_pct=self._battery,
            roll_deg=math.degrees(phi) + 0.2 * n[0], pitch_deg=-math.degrees(theta) + 0.2 * n[1],
            yaw_deg=yaw, altitude_m=max(0.0, self._pos[2] + 0.01 * n[4]) if airborne else 0.0,
            vx_body_mps=forward if airborne else 0.0, vy_body_mps=right if airborne else 0.0,
            vz_mps=-self._vel[2] + 0.04 * n[5] if airborne else 0.0)
