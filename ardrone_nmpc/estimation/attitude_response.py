"""The drone's command → attitude response, measured from its own commands and navdata.

A real AR.Drone's command delay (radio, firmware) and its tilt per unit PCMD are not known
before it flies, and they change with the hull, the battery and the radio. Every flight
measures both from what it sent (PCMD roll/pitch fractions, at their send times) and what the
drone reported (navdata roll/pitch, at their receipt times). The model, per axis (roll,
pitch; the drone's signs, in which navdata and PCMD have the same sign)::

    tilt(t) = k · E · [1/(τ s + 1)] c(t − d) + b

with E the configured ``euler_angle_max``, a pure delay d and a lag τ shared by both axes, a
gain k and a trim offset b per axis.

The fit runs as the samples arrive, at a fixed cost per navdata sample: on a grid of delays
(10 ms apart, 0–0.6 s) and lags, the lag's output is known exactly at any time from its value
at the last command before it (the commands are held between sends), so each sample adds its
model value at every grid point to running sums (Σx, Σx², Σxy per axis, with an exponential
forgetting over ``window_s``), from which the gains and the residual of every grid point
follow in closed form. The best grid point is the estimate; a parabola through the residual
along the delay refines d and its curvature gives d's uncertainty, the sums give the gains'.
Every σ is inflated by the residual's lag-1 correlation (a coloured residual holds less
information than as many independent samples). docs/identification.md §3 derives it.

:class:`AttitudeResponseEstimator` is the streaming fit (the tick's ``ResponseEstimation``
stage feeds it); :func:`fit_attitude_response` feeds it whole arrays (a log: the summary,
``identify``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ardrone_nmpc.core.entry_points import ArrayKind, VettedCall
from ardrone_nmpc.estimation import response_kernels as rk

__all__ = ["AttitudeEstimate", "AttitudeResponseEstimator", "CONFIDENT_DELAY_CONTRAST",
           "CONFIDENT_DELAY_R2", "CONFIDENT_DELAY_STD_S", "CONFIDENT_GAIN_REL_STD", "CONFIDENT_R2",
           "NO_ESTIMATE", "fit_attitude_response", "warm_up_kernels"]

DELAY_STEP_S = 0.01
MAX_DELAY_S = 0.6
LAG_GRID_S = (0.03, 0.06, 0.1, 0.15, 0.2, 0.3)
#: Samples between refreshes of the best grid point whose residual is tracked.
REFRESH_SAMPLES = 15
#: The delay is known once its σ is at most this (s) and the fit explains at least
#: CONFIDENT_DELAY_R2 of the attitude's variance; the gain once its σ is at most
#: CONFIDENT_GAIN_REL_STD of itself and the fit explains CONFIDENT_R2. The delay shows
#: first: its timing is in the shape of the response, the gain in its size against the noise.
CONFIDENT_DELAY_STD_S = 0.02
CONFIDENT_DELAY_R2 = 0.2
#: ... and no delay a control tick (65 ms) or more from it explains the attitude nearly as
#: well at the same lag: its residual is at least CONFIDENT_DELAY_CONTRAST σ² (inflated) above
#: the best's. The parabola's σ sees only the best dip of the residual; with little excitation
#: (a take-off's first seconds) the commands, held a whole tick, fit almost as well one or more
#: ticks off, and a confident 0.10 s was locked in for a 0.26 s drone (docs/identification.md
#: §3). A single dip with σ ≤ 20 ms rises by (65/20)² ≈ 10.6 σ² at a tick: it passes.
DELAY_RIVAL_SEPARATION_S = 0.065
CONFIDENT_DELAY_CONTRAST = 9.0
CONFIDENT_GAIN_REL_STD = 0.1
CONFIDENT_R2 = 0.3


_new_object = object.__new__


class _kept:
    """``functools.cached_property`` without Python 3.11's lock (~0.4 µs a first read): the
    value stored in the instance's ``__dict__``, which a non-data descriptor yields to."""

    def __init__(self, func) -> None:
        self.func, self.name, self.__doc__ = func, func.__name__, func.__doc__

    def __get__(self, obj, owner=None):
        if obj is None:
            return self
        value = obj.__dict__[self.name] = self.func(obj)
        return value


