"""Compiled steps of the attitude-response fit (:mod:`~ardrone_nmpc.estimation.attitude_response`).

Each navdata sample adds its model value at every grid point (delays × lags × axes) to the
running sums: two dozen numpy operations on arrays of a few hundred elements, the largest
cost of a tick with something ``auto`` (issue 26). These loops compute the same expressions
in the same order — sums, products and quotients round alike in numpy and in a compiled loop
on the pinned target, which fuses nothing — so the fit is the same bits. The exponentials
are the C library's ``exp`` (``math.exp`` in Python, the same function): numpy's vectorised
``exp`` is chosen by the CPU at run time and differs in the last bit on AVX-512 machines
from the one on AVX2 machines (4.6 % of arguments), which made the fit, and the flights it
steers, depend on the CPU (docs/solver-notes.md §9).

Those exponentials, 372 a sample, were most of the step's cost. Their arguments repeat: a
decay's is ``−d/τ`` with d a sample's time, less a delay, less a command's time — times
rounded to the microsecond, commands and samples on fixed periods — and a 60 s square sees
some 400 distinct values of d (exact doubles) among 59 000. :func:`fold_sample` keeps the
decays of the recent ones in a small cache in the state (:func:`memo_decays`): a value found
there was made by the same ``math.exp`` of the same argument, so it is the same bits; one not
found is computed and stored. The cache only saves time; what it holds never changes a bit.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ardrone_nmpc.core.kernel_cache import flush_stale_caches
from ardrone_nmpc.core.numerics import INNER_KERNEL, OUTER_KERNEL
from ardrone_nmpc.core.python_floats import py_max, py_min, py_square
from ardrone_nmpc.core.sorted_search import count_at_or_below
from ardrone_nmpc.estimation.response_lanes import fit_pairs, fold_lags

__all__ = ["CMD_NONE", "CMD_RESTART", "CMD_SEND", "ESTIMATE_ANSWER", "ESTIMATE_PARAMS", "HEAD",
           "MEMO_SETS", "S_B", "S_BITS", "S_CAPACITY", "S_COUNT", "S_DELAYS", "S_EULER_MAX", "S_G",
           "S_HAS_BEST", "S_HAS_R", "S_K", "S_L", "S_LAGS", "S_LAST_T", "S_N", "S_R", "S_REFRESH",
           "S_RES", "S_SINCE_BEST", "S_SY", "S_SYY", "S_UNORDERED", "S_WINDOW", "S_X", "S_Y",
           "TIMES_ROUNDED", "estimate_size", "feed", "fit_estimate", "fit_grid", "fit_size",
           "fold_sample", "held_count", "memo_decays", "memo_view", "microseconds", "new_state",
           "state_size"]

# The streaming fit's whole state is one float64 buffer (one argument to unbox per call, not a
# dozen: numba's dispatch costs ~50–100 ns an argument, issue 26): a head of scalars (these
# slots, the fit's fixed parameters among them), then Σx, Σx², Σx·y (each K×L×2), the
# commands' times (C), values (C×2) and lag outputs (C×L×2), the decays' cache (MEMO_SETS × 2
# slots of a d and its L decays) and last the grid: the delays (K) and the lags (L). Built once
# by :func:`new_state`.
S_N = 0              # the samples' effective number
S_LAST_T = 1         # the last sample's time (NaN before the first)
S_COUNT = 2          # commands held
S_SINCE_BEST = 3     # samples since the best grid point was refreshed
S_HAS_R = 4          # 1.0: the residual of the last sample is in S_R
S_R = 5              # (2) that residual
S_HAS_BEST = 7       # 1.0: a best grid point is tracked
S_K = 8              # its delay index
S_L = 9              # its lag index
S_G = 10             # (2) its gains
S_B = 12             # (2) its offsets
S_RES = 14           # (3) Σr², Σr·r_prev, r_prev's weight
S_SY = 17            # (2) Σy
S_SYY = 19           # (2) Σy²
S_Y = 21             # (2) the last sample (rad)
S_CAPACITY = 23      # the parameters, fixed: commands held at most (C)
S_EULER_MAX = 24     # the drone's tilt at a command of 1 (rad)
S_WINDOW = 25        # the forgetting's time constant (s; inf: none)
S_REFRESH = 26       # samples between refreshes of the best grid point
S_DELAYS = 27        # the delays' number (K)
S_LAGS = 28          # the lags' number (L)
S_BITS = 29          # scratch: a double whose bits the cache hashes (memo_decays)
S_X = 30             # (2) scratch: the tracked best model's value of the sample (fold_sample)
S_UNORDERED = 32     # 1.0 once a NaN command time was held: the times may be out of order
HEAD = 33
#: What :func:`feed` does with the command after the sample.
CMD_NONE = 0
CMD_RESTART = 1
CMD_SEND = 2
#: Added to ``cmd_kind``: the times passed are rounded to the microsecond already (:func:`feed`).
TIMES_ROUNDED = 4
#: The decays' cache: sets of two slots, a slot's set picked by a hash of d's bits. A 60 s
#: square's ~400 values of d miss it ~440 times (each miss 6 exponentials) of 59 000.
MEMO_SETS = 512
_HASH = np.int64(-7046029254386353131)  # 0x9E3779B97F4A7C15 (Fibonacci hashing), as int64
_DEG2RAD = math.pi / 180.0  # numpy's radians (and math.radians): x · (π/180)


def state_size(delays: int, lags: int, capacity: int) -> int:
    """Length of the state buffer of a grid of ``delays`` × ``lags`` and ``capacity`` commands."""
    return (HEAD + 3 * delays * lags * 2 + capacity * (1 + 2 + lags * 2)
            + 2 * MEMO_SETS * (1 + lags) + delays + lags)


def new_state(delays_s: np.ndarray, lags_s: np.ndarray, capacity: int, euler_max_rad: float,
              window_s: float, refresh_samples: int) -> np.ndarray:
    """The state buffer of a new fit (no sample, no command) with its parameters and grid."""
    K, L = delays_s.size, lags_s.size
    state = np.zeros(state_size(K, L, capacity))
    state[S_LAST_T] = math.nan
    state[S_CAPACITY], state[S_EULER_MAX] = capacity, euler_max_rad
    state[S_WINDOW], state[S_REFRESH] = window_s, refresh_samples
    state[S_DELAYS], state[S_LAGS] = K, L
    state[state.size - K - L:state.size - L] = delays_s
    state[state.size - L:] = lags_s
    memo_view(state)[:, 0] = math.nan  # no key: NaN equals nothing
    return state


def memo_view(state: np.ndarray) -> np.ndarray:
    """The decays' cache of a state buffer: (2 · MEMO_SETS, 1 + L) rows of a d and its decays."""
    K, L = int(state[S_DELAYS]), int(state[S_LAGS])
    end = state.size - K - L
    return state[end - 2 * MEMO_SETS * (1 + L):end].reshape((2 * MEMO_SETS, 1 + L))


