"""Compiled reference lookups: the NMPC asks for its horizon reference every tick.

:meth:`~ardrone_nmpc.reference.trajectories.Waypoints.state_at` (the square, a waypoint file)
did some twenty numpy operations on arrays of a horizon's length — the largest cost of a
lockstep tick outside the solver (issue 26). :func:`waypoint_states` computes the same
expressions per time, in the same order (``a + frac·(b − a)``: subtractions, products and sums
round alike in numpy and in a compiled loop on the pinned target, which fuses nothing), so the
states are the same bits. Imported only when a waypoint reference is first looked up: the
command line's start-up imports no numba.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ardrone_nmpc.core.kernel_cache import flush_stale_caches
from ardrone_nmpc.core.numerics import OUTER_KERNEL
from ardrone_nmpc.core.sorted_search import count_at_or_below
from ardrone_nmpc.core.types import IX_PSI, IX_VX, IX_VY, IX_VZ, IX_X, IX_Y, IX_Z

__all__ = ["waypoint_states"]


@njit(cache=True, **OUTER_KERNEL)
def waypoint_states(t_knots: np.ndarray, positions_m: np.ndarray, psi_rad: np.ndarray,
                    dt_s: np.ndarray, vel_mps: np.ndarray, t_s: np.ndarray,
                    out: np.ndarray) -> None:
    """The states of :class:`~ardrone_nmpc.reference.trajectories.Waypoints` at ``t_s`` into
    ``out`` (len(t), 7) (its ``state_at``, the same bits)."""
    t_first, t_last = t_knots[0], t_knots[-1]
    for j in range(t_s.size):
        t = t_s[j]
        # clip(searchsorted(t_knots, t, side="right") − 1, 0, K − 2)
        k = min(max(count_at_or_below(t_knots, t_knots.size, t) - 1, 0), t_knots.size - 2)
        inside = t >= t_first and t < t_last
        after = t >= t_last
        frac = 1.0 if after else ((t - t_knots[k]) / dt_s[k] if inside else 0.0)
        for c, col in enumerate((IX_X, IX_Y, IX_Z)):
            a, b = positions_m[k, c], positions_m[k + 1, c]
            out[j, col] = b if after else a + frac * (b - a)
        for c, col in enumerate((IX_VX, IX_VY, IX_VZ)):
            out[j, col] = vel_mps[k, c] if inside else 0.0
        psi_a, psi_b = psi_rad[k], psi_rad[k + 1]
        out[j, IX_PSI] = psi_b if after else psi_a + frac * (psi_b - psi_a)


flush_stale_caches(__name__)  # kernels calling other files: core/kernel_cache.py