@dataclass(frozen=True)
class AttitudeEstimate:
    """One fit: the delay (s) and its σ, the gain per axis [roll, pitch] relative to E and
    their σ, the lag τ (s), the share of the attitude's variance it explains (R²) and the
    navdata samples behind it (their effective number, with the forgetting)."""

    delay_s: float
    delay_std_s: float
    gain: tuple[float, float]
    gain_std: tuple[float, float]
    lag_s: float
    r2: float
    samples: float
    #: How much worse the best delay DELAY_RIVAL_SEPARATION_S or more away fits (at the same
    #: lag): the rise of the residual over σ², inflated like every σ (a χ², one degree of
    #: freedom).
    delay_contrast: float = math.inf

    # made when first read, then kept (the instance's __dict__, beside the frozen fields):
    # the tick's event and its adaptation read each up to four times a fit
    @_kept
    def gain_mean(self) -> float:
        """The two axes' gains, weighted by their precision (an axis never moved weighs
        nothing); NaN without either."""
        num = den = 0.0  # as ``sum`` adds: from 0, the axes in order
        seen = False
        for g, s in zip(self.gain, self.gain_std):
            if math.isfinite(g) and math.isfinite(s):
                w = 1.0 / max(s, 1e-9) ** 2
                num += g * w
                den += w
                seen = True
        return num / den if seen else math.nan

    @_kept
    def gain_mean_std(self) -> float:
        w = 0.0
        for s in self.gain_std:
            if math.isfinite(s):
                w += 1.0 / max(s, 1e-9) ** 2
        return 1.0 / math.sqrt(w) if w > 0 else math.inf

    @classmethod
    def _fitted(cls, delay_s, delay_std_s, gain, gain_std, lag_s, r2, samples, delay_contrast,
                gain_mean, gain_mean_std, means_made) -> AttitudeEstimate:
        """The estimate ``response_kernels.fit_estimate`` made, with its mean gain and σ when
        it made them (``means_made``), as the first reads would keep them. Its fields set as
        the frozen ``__init__`` sets them (``object.__setattr__`` each: ~0.1 µs apiece), in
        one update of the instance's dict."""
        est = _new_object(cls)
        if means_made:
            est.__dict__.update(delay_s=delay_s, delay_std_s=delay_std_s, gain=gain,
                                gain_std=gain_std, lag_s=lag_s, r2=r2, samples=samples,
                                delay_contrast=delay_contrast, gain_mean=gain_mean,
                                gain_mean_std=gain_mean_std)
        else:  # read, they raise as they did (a weight's square overflows)
            est.__dict__.update(delay_s=delay_s, delay_std_s=delay_std_s, gain=gain,
                                gain_std=gain_std, lag_s=lag_s, r2=r2, samples=samples,
                                delay_contrast=delay_contrast)
        return est

    @property
    def delay_confident(self) -> bool:
        """Delay σ ≤ 20 ms, R² ≥ 0.2, and no rival delay a tick (65 ms) or more away within
        a contrast of 9 (3 σ)."""
        return (math.isfinite(self.delay_std_s) and self.delay_std_s <= CONFIDENT_DELAY_STD_S
                and self.r2 >= CONFIDENT_DELAY_R2
                and self.delay_contrast >= CONFIDENT_DELAY_CONTRAST)

    @property
    def gain_confident(self) -> bool:
        """Gain σ ≤ 10 % of it, R² ≥ 0.3."""
        return (self.r2 >= CONFIDENT_R2
                and self.gain_mean_std <= CONFIDENT_GAIN_REL_STD * abs(self.gain_mean))

    @property
    def confident(self) -> bool:
        """Both the delay and the gain are known."""
        return self.delay_confident and self.gain_confident


