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
from numba import njit

from ardrone_nmpc.core.angle_kernels import wrap_half_turn
from ardrone_nmpc.core.angles import wrap_angle_rad
from ardrone_nmpc.core.kernel_cache import flush_stale_caches
from ardrone_nmpc.core.numerics import INNER_KERNEL, OUTER_KERNEL
from ardrone_nmpc.core.types import IX_PSI, IX_VX, IX_VY, IX_VZ, IX_X, IX_Y, IX_Z

__all__ = ["AXES", "SATURATION_FRAC", "STEADY_FRACTION", "ReferenceIntegrator", "frozen_axes",
           "integrate_period"]

AXES = ("x", "y", "z", "psi")
_POS = (IX_X, IX_Y, IX_Z, IX_PSI)   # state indices of the shifted reference components
_POS_LIST = list(_POS)
_VEL = (IX_VX, IX_VY, IX_VZ)
_NO_PREVIEW = np.zeros((0, 7))
# the rows of ReferenceIntegrator._carry: what each axis carries from one update to the next
_LAST, _REST_S, _INTEGRAL, _REST_LO, _REST_HI = range(5)
# ReferenceIntegrator._work, one float64 buffer (one argument of integrate_period, not six:
# numba's dispatch costs ~50–100 ns an argument, issue 26): the law (4 axes × 8), the carry (5 × 4),
# the shift (4), the last ψ error (1), the period (1), and scratch for the errors and their
# rates (4 each): read flat, no reshape or allocation in the kernel (each costs ~50 ns)
_W_LAW, _W_CARRY, _W_SHIFT, _W_PSI, _W_PERIOD, _W_E, _W_RATE = 0, 32, 52, 56, 57, 58, 62
_W_SIZE = 66
_NONE_FROZEN = (False, False, False, False)
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
    so either one on its limit freezes both; gaz freezes z, yaw ψ. Its compiled twin (the
    nominal tick's): ``runtime/after_solve._freeze``, kept equal by its tests.
    """
    roll, pitch, gaz, yaw = pcmd_fracs  # spelled out: two list comprehensions cost µs a tick
    if (-SATURATION_FRAC < roll < SATURATION_FRAC and -SATURATION_FRAC < pitch < SATURATION_FRAC
            and -SATURATION_FRAC < gaz < SATURATION_FRAC
            and -SATURATION_FRAC < yaw < SATURATION_FRAC and (not flags or flags == "0000")):
        return _NONE_FROZEN  # the usual tick: all inside, nothing flagged (a NaN goes below)
    s0, s1 = abs(roll) >= SATURATION_FRAC, abs(pitch) >= SATURATION_FRAC
    s2, s3 = abs(gaz) >= SATURATION_FRAC, abs(yaw) >= SATURATION_FRAC
    if flags and flags != "0000":
        c0, c1, c2, c3 = flags
        s0, s1, s2, s3 = (s0 or c0 == "1", s1 or c1 == "1", s2 or c2 == "1", s3 or c3 == "1")
    tilt = s0 or s1
    return tilt, tilt, s2, s3


@njit(cache=True, **OUTER_KERNEL)
def integrate_period(x, ref, preview, work, flags):
    """:meth:`ReferenceIntegrator.update`'s law, compiled: one period of every axis.

    ``work`` (:data:`_W_SIZE`) holds the law (4, 8): error band, speed band, steady band,
    release speed, hold, ki, kp, max shift per axis; the carry (5, 4), the rows ``_LAST`` …
    ``_REST_HI``; the shift (4); the last ψ error (NaN before the first); the period; scratch.
    ``flags`` (3, 4) are the axes latched, learning and frozen this period (the last row
    cleared on the way out: the caller sets it only when an axis is frozen). All in place.
    Python's ``min``/``max`` are spelled out (the first argument unless the second is
    strictly beyond it), so a NaN goes where it went in Python.
    """
    c = _W_CARRY  # the carry's row r, axis k at c + 4·r + k
    period = work[_W_PERIOD]
    latched = flags[0]
    learning = flags[1]
    frozen = flags[2]
    pos = _POS
    e = work[_W_E:_W_E + 4]
    rate = work[_W_RATE:_W_RATE + 4]
    for k in range(4):
        e[k] = x[pos[k]] - ref[pos[k]]
        rate[k] = 0.0
    e[3] = wrap_half_turn(e[3], math.pi)
    for k in range(3):
        rate[k] = x[_VEL[k]]
    if math.isfinite(work[_W_PSI]):
        rate[3] = wrap_half_turn(e[3] - work[_W_PSI], math.pi) / period
    work[_W_PSI] = e[3]
    for k in range(4):
        w = _W_LAW + 8 * k
        error_band, speed_band = work[w], work[w + 1]
        steady_band, release = work[w + 2], work[w + 3]
        hold, ki, kp, lim = work[w + 4], work[w + 5], work[w + 6], work[w + 7]
        last, rest_s, integral = c + 4 * _LAST + k, c + 4 * _REST_S + k, c + 4 * _INTEGRAL + k
        rest_lo, rest_hi = c + 4 * _REST_LO + k, c + 4 * _REST_HI + k
        ek, refk = e[k], ref[pos[k]]
        still = True
        for j in range(preview.shape[0]):
            if not abs(preview[j, pos[k]] - refk) <= _REF_STILL:
                still = False
        moved = abs(refk - work[last]) > _REF_STILL or not still  # first update: NaN
        work[last] = refk
        inside = math.isfinite(ek) and abs(ek) < error_band
        at_rest = inside and abs(rate[k]) < speed_band and not moved
        if at_rest and work[rest_s] > 0.0:
            lo = ek if ek < work[rest_lo] else work[rest_lo]
            hi = ek if ek > work[rest_hi] else work[rest_hi]
            spread = STEADY_FRACTION * abs(ek)
            if hi - lo <= (spread if spread > steady_band else steady_band):
                work[rest_lo], work[rest_hi] = lo, hi
                work[rest_s] += period
            else:  # still converging by itself: the rest starts again from here
                work[rest_lo] = work[rest_hi] = ek
                work[rest_s] = period
        elif at_rest:
            work[rest_lo] = work[rest_hi] = ek
            work[rest_s] = period
        else:
            work[rest_s] = 0.0
        if not inside or moved or abs(rate[k]) > release:
            latched[k] = False
        elif work[rest_s] > hold:
            latched[k] = True
        learning[k] = latched[k] and not frozen[k]
        frozen[k] = False
        if learning[k]:
            work[integral] = _clip(work[integral] - ki * ek * period, lim)
            work[_W_SHIFT + k] = _clip(work[integral] - kp * ek, lim)


@njit(cache=True, **OUTER_KERNEL)
def _shifted(states, shift):
    """A copy of ``states`` (n, 7) with ``shift`` (4) added to x, y, z, ψ."""
    out = states.copy()
    for j in range(out.shape[0]):
        for k in range(4):
            out[j, _POS[k]] += shift[k]
    return out


@njit(cache=True, **INNER_KERNEL)
def _clip(value, lim):
    """``min(max(value, -lim), lim)`` with Python's ``min`` and ``max``."""
    low = -lim if -lim > value else value
    return lim if lim < low else low


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
        self.ki_per_s = _per_axis(ki_per_s)
        self.error_band = _per_axis(error_band)
        self.speed_band = _per_axis(speed_band)
        self.max_shift = _per_axis(max_shift)
        # what integrate_period reads and writes, in two buffers (_W_*); the names are views
        self._work = np.zeros(_W_SIZE)
        # latched, learning, and the axes frozen for the next period: a row the kernel reads
        # and clears, set only when one is (a tuple argument costs ~60 ns a call, issue 26)
        self._flags = np.zeros((3, n), dtype=bool)
        self._bind_views()
        self._law[:] = np.stack((
            self.error_band, self.speed_band, self.steady_band, self.release_speed,
            self.hold_s, self.ki_per_s, self.kp, self.max_shift), axis=1)
        self._carry[_LAST] = math.nan  # the reference components of the last update
        self._last_error_psi[0] = math.nan
        self.period_s = period_s

    def _bind_views(self) -> None:
        """The public arrays and the law, carry and last ψ error as views of the buffers."""
        work, flags = self._work, self._flags
        self.shift = work[_W_SHIFT:_W_PSI]
        self.latched = flags[0]  # learning until the error or reference moves
        self.learning = flags[1]  # which axes integrated on the last update
        self._frozen = flags[2]
        # the law per axis (rows of integrate_period's law) and what it carries between updates
        self._law = work[_W_LAW:_W_CARRY].reshape(len(AXES), 8)
        self._carry = work[_W_CARRY:_W_SHIFT].reshape(5, len(AXES))
        self._last_error_psi = work[_W_PSI:_W_PERIOD]

    def __setstate__(self, state: dict) -> None:
        """A deep copy or unpickling: each view was copied apart from its buffer (numpy
        copies a view's data alone); made views of the copied buffers again, so the kernel's
        writes reach ``shift``, ``latched`` and ``learning``."""
        self.__dict__.update(state)
        self._bind_views()

    @property
    def period_s(self) -> float:
        """The integration step (s), held in the kernel's buffer."""
        return float(self._work[_W_PERIOD])

    @period_s.setter
    def period_s(self, period_s: float) -> None:
        self._work[_W_PERIOD] = float(period_s)

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
        preview = _NO_PREVIEW if preview is None else np.asarray(preview, dtype=np.float64)
        f0, f1, f2, f3 = frozen
        return self.step(np.asarray(x, dtype=np.float64), np.asarray(ref, dtype=np.float64),
                         (bool(f0), bool(f1), bool(f2), bool(f3)), preview)

    def step(self, x: np.ndarray, ref: np.ndarray, frozen: tuple[bool, bool, bool, bool],
             preview: np.ndarray | None) -> np.ndarray:
        """:meth:`update` for the tick: ``x``, ``ref`` (7,) and ``preview`` (n, 7) float64
        arrays (or None), ``frozen`` four bools — no conversions."""
        if frozen is not _NONE_FROZEN:  # (the usual tick's: the row is clear already)
            self._frozen[:] = frozen
        integrate_period(x, ref, _NO_PREVIEW if preview is None else preview, self._work,
                   self._flags)
        return self.shift

    def shifted(self, states: np.ndarray) -> np.ndarray:
        """Reference states (n, 7) with the shift added to x, y, z, ψ (a new array)."""
        states = np.asarray(states, dtype=np.float64)
        if states.ndim != 2:
            out = np.array(states, copy=True)
            out[..., _POS_LIST] += self.shift
            return out
        return _shifted(states, self.shift)


flush_stale_caches(__name__)  # kernels calling other files: core/kernel_cache.py