def fit_size(delays: int, lags: int) -> int:
    """Length of :func:`fit_grid`'s output buffer: the centred Σx², the gains, the residual
    per axis (each K×L×2), the residual (K×L) and the centred Σy² (2)."""
    return 3 * delays * lags * 2 + delays * lags + 2


#: :func:`fit_estimate`'s parameters (five floats after :func:`fit_grid`'s output, set once by
#: its caller: ``attitude_response``'s grid step and rival separation, each expression made in
#: Python, and the exponent 2.0) and its answer (thirteen floats after them, in this order):
#: the delay and its σ, the gains and their σ (2 each), the lag, R², the samples, the delay's
#: contrast, the mean gain and its σ, and 1.0 if those two were made (0.0: a weight overflowed,
#: where Python's ``**`` raises: left to Python).
ESTIMATE_PARAMS = 5
ESTIMATE_ANSWER = 13


def estimate_size(delays: int, lags: int) -> int:
    """Length of :func:`fit_estimate`'s buffer: :func:`fit_size`'s, its parameters, its answer."""
    return fit_size(delays, lags) + ESTIMATE_PARAMS + ESTIMATE_ANSWER


@njit(cache=True, **INNER_KERNEL)
def memo_decays(d: float, lags_s: np.ndarray, memo: np.ndarray, bits: np.ndarray,
                ints: np.ndarray) -> int:
    """Where in the cache ``memo`` (:func:`memo_view`, flat: rows of 1 + L) ``exp(−d / τ)``
    of every lag τ starts (the C library's ``exp``; lag m at the answer + m): found there
    when it holds ``d``, otherwise computed and stored in the first slot of d's set (its
    former occupant moved to the second, which is dropped).

    A slot matches when its key equals d: the same double (or ±0, whose decays are all 1), so
    the decays it holds are this d's, to the bit. NaN matches nothing. ``bits`` is a (1,)
    float64 scratch (``S_BITS``) and ``ints`` its int64 view (made once by the caller: a
    view costs an allocation): d's bits, hashed to the set."""
    w = lags_s.size + 1
    bits[0] = d
    i = 2 * w * (((ints[0] * _HASH) >> 55) & (MEMO_SETS - 1))  # the top 9 bits of the product
    if memo[i] == d:
        return i + 1
    if memo[i + w] == d:
        return i + w + 1
    for c in range(w):  # the first slot to the second
        memo[i + w + c] = memo[i + c]
    memo[i] = d
    for m in range(lags_s.size):
        memo[i + 1 + m] = math.exp(-d / lags_s[m])
    return i + 1


