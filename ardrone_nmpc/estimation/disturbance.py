"""Offset-free tracking: integral action on the position/yaw error as a reference shift.

The NMPC's model (eq. 3.13) knows no wind, no vertical gain mismatch, no battery sag and no
sensor bias; under a constant one the closed loop settles a constant offset Δ away from its
reference. The model is invariant under translations of x, y, z (positions appear only in the
cost), so moving the reference by s moves that equilibrium by s: an integrator that shifts the
NMPC's reference by ``s' = −ki·(p − p_ref)`` stops exactly when the measured position is on the
reference, whatever Δ was. At rest, ``−s`` *is* the disturbance estimate, expressed as the offset
it would cause (docs/solver-notes.md, "Offset-free tracking", argues the choice with numbers).
"""

from __future__ import annotations

import math

import numpy as np

from ardrone_nmpc.core.angles import wrap_angle_rad
from ardrone_nmpc.core.types import IX_PSI, IX_VX, IX_VY, IX_VZ, IX_X, IX_Y, IX_Z

__all__ = ["AXES", "SATURATION_FRAC", "STEADY_FRACTION", "ReferenceIntegrator", "frozen_axes"]

AXES = ("x", "y", "z", "psi")
_POS = (IX_X, IX_Y, IX_Z, IX_PSI)   # state indices of the shifted reference components
_VEL = (IX_VX, IX_VY, IX_VZ)
_REF_STILL = 1e-9  # a reference component that changes by more than this has moved
#: A PCMD fraction this close to ±1 counts as on the drone's limit (the ż reference is clipped
#: to control_vz_max before the mapping, so the gaz flag alone would never show it).
SATURATION_FRAC = 0.999
#: The error counts as steady while its range since coming to rest is within this fraction of
#: it (or within ``steady_band``, for small errors).
STEADY_FRACTION = 0.2


def _per_axis(values) -> np.ndarray:
    """One float per axis of :data:`AXES` (a config vector)."""
    a = np.asarray(values, dtype=float)
    if a.shape != (len(AXES),):
        raise ValueError(f"one value per axis {AXES} expected, got {values!r}")
    return a


def frozen_axes(pcmd_fracs: tuple[float, float, float, float],
                flags: str | None) -> tuple[bool, bool, bool, bool]:
    """Which of [x, y, z, ψ] must not integrate, from the command sent.

    ``pcmd_fracs`` = (roll, pitch, gaz, yaw) fractions, ``flags`` the ``cmd_saturated`` string
    ("0100"; None for none). Roll and pitch act on x and y together once the drone has turned,
    so either one on its limit freezes both; gaz freezes z, yaw ψ.
    """
    sat = [abs(f) >= SATURATION_FRAC for f in pcmd_fracs]
    if flags:
        sat = [s or c == "1" for s, c in zip(sat, flags)]
    tilt = sat[0] or sat[1]
    return tilt, tilt, sat[2], sat[3]


