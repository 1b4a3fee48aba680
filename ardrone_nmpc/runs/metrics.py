"""Run metrics as pure functions of plain arrays: step response, path deviation, input
peaks and saturation, obstacle clearance, solver statistics, skipped deadlines.

:mod:`ardrone_nmpc.runs.summary` applies them to a run (which rows, which columns:
docs/design.md §5); nothing here knows a run directory, a config file or a table.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Sequence
from typing import Any

import numpy as np

from ardrone_nmpc.control.obstacles import clearance_m

__all__ = ["CLEARANCE_TOLERANCE_M", "clearance_stats", "input_stats", "path_deviation",
           "percentiles", "rmse", "skipped_deadlines", "solver_stats", "step_metrics"]

#: A tick violates an obstacle's constraint when its centre is closer than d − this (m).
CLEARANCE_TOLERANCE_M = 0.05


def rmse(e: np.ndarray) -> float:
    """Root mean square of the finite values of ``e`` (NaN if none)."""
    e = e[np.isfinite(e)]
    return float(np.sqrt(np.mean(e * e))) if e.size else math.nan


def percentiles(x: np.ndarray) -> tuple[float, float, float] | None:
    """(p50, p99, max) of the finite values of ``x``; None if none."""
    x = x[np.isfinite(x)]
    if x.size == 0:
        return None
    p50, p99 = np.percentile(x, (50, 99))  # one partition for both: each as if alone,
    # but for a zero: +0 and −0 compare equal, so which one lands at the index depends on the
    # partition (any other value is the same order statistic, the same bits)
    if p50 == 0.0:
        p50 = np.percentile(x, 50)
    if p99 == 0.0:
        p99 = np.percentile(x, 99)
    return float(p50), float(p99), float(x.max())


def _crossing_time(t: np.ndarray, e: np.ndarray, k: int) -> float:
    """Time where ``e`` (linear between samples) crosses 0 between samples k−1 and k, given
    ``e[k-1] < 0 ≤ e[k]`` (or t[k] for k = 0)."""
    if k == 0:
        return float(t[0])
    e0, e1 = float(e[k - 1]), float(e[k])
    if e1 == e0:
        return float(t[k])
    return float(t[k - 1] + (t[k] - t[k - 1]) * (-e0) / (e1 - e0))


def step_metrics(t_s: np.ndarray, y: np.ndarray, *, y0: float, y_final: float, t_step_s: float,
                 band: float = 0.02, min_dwell_s: float = 1.0) -> dict[str, float]:
    """Step-response metrics of ``y`` (any unit) for a step ``y0 → y_final`` at ``t_step_s``.

    Samples with a non-finite time or value are ignored; times must increase. Crossing times
    are interpolated linearly between samples.

    Returns
    -------
    dict with
        ``rise_time_s`` — s from the first 10 % to the first following 90 % crossing of the step
        (after ``t_step_s``); NaN if y never gets there.
        ``settling_time_s`` — s after ``t_step_s`` from which ``|y − y_final|`` stays within
        ``band·|y_final − y0|`` up to the end of the record; 0 if always within; NaN if the last
        sample is outside, or if that final stay inside lasts less than ``min_dwell_s`` (an
        oscillation that happens to end in the band has not settled).
        ``overshoot_pct`` — largest excursion beyond ``y_final`` in the direction of the step,
        % of ``|y_final − y0|``; 0 if y never passes ``y_final``.
        ``steady_state_error`` — mean of ``y − y_final`` over the last 10 % of the record's time
        span (unit of y, signed).
        ``rmse`` — RMS of ``y − y_final`` over the samples at or after ``t_step_s`` (the
        reference step signal is ``y_final`` there; unit of y).
        All NaN if there is no sample after the step.

    Raises
    ------
    ValueError if ``y_final == y0`` (no step) or ``band`` is not in (0, 1).
    """
    step = float(y_final) - float(y0)
    if step == 0.0 or not math.isfinite(step):
        raise ValueError(f"step_metrics: y_final ({y_final}) must differ from y0 ({y0})")
    if not 0.0 < band < 1.0:
        raise ValueError(f"step_metrics: band must be in (0, 1), got {band}")
    t = np.asarray(t_s, dtype=np.float64).reshape(-1)
    y = np.asarray(y, dtype=np.float64).reshape(-1)
    if t.shape != y.shape:
        raise ValueError(f"step_metrics: t_s and y differ in length ({t.size} vs {y.size})")
    ok = np.isfinite(t) & np.isfinite(y)
    t, y = t[ok], y[ok]
    nan = {"rise_time_s": math.nan, "settling_time_s": math.nan, "overshoot_pct": math.nan,
           "steady_state_error": math.nan, "rmse": math.nan}
    after = t >= t_step_s
    if not after.any():
        return nan
    t_all, y_all = t, y
    t, y = t[after], y[after]
    s = (y - float(y0)) / step  # normalised: 0 before, 1 at the target, in the step direction

    # rise time: first 10 % crossing, then the first 90 % crossing after it
    rise = math.nan
    above10 = np.flatnonzero(s >= 0.1)
    if above10.size:
        k10 = int(above10[0])
        t10 = _crossing_time(t, s - 0.1, k10)
        above90 = np.flatnonzero(s[k10:] >= 0.9)
        if above90.size:
            k90 = k10 + int(above90[0])
            t90 = _crossing_time(t, s - 0.9, k90)
            rise = max(0.0, t90 - t10)

    # settling time: after the last sample outside the band
    err = np.abs(s - 1.0) - band  # > 0 outside the band
    outside = np.flatnonzero(err > 0.0)
    if outside.size == 0:
        settling = 0.0
    elif outside[-1] == s.size - 1:
        settling = math.nan
    else:
        k = int(outside[-1]) + 1  # first sample of the final stay inside
        # crossing of the band edge between k-1 (outside) and k (inside)
        t_in = _crossing_time(t, -err, k)
        settling = t_in - float(t_step_s) if float(t[-1]) - t_in >= min_dwell_s else math.nan

    overshoot = max(0.0, float(np.max(s)) - 1.0) * 100.0

    t_last = float(t_all[-1])
    window = t_all >= t_last - 0.1 * (t_last - float(t_all[0]))
    sse = float(np.mean(y_all[window] - float(y_final)))

    rmse = float(np.sqrt(np.mean((y - float(y_final)) ** 2)))
    return {"rise_time_s": rise, "settling_time_s": settling, "overshoot_pct": overshoot,
            "steady_state_error": sse, "rmse": rmse}


def path_deviation(positions_m: np.ndarray, polyline_m: np.ndarray) -> tuple[float, float]:
    """Mean and max distance (m) of positions from a polyline.

    Each position's distance is to the nearest point of the nearest *segment* (a point beyond a
    segment's end measures to the end point); a one-point polyline measures to that point.
    Rows with a non-finite coordinate are ignored. The distances are computed by a compiled
    loop over points × segments (:mod:`ardrone_nmpc.runs.path_kernels`, the bits of the
    numpy broadcasting it replaced); their mean is numpy's.

    Parameters
    ----------
    positions_m : (K, 3) positions (m).
    polyline_m : (M, 3) polyline vertices (m), M ≥ 1.

    Returns
    -------
    (mean_m, max_m); (NaN, NaN) if there is no finite position.
    """
    p = np.asarray(positions_m, dtype=np.float64).reshape(-1, 3)
    poly = np.asarray(polyline_m, dtype=np.float64).reshape(-1, 3)
    if poly.shape[0] == 0:
        raise ValueError("path_deviation: the polyline has no point")
    if not np.all(np.isfinite(poly)):
        raise ValueError("path_deviation: the polyline has non-finite points")
    p = p[np.all(np.isfinite(p), axis=1)]
    if p.shape[0] == 0:
        return math.nan, math.nan
    if poly.shape[0] == 1:
        d = np.linalg.norm(p - poly[0], axis=1)
        return float(d.mean()), float(d.max())
    from ardrone_nmpc.runs.path_kernels import polyline_distances_m  # numba: when used

    dist = polyline_distances_m(np.ascontiguousarray(p), np.ascontiguousarray(poly))
    return float(dist.mean()), float(dist.max())


def input_stats(u: np.ndarray, lower: Sequence[float], upper: Sequence[float], *,
                tol: float = 1e-9) -> dict[str, np.ndarray]:
    """Peak magnitude and saturation of each input.

    Parameters
    ----------
    u : (K, m) inputs, one row per tick (units of the bounds); NaN entries (no input that
        tick) are ignored per input.
    lower, upper : (m,) bounds.
    tol : a value within ``tol·max(1, |bound|)`` of a bound counts as at it.

    Returns
    -------
    dict with ``peak_abs`` (m,) max |u| (NaN without samples) and ``saturated_fraction`` (m,)
    the fraction of an input's finite samples at or beyond a bound (NaN without samples).
    """
    u = np.asarray(u, dtype=np.float64)
    if u.ndim == 1:
        u = u[:, None]
    lo = np.asarray(lower, dtype=np.float64).reshape(-1)
    hi = np.asarray(upper, dtype=np.float64).reshape(-1)
    if lo.shape != (u.shape[1],) or hi.shape != (u.shape[1],):
        raise ValueError(f"input_stats: bounds must have {u.shape[1]} values")
    finite = np.isfinite(u)
    n = finite.sum(axis=0)
    au = np.where(finite, np.abs(u), -np.inf)
    peak = np.where(n > 0, au.max(axis=0, initial=-np.inf), np.nan)
    at_lo = u <= lo + tol * np.maximum(1.0, np.abs(lo))
    at_hi = u >= hi - tol * np.maximum(1.0, np.abs(hi))
    sat = ((at_lo | at_hi) & finite).sum(axis=0)
    frac = np.divide(sat, n, out=np.full(u.shape[1], np.nan), where=n > 0)
    return {"peak_abs": peak, "saturated_fraction": frac}


def clearance_stats(positions_m: np.ndarray, obstacle, *,
                    tolerance_m: float = CLEARANCE_TOLERANCE_M) -> dict[str, float]:
    """Clearance of a path from one obstacle (``config.ObstacleConfig``).

    Parameters
    ----------
    positions_m : (K, 3) positions (m); rows with a non-finite coordinate are ignored.
    obstacle : with ``kind``, ``center_m``, ``radius_m``, ``margin_m``.
    tolerance_m : how far inside ``d = radius + margin`` a tick may be before it counts.

    Returns
    -------
    dict with ``min_clearance_m`` — min of ``‖p − c‖ − radius`` (horizontal for a cylinder;
    NaN without positions) — and ``violations`` — the count of positions with
    ``‖p − c‖ < d − tolerance_m``, i.e. clearance below ``margin − tolerance_m``.
    """
    p = np.asarray(positions_m, dtype=np.float64).reshape(-1, 3)
    p = p[np.all(np.isfinite(p), axis=1)]
    clearance = clearance_m(p, obstacle)
    return {"min_clearance_m": float(clearance.min()) if clearance.size else math.nan,
            "violations": int(np.sum(clearance < obstacle.margin_m - tolerance_m))}


def solver_stats(solve_us: np.ndarray, status: Sequence[str] | np.ndarray) -> dict[str, Any]:
    """Solve-time statistics and failed solves.

    Parameters
    ----------
    solve_us : (K,) solve times (µs); NaN (no solve that tick) is ignored.
    status : (K,) solver statuses; ``""`` (no solve) and ``"ok"`` are not failures.

    Returns
    -------
    dict with ``mean_us``, ``p99_us`` (linear-interpolated 99th percentile), ``max_us`` (NaN
    without a solve), ``solves`` (count of finite times), ``non_ok`` (count) and
    ``by_status`` (status → count, failures only).
    """
    t = np.asarray(solve_us, dtype=np.float64).reshape(-1)
    t = t[np.isfinite(t)]
    by_status: dict[str, int] = {}
    for s, count in Counter(status).items():  # each distinct status looked at once
        s = "" if s is None or (isinstance(s, float) and math.isnan(s)) else str(s)
        if s and s != "ok":
            by_status[s] = by_status.get(s, 0) + count
    if t.size:
        mean, p99, mx = float(t.mean()), float(np.percentile(t, 99)), float(t.max())
    else:
        mean = p99 = mx = math.nan
    return {"mean_us": mean, "p99_us": p99, "max_us": mx, "solves": int(t.size),
            "non_ok": int(sum(by_status.values())), "by_status": dict(sorted(by_status.items()))}


def skipped_deadlines(t_s: np.ndarray, period_s: float) -> int:
    """Control deadlines skipped between consecutive logged ticks: a tick logs at its
    deadline's time, so a gap of g periods in ``t_s`` is g − 1 skipped deadlines (the loop
    skips, rather than bursts through, the deadlines a long tick overran)."""
    t = np.asarray(t_s, dtype=np.float64)
    t = t[np.isfinite(t)]
    if t.size < 2:
        return 0
    gaps = np.rint(np.diff(t) / period_s)
    return int(np.sum(np.maximum(gaps - 1.0, 0.0)))