@njit(cache=True, **INNER_KERNEL)
def held_count(times: np.ndarray, n: int, c: int, at: float, ordered: bool) -> int:
    """How many of the ``n`` command times are at or before ``at``: ``count_at_or_below``,
    for an ``at`` no later than the one whose count ``c`` is (or any, with c = n).

    The delays ascend, so a sample's ``at`` descend and each count is the last one, or a
    step below it (commands 65 ms apart, delays 10 ms): a walk down from ``c`` — a
    comparison or two, not a binary search's six unpredictable branches. The same count
    whenever the times ascend (NaN, which sorts last there, counted as after ``at``); a
    NaN command time (``ordered`` false: later ones follow it unsorted) or a NaN ``at``
    take the binary search, whose answer on such an array is its own."""
    if not ordered or at != at:
        return count_at_or_below(times, n, at)
    while c > 0 and not times[c - 1] <= at:
        c -= 1
    return c


@njit(cache=True, **INNER_KERNEL)
def microseconds(t_s: float) -> float:
    """``round(t_s, 6)``, to the bit, for 1 µs ≤ t_s < 2⁴⁰ µs; −1 elsewhere (NaN included),
    where Python's ``round`` must do it (``attitude_response._microseconds``).

    ``round`` rounds the exact t·10⁶ to an integer n, ties to even, and returns the double
    nearest n·10⁻⁶. Here: y = t·10⁶ rounded and its error e (exact: Dekker's product, 10⁶
    splitting into itself), so t·10⁶ = y + e exactly; with n₀ = ⌊y⌋, f = y − n₀ ∈ [0, 1)
    and f − ½ are exact (multiples of y's ulp ≤ 2⁻¹²), and the sign of (f − ½) + e is that of
    the exact sum (a rounded sum is 0 only when the exact one is): above ½ n₀ + 1, below n₀,
    at ½ the even one. n < 2⁵³ and 10⁶ are exact doubles, so n / 10⁶ (correctly rounded) is
    the double nearest n·10⁻⁶. (The tick's times are rarely within ¼ µs of a whole one — a
    navdata period of ⅓ ms is not —, so a shortcut for those alone would not do.)"""
    y = t_s * 1e6
    if not 1.0 <= y < 1099511627776.0:  # 2⁴⁰
        return -1.0
    c = 134217729.0 * t_s  # Veltkamp's split of t into 26 + 27 bits (2²⁷ + 1)
    hi = c - (c - t_s)
    lo = t_s - hi
    e = (hi * 1e6 - y) + lo * 1e6  # each product exact: 10⁶ has 20 bits
    n = math.floor(y)
    s = ((y - n) - 0.5) + e
    if s > 0.0 or (s == 0.0 and n % 2 == 1):
        n += 1
    return n / 1e6


