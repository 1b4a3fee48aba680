"""The P controller's tick (thesis eq. 4.16) in one compiled call (issue 26).

``Control.solve`` of the P controller made two Python calls a tick: the reference now
(``HoldStartThen.state_at``: its conversions, then the waypoint kernel) and
:func:`~ardrone_nmpc.control.proportional.p_control`. Against a waypoint reference (the
square, steps, hover: ``HoldStartThen.waypoint_args`` with knots) :func:`p_tick` does both:
the lookup is :func:`~ardrone_nmpc.runtime.tick_kernels.nmpc_inputs`' with one time (no
horizon, nothing pending: the same kernel, the same held start before t = 0) and the law is
``p_control``'s own, ``control/proportional.p_law`` compiled (:data:`p_law`), its heading
wrap :func:`~ardrone_nmpc.core.angle_kernels.wrap_half_turn` (the same bits, tests hold
them to it). A curve's table (``tabulated``) and anything else keep the Python path.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ardrone_nmpc.control import proportional
from ardrone_nmpc.core.angle_kernels import wrap_half_turn
from ardrone_nmpc.core.kernel_cache import first_warm_up, flush_stale_caches
from ardrone_nmpc.core.numerics import INNER_KERNEL, OUTER_KERNEL, compiled_twin
from ardrone_nmpc.core.types import STATE_DIM
from ardrone_nmpc.runtime.tick_kernels import nmpc_inputs, nmpc_work

__all__ = ["p_law", "p_tick", "p_work", "warm_up_kernels"]

_NOTHING = np.zeros((1, 4))  # no input pending (the P controller predicts no delay)
_NO_SHIFT = np.zeros(0)


def p_work(period_s: float, waypoint_args: tuple) -> tuple[np.ndarray, np.ndarray] | None:
    """:func:`p_tick`'s ``work`` and ``rows`` of a waypoint trajectory's ``waypoint_args``
    (one time: the reference now), or None when it has no knots (a table: Python's path)."""
    if waypoint_args[0].size == 0:
        return None
    return nmpc_work(period_s, 1, waypoint_args)


@njit(cache=True, **INNER_KERNEL)
def _wrap_rad(a):
    """``wrap_angle_rad`` of a heading compiled (the same bits for a finite one; NaN else,
    where the Python wrap answers NaN or raises: the compiled ticks take finite headings)."""
    return wrap_half_turn(a, math.pi)


#: ``control/proportional.p_law`` compiled (its one source): :func:`p_tick`'s law and the
#: P controller's compiled nominal tick's (``runtime/control_tick_p``)
p_law = compiled_twin(proportional.p_law, "p_law", INNER_KERNEL, wrap_angle_rad=_wrap_rad)


@njit(cache=True, **OUTER_KERNEL)
def p_tick(x: np.ndarray, t_s: float, k1: float, k2: float, k3: float, k4: float,
           ref: np.ndarray, work: np.ndarray, rows: np.ndarray) -> tuple:
    """``ref`` (1, 7) = the reference at ``t_s`` and ``p_control(x, ref[0], gains)``'s
    ``(vz_ref_mps, phi_rad, theta_rad, psirate_radps)``, unclipped."""
    nmpc_inputs(x, _NOTHING, 0, 0, x, t_s, 0.0, _NO_SHIFT, ref, work, rows)
    return p_law(x, ref[0], k1, k2, k3, k4)


def warm_up_kernels() -> None:
    """Load (or compile) :func:`p_tick` now — once per process — not on the first tick
    aloft (``Tick``: a P flight against a waypoint reference), its callees from the cache
    first (``core/kernel_cache.first_warm_up``)."""
    if first_warm_up(p_tick):
        work, rows = nmpc_work(0.065, 1, (np.array([0.0, 1.0]), np.zeros((2, 3)), np.zeros(2),
                                          np.ones(1), np.zeros((1, 3)), np.zeros(STATE_DIM)))
        p_tick(np.zeros(STATE_DIM), 0.5, 1.0, 1.0, 1.0, 1.0, np.empty((1, STATE_DIM)), work,
               rows)


flush_stale_caches(__name__)  # kernels calling other files: core/kernel_cache.py
