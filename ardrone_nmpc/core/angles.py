"""Angle helpers: wrapping to (−π, π] and unwrapping next to a reference.

DESIGN.md §4 wraps ψ to (−π, π]. Errors between headings must be wrapped before a gain is
applied, otherwise a drone at ψ = 3.1 rad asked for ψ_d = −3.1 rad turns the long way round.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["TWO_PI", "wrap_angle_rad", "unwrap_near"]

TWO_PI = 2.0 * math.pi


def _wrap_scalar(a: float) -> float:
    # math.remainder is the exact IEEE remainder: for |a| < π it returns a unchanged (so the
    # wrap is idempotent bit for bit) and it lands in [−π, π]; only −π needs moving to π.
    if not math.isfinite(a):
        return math.nan
    r = math.remainder(a, TWO_PI)
    return math.pi if r <= -math.pi else r


_wrap_array = np.vectorize(_wrap_scalar, otypes=[float])


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
    if np.ndim(a) == 0:
        return _wrap_scalar(float(a))
    return _wrap_array(np.asarray(a, dtype=float))


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
