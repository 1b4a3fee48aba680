"""The drone's command → attitude response, measured from its own commands and navdata.

A real AR.Drone's command delay (radio, firmware) and its tilt per unit PCMD are not known
before it flies, and they change with the hull, the battery and the radio. Every flight
measures both from what it sent (PCMD roll/pitch fractions, at their send times) and what the
drone reported (navdata roll/pitch, at their receipt times): the model is

    tilt(t) = k · E · [1/(τ s + 1)] c(t − d) + b        per axis (roll, pitch)

(E: ``euler_angle_max``; the drone's signs, in which navdata roll/pitch and PCMD roll/pitch
have the same sign), a pure delay d and a lag τ shared by both axes, a gain k and a trim
offset b per axis. The fit is a grid search over d (5 ms steps) and τ with the gains and
offsets in closed form; d is refined by a parabola through the residual around its minimum,
whose curvature gives its uncertainty (docs/identification.md §3 derives it). The residual's
lag-1 correlation inflates every uncertainty (a coloured residual holds less information than
as many independent samples).

:func:`fit_attitude_response` fits arrays (a log, ``identify``, the summary);
:class:`AttitudeResponseEstimator` keeps a window of one flight's samples and refits now and
then (the tick's ``DelayEstimation`` stage).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np
from scipy.signal import lfilter

__all__ = ["AttitudeEstimate", "AttitudeResponseEstimator", "DELAY_GRID_S", "LAG_GRID_S",
           "fit_attitude_response"]

STEP_S = 0.005
DELAY_GRID_S = (0.0, 0.6)                     # searched delays (s)
LAG_GRID_S = (0.02, 0.04, 0.06, 0.08, 0.1, 0.13, 0.16, 0.2, 0.25, 0.3)
#: Confident: the delay known to this (s, one σ) and the gain to this fraction of itself.
CONFIDENT_DELAY_STD_S = 0.02
CONFIDENT_GAIN_REL_STD = 0.1
#: ... with the fit explaining at least this share of the attitude's variance.
CONFIDENT_R2 = 0.6


@dataclass(frozen=True)
class AttitudeEstimate:
    """One fit: the delay (s) and its σ, the gain per axis [roll, pitch] relative to E and
    their σ, the lag τ (s), the share of the attitude's variance it explains (R²), the
    navdata samples used, and whether it is confident (module constants)."""

    delay_s: float
    delay_std_s: float
    gain: tuple[float, float]
    gain_std: tuple[float, float]
    lag_s: float
    r2: float
    samples: int

    @property
    def gain_mean(self) -> float:
        """The two axes' gains, weighted by their precision."""
        w = [1.0 / max(s, 1e-9) ** 2 for s in self.gain_std]
        return float(np.dot(w, self.gain) / sum(w))

    @property
    def gain_mean_std(self) -> float:
        return float(1.0 / math.sqrt(sum(1.0 / max(s, 1e-9) ** 2 for s in self.gain_std)))

    @property
    def confident(self) -> bool:
        return (math.isfinite(self.delay_std_s) and self.delay_std_s <= CONFIDENT_DELAY_STD_S
                and self.r2 >= CONFIDENT_R2
                and self.gain_mean_std <= CONFIDENT_GAIN_REL_STD * self.gain_mean)


NO_ESTIMATE = AttitudeEstimate(math.nan, math.inf, (math.nan, math.nan), (math.inf, math.inf),
                               math.nan, math.nan, 0)


def _held(t_cmd: np.ndarray, cmd: np.ndarray, grid: np.ndarray) -> np.ndarray:
    """The commands (n, 2) held from each send time on, sampled on ``grid``."""
    k = np.searchsorted(t_cmd, grid, side="right") - 1
    out = cmd[np.clip(k, 0, len(t_cmd) - 1)]
    out[k < 0] = 0.0
    return out


def _coloured(residual: np.ndarray) -> float:
    """√((1 + ρ₁)/(1 − ρ₁)): how much a residual's lag-1 correlation ρ₁ inflates a σ."""
    r = residual - residual.mean()
    den = float(np.dot(r, r))
    rho = float(np.dot(r[1:], r[:-1]) / den) if den > 0 else 0.0
    rho = min(max(rho, 0.0), 0.95)
    return math.sqrt((1.0 + rho) / (1.0 - rho))