@njit(cache=True, **INNER_KERNEL)
def fold_sample(times: np.ndarray, n: int, ordered: bool, t_s: float, delays_s: np.ndarray,
                lags_s: np.ndarray, memo: np.ndarray, bits: np.ndarray, ints: np.ndarray,
                u: np.ndarray, ylag: np.ndarray, y: np.ndarray, forget: float,
                sums: np.ndarray, best: int, x_best: np.ndarray) -> None:
    """The model value x (K × L × 2) of a sample at ``t_s`` at every grid point — per delay
    d the last of the ``n`` commands at or before ``t_s − d`` (j, :func:`held_count`) and
    the lag's output ``u + (y_lag − u)·decay`` from it, each lag τ's decay
    ``exp(−(t_s − d − times[j]) / τ)`` (the C library's ``exp``, through the cache ``memo``:
    :func:`memo_decays`) — folded into the sums, first faded by ``forget`` (unless it is 1):
    Σx, Σx², Σx·y, one after the other in ``sums`` (each K × L × 2). x itself is kept only
    at the flat index ``best`` (the tracked model's, of (k, l, 0); −1: none), in ``x_best``.
    Every array flat, in C order: ``u`` (C × 2), ``ylag`` (C × L × 2). (Flat: a compiled
    reshape costs a call of numba's C helper, ~50 ns each, a dozen a tick.)

    Each element's expressions as numpy's broadcast wrote them; what is read more than once
    (the command, the decay, y) is read once into a local — the same doubles — and the
    fading's test is made once, not per element. Per delay, not a pass for the decays and
    another for the sums: the decays are read where the cache holds them."""
    y0, y1 = y[0], y[1]
    K, L = delays_s.size, lags_s.size
    kl2 = K * L * 2
    scale = forget != 1.0
    c = n
    for k in range(K):
        at = t_s - delays_s[k]
        c = held_count(times, n, c, at, ordered)
        jk = c - 1
        r = memo_decays(at - times[jk], lags_s, memo, bits, ints)
        u0, u1 = u[2 * jk], u[2 * jk + 1]
        gk, ek = 2 * jk * L, 2 * k * L  # (jk, 0, 0) in ylag, (k, 0, 0) in each sum
        # the lags without a test per lag (the tracked model's value made after them, the
        # same expression), the two axes of each at once (response_lanes: the same bits);
        # its indices non-negative (a row −1 read as numba reads it: the last)
        fold_lags(sums, ylag, memo, ek, gk + ylag.size if gk < 0 else gk, r, L, kl2, u0, u1,
                  y0, y1, forget, scale)
        if ek <= best < ek + 2 * L:  # the tracked model is at this delay
            m = (best - ek) // 2
            dk = memo[r + m]
            g = gk + 2 * m
            x_best[0] = u0 + (ylag[g] - u0) * dk
            x_best[1] = u1 + (ylag[g + 1] - u1) * dk


