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
from ardrone_nmpc.core.numerics import INNER_KERNEL, OUTER_KERNEL
from ardrone_nmpc.core.sorted_search import count_at_or_below
from ardrone_nmpc.core.types import IX_PSI, IX_VX, IX_VY, IX_VZ, IX_X, IX_Y, IX_Z

__all__ = ["held_waypoint_horizon", "waypoint_states"]

#: The state slots a reference shift moves (offset-free tracking: x, y, z, ψ), as in
#: :mod:`ardrone_nmpc.estimation.disturbance`.
_SHIFTED = (IX_X, IX_Y, IX_Z, IX_PSI)


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


@njit(cache=True, **INNER_KERNEL)
def held_waypoint_horizon(t_knots: np.ndarray, positions_m: np.ndarray, psi_rad: np.ndarray,
                          dt_s: np.ndarray, vel_mps: np.ndarray, start: np.ndarray,
                          t_s: float, lead_s: float, offsets: np.ndarray, shift: np.ndarray,
                          times: np.ndarray, clamped: np.ndarray, states: np.ndarray,
                          horizon: np.ndarray) -> None:
    """The NMPC's reference of one tick in one call (``Control.solve``'s general path, the
    same bits): ``times`` = [t, (t + lead) + offsets[1:]], ``states`` (len, 7) the
    :class:`~ardrone_nmpc.reference.experiment.HoldStartThen` of a waypoint trajectory at
    them (``start`` before t = 0), and — when ``shift`` (4) is not empty — ``horizon`` =
    ``states[1:]`` with the offset-free shift added to x, y, z, ψ (``ReferenceIntegrator.
    shifted``). ``clamped`` is scratch of ``times``' length. Only kernels call it
    (``runtime/tick_kernels.nmpc_inputs``); tests its ``callable_from_python`` twin."""
    base = t_s + lead_s
    n = offsets.size
    for i in range(n):
        times[i] = base + offsets[i]
    times[0] = t_s
    inside = True  # min(times) > 0 (NaN is not): nothing held
    for i in range(n):
        if not times[i] > 0.0:
            inside = False
    if inside:
        waypoint_states(t_knots, positions_m, psi_rad, dt_s, vel_mps, times, states)
    else:
        for i in range(n):  # np.maximum(t, 0.0): t unless t < 0 (NaN stays NaN)
            t = times[i]
            clamped[i] = t if (t >= 0.0 or t != t) else 0.0
        waypoint_states(t_knots, positions_m, psi_rad, dt_s, vel_mps, clamped, states)
        for i in range(n):
            if times[i] < 0.0:
                for c in range(states.shape[1]):
                    states[i, c] = start[c]
    if shift.size:
        for j in range(horizon.shape[0]):
            for c in range(states.shape[1]):
                horizon[j, c] = states[j + 1, c]
            for k in range(4):
                horizon[j, _SHIFTED[k]] += shift[k]


flush_stale_caches(__name__)  # kernels calling other files: core/kernel_cache.py