def fit_attitude_response(t_cmd, cmd_frac, t_meas, meas_rad, *, euler_angle_max_rad: float,
                          lags_s=LAG_GRID_S, delays_s=DELAY_GRID_S) -> AttitudeEstimate:
    """Fit the module's model.

    Parameters
    ----------
    t_cmd : (n,) send times of the commands (s), increasing.
    cmd_frac : (n, 2) PCMD [roll, pitch] fractions sent then (held until the next).
    t_meas : (m,) times of the navdata samples (s), increasing, on the same clock.
    meas_rad : (m, 2) navdata [roll, pitch] (rad, the drone's signs).
    euler_angle_max_rad : E, the tilt at PCMD ±1 the drone was configured with.

    Returns :data:`NO_ESTIMATE` (NaN, infinite σ) when the data cannot say anything (too few
    samples, no excitation).
    """
    t_cmd = np.asarray(t_cmd, float)
    t_meas = np.asarray(t_meas, float)
    u = np.asarray(cmd_frac, float).reshape(-1, 2) * euler_angle_max_rad
    y = np.asarray(meas_rad, float).reshape(-1, 2)
    ok = np.all(np.isfinite(y), axis=1)
    t_meas, y = t_meas[ok], y[ok]
    d_max = delays_s[1]
    lags_s = tuple(lags_s)
    keep = t_meas >= t_cmd[0] + d_max if len(t_cmd) else np.zeros(0, bool)
    t_meas, y = t_meas[keep], y[keep]
    m = len(t_meas)
    if m < 20 or len(t_cmd) < 10:
        return NO_ESTIMATE
    grid = np.arange(t_cmd[0], t_meas[-1] + STEP_S, STEP_S)
    held = _held(t_cmd, np.nan_to_num(u), grid)
    shifts = np.arange(int(round(delays_s[0] / STEP_S)), int(round(d_max / STEP_S)) + 1)
    idx = np.clip(np.rint((t_meas - grid[0]) / STEP_S).astype(int), 0, len(grid) - 1)
    yc = y - y.mean(axis=0)
    syy = np.sum(yc * yc, axis=0)
    # coarse to fine: every other delay on every other lag, then all delays and lags next to
    # the best (the residual is smooth in both)
    coarse = _search(held, idx, shifts[::2], lags_s[::2], yc, syy)
    j = lags_s.index(coarse[1])
    near_lags = lags_s[max(j - 1, 0):j + 2]
    i = int(np.searchsorted(shifts, coarse[2]))
    near = shifts[max(i - 6, 0):i + 7]
    rss, tau, shift, curve = _search(held, idx, near, near_lags, yc, syy)
    k = int(np.searchsorted(near, shift))
    return _estimate(curve, k, tau, held, idx[None, :] - near[:, None], near, y, yc, syy,
                     len(t_meas))


def _filtered(held: np.ndarray, tau: float) -> np.ndarray:
    a = math.exp(-STEP_S / tau)
    return lfilter([1.0 - a], [1.0, -a], held, axis=0)


def _search(held, idx, shifts, lags, yc, syy):
    """(rss, lag, shift, rss over ``shifts`` at that lag) of the best grid point."""
    sample = idx[None, :] - shifts[:, None]            # (delays, m)
    best = (math.inf, lags[0], shifts[0], None)
    for tau in lags:
        x = _filtered(held, tau)
        rss = np.zeros(len(shifts))
        for ax in range(2):
            xs = x[sample, ax]                           # (delays, m)
            xc = xs - xs.mean(axis=1, keepdims=True)
            sxx = np.sum(xc * xc, axis=1)
            sxy = xc @ yc[:, ax]
            rss += syy[ax] - np.where(sxx > 0, sxy * sxy / np.maximum(sxx, 1e-300), 0.0)
        i = int(np.argmin(rss))
        if rss[i] < best[0]:
            best = (float(rss[i]), tau, int(shifts[i]), rss)
    return best