@njit(cache=True, **OUTER_KERNEL)
def feed(state: np.ndarray, has_sample: bool, sample_t_s: float, roll_deg: float,
         pitch_deg: float, cmd_kind: int, cmd_t_s: float, roll_frac: float,
         pitch_frac: float) -> int:
    """One tick of the streaming fit (its state and parameters ``state``, :func:`new_state`):
    ``AttitudeResponseEstimator``'s ``navdata``, then its ``command`` or ``restart`` — the same
    expressions in the same order. The times are rounded to the microsecond here
    (:func:`microseconds`, ``round(t, 6)``) unless ``cmd_kind`` has :data:`TIMES_ROUNDED`
    added; where that does not answer (a time below 1 µs) it returns −1 at once, nothing
    changed, and the caller rounds them in Python and calls again. Otherwise returns 0 if
    there was no sample or it could not be used, 1 if it was folded in, 2 if, moreover, the
    best grid point was refreshed (every ``S_REFRESH`` samples: the fit of the grid, as
    ``_fit`` makes it).

    One function, not one per step: every compiled level below an entry point costs its
    cold start a copy of the levels beneath (docs/solver-notes.md §5)."""
    if cmd_kind >= TIMES_ROUNDED:
        cmd_kind -= TIMES_ROUNDED
    else:  # each time to the microsecond only where it is read
        if has_sample:
            sample_t_s = microseconds(sample_t_s)
            if sample_t_s < 0.0:
                return -1
        if cmd_kind == CMD_SEND:
            cmd_t_s = microseconds(cmd_t_s)
            if cmd_t_s < 0.0:
                return -1
    K, L = int(state[S_DELAYS]), int(state[S_LAGS])
    capacity = int(state[S_CAPACITY])
    euler_max_rad = state[S_EULER_MAX]
    window_s = state[S_WINDOW]
    refresh_samples = state[S_REFRESH]
    end = state.size
    delays_s = state[end - K - L:end - L]
    lags_s = state[end - L:end]
    kl2 = K * L * 2
    o = HEAD
    # flat views, C order (no reshape: each costs a C call); the shapes in the comments
    sums = state[o:o + 3 * kl2]  # Σx, Σx², Σx·y: (3, K, L, 2)
    o += 3 * kl2
    t = state[o:o + capacity]
    o += capacity
    u = state[o:o + 2 * capacity]  # (C, 2)
    o += 2 * capacity
    ylag = state[o:o + capacity * L * 2]  # (C, L, 2)
    o += capacity * L * 2
    memo = state[o:o + 2 * MEMO_SETS * (1 + L)]  # (2 · MEMO_SETS, 1 + L)
    bits = state[S_BITS:S_BITS + 1]
    ints = bits.view(np.int64)
    code = 0
    n = int(state[S_COUNT])
    # --- the navdata sample (``navdata``)
    y0 = roll_deg * _DEG2RAD
    y1 = pitch_deg * _DEG2RAD
    last_t = state[S_LAST_T]
    if has_sample and not (n < 2 or not (math.isfinite(y0) and math.isfinite(y1))
                           or sample_t_s <= last_t or t[0] > sample_t_s - delays_s[K - 1]):
        t_s = sample_t_s
        forget = math.exp(-(t_s - last_t) / window_s) if math.isfinite(last_t) else 1.0
        state[S_LAST_T] = t_s
        y = state[S_Y:S_Y + 2]
        y[0] = y0
        y[1] = y1
        has_best = state[S_HAS_BEST] != 0.0
        best = 2 * (int(state[S_K]) * L + int(state[S_L])) if has_best else -1
        x = state[S_X:S_X + 2]
        fold_sample(t, n, state[S_UNORDERED] == 0.0, t_s, delays_s, lags_s, memo, bits, ints,
                    u, ylag, y, forget, sums, best, x)
        if has_best:  # the residual of the tracked best model (its lag-1 ρ)
            r0 = y0 - (state[S_G] * x[0] + state[S_B])
            r1 = y1 - (state[S_G + 1] * x[1] + state[S_B + 1])
            for i in range(3):
                state[S_RES + i] *= forget
            if state[S_HAS_R] != 0.0:
                p0, p1 = state[S_R], state[S_R + 1]
                state[S_RES] += r0 * r0 + r1 * r1
                state[S_RES + 1] += r0 * p0 + r1 * p1
                state[S_RES + 2] += 1.0
            state[S_R] = r0
            state[S_R + 1] = r1
            state[S_HAS_R] = 1.0
        state[S_N] = state[S_N] * forget + 1.0
        for a in range(2):
            ya = state[S_Y + a]
            state[S_SY + a] = state[S_SY + a] * forget + ya
            state[S_SYY + a] = state[S_SYY + a] * forget + ya * ya
        state[S_SINCE_BEST] += 1.0
        code = 1
        if state[S_SINCE_BEST] >= refresh_samples:  # the residual tracks a recent best model
            state[S_SINCE_BEST] = 0.0
            code = 2
            if not state[S_N] < 20:  # the best grid point and its model, as ``_fit``'s
                fit_grid(state, np.empty(3 * kl2 + K * L + 2))  # fit_size
    # --- then the command (``command``, held until the next) or the restart
    if cmd_kind == CMD_RESTART:
        state[S_COUNT] = 0.0
        state[S_HAS_R] = 0.0
    elif cmd_kind == CMD_SEND:
        t_s = cmd_t_s
        u0 = roll_frac * euler_max_rad
        u1 = pitch_frac * euler_max_rad
        if n and t_s <= t[n - 1]:
            return code
        if n:
            if n == capacity:  # full: keep the newest half (what the longest delay needs)
                keep = n // 2
                for i in range(keep):
                    t[i] = t[n - keep + i]
                    for a in range(2):
                        u[2 * i + a] = u[2 * (n - keep + i) + a]
                    for c in range(2 * L):
                        ylag[2 * L * i + c] = ylag[2 * L * (n - keep + i) + c]
                n = keep
            t0 = t[n - 1]
            r = memo_decays(t_s - t0, lags_s, memo, bits, ints)  # exp(−(t_s − t0) / τ)
            for m in range(L):  # the lags' outputs, from the last command's
                dec = memo[r + m]
                for a in range(2):
                    ua = u[2 * (n - 1) + a]
                    ylag[2 * (n * L + m) + a] = ua + (ylag[2 * ((n - 1) * L + m) + a] - ua) * dec
        else:  # no past: as if held for long
            for m in range(L):
                ylag[2 * (n * L + m)] = u0
                ylag[2 * (n * L + m) + 1] = u1
        if t_s != t_s:  # later times follow it unsorted (held_count)
            state[S_UNORDERED] = 1.0
        t[n] = t_s
        u[2 * n] = u0
        u[2 * n + 1] = u1
        state[S_COUNT] = n + 1.0
    return code


