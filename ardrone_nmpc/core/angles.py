"""Angle helpers — the one home of angle wrapping: to (−π, π] (rad) or (−180, 180] (°), and
unwrapping next to a reference.

ψ is wrapped to (−π, π] (docs/design.md). Errors between headings must be wrapped before a
gain is applied, otherwise a drone at ψ = 3.1 rad asked for ψ_d = −3.1 rad turns the long way
round. :func:`unwrap_near_turns` is plain arithmetic so that the numba kernels compile it.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["TWO_PI", "ieee_remainder", "wrap_angle_rad", "wrap_angle_deg", "unwrap_near",
           "unwrap_near_turns"]

TWO_PI = 2.0 * math.pi


def _wrap_scalar(a: float) -> float:
    # math.remainder is the exact IEEE remainder: for |a| < π it returns a unchanged (so the
    # wrap is idempotent bit for bit) and it lands in [−π, π]; only −π needs moving to π.
    if not math.isfinite(a):  # first: an ordered comparison with NaN raises the FPU's
        return math.nan       # invalid flag (np.vectorize warns); math.remainder(inf, …) raises
    if -math.pi < a <= math.pi:  # already wrapped (most calls: a heading every tick): what
        return float(a)          # remainder would return, without computing it
    r = math.remainder(a, TWO_PI)
    return math.pi if r <= -math.pi else r


_wrap_each = np.vectorize(_wrap_scalar, otypes=[float])


def _wrap_array(a: np.ndarray) -> np.ndarray:
    """:func:`_wrap_scalar` of each element, bit for bit: those already in (−π, π] — nearly
    all of a logged heading's or heading error's — copied as they are (what it returns for
    them), only the others wrapped one by one (a summary's ψ column: ~0.3 ms → ~10 µs)."""
    out = np.array(a, dtype=float)
    with np.errstate(invalid="ignore"):  # a NaN is not inside: wrapped one by one (NaN)
        outside = ~((-math.pi < out) & (out <= math.pi))
    if outside.any():
        out[outside] = _wrap_each(out[outside])
    return out


def ieee_remainder(x: float, y: float) -> float:
    """``math.remainder(x, y)`` for finite ``x`` and finite ``y`` ≠ 0, in plain arithmetic so
    that the kernels compile it (numba has no ``math.remainder``): CPython's own algorithm,
    bit for bit — ``%`` of non-negative floats is C's ``fmod``, exact."""
    absx, absy = abs(x), abs(y)
    m = absx % absy
    c = absy - m
    if m < c:
        r = m
    elif m > c:
        r = -c
    else:  # half way: the even multiple
        r = m - 2.0 * ((0.5 * (absx - m)) % absy)
    return math.copysign(1.0, x) * r



def wrap_angle_rad(a):
    """Wrap an angle to the half-open interval (−π, π].

    Parameters
    ----------
    a : float or array_like
        Angle(s) in rad.

    Returns
    -------
    float or ndarray
        ``a + 2πk`` for the integer ``k`` that puts it in (−π, π]; a python float for a scalar
        input, an array of the input's shape otherwise.

    Notes
    -----
    A non-finite input gives NaN (like numpy ufuncs) rather than raising: the command mapping
    is the single gate that refuses to turn a NaN into a drone command.
    """
    if isinstance(a, float):  # python and numpy floats: the simulators' per-step path
        return _wrap_scalar(a)
    if np.ndim(a) == 0:
        return _wrap_scalar(float(a))
    return _wrap_array(np.asarray(a, dtype=float))


def wrap_angle_deg(a: float) -> float:
    """Wrap an angle in degrees to (−180, 180] (the navdata yaw); NaN if not finite.

    A checksum-valid navdata packet may carry ±inf (the wire is float32): NaN marks the
    sample unusable instead of raising in a receiver thread.
    """
    a = float(a)
    if not math.isfinite(a):
        return math.nan
    r = math.remainder(a, 360.0)
    return 180.0 if r <= -180.0 else r


def unwrap_near(angle_rad: float, ref_rad: float) -> float:
    """Return ``angle_rad + 2πk`` closest to ``ref_rad``.

    Used to keep a heading reference continuous with the measured heading (e.g. across the ±π
    seam) so that a difference of the two is the short way round.

    Parameters
    ----------
    angle_rad : float
        Angle to move, rad.
    ref_rad : float
        Reference angle, rad (any value, not necessarily wrapped).

    Returns
    -------
    float
        The equivalent angle in (ref − π, ref + π], rad.
    """
    return float(ref_rad) + wrap_angle_rad(float(angle_rad) - float(ref_rad))


def unwrap_near_turns(angle_rad, ref_rad):
    """``angle_rad + 2πk`` with ``k = rint((ref_rad − angle_rad) / 2π)``, for finite inputs.

    :func:`unwrap_near` by whole turns: plain arithmetic and a ufunc, so numba compiles it
    (the solver kernels unwrap the reference horizon with it) and it works elementwise on
    numpy arrays. It can differ from :func:`unwrap_near` in the last bit, and at an exact
    half turn it may land on ``ref − π`` instead of ``ref + π`` (``rint`` rounds half to even).
    """
    return angle_rad + TWO_PI * np.rint((ref_rad - angle_rad) / TWO_PI)