def _estimate(rss, i, tau, held, sample, shifts, y, yc, syy, m) -> AttitudeEstimate:
    """The estimate at grid point ``i`` of the delay curve ``rss`` for lag ``tau``."""
    x = _filtered(held, tau)
    gains, gain_var, residual = [], [], []
    for ax in range(2):
        xs = x[sample[i], ax]
        xc = xs - xs.mean()
        sxx = float(xc @ xc)
        if sxx <= 0.0:
            return NO_ESTIMATE
        k = float(xc @ yc[:, ax]) / sxx
        r = yc[:, ax] - k * xc
        residual.append(r)
        gains.append(k)
        gain_var.append(float(r @ r) / max(m - 2, 1) / sxx)
    sigma2 = float(rss[i]) / max(2 * m - 5, 1)
    inflate = max(_coloured(residual[0]), _coloured(residual[1]))
    # the delay: a parabola through the residual curve at its minimum; Δrss = (d − d̂)²·c/…
    delay = shifts[i] * STEP_S
    delay_var = math.inf
    if 0 < i < len(rss) - 1:
        lo, mid, hi = rss[i - 1], rss[i], rss[i + 1]
        curv = (lo - 2.0 * mid + hi) / STEP_S ** 2
        if curv > 0:
            delay += 0.5 * STEP_S * (lo - hi) / (lo - 2.0 * mid + hi)
            delay_var = 2.0 * sigma2 / curv
    r2 = 1.0 - float(rss[i]) / float(syy.sum()) if syy.sum() > 0 else math.nan
    s = inflate
    return AttitudeEstimate(
        float(delay), s * math.sqrt(delay_var), (gains[0], gains[1]),
        (s * math.sqrt(gain_var[0]), s * math.sqrt(gain_var[1])), float(tau), r2, m)


class AttitudeResponseEstimator:
    """One flight's estimate, refitted every ``refit_s`` over the last ``window_s``.

    Feed every command sent (:meth:`command`) and every new navdata sample (:meth:`navdata`);
    :attr:`estimate` is the newest fit (:data:`NO_ESTIMATE` before the first).
    """

    def __init__(self, euler_angle_max_rad: float, *, window_s: float = 30.0,
                 refit_s: float = 2.0, min_span_s: float = 5.0) -> None:
        self.euler_angle_max_rad = float(euler_angle_max_rad)
        self.window_s = float(window_s)
        self.refit_s = float(refit_s)
        self.min_span_s = float(min_span_s)
        self._cmd: deque = deque()    # (t, roll, pitch)
        self._nav: deque = deque()    # (t, roll rad, pitch rad)
        self._last_fit_t = -math.inf
        self.estimate = NO_ESTIMATE

    def command(self, t_s: float, roll_frac: float, pitch_frac: float) -> None:
        self._cmd.append((t_s, roll_frac, pitch_frac))

    def navdata(self, t_s: float, roll_deg: float, pitch_deg: float) -> None:
        if self._nav and t_s <= self._nav[-1][0]:
            return  # the same sample seen again
        self._nav.append((t_s, math.radians(roll_deg), math.radians(pitch_deg)))

    def restart(self) -> None:
        """Forget the samples (the drone flew something else than the commands: a hover);
        the last estimate stays."""
        self._cmd.clear()
        self._nav.clear()

    def update(self, t_s: float) -> bool:
        """Refit if it is time (``refit_s`` since the last); True when it did."""
        if t_s - self._last_fit_t < self.refit_s or not self._nav or not self._cmd:
            return False
        for q in (self._cmd, self._nav):
            while q and q[0][0] < t_s - self.window_s:
                q.popleft()
        if not self._cmd or self._nav[-1][0] - self._cmd[0][0] < self.min_span_s:
            return False
        self._last_fit_t = t_s
        c = np.array(self._cmd)
        n = np.array(self._nav)
        self.estimate = fit_attitude_response(
            c[:, 0], c[:, 1:], n[:, 0], n[:, 1:], euler_angle_max_rad=self.euler_angle_max_rad)
        return True