@njit(cache=True, **OUTER_KERNEL)
def fit_grid(state: np.ndarray, out: np.ndarray) -> int:
    """Every grid point's least-squares fit from the sums (``AttitudeResponseEstimator._fit``'s
    numpy, the same expressions in the same order): into ``out`` (:func:`fit_size`) the
    centred Σx², the gains, the residual per axis and summed over the axes, the centred Σy².
    Returns the flat index of the least residual (``argmin``: the first, or the first NaN),
    or −1 when no grid point's commands moved or the attitude did not vary; otherwise that
    grid point's model (its gains and offsets) is the one whose residual :func:`feed` tracks
    from now on (slots ``S_HAS_BEST`` … ``S_B + 1``)."""
    K, L = int(state[S_DELAYS]), int(state[S_LAGS])
    kl2 = K * L * 2
    n = state[S_N]
    o = HEAD
    sx = state[o:o + kl2]
    sxx = state[o + kl2:o + 2 * kl2]
    sxy = state[o + 2 * kl2:o + 3 * kl2]
    sxx_c = out[0:kl2]
    gain = out[kl2:2 * kl2]
    rss_axis = out[2 * kl2:3 * kl2]
    rss = out[3 * kl2:3 * kl2 + K * L]
    syy = out[3 * kl2 + K * L:3 * kl2 + K * L + 2]
    for a in range(2):
        sy = state[S_SY + a]
        syy[a] = state[S_SYY + a] - sy * sy / n
    # every grid point's two axes at once (response_lanes: each lane this loop's scalar
    # expressions, the same bits):
    # c = Σx² − Σx·Σx / n; c > 1e-12: gain = (Σx·y − Σx·Σy / n) / c, residual Σy²_c − gain·cy
    any_ok = fit_pairs(state, out, HEAD, K * L, kl2, n, state[S_SY], state[S_SY + 1], syy[0],
                       syy[1])
    if not any_ok or (0.0 + syy[0]) + syy[1] <= 0.0:
        return -1
    best = 0
    low = rss[0]
    if low == low:
        for i in range(1, K * L):
            v = rss[i]
            if v != v:
                best = i
                break
            if v < low:
                low = v
                best = i
    k, m = best // L, best % L
    for a in range(2):
        e = 2 * best + a
        g = gain[e]
        state[S_G + a] = g
        state[S_B + a] = (state[S_SY + a] - g * sx[e]) / n
    state[S_HAS_BEST] = 1.0
    state[S_K] = k
    state[S_L] = m
    return best


