"""Baseline proportional controller (thesis eq. 4.16), made frame-correct.

Eq. 4.16 as printed::

    ż = k1 (z_d − z)
    φ = k2 (ẏ_d − ẏ),   ẏ_d = y_d − y
    θ = k3 (ẋ_d − ẋ),   ẋ_d = x_d − x
    ψ = k4 (ψ_d − ψ)     (a yaw-*rate* command: the drone's yaw input is ψ̇)

is only right at ψ = 0 and with φ's sign flipped: in the model (eq. 3.13) θ > 0 accelerates
along the body's forward axis and φ > 0 towards the body's *right* (−y at ψ = 0). So the world
velocity error is rotated into the body frame by ψ first, θ acts on its forward part and φ on
minus its left part, and the heading error is wrapped so the drone turns the short way.

No clipping happens here: the thesis' point is that the P inputs go well beyond the NMPC's ±1
bound; the command mapping clips and flags saturation.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

from ardrone_nmpc.core.angles import wrap_angle_rad
from ardrone_nmpc.core.types import (IX_PSI, IX_VX, IX_VY, IX_X, IX_Y, IX_Z, STATE_DIM,
                                     AttitudeCommand)

__all__ = ["PGains", "p_control", "p_law"]


@dataclass(frozen=True)
class PGains:
    """Gains of the P controller. The thesis does not give them; these are chosen.

    The numbers are sized against the simulated AR.Drone's inner loops (docs/plant.md:
    vz lag τ_z = 0.5 s, tilt lag 0.1 s, yaw-rate lag 0.1 s, command delay 0.26 s) and the
    thesis' P settling times (z 2 s, x 4 s, y 4.5 s, ψ 2.5 s).

    Tuned in lockstep simulation against that plant, with its 0.26 s delay (each figure:
    ``ardrone-nmpc simulate configs/<step>.yaml --set controller.kind=p``, seed 0; settling
    in the 2 % band): x step 3.9 s / 1.8 % overshoot, ψ step 2.2 s / 0.2 %, z step 5.6 s /
    6.9 %. The first guesses sized from the time constants alone (1.5, 0.35, 0.35, 2.0)
    never settled x (14 % overshoot, the delay makes the velocity loop ring) and overshot
    z by 30 % and ψ by 25 %.

    Attributes
    ----------
    k1_per_s : float
        Altitude error → ż reference, 1/s. Above ≈ 0.8 the 0.5 s vz lag plus the delay
        overshoots; the thesis' 2 s take-off is out of reach for P on this plant (5.6 s).
    k2_rad_per_mps : float
        Body-left velocity error → roll φ, rad per m/s (applied with a minus sign, see module).
    k3_rad_per_mps : float
        Body-forward velocity error → pitch θ, rad per m/s; the unit-gain position loop
        (ẋ_d = x_d − x) on top makes the 1.5 m step take ≈ 4 s, as in the thesis.
    k4_per_s : float
        Heading error → yaw rate, 1/s: a 1 s time constant over the 0.1 s yaw-rate loop.
    """

    k1_per_s: float = 0.7
    k2_rad_per_mps: float = 0.2
    k3_rad_per_mps: float = 0.2
    k4_per_s: float = 1.0

    def __post_init__(self) -> None:
        for name in ("k1_per_s", "k2_rad_per_mps", "k3_rad_per_mps", "k4_per_s"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0.0):
                raise ValueError(f"{name} must be finite and > 0, got {v!r}")


def p_control(
    state: Sequence[float], reference: Sequence[float], gains: PGains = PGains()
) -> AttitudeCommand:
    """Proportional attitude command of eq. 4.16 in the body frame.

    Parameters
    ----------
    state : sequence of float, shape (7,)
        ``[x, ẋ, y, ẏ, z, ż, ψ]`` (m, m/s, m, m/s, m, m/s, rad), world frame.
    reference : sequence of float, shape (7,)
        Desired state in the same order; only x_d, y_d, z_d and ψ_d are used (eq. 4.16 derives
        the desired velocity from the position error with unit gain).
    gains : PGains, optional

    Returns
    -------
    AttitudeCommand
        ``vz_ref_mps = k1 (z_d − z)``;
        ``theta_rad = k3 · e_forward``, ``phi_rad = −k2 · e_left`` where ``e`` is
        ``(x_d − x − ẋ, y_d − y − ẏ)`` rotated into the body frame by ψ;
        ``psirate_radps = k4 · wrap(ψ_d − ψ)``. Unclipped.
    """
    g = gains
    vz, phi, theta, rate = p_law(_floats(state, _STATE_USED), _floats(reference, _REF_USED),
                                 g.k1_per_s, g.k2_rad_per_mps, g.k3_rad_per_mps, g.k4_per_s)
    return AttitudeCommand(vz_ref_mps=vz, phi_rad=phi, theta_rad=theta, psirate_radps=rate)


def p_law(x, r, k1, k2, k3, k4):
    """Eq. 4.16 in the body frame (:func:`p_control`'s law, unclipped) of the state ``x`` and
    the reference ``r`` (indexed as the state), the gains as numbers: ``(vz_ref_mps, phi_rad,
    theta_rad, psirate_radps)``. The one home of its arithmetic: :func:`p_control` calls it
    on Python floats, and it is compiled as it is — its heading wrapped by the compiled
    twin of :func:`~ardrone_nmpc.core.angles.wrap_angle_rad` — for the compiled P ticks
    (``runtime/p_tick.p_law``)."""
    psi = x[IX_PSI]
    # Desired world velocity = position error (unit gain), minus the measured velocity.
    ex = r[IX_X] - x[IX_X] - x[IX_VX]
    ey = r[IX_Y] - x[IX_Y] - x[IX_VY]
    c, s = math.cos(psi), math.sin(psi)
    e_forward = c * ex + s * ey
    e_left = -s * ex + c * ey
    # φ > 0 pushes right (−left), eq. 3.13
    return (k1 * (r[IX_Z] - x[IX_Z]), -k2 * e_left, k3 * e_forward,
            k4 * wrap_angle_rad(r[IX_PSI] - psi))


_STATE_USED = (IX_PSI, IX_X, IX_VX, IX_Y, IX_VY, IX_Z)  # (float() of each, in this order)
_REF_USED = (IX_X, IX_Y, IX_Z, IX_PSI)


def _floats(values: Sequence[float], used: tuple[int, ...]) -> list[float]:
    """``float()`` of ``values``' entries at ``used`` (a list indexed as the state; 0 else)."""
    out = [0.0] * STATE_DIM
    for i in used:
        out[i] = float(values[i])
    return out