# bound once: the tick feeds one a period
_feed, _CMD_SEND, _TIMES_ROUNDED = rk.feed, rk.CMD_SEND, rk.TIMES_ROUNDED


def _feed_dispatched(state: np.ndarray, has: bool, sample_t_s, roll_deg, pitch_deg,
                     cmd_kind: int, cmd_t_s, roll_frac, pitch_frac) -> int:
    """``response_kernels.feed`` through numba's dispatcher, every number made a float first
    (its one compiled signature) — until the estimator binds the signature's compiled entry
    point (:data:`_FEED`)."""
    return _feed(state, has, float(sample_t_s), float(roll_deg), float(pitch_deg), cmd_kind,
                 float(cmd_t_s), float(roll_frac), float(pitch_frac))


#: ``response_kernels.feed``'s call on an estimator's own state (one :func:`~.response_kernels.
#: new_state` built: float64, 1-D, C-contiguous, aligned, writeable) and the numbers
#: :func:`_feed_dispatched` makes floats: its compiled entry point once the dispatcher has it
#: (core/entry_points.VettedCall.bind), which skips the dispatcher's look-up of nine
#: arguments' types (~0.1 µs) and makes each number a float itself (numba unboxes a float64
#: by ``PyNumber_Float``, what ``float`` does)
_FEED = VettedCall(_feed, ArrayKind(1), True, 0.0, 0.0, 0.0, 0, 0.0, 0.0, 0.0,
                   dispatch=_feed_dispatched)
#: ``response_kernels.fit_estimate``'s call on an estimator's state and fit buffer
_FIT = VettedCall(rk.fit_estimate, ArrayKind(1), ArrayKind(1))


NO_ESTIMATE = AttitudeEstimate(math.nan, math.inf, (math.nan, math.nan), (math.inf, math.inf),
                               math.nan, math.nan, 0.0, 0.0)


def _microseconds(t_s: float) -> float:
    """A time to the microsecond: the same sample, its time gone through a log's ms ages and
    back (``replay --rerun``), is the same time, and the fit the same bits. The compiled step
    rounds the tick's times itself (``response_kernels.microseconds``, ``round(t, 6)`` to the
    bit) and leaves to this only those it refuses — below 1 µs, beyond 2⁴⁰ µs, NaN."""
    return round(float(t_s), 6)


#: fit_estimate's parameters (response_kernels.ESTIMATE_PARAMS), each made here in Python: ½
#: the delays' step, step², step² / 12, the least separation of a rival, and the exponent of
#: the squares ``**`` makes (read at run time: the C library's ``pow``, not x · x)
_ESTIMATE_PARAMS = (0.5 * DELAY_STEP_S, DELAY_STEP_S ** 2, DELAY_STEP_S ** 2 / 12.0,
                    DELAY_RIVAL_SEPARATION_S - 1e-9, 2.0)