@njit(cache=True, **INNER_KERNEL)
def _inflation(state: np.ndarray) -> float:
    """√((1 + ρ₁)/(1 − ρ₁)) of the tracked residual's lag-1 correlation ρ₁ (1 with fewer than
    ten pairs or no residual)."""
    rr, rr1, w = state[S_RES], state[S_RES + 1], state[S_RES + 2]
    if w < 10.0 or rr <= 0.0:
        return 1.0
    rho = py_min(py_max(rr1 / rr, 0.0), 0.95)
    return math.sqrt((1.0 + rho) / (1.0 - rho))


@njit(cache=True, **INNER_KERNEL)
def _refine(rss: np.ndarray, L: int, m: int, k: int, delays_s: np.ndarray, sigma2: float,
            params: np.ndarray) -> tuple:
    """The delay from a parabola through the residual at lag ``m`` (``rss`` flat, K × L) at
    delay ``k`` and its neighbours (the first or last three on an edge of the grid: the vertex
    kept inside it), and its variance 2σ²/curvature, no less than the grid's step² / 12. A
    neighbour before the first is the last (Python's list index −1, on a grid of two)."""
    K = delays_s.size
    if K < 2:
        raise IndexError("list index out of range")  # (a grid of one has no neighbours)
    i = min(max(k, 1), K - 2)
    lo = rss[((i - 1) % K) * L + m]
    mid, hi = rss[i * L + m], rss[(i + 1) * L + m]
    if not (math.isfinite(lo) and math.isfinite(mid) and math.isfinite(hi)):
        return delays_s[k], math.inf
    second = lo - 2.0 * mid + hi
    if not second > 0.0:
        return delays_s[k], math.inf
    delay = delays_s[i] + params[0] * (lo - hi) / second  # ½ step
    delay = py_min(py_max(delay, delays_s[0]), delays_s[K - 1])
    return delay, py_max(2.0 * sigma2 * params[1] / second, params[2])  # step², step² / 12


@njit(cache=True, **INNER_KERNEL)
def _gain_means(answer: np.ndarray, two: float) -> bool:
    """``AttitudeEstimate.gain_mean`` and ``gain_mean_std`` of the gains and σ in ``answer``
    (slots 2–5) into its slots 10 and 11, the same expressions in the same order; False
    (nothing written) when a weight's square overflows, where Python raises."""
    p0 = py_square(py_max(answer[4], 1e-9), two) if math.isfinite(answer[4]) else -1.0
    p1 = py_square(py_max(answer[5], 1e-9), two) if math.isfinite(answer[5]) else -1.0
    if math.isinf(p0) or math.isinf(p1):
        return False
    num = den = 0.0  # as gain_mean adds: from 0, the axes in order
    w_all = 0.0      # gain_mean_std's: every finite σ
    seen = False
    for a in range(2):
        p = p0 if a == 0 else p1
        if p < 0.0:  # σ not finite
            continue
        w = 1.0 / p
        w_all += w
        g = answer[2 + a]
        if math.isfinite(g):
            num += g * w
            den += w
            seen = True
    answer[10] = num / den if seen else math.nan
    answer[11] = 1.0 / math.sqrt(w_all) if w_all > 0 else math.inf
    return True


