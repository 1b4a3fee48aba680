"""The tick stages' compiled steps (issue 26): the estimate, and the NMPC's inputs — the state
the new command will meet and the reference it is solved against — each in one call.

:func:`estimate_step` is the estimation stage's update with its ż estimator (any
``estimator.kind``: the Kalman filter, the Luenberger observer, the difference, none) and the
backward difference of x, y: six Python calls and their checks, one compiled one. The
observer's coefficients for each Δt come from its own Python object (an expm each), kept in a
small table in the state: a Δt not in it is answered :data:`NO_COEFFICIENTS` and the caller
fills it (``runtime/estimate``).

``Control.solve`` made four calls of its own a tick before the solver's — the delay
prediction's rollout (:meth:`~ardrone_nmpc.runtime.stages.DelayPrediction.predict`), the
horizon's times, the reference lookup (``HoldStartThen.state_at`` of a waypoint trajectory)
and the offset-free shift — each with its arrays to allocate and its numba call to dispatch.
:func:`nmpc_inputs` runs the same kernels, on the same arrays, in one call: the same bits.
A curve (ellipse, Lorenz, excitation: ``reference/experiment.tabulated``) is read from a
table of its states at the horizon's times, filled by its own ``state_at`` for a tick or a
block of ticks (:func:`fill_reference_table`): the same bits by construction.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ardrone_nmpc.control.kernels import rollout_rk4_into
from ardrone_nmpc.core.kernel_cache import first_warm_up, flush_stale_caches
from ardrone_nmpc.core.numerics import INNER_KERNEL, OUTER_KERNEL
from ardrone_nmpc.core.types import IX_PSI, IX_X, IX_Y, IX_Z, STATE_DIM
from ardrone_nmpc.reference.kernels import waypoint_states

__all__ = ["E_SIZE", "E_STEP", "E_X", "ESTIMATED", "NO_COEFFICIENTS", "REFUSED", "TABLE_TICKS",
           "W_HEAD", "W_KNOTS", "W_PERIOD", "W_TIMES", "estimate_step", "fill_reference_table",
           "nmpc_inputs", "nmpc_work", "nmpc_work_views", "sample_waypoint_work", "table_tick",
           "warm_up_kernels"]


#: The state slots a reference shift moves (offset-free tracking: x, y, z, ψ), as in
#: :mod:`ardrone_nmpc.estimation.disturbance`.
_SHIFTED = (IX_X, IX_Y, IX_Z, IX_PSI)


# :func:`nmpc_inputs`' fixed buffers and parameters, built once per flight (:func:`nmpc_work`;
# numba's dispatch costs ~50–100 ns an argument, issue 26) in two arrays. ``work``, float64:
# these slots, then the horizon's offsets, times and their clamp at 0 (N each), the shifted
# horizon (N − 1, 7, row-major), the rollout's scratch (5 × 7: its slopes, not allocated every
# tick) and the waypoint trajectory's (``HoldStartThen.waypoint_args``) knots (K), ψ (K),
# Δt (K − 1) and start (7). ``rows`` (2K − 1, 3): its positions (K) then its
# segment velocities (K − 1) — 2-D slices of it, not reshapes of ``work``: a reshape costs the
# cold start ~0.1 s of compile each.
W_PERIOD = 0    # the control period (s): the delay prediction's RK4 step
W_TIMES = 1     # N, the horizon's times (its stages + 1, and the reference now)
W_KNOTS = 2     # K, the waypoints
W_HEAD = 3
_ROLLOUT_SCRATCH = 5 * STATE_DIM  # rollout_rk4_into's
#: The ticks a reference table holds (:func:`fill_reference_table`): a block's most
#: (``runtime/lockstep.BLOCK_TICKS``; ``TickBlocks`` flies no longer block against one).
TABLE_TICKS = 32


def nmpc_work(period_s: float, n_times: int,
              waypoint_args: tuple) -> tuple[np.ndarray, np.ndarray]:
    """:func:`nmpc_inputs`' ``work`` (the ``W_*`` slots) and ``rows`` for ``n_times`` horizon
    times and a waypoint trajectory's arrays; offsets, times, clamp and horizon zero. No
    knots (K = 0): ``rows`` is a reference table (:func:`fill_reference_table`) of
    :data:`TABLE_TICKS` ticks, its times NaN (no tick's)."""
    t_knots, positions_m, psi_rad, dt_s, vel_mps, start = waypoint_args
    head = np.array([period_s, n_times, t_knots.size], dtype=np.float64)
    buffers = np.zeros(3 * n_times + (n_times - 1) * STATE_DIM + _ROLLOUT_SCRATCH)
    work = np.concatenate((head, buffers, t_knots, psi_rad, dt_s, start)).astype(np.float64)
    if t_knots.size == 0:
        return work, np.full((TABLE_TICKS * n_times, 1 + STATE_DIM), np.nan)
    rows = np.ascontiguousarray(np.concatenate((positions_m, vel_mps)), dtype=np.float64)
    return work, rows


def fill_reference_table(traj, t_exp_s: np.ndarray, lead_s: float, work: np.ndarray,
                         rows: np.ndarray) -> None:
    """A reference table's first ``len(t_exp_s)`` ticks (``rows``, of :func:`nmpc_work`; n
    rows a tick: the time, then the state): each tick's horizon times as
    :func:`nmpc_inputs` makes them — [t, (t + lead) + offsets[1:]], ``Control.solve``'s
    general path's too — and ``traj.state_at`` at all of them in one call (a tabulated
    reference's states are elementwise: ``reference/experiment.tabulated``)."""
    n = int(work[W_TIMES])
    times = np.add((t_exp_s + lead_s)[:, None], work[W_HEAD:W_HEAD + n])
    times[:, 0] = t_exp_s
    flat = times.reshape(-1)
    m = flat.size
    rows[:m, 0] = flat
    rows[:m, 1:] = traj.state_at(flat)


@njit(cache=True, **INNER_KERNEL)
def table_tick(t_s: float, lead_s: float, work: np.ndarray, rows: np.ndarray) -> int:
    """The tick of the reference table ``rows`` (:func:`fill_reference_table`) whose times
    are the horizon's at ``t_s`` bit for bit — [t, (t + lead) + offsets[1:]], as
    :func:`nmpc_inputs` makes them —, or −1: none (a NaN time matches none)."""
    n = int(work[W_TIMES])
    base = t_s + lead_s
    for j in range(rows.shape[0] // n):
        r = j * n
        same = _same_bits(rows[r, 0], t_s)
        i = 1
        while same and i < n:
            same = _same_bits(rows[r + i, 0], base + work[W_HEAD + i])
            i += 1
        if same:
            return j
    return -1


@njit(cache=True, inline="always", **INNER_KERNEL)
def _same_bits(a: float, b: float) -> bool:
    """``a`` and ``b`` the same float64 (−0.0 is not +0.0: a state may differ at them)."""
    return a == b and math.copysign(1.0, a) == math.copysign(1.0, b)


def nmpc_work_views(work: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The offsets, times, clamp (N each) and the shifted horizon (N − 1, 7) in ``work``
    (views: the caller writes the offsets, the solver reads the horizon)."""
    n = int(work[W_TIMES])
    o = W_HEAD
    return (work[o:o + n], work[o + n:o + 2 * n], work[o + 2 * n:o + 3 * n],
            work[o + 3 * n:o + 3 * n + (n - 1) * STATE_DIM].reshape((n - 1, STATE_DIM)))


@njit(cache=True, **OUTER_KERNEL)
def nmpc_inputs(x: np.ndarray, sent: np.ndarray, first: int, pending: int, x_solve: np.ndarray,
                t_s: float, lead_s: float, shift: np.ndarray, states: np.ndarray,
                work: np.ndarray, rows: np.ndarray) -> None:
    """``Control.solve``'s inputs of the NMPC, the same bits as its general path (the offsets,
    times, clamp, horizon, trajectory and period in ``work`` and ``rows``, :func:`nmpc_work`):

    * ``x_solve`` = ``x`` rolled through the ``pending`` inputs ``sent[first:first +
      pending]`` (``DelayPrediction.predict``; nothing written when none is pending);
    * ``times`` = [t, (t + lead) + offsets[1:]] and ``states`` (N, 7) the
      :class:`~ardrone_nmpc.reference.experiment.HoldStartThen` of a waypoint trajectory
      (``reference/kernels.waypoint_states``'s arrays) at them, ``start`` before t = 0;
    * when ``shift`` (4) is not empty, ``horizon`` = ``states[1:]`` with the offset-free shift
      added to x, y, z, ψ (``ReferenceIntegrator.shifted``).

    Without knots (K = 0) the states are the reference table's tick at these times
    (:func:`table_tick`; the caller has found one: NaN states else).

    The clamp is scratch of the times' length. One kernel, its lookup written here rather
    than in a kernel of its own: every compiled level costs a cold start a compile."""
    n = int(work[W_TIMES])
    nk = int(work[W_KNOTS])
    o = W_HEAD  # the offsets from here (read by index: a slice is compiled code too)
    times = work[o + n:o + 2 * n]
    clamped = work[o + 2 * n:o + 3 * n]
    o += 3 * n
    h0 = o  # the shifted horizon, row-major (no reshape: a smaller compile)
    o += (n - 1) * STATE_DIM
    scratch = work[o:o + _ROLLOUT_SCRATCH]
    o += _ROLLOUT_SCRATCH
    t_knots = work[o:o + nk]
    psi_rad = work[o + nk:o + 2 * nk]
    dt_s = work[o + 2 * nk:o + 3 * nk - 1]
    s0 = o + 3 * nk - 1  # the start
    positions_m = rows[:nk]
    vel_mps = rows[nk:]
    if pending:
        rollout_rk4_into(x, sent[first:first + pending], work[W_PERIOD], x_solve, scratch)
    base = t_s + lead_s
    for i in range(n):
        times[i] = base + work[W_HEAD + i]
    times[0] = t_s
    if nk == 0:  # a reference table's tick
        j = table_tick(t_s, lead_s, work, rows)
        for i in range(n):
            for c in range(STATE_DIM):
                states[i, c] = rows[j * n + i, 1 + c] if j >= 0 else math.nan
    else:
        inside = True  # min(times) > 0 (NaN is not): nothing held
        for i in range(n):
            if not times[i] > 0.0:
                inside = False
        if inside:
            waypoint_states(t_knots, positions_m, psi_rad, dt_s, vel_mps, times, states)
        else:
            for i in range(n):  # np.maximum(t, 0.0): t if t > 0 or NaN, else +0.0 (−0.0 too)
                t = times[i]
                clamped[i] = t if (t > 0.0 or t != t) else 0.0
            waypoint_states(t_knots, positions_m, psi_rad, dt_s, vel_mps, clamped, states)
            for i in range(n):
                if times[i] < 0.0:
                    for c in range(STATE_DIM):
                        states[i, c] = work[s0 + c]
    if shift.size:
        for j in range(n - 1):
            row = h0 + j * STATE_DIM
            for c in range(STATE_DIM):
                work[row + c] = states[j + 1, c]
            for k in range(4):
                work[row + _SHIFTED[k]] += shift[k]


# The estimation stage's state for :func:`estimate_step` (``Estimation``: its ż estimator and
# the backward difference of x, y), one float64 buffer: these slots.
E_HAS_POSE = 0      # 1.0 once a pose was seen
E_LAST_T = 1        # that pose's time
E_Q, E_R, E_P0 = 2, 3, 4          # the filter's constants (ScalarKalmanVz's q, r, p0)
E_MIDPOINT = 5      # 1.0: the difference models ż at mid-tick (measurement_at_midpoint)
E_Z, E_VZ, E_P, E_K, E_INIT = 6, 7, 8, 9, 10  # its z anchor (observer: ẑ), ż, P, K, initialised
E_HAS_PREV = 11     # the difference's previous position is held
E_PREV_X, E_PREV_Y = 12, 13
E_VEL_X, E_VEL_Y = 14, 15         # its velocity
E_X = 16            # (7) the estimate [x, ẋ, y, ẏ, z, ż, ψ] (the caller's view)
E_VZ_KIND = 23      # VZ_KALMAN, VZ_LUENBERGER, VZ_DIFFERENCE or VZ_NONE
E_Z_PREV = 24       # the observer's z[k−1]
E_STEP = 25         # the slots a step writes (before these: what before_solve puts back)
E_TABLE = E_STEP    # (LU_ENTRIES × LU_ENTRY) the observer's coefficients: Δt, then the ten of
LU_ENTRY = 11       # LuenbergerVz.coefficients(Δt); an unused entry's Δt is NaN
LU_ENTRIES = 32     # (its own cache's size: a lockstep flight sees ~15 Δt, its pose stamps')
E_SIZE = E_TABLE + LU_ENTRIES * LU_ENTRY
#: the ż estimators (``estimator.kind``): kalman, luenberger, difference, none (ż ≡ 0)
VZ_KALMAN, VZ_LUENBERGER, VZ_DIFFERENCE, VZ_NONE = 0.0, 1.0, 2.0, 3.0
#: What :func:`estimate_step` returns.
ESTIMATED, REFUSED, NO_COEFFICIENTS = 0, 1, 2


@njit(cache=True, **OUTER_KERNEL)
def estimate_step(s: np.ndarray, px: float, py: float, pz: float, psi_rad: float, t_s: float,
                  zacc_mps2: float, navdata: bool, nav_vx_mps: float, nav_vy_mps: float) -> int:
    """``Estimation.update`` with its ż estimator (``s[E_VZ_KIND]``: a ``ScalarKalmanVz``, a
    ``LuenbergerVz``, a ``FiniteDifferenceVz`` or a ``NoVz``) and the backward difference of
    x, y (their ``reset``/``update``, the same expressions in the same order) into the
    estimate ``s[E_X:E_X + 7]`` over the state ``s`` (the ``E_*`` slots); ``navdata``: ẋ, ẏ
    are ``nav_v*_mps`` (navdata, rotated by the caller), else the difference's. Returns, with
    nothing changed, :data:`REFUSED` for an input the Python estimators refuse (non-finite, a
    time not after the last: the caller raises their error) and :data:`NO_COEFFICIENTS` when
    the observer's table lacks this Δt (the caller adds it)."""
    kind = s[E_VZ_KIND]
    if s[E_HAS_POSE] == 0.0 or t_s != s[E_LAST_T]:
        if s[E_HAS_POSE] == 0.0:  # reset(z), then the difference's first position (dt = 1)
            if not (math.isfinite(pz) and math.isfinite(px) and math.isfinite(py)):
                return REFUSED
            s[E_Z] = pz
            s[E_VZ] = 0.0
            s[E_P] = s[E_P0]
            s[E_K] = math.nan
            s[E_INIT] = 0.0
            s[E_Z_PREV] = pz
            s[E_VEL_X] = 0.0
            s[E_VEL_Y] = 0.0
        else:
            dt = t_s - s[E_LAST_T]
            if not (math.isfinite(pz) and math.isfinite(zacc_mps2) and math.isfinite(dt)
                    and dt > 0.0 and math.isfinite(px) and math.isfinite(py)):
                return REFUSED
            if s[E_INIT] == 0.0:  # the filter's first update only anchors z
                s[E_Z] = pz
                s[E_Z_PREV] = pz
                s[E_INIT] = 1.0
            elif kind == VZ_LUENBERGER:
                c = _coefficients_at(s, dt)
                if c < 0:
                    return NO_COEFFICIENTS
                u = zacc_mps2
                zp, zh, vz = s[E_Z_PREV], s[E_Z], s[E_VZ]
                s[E_Z] = s[c] * zh + s[c + 1] * vz + s[c + 4] * zp + s[c + 6] * pz + s[c + 8] * u
                s[E_VZ] = (s[c + 2] * zh + s[c + 3] * vz + s[c + 5] * zp + s[c + 7] * pz
                           + s[c + 9] * u)
                s[E_Z_PREV] = pz
            elif kind == VZ_KALMAN:
                u = zacc_mps2
                y = (pz - s[E_Z]) / dt
                vz_prior = s[E_VZ] + dt * u
                p_prior = s[E_P] + s[E_Q]
                y_pred = vz_prior - 0.5 * dt * u if s[E_MIDPOINT] != 0.0 else vz_prior
                k = p_prior / (p_prior + s[E_R])
                s[E_VZ] = vz_prior + k * (y - y_pred)
                s[E_P] = (1.0 - k) * p_prior
                s[E_K] = k
                s[E_Z] = pz
            elif kind == VZ_DIFFERENCE:
                s[E_VZ] = (pz - s[E_Z]) / dt
                s[E_Z] = pz
            # (VZ_NONE: ż stays the 0.0 of the reset)
            if s[E_HAS_PREV] != 0.0:
                s[E_VEL_X] = (px - s[E_PREV_X]) / dt
                s[E_VEL_Y] = (py - s[E_PREV_Y]) / dt
        s[E_HAS_PREV] = 1.0
        s[E_PREV_X] = px
        s[E_PREV_Y] = py
        s[E_HAS_POSE] = 1.0
        s[E_LAST_T] = t_s
    s[E_X] = px
    s[E_X + 1] = nav_vx_mps if navdata else s[E_VEL_X]
    s[E_X + 2] = py
    s[E_X + 3] = nav_vy_mps if navdata else s[E_VEL_Y]
    s[E_X + 4] = pz
    s[E_X + 5] = s[E_VZ]
    s[E_X + 6] = psi_rad
    return ESTIMATED


@njit(cache=True, inline="always", **INNER_KERNEL)
def _coefficients_at(s: np.ndarray, dt: float) -> int:
    """Where the observer's ten coefficients for ``dt`` start in ``s``; −1: not in its table."""
    for i in range(LU_ENTRIES):
        at = E_TABLE + i * LU_ENTRY
        if s[at] == dt:
            return at + 1
    return -1


def sample_waypoint_work() -> tuple[int, np.ndarray, np.ndarray]:
    """A sample waypoint flight's :func:`nmpc_work`: ``(n, work, rows)`` for a two-waypoint
    trajectory and one stage (``n`` = 3 times) — what a warm-up calls the kernels taking
    ``work`` and ``rows`` with, once, to load (or compile) them."""
    n = 3
    work, rows = nmpc_work(0.065, n, (np.array([0.0, 1.0]), np.zeros((2, 3)), np.zeros(2),
                                      np.ones(1), np.zeros((1, 3)), np.zeros(STATE_DIM)))
    return n, work, rows


def warm_up_kernels(*, estimate: bool = True, nmpc: bool = True) -> None:
    """Load (or compile) :func:`estimate_step` and :func:`nmpc_inputs` now — once per
    process — not on the first tick aloft (``Tick``: each only if its flight uses it, a
    compile costs a cold start ~0.2 s and ~1 s of CPU; ``runtime/precompile.py`` compiles the
    estimate's in the background). Their callees are loaded from the cache first
    (``core/kernel_cache.first_warm_up``: the rollout's own machine code, cached or compiled
    alike)."""
    if estimate and first_warm_up(estimate_step):
        estimate_step(np.zeros(E_SIZE), 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, False, 0.0, 0.0)
    if nmpc and first_warm_up(nmpc_inputs):
        n, work, rows = sample_waypoint_work()
        x = np.zeros(STATE_DIM)
        nmpc_inputs(x, np.zeros((2, 4)), 0, 1, np.zeros(STATE_DIM), 0.0, 0.0, np.zeros(4),
                    np.zeros((n, STATE_DIM)), work, rows)


flush_stale_caches(__name__)  # kernels calling other files: core/kernel_cache.py
