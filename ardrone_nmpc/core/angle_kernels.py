"""The angle wrap compiled, for the numba kernels (numba has no ``math.remainder``):
:func:`~ardrone_nmpc.core.angles.wrap_angle_rad` and
:func:`~ardrone_nmpc.core.angles.wrap_angle_deg`'s rule on
:func:`~ardrone_nmpc.core.angles.ieee_remainder`, the same bits (tests hold them to it)."""

from __future__ import annotations

import math

from numba import njit

from ardrone_nmpc.core.angles import ieee_remainder
from ardrone_nmpc.core.kernel_cache import flush_stale_caches
from ardrone_nmpc.core.numerics import INNER_KERNEL, OUTER_KERNEL

__all__ = ["wrap_half_turn"]

_remainder = njit(cache=True, **INNER_KERNEL)(ieee_remainder)


@njit(cache=True, **OUTER_KERNEL)
def wrap_half_turn(a, half_turn):
    """``a`` wrapped to (−half_turn, half_turn]: π for radians, 180.0 for degrees; NaN if
    not finite."""
    if not math.isfinite(a):
        return math.nan
    r = _remainder(a, 2.0 * half_turn)
    return half_turn if r <= -half_turn else r


flush_stale_caches(__name__)  # kernels calling other files: core/kernel_cache.py
