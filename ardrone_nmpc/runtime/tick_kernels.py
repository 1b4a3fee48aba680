"""The tick's NMPC inputs in one compiled call (issue 26): the state the new command will meet
and the reference it is solved against.

``Control.solve`` made four calls of its own a tick before the solver's — the delay
prediction's rollout (:meth:`~ardrone_nmpc.runtime.stages.DelayPrediction.predict`), the
horizon's times, the reference lookup (``HoldStartThen.state_at`` of a waypoint trajectory)
and the offset-free shift — each with its arrays to allocate and its numba call to dispatch.
:func:`nmpc_inputs` runs the same kernels, on the same arrays, in one call: the same bits.
Other reference kinds keep the general path.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ardrone_nmpc.control.kernels import rollout_rk4
from ardrone_nmpc.core.kernel_cache import flush_stale_caches, load_cached_callees
from ardrone_nmpc.core.numerics import OUTER_KERNEL
from ardrone_nmpc.reference.kernels import held_waypoint_horizon

__all__ = ["nmpc_inputs", "warm_up_kernels"]


@njit(cache=True, **OUTER_KERNEL)
def nmpc_inputs(x: np.ndarray, sent: np.ndarray, first: int, pending: int, period_s: float,
                x_solve: np.ndarray, t_knots: np.ndarray, positions_m: np.ndarray,
                psi_rad: np.ndarray, dt_s: np.ndarray, vel_mps: np.ndarray, start: np.ndarray,
                t_s: float, lead_s: float, offsets: np.ndarray, shift: np.ndarray,
                times: np.ndarray, clamped: np.ndarray, states: np.ndarray,
                horizon: np.ndarray) -> None:
    """``x_solve`` = ``x`` rolled through the ``pending`` inputs ``sent[first:first +
    pending]`` (``DelayPrediction.predict``; nothing written when none is pending), then
    :func:`~ardrone_nmpc.reference.kernels.held_waypoint_horizon`'s ``times``, ``states``
    and shifted ``horizon``."""
    if pending:
        rollout_rk4(x, sent[first:first + pending], period_s, x_solve)
    held_waypoint_horizon(t_knots, positions_m, psi_rad, dt_s, vel_mps, start, t_s, lead_s,
                          offsets, shift, times, clamped, states, horizon)


_kernels_warm = False


def warm_up_kernels() -> None:
    """Load (or compile) :func:`nmpc_inputs` now — once per process — not on the first tick
    (``Control.warm_up``; a cold start's background compile, ``runtime/precompile.py``).
    Its callees are loaded from the cache first (``core/kernel_cache.load_cached_callees``:
    the rollout's own machine code, cached or compiled alike)."""
    global _kernels_warm
    if _kernels_warm:
        return
    load_cached_callees(nmpc_inputs)
    knots, n = np.array([0.0, 1.0]), 3  # a two-waypoint trajectory, one stage
    x, states = np.zeros(7), np.zeros((n, 7))
    nmpc_inputs(x, np.zeros((2, 4)), 0, 1, 0.065, np.zeros(7), knots, np.zeros((2, 3)),
                np.zeros(2), np.ones(1), np.zeros((1, 3)), x, 0.0, 0.0, np.zeros(n),
                np.zeros(4), np.zeros(n), np.zeros(n), states, np.zeros((n - 1, 7)))
    _kernels_warm = True


flush_stale_caches(__name__)  # kernels calling other files: core/kernel_cache.py