@njit(cache=True, **OUTER_KERNEL)
def fit_estimate(state: np.ndarray, out: np.ndarray) -> int:
    """``AttitudeResponseEstimator._fit`` in one call: :func:`fit_grid` into ``out``, then the
    best grid point's estimate into ``out``'s answer (:data:`ESTIMATE_ANSWER`, after its
    :data:`ESTIMATE_PARAMS`) — the same expressions in the same order, Python's ``max``,
    ``min`` and ``**`` (:func:`py_max`, :func:`py_square`), numpy's ``min`` of the rivals
    (NaN if any is). Returns :func:`fit_grid`'s best flat index, or −1: no estimate (fewer
    than 20 samples, nothing moved; the state untouched with fewer than 20)."""
    n = state[S_N]
    if n < 20:
        return -1
    best = fit_grid(state, out)
    if best < 0:
        return -1
    K, L = int(state[S_DELAYS]), int(state[S_LAGS])
    kl, kl2 = K * L, K * L * 2
    end = state.size
    delays_s = state[end - K - L:end - L]
    k, m = best // L, best % L
    sxx, gain, rss_axis = out[0:kl2], out[kl2:2 * kl2], out[2 * kl2:3 * kl2]
    rss = out[3 * kl2:3 * kl2 + kl]
    f = 3 * kl2 + kl + 2  # fit_size
    params = out[f:f + ESTIMATE_PARAMS]
    answer = out[f + ESTIMATE_PARAMS:f + ESTIMATE_PARAMS + ESTIMATE_ANSWER]
    low = rss[best]
    sigma2 = low / py_max(2.0 * n - 5.0, 1.0)
    inflate = _inflation(state)
    delay, delay_var = _refine(rss, L, m, k, delays_s, sigma2, params)
    answer[0] = delay
    answer[1] = inflate * math.sqrt(delay_var)
    for a in range(2):
        e = 2 * best + a
        sa = sxx[e]
        if sa > 1e-12:
            answer[2 + a] = gain[e]
            answer[4 + a] = inflate * math.sqrt(py_max(rss_axis[e], 0.0)
                                                / py_max(n - 2.0, 1.0) / sa)
        else:
            answer[2 + a] = math.nan
            answer[4 + a] = math.inf
    answer[6] = state[end - L + m]
    answer[7] = 1.0 - low / (out[3 * kl2 + kl] + out[3 * kl2 + kl + 1])  # Σy² of both axes
    answer[8] = n
    answer[9] = _contrast(rss, L, m, k, delays_s, sigma2 * py_square(inflate, params[4]),
                          params[3])
    answer[12] = 1.0 if _gain_means(answer, params[4]) else 0.0
    return best


@njit(cache=True, **INNER_KERNEL)
def _contrast(rss: np.ndarray, L: int, m: int, k: int, delays_s: np.ndarray, sigma2: float,
              rival_s: float) -> float:
    """(least residual at lag ``m`` — ``rss`` flat, K × L — at ``rival_s`` or more from delay
    ``k``: numpy's ``min``, NaN if any is) − the residual at ``k``, over ``sigma2``; ∞ when the
    grid holds no such delay or ``sigma2`` is not > 0."""
    rival, least, at = False, 0.0, delays_s[k]
    for j in range(delays_s.size):
        if abs(delays_s[j] - at) >= rival_s:
            v = rss[j * L + m]
            if not rival:
                least, rival = v, True
            elif least == least and not v >= least:  # less, or NaN (which numpy's min keeps)
                least = v
    if not rival or not sigma2 > 0.0:
        return math.inf
    return (least - rss[k * L + m]) / sigma2


flush_stale_caches(__name__)  # kernels calling other files: core/kernel_cache.py