class AttitudeResponseEstimator:
    """The streaming fit (module docstring).

    Feed every command sent (:meth:`command`, in time order) and every navdata sample
    (:meth:`navdata`, each after the commands sent before it); :attr:`estimate` is the fit of
    what it has seen, weighted by ``exp(−age / window_s)`` (``inf``: all alike).
    """

    def __init__(self, euler_angle_max_rad: float, *, window_s: float = 30.0,
                 lags_s=LAG_GRID_S, max_delay_s: float = MAX_DELAY_S) -> None:
        self.euler_angle_max_rad = float(euler_angle_max_rad)
        self.window_s = float(window_s)
        self.lags_s = np.asarray(lags_s, dtype=float)
        self.delays_s = np.arange(0.0, max_delay_s + 0.5 * DELAY_STEP_S, DELAY_STEP_S)
        n_k, n_l = len(self.delays_s), len(self.lags_s)
        # the commands held: send times, values (rad), the lags' outputs at those times
        self._capacity = 2 * int(math.ceil(max_delay_s / 0.02)) + 8
        # the whole state in one buffer the compiled step works on (response_kernels), with
        # the fit's parameters and grid (what each call would otherwise pass); the sums' names
        # are views of it (_bind_views)
        self._state = rk.new_state(self.delays_s, self.lags_s, self._capacity,
                                   self.euler_angle_max_rad, self.window_s, REFRESH_SAMPLES)
        # fit_estimate's buffer: fit_grid's output, the parameters, the answer (_bind_views)
        self._fit_out = np.zeros(rk.estimate_size(n_k, n_l))
        f = rk.fit_size(n_k, n_l)
        self._fit_out[f:f + rk.ESTIMATE_PARAMS] = _ESTIMATE_PARAMS
        self._bind_views()  # (and the compiled step: _step)
        self._estimate: AttitudeEstimate | None = NO_ESTIMATE

    def _bind_views(self) -> None:
        """The sums and the fit's answer as views of the state and fit buffers."""
        st, out = self._state, self._fit_out
        n_k, n_l = len(self.delays_s), len(self.lags_s)
        shape, kl2 = (n_k, n_l, 2), n_k * n_l * 2
        o = rk.HEAD
        self._sx, self._sxx, self._sxy = (st[o + i * kl2:o + (i + 1) * kl2].reshape(shape)
                                          for i in range(3))
        self._sy, self._syy = st[rk.S_SY:rk.S_SY + 2], st[rk.S_SYY:rk.S_SYY + 2]
        self._res = st[rk.S_RES:rk.S_RES + 3]  # Σr², Σr·r_prev, and r_prev's weight
        self._answer = out[out.size - rk.ESTIMATE_ANSWER:]  # fit_estimate's (its estimate)
        # the compiled steps: their entry points once known for these buffers, else the
        # dispatchers until their first calls (core/entry_points.VettedCall.bind)
        _FEED.bind(self, "_step", st)
        _FIT.bind(self, "_fit_step", st, out)

    def __getstate__(self) -> dict:
        """Without the compiled steps (an entry point does not pickle): bound again."""
        state = self.__dict__.copy()
        del state["_step"], state["_fit_step"]
        return state

    def __setstate__(self, state: dict) -> None:
        """A deep copy or unpickling: each view was copied apart from its buffer (numpy
        copies a view's data alone); made views of the copied buffers again, so what the
        kernels write is what the fit reads."""
        self.__dict__.update(state)
        self._bind_views()

    @property
    def _n(self) -> float:
        """The samples' effective number (with the forgetting)."""
        return float(self._state[rk.S_N])

    # ---------------------------------------------------------------------- feeding
    def feed(self, sample_t_s: float | None, roll_deg: float, pitch_deg: float,
             cmd_kind: int, cmd_t_s: float = 0.0, roll_frac: float = 0.0,
             pitch_frac: float = 0.0) -> bool:
        """One tick in one compiled call: a navdata sample (None: none), then a command
        (``cmd_kind`` :data:`~.response_kernels.CMD_SEND`), a :meth:`restart`
        (``CMD_RESTART``) or nothing (``CMD_NONE``). Returns :meth:`navdata`'s answer."""
        # the kernel rounds each time to the microsecond where it reads it, or answers −1
        # (nothing done) for Python's round to do it (a time below 1 µs: a flight's start)
        has = sample_t_s is not None
        step = self._step  # (the same call for both: a first call rebinds _step)
        code = step(self._state, has, sample_t_s if has else 0.0, roll_deg, pitch_deg,
                    cmd_kind, cmd_t_s, roll_frac, pitch_frac)
        if code < 0:
            code = step(self._state, has, _microseconds(sample_t_s) if has else 0.0, roll_deg,
                        pitch_deg, cmd_kind + _TIMES_ROUNDED,
                        _microseconds(cmd_t_s) if cmd_kind == _CMD_SEND else 0.0, roll_frac,
                        pitch_frac)
        if code:  # a new sample: the estimate is fitted when it is read
            self._estimate = None
            return True
        return False

    def command(self, t_s: float, roll_frac: float, pitch_frac: float) -> None:
        """A command sent at ``t_s``, held until the next."""
        self.feed(None, 0.0, 0.0, rk.CMD_SEND, t_s, roll_frac, pitch_frac)

    def restart(self) -> None:
        """The drone flew something else than the commands (its own hover): forget the
        commands; what the sums learned stays (and fades)."""
        self._state[rk.S_COUNT] = 0.0
        self._state[rk.S_HAS_R] = 0.0

    def navdata(self, t_s: float, roll_deg: float, pitch_deg: float) -> bool:
        """A navdata sample received at ``t_s``; False if it could not be used (a sample seen
        before, not finite, or commands not reaching back the longest delay)."""
        return self.feed(t_s, roll_deg, pitch_deg, rk.CMD_NONE)

    # ---------------------------------------------------------------------- the fit
    @property
    def estimate(self) -> AttitudeEstimate:
        if self._estimate is None:
            self._estimate = self._fit()
        return self._estimate

    def _fit(self) -> AttitudeEstimate:
        """The fit of the grid and the best grid point's estimate in one compiled call
        (``response_kernels.fit_estimate``; the module docstring's fit); the best's model is
        the one whose residual the compiled step tracks from now on."""
        state, out = self._state, self._fit_out
        if self._fit_step(state, out) < 0:
            return NO_ESTIMATE
        (delay, delay_std, g0, g1, s0, s1, lag, r2, n, contrast, gain_mean, gain_mean_std,
         made) = self._answer.tolist()
        return AttitudeEstimate._fitted(delay, delay_std, (g0, g1), (s0, s1), lag, r2, n,
                                        contrast, gain_mean, gain_mean_std, made)