class ReferenceIntegrator:
    """The reference shift ``s`` = [x, y, z, ψ] and its integration law.

    Parameters
    ----------
    ki_per_s, error_band, speed_band, max_shift, hold_s, kp, release_speed, steady_band :
        (4,) per axis, [x, y, z, ψ] (1/s; m, m, m, rad; m/s, m/s, m/s, rad/s; m, m, m, rad;
        s; –; as speed_band; as error_band).
    period_s : integration step (s), the control period.
    """

    def __init__(self, ki_per_s, error_band, speed_band, max_shift, hold_s,
                 period_s: float, kp=(0.0,) * 4, release_speed=(math.inf,) * 4,
                 steady_band=(math.inf,) * 4) -> None:
        n = len(AXES)
        self.steady_band = _per_axis(steady_band)
        self.release_speed = _per_axis(release_speed)
        self.kp = _per_axis(kp)
        self.hold_s = _per_axis(hold_s)
        self._rest_s = np.zeros(n)  # how long each axis has been at rest inside its band
        self.latched = np.zeros(n, dtype=bool)  # learning until the error or reference moves
        self._last = np.full(n, math.nan)  # the reference components of the last update
        self._last_error_psi = math.nan
        self._integral = np.zeros(n)  # the integral part of the shift
        self._rest_lo = np.zeros(n)  # the error's range since the axis came to rest
        self._rest_hi = np.zeros(n)
        self.ki_per_s = _per_axis(ki_per_s)
        self.error_band = _per_axis(error_band)
        self.speed_band = _per_axis(speed_band)
        self.max_shift = _per_axis(max_shift)
        self.period_s = float(period_s)
        self.shift = np.zeros(n)
        self.learning = np.zeros(n, dtype=bool)  # which axes integrated on the last update

    @classmethod
    def from_config(cls, cfg, period_s: float) -> ReferenceIntegrator:
        """From ``controller.offset_free``
        (:class:`~ardrone_nmpc.config.schema.OffsetFreeConfig`)."""
        return cls(cfg.ki_per_s, cfg.error_band, cfg.speed_band, cfg.max_shift, cfg.hold_s,
                   period_s, cfg.kp, cfg.release_speed, cfg.steady_band)

    def errors(self, x: np.ndarray, ref: np.ndarray) -> np.ndarray:
        """Tracking errors [x, y, z, ψ] of the estimate ``x`` (7,) against ``ref`` (7,)."""
        e = np.array([x[i] - ref[i] for i in _POS])
        e[3] = wrap_angle_rad(e[3])
        return e

    def update(self, x: np.ndarray, ref: np.ndarray,
               frozen: tuple[bool, bool, bool, bool] = (False,) * 4,
               preview: np.ndarray | None = None) -> np.ndarray:
        """One control period of integration; returns the new shift (the object's own array).

        Per axis: the integrator starts learning once the axis has been at rest (|ė| below
        the speed band, |e| inside the error band and steady: its range since coming to rest
        within ``steady_band``) for ``hold_s`` — the tail of a step, still converging, is the
        loop's own — and keeps learning, ``s ← s − ki·e·period`` (shift = integral − kp·e),
        until |e| leaves the error band, |ė| exceeds ``release_speed`` (a gust, not a constant
        disturbance) or the reference moves — now, or anywhere in ``preview`` (n, 7), the
        reference the NMPC sees over its horizon: it starts a step before the reference
        does. ``frozen`` axes keep their shift (anti-windup).
        The shift is clipped to ±max_shift. ė is the estimate's velocity, for ψ the
        difference of its error over one period.
        """
        e = self.errors(x, ref)
        rate = [x[i] for i in _VEL] + [0.0]
        if math.isfinite(self._last_error_psi):
            rate[3] = wrap_angle_rad(e[3] - self._last_error_psi) / self.period_s
        self._last_error_psi = e[3]
        for k, i in enumerate(_POS):
            moved = abs(ref[i] - self._last[k]) > _REF_STILL  # False on the first update (NaN)
            if preview is not None:
                moved = moved or not np.all(np.abs(preview[:, i] - ref[i]) <= _REF_STILL)
            self._last[k] = ref[i]
            inside = math.isfinite(e[k]) and abs(e[k]) < self.error_band[k]
            at_rest = inside and abs(rate[k]) < self.speed_band[k] and not moved
            if at_rest and self._rest_s[k] > 0.0:
                lo = min(self._rest_lo[k], e[k])
                hi = max(self._rest_hi[k], e[k])
                # steady: the range within the band or a fifth of the error — a converging tail
                # changes by (1 − e^(−hold/τ)) of itself, most of it for hold ≳ τ
                if hi - lo <= max(self.steady_band[k], STEADY_FRACTION * abs(e[k])):
                    self._rest_lo[k], self._rest_hi[k] = lo, hi
                    self._rest_s[k] += self.period_s
                else:  # still converging by itself: the rest starts again from here
                    self._rest_lo[k] = self._rest_hi[k] = e[k]
                    self._rest_s[k] = self.period_s
            elif at_rest:
                self._rest_lo[k] = self._rest_hi[k] = e[k]
                self._rest_s[k] = self.period_s
            else:
                self._rest_s[k] = 0.0
            if not inside or moved or abs(rate[k]) > self.release_speed[k]:
                self.latched[k] = False
            elif self._rest_s[k] > self.hold_s[k]:
                self.latched[k] = True
            self.learning[k] = self.latched[k] and not frozen[k]
            if self.learning[k]:
                lim = self.max_shift[k]
                integral = self._integral[k] - self.ki_per_s[k] * e[k] * self.period_s
                self._integral[k] = min(max(integral, -lim), lim)
                self.shift[k] = min(max(self._integral[k] - self.kp[k] * e[k], -lim), lim)
        return self.shift

    def shifted(self, states: np.ndarray) -> np.ndarray:
        """Reference states (n, 7) with the shift added to x, y, z, ψ (a new array)."""
        out = np.array(states, dtype=float, copy=True)
        for k, i in enumerate(_POS):
            out[..., i] += self.shift[k]
        return out
