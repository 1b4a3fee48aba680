"""Controller output → AR.Drone PCMD fractions (docs/design.md §4).

``roll = φ/E``, ``pitch = −θ/E`` (negative pitch = nose down = forward), ``gaz = ż_ref/V``,
``yaw = −ψ̇/Y`` (PCMD yaw > 0 turns clockwise seen from above, world ψ is counter-clockwise),
with E, V, Y the drone's configured ``euler_angle_max``, ``control_vz_max`` and ``control_yaw``.
Each fraction is clipped to [−1, 1] and the clipping is flagged, never silent. A non-finite
value anywhere is refused: no command is ever built from NaN.

That is the SDK's convention (``drone.command_convention: sdk``). The ARDrone Simulink
Development Kit's (``kit``) writes rad, m/s and rad/s as the fraction itself: E = V = Y = 1
(:func:`command_scales`); the drone's configured limits still bound what it does.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ardrone_nmpc.core.types import AttitudeCommand, slot_init

__all__ = ["DroneLimits", "PcmdCommand", "MappingError", "UNSATURATED", "command_scales",
           "map_to_pcmd", "pcmd_of", "pcmd_of_floats", "vz_reference_mps"]


class MappingError(ValueError):
    """A command could not be mapped (a non-finite input); the message names the field."""


def _finite(name: str, value: float) -> float:
    v = float(value)
    if not math.isfinite(v):
        raise MappingError(f"{name} must be finite, got {v!r}")
    return v


@dataclass(frozen=True)
class DroneLimits:
    """The command at PCMD ±1: the drone's configured limits (AR.Drone SDK defaults) under the
    SDK convention, 1 rad, 1 m/s, 1 rad/s under the kit's (:func:`command_scales`).

    Attributes
    ----------
    euler_angle_max_rad : float
        Tilt at PCMD roll/pitch = ±1, rad (``control:euler_angle_max``, default 0.2094 = 12°).
    control_vz_max_mps : float
        Vertical speed at PCMD gaz = ±1, m/s (``control:control_vz_max``, default 0.7).
    control_yaw_radps : float
        Yaw rate at PCMD yaw = ±1, rad/s (``control:control_yaw``, default 1.745 = 100°/s).
    """

    euler_angle_max_rad: float = 0.2094
    control_vz_max_mps: float = 0.7
    control_yaw_radps: float = 1.745

    def __post_init__(self) -> None:
        for name in ("euler_angle_max_rad", "control_vz_max_mps", "control_yaw_radps"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0.0):
                raise ValueError(f"{name} must be finite and > 0, got {v!r}")


#: The kit's convention: one unit of command (rad, m/s, rad/s) per unit of PCMD fraction.
KIT_SCALES = DroneLimits(1.0, 1.0, 1.0)


def command_scales(drone) -> DroneLimits:
    """The command at PCMD ±1 under ``drone.command_convention`` (a ``drone`` config section):
    the configured limits (``sdk``), or one unit per unit of fraction (``kit``). The mapping
    divides by them, the NMPC plans within them and the ż reference is clipped to them."""
    if drone.command_convention == "kit":
        return KIT_SCALES
    return DroneLimits(drone.euler_angle_max_rad, drone.control_vz_max_mps,
                       drone.control_yaw_radps)


#: ``PcmdCommand.saturated`` of a command inside [−1, 1] (one tuple: an identity test)
UNSATURATED = (False, False, False, False)


@slot_init  # built every tick: each slot set through its descriptor (core/types.py)
@dataclass(frozen=True, slots=True)
class PcmdCommand:
    """One AT*PCMD's four fractions in [−1, 1] and which of them were clipped.

    Attributes
    ----------
    roll_frac, pitch_frac, gaz_frac, yaw_frac : float
        PCMD fractions in [−1, 1] (AR.Drone signs, see module docstring).
    saturated : tuple of 4 bool
        Per fraction (roll, pitch, gaz, yaw): True when the unclipped value exceeded ±1.
    """

    roll_frac: float
    pitch_frac: float
    gaz_frac: float
    yaw_frac: float
    saturated: tuple[bool, bool, bool, bool] = UNSATURATED

    @property
    def any_saturated(self) -> bool:
        """True when at least one fraction was clipped."""
        return any(self.saturated)


_make_pcmd = PcmdCommand.make  # a module global: one lookup, not two


def _clip_unit(v: float) -> tuple[float, bool]:
    if v > 1.0:
        return 1.0, True
    if v < -1.0:
        return -1.0, True
    # + 0.0 turns −0.0 (e.g. pitch = −θ/E at θ = 0) into 0.0: on the wire −0.0 is the int32
    # −2147483648, a value no drone firmware is known to accept.
    return v + 0.0, False


def map_to_pcmd(cmd: AttitudeCommand, limits: DroneLimits = DroneLimits()) -> PcmdCommand:
    """Scale an attitude command to PCMD fractions, clipping to [−1, 1] with flags.

    Parameters
    ----------
    cmd : AttitudeCommand
        ż reference (m/s), φ and θ (rad), ψ̇ (rad/s) in the thesis/world conventions.
    limits : DroneLimits, optional

    Returns
    -------
    PcmdCommand

    Raises
    ------
    MappingError
        If any field of ``cmd`` is not finite (the message names it).
    """
    return pcmd_of(cmd.vz_ref_mps, cmd.phi_rad, cmd.theta_rad, cmd.psirate_radps, limits)


def pcmd_of(vz_ref_mps: float, phi_rad: float, theta_rad: float, psirate_radps: float,
            limits: DroneLimits) -> PcmdCommand:
    """:func:`map_to_pcmd` of the four values (no :class:`AttitudeCommand` to build: the tick
    maps one every 65 ms, and each record costs)."""
    phi, theta = float(phi_rad), float(theta_rad)
    vz, psirate = float(vz_ref_mps), float(psirate_radps)
    if not (math.isfinite(phi) and math.isfinite(theta) and math.isfinite(vz)
            and math.isfinite(psirate)):  # refused, naming the first in this order
        _finite("phi_rad", phi)
        _finite("theta_rad", theta)
        _finite("vz_ref_mps", vz)
        _finite("psirate_radps", psirate)
    return pcmd_of_floats(vz, phi, theta, psirate, limits.euler_angle_max_rad,
                          limits.control_vz_max_mps, limits.control_yaw_radps)


def pcmd_of_floats(vz_ref_mps: float, phi_rad: float, theta_rad: float, psirate_radps: float,
                   euler_angle_max_rad: float, control_vz_max_mps: float,
                   control_yaw_radps: float) -> PcmdCommand:
    """:func:`pcmd_of`'s arithmetic, for a caller that has the four values as finite Python
    floats already and the limits unpacked (the tick's supervision: no checks, no
    conversions, no attribute lookups). A NaN or a numpy scalar here is the caller's bug.
    Its compiled twin (the nominal tick's): ``runtime/after_solve._fractions``, kept equal by
    ``tests/unit/test_after_solve.py``."""
    # _clip_unit of each, spelled out (four calls and tuples cost ~0.4 µs a tick);
    # ``make``: the same record without the subclass test (core/types.slot_init, ~70 ns)
    roll, pitch = phi_rad / euler_angle_max_rad, -theta_rad / euler_angle_max_rad
    gaz, yaw = vz_ref_mps / control_vz_max_mps, -psirate_radps / control_yaw_radps
    if -1.0 <= roll <= 1.0 and -1.0 <= pitch <= 1.0 and -1.0 <= gaz <= 1.0 and -1.0 <= yaw <= 1.0:
        return _make_pcmd(roll + 0.0, pitch + 0.0, gaz + 0.0, yaw + 0.0, UNSATURATED)
    roll, s_roll = _clip_unit(roll)
    pitch, s_pitch = _clip_unit(pitch)
    gaz, s_gaz = _clip_unit(gaz)
    yaw, s_yaw = _clip_unit(yaw)
    return _make_pcmd(roll, pitch, gaz, yaw, (s_roll, s_pitch, s_gaz, s_yaw))


def vz_reference_mps(vz_est_mps: float, zacc_mps2: float, dt_s: float) -> float:
    """ż reference for the drone from the NMPC's z̈ (thesis, end of §4.4).

    The drone's vertical input is a speed, the NMPC's is an acceleration: integrate the
    acceleration over one control period from the estimator's ż, ``vz_est + z̈·Δt``
    (the Kalman prediction step of eq. 4.9).

    Parameters
    ----------
    vz_est_mps : float
        Current ż estimate, m/s.
    zacc_mps2 : float
        Commanded z̈ (u1), m/s².
    dt_s : float
        Control period, s, >= 0.

    Returns
    -------
    float
        ż reference, m/s (unclipped; :func:`map_to_pcmd` clips and flags).

    Raises
    ------
    MappingError
        Non-finite input (named) or negative ``dt_s``.
    """
    vz = _finite("vz_est_mps", vz_est_mps)
    a = _finite("zacc_mps2", zacc_mps2)
    dt = _finite("dt_s", dt_s)
    if dt < 0.0:
        raise MappingError(f"dt_s must be >= 0, got {dt!r}")
    return vz + a * dt