_kernels_warm = False


def warm_up_kernels() -> None:
    """Load (or compile) the streaming fit's kernels now — once per process — not on the
    first tick aloft (a ``fly`` would wait seconds for a compile mid-air)."""
    global _kernels_warm
    if not _kernels_warm:
        est = AttitudeResponseEstimator(1.0)
        est.feed(None, 0.0, 0.0, rk.CMD_RESTART)
        est._state[rk.S_N] = 1.0  # numba raises on a division by zero, as Python does
        rk.fit_grid(est._state, est._fit_out)
        est._state[rk.S_N] = 20.0
        est._fit()  # fit_estimate (its answer: none, nothing moved)
        _kernels_warm = True


def fit_attitude_response(t_cmd, cmd_frac, t_meas, meas_rad, *, euler_angle_max_rad: float,
                          window_s: float = math.inf) -> AttitudeEstimate:
    """The estimate of whole arrays: commands (n,) send times and (n, 2) [roll, pitch] PCMD
    fractions; navdata (m,) receipt times and (m, 2) [roll, pitch] (rad, the drone's signs),
    on the same clock. All samples weigh alike unless ``window_s`` is finite."""
    est = AttitudeResponseEstimator(euler_angle_max_rad, window_s=window_s)
    t_cmd = np.asarray(t_cmd, float)
    cmd = np.asarray(cmd_frac, float).reshape(-1, 2)
    t_meas = np.asarray(t_meas, float)
    meas = np.degrees(np.asarray(meas_rad, float).reshape(-1, 2))
    i = 0
    for tm, (roll, pitch) in zip(t_meas, meas):
        while i < len(t_cmd) and t_cmd[i] < tm:
            if np.all(np.isfinite(cmd[i])):
                est.command(t_cmd[i], cmd[i, 0], cmd[i, 1])
            i += 1
        est.navdata(tm, roll, pitch)
    return est.estimate
