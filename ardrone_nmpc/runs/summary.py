"""Run metrics (the rows of ``summary.csv``, docs/design.md) and their tables.

The metric functions are pure numpy and take plain arrays; :func:`summarise` applies them to a
run read by :func:`~ardrone_nmpc.runs.rundir.read_run`, and :func:`render_summary` /
:func:`render_side_by_side` lay the rows out as ``rich`` tables. ``summary.csv`` itself is
written and read by :mod:`ardrone_nmpc.runs.rundir` (:class:`SummaryRow`).

What :func:`summarise` measures, and over which rows
---------------------------------------------------

* **Experiment window**: tracking metrics and inputs use the rows with ``t_s ≥ 0`` (a simulated
  run logs a settle phase before the experiment at ``t_s < 0``); if there are none, all rows.
  Loop, link and solver health use every row.
* **Position source**: when the plant-truth columns ``x_true_m, y_true_m, z_true_m,
  psi_true_rad`` are all present with finite values (a simulation), tracking metrics use them,
  otherwise the measured ``x_m, y_m, z_m, psi_rad`` (real flight). The row
  ``run / truth_source`` says which (1 = truth, 0 = measured).
* **Steps** (reference kind ``step``): every axis whose target differs from its start (x, y, z
  compare ``target_m`` with ``start_m``, ψ ``target_psi_rad`` with ``start_psi_rad``) gets
  :func:`step_metrics` with the step at ``reference.step_time_s``. ψ is compared with the target
  the short way round (wrapped error).
* **Paths** (``square``, ``square_altitudes``, ``ellipse``, ``lorenz``, ``path``): mean and
  max :func:`path_deviation` of the positions from the trajectory's polyline, over the flying
  ticks (mode not ``landed``/``taking_off``/``landing``; all ticks when the mode column is empty
  or holds one value only). Paths and ``hover`` also get the RMSE of each axis against the
  logged reference columns over the same ticks, and the 3-D position RMSE (axis ``xyz``).
* **Obstacles** (``controller.obstacles``; axis ``obstacle<k>``, k its index in the config):
  ``min_clearance`` = min over the flight of ``‖p − c‖ − radius`` (m; horizontal distance
  for a cylinder, negative inside the obstacle) and ``clearance_violations`` = ticks with
  ``‖p − c‖ < d − CLEARANCE_TOLERANCE_M``, ``d = radius + margin`` the NMPC's constraint
  distance (:func:`clearance_stats`). Over every flying tick with a finite position, the
  settle phase included: a safety margin holds for the whole flight, not the experiment
  window only.
* **Inputs**: per input the peak |u| and the fraction of ticks at or beyond a bound of
  ``controller.u_min``/``u_max`` (:func:`input_stats`); per PCMD channel the fraction of ticks
  whose ``cmd_saturated`` flag is set.
* **Solver**: solve time mean/p99/max over the ticks that logged one; ticks whose
  ``solver_status`` is set and not ``ok`` (total and per status); the solves; per solve the
  tick's Newton iterations (mean/max) and ‖F‖ at its exit (p50/max).
* **Loop**: ``fallbacks`` = rows of the experiment window whose mode is set and is not
  ``track`` (hovers on stale data, P-controller fallbacks, supervisor landings…);
  ``overruns`` = control deadlines skipped between two logged ticks because a tick ran past
  the next deadline (a gap of g periods in ``t_s`` is g − 1 overruns; the ``loop_timing``
  event of ``fly`` counts the same); ``tick_late_ms`` p50/p99/max and ``compute_us``
  mean/p99/max when logged.
* **Links**: mocap and navdata age p99/max (finite ages) and the ticks without any sample yet
  (age ``inf``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ardrone_nmpc.control.obstacles import clearance_m
from ardrone_nmpc.core.angles import wrap_angle_rad
from ardrone_nmpc.reference.trajectories import make_trajectory
from ardrone_nmpc.reference.waypoints import ReferenceError
from ardrone_nmpc.runs.rundir import RunData, SummaryRow, read_run, read_summary, write_summary
from ardrone_nmpc.runs.window import GROUND_MODES, experiment_rows, flying_rows

if TYPE_CHECKING:  # pragma: no cover
    from rich.table import Table

__all__ = [
    "CLEARANCE_TOLERANCE_M",
    "GROUND_MODES",
    "NOMINAL_MODE",
    "PATH_KINDS",
    "SummaryRow",
    "clearance_stats",
    "format_value",
    "input_stats",
    "path_deviation",
    "read_summary",
    "write_run_summary",
    "render_side_by_side",
    "render_summary",
    "skipped_deadlines",
    "solver_stats",
    "step_metrics",
    "summarise",
]

#: The mode of a tick that tracks the experiment's reference; any other set mode is a fallback.
NOMINAL_MODE = "track"
#: A tick violates an obstacle's constraint when its centre is closer than d − this (m).
CLEARANCE_TOLERANCE_M = 0.05
#: Reference kinds measured by path deviation.
PATH_KINDS = frozenset({"square", "square_altitudes", "ellipse", "lorenz", "path"})

_INPUTS = (("u_zacc", "u_zacc_mps2", "m/s^2"), ("u_phi", "u_phi_rad", "rad"),
           ("u_theta", "u_theta_rad", "rad"), ("u_psirate", "u_psirate_radps", "rad/s"))
_PCMD = ("cmd_roll", "cmd_pitch", "cmd_gaz", "cmd_yaw")
_AXES = (("x", "x_m", "x_true_m", "x_ref_m", "m"), ("y", "y_m", "y_true_m", "y_ref_m", "m"),
         ("z", "z_m", "z_true_m", "z_ref_m", "m"),
         ("psi", "psi_rad", "psi_true_rad", "psi_ref_rad", "rad"))


# ----------------------------------------------------------------------------- metrics


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


def path_deviation(positions_m: np.ndarray, polyline_m: np.ndarray,
                   chunk_elements: int = 1_000_000) -> tuple[float, float]:
    """Mean and max distance (m) of positions from a polyline.

    Each position's distance is to the nearest point of the nearest *segment* (a point beyond a
    segment's end measures to the end point); a one-point polyline measures to that point.
    Rows with a non-finite coordinate are ignored. Vectorised over points × segments, in chunks
    of about ``chunk_elements`` pairs to bound memory.

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
    a = poly[:-1]                      # (S, 3) segment starts
    ab = poly[1:] - a                  # (S, 3) segment vectors
    ab2 = np.einsum("ij,ij->i", ab, ab)
    inv = np.divide(1.0, ab2, out=np.zeros_like(ab2), where=ab2 > 0.0)  # zero-length → t = 0
    n_seg = a.shape[0]
    step = max(1, chunk_elements // n_seg)
    dist = np.empty(p.shape[0])
    for i in range(0, p.shape[0], step):
        q = p[i:i + step]
        ap = q[:, None, :] - a[None, :, :]                      # (c, S, 3)
        u = np.clip(np.einsum("csk,sk->cs", ap, ab) * inv, 0.0, 1.0)
        diff = ap - u[:, :, None] * ab[None, :, :]
        d2 = np.einsum("csk,csk->cs", diff, diff)
        dist[i:i + step] = np.sqrt(d2.min(axis=1))
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


def _relative_to_moving(xyz_m: np.ndarray, obstacle, cols, rows: np.ndarray,
                        n: int) -> np.ndarray:
    """For a moving obstacle (``mocap_object``): the positions moved so that the obstacle sits
    at its configured centre on every tick (its logged ``target_*`` position; ticks before it
    was seen keep the centre), so :func:`clearance_stats` measures the distance to it."""
    if not obstacle.mocap_object or "target_x_m" not in cols:
        return xyz_m
    target = np.column_stack([np.asarray(cols.get(c, np.full(n, np.nan)), dtype=np.float64)
                              for c in ("target_x_m", "target_y_m", "target_z_m")])[rows]
    seen = np.all(np.isfinite(target), axis=1)
    out = xyz_m.copy()
    out[seen] += np.asarray(obstacle.center_m) - target[seen]
    return out


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
    for s in status:
        s = "" if s is None or (isinstance(s, float) and math.isnan(s)) else str(s)
        if s and s != "ok":
            by_status[s] = by_status.get(s, 0) + 1
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


# ----------------------------------------------------------------------------- summarise


def _strings(arr: np.ndarray | None, n: int) -> np.ndarray:
    if arr is None:
        return np.full(n, "", dtype=object)
    return np.array(["" if v is None or (isinstance(v, float) and math.isnan(v)) else str(v)
                     for v in arr], dtype=object)


def _percentiles(x: np.ndarray) -> tuple[float, float, float] | None:
    x = x[np.isfinite(x)]
    if x.size == 0:
        return None
    return float(np.percentile(x, 50)), float(np.percentile(x, 99)), float(x.max())


def _per_solve(column: np.ndarray | None, solved: np.ndarray) -> np.ndarray:
    """The finite values of ``column`` on the rows with a solve (empty without the column)."""
    if column is None:
        return np.zeros(0)
    v = np.asarray(column, dtype=np.float64)[solved]
    return v[np.isfinite(v)]


def _rmse(e: np.ndarray) -> float:
    e = e[np.isfinite(e)]
    return float(np.sqrt(np.mean(e * e))) if e.size else math.nan


def summarise(run: RunData) -> list[SummaryRow]:
    """The metrics of a run as :class:`SummaryRow` s (see the module docstring for which rows
    each metric uses). Needs the columns :func:`~ardrone_nmpc.runs.rundir.read_run` provides."""
    cfg = run.config
    cols: Mapping[str, np.ndarray] = run.columns
    t = np.asarray(cols["t_s"], dtype=np.float64)
    n = t.size
    rows: list[SummaryRow] = []
    add = rows.append

    window = experiment_rows(t)
    mode = _strings(cols.get("mode"), n)

    truth = all(c in cols and np.isfinite(cols[c]).any() for _, _, c, _, _ in _AXES)
    pos = {axis: np.asarray(cols[true if truth else meas], dtype=np.float64)
           for axis, meas, true, _, _ in _AXES}

    add(SummaryRow("run", "ticks", float(n), "count"))
    tw = t[window]
    add(SummaryRow("run", "duration", float(tw[-1] - tw[0]) if tw.size else math.nan, "s"))
    add(SummaryRow("run", "truth_source", 1.0 if truth else 0.0, "flag"))

    ref = cfg.reference
    if ref.kind == "step":
        starts = (*ref.start_m, ref.start_psi_rad)
        targets = (*ref.target_m, ref.target_psi_rad)
        for (axis, _, _, _, unit), y0, yf in zip(_AXES, starts, targets):
            if y0 == yf:
                continue
            y = pos[axis][window]
            if axis == "psi":  # compare with the target the short way round
                y = yf + np.asarray(wrap_angle_rad(y - yf), dtype=np.float64)
            m = step_metrics(t[window], y, y0=y0, y_final=yf, t_step_s=ref.step_time_s)
            add(SummaryRow(axis, "rise_time", m["rise_time_s"], "s"))
            add(SummaryRow(axis, "settling_time", m["settling_time_s"], "s"))
            add(SummaryRow(axis, "overshoot", m["overshoot_pct"], "%"))
            add(SummaryRow(axis, "steady_state_error", m["steady_state_error"], unit))
            add(SummaryRow(axis, "rmse", m["rmse"], unit))
    else:
        sel = window & flying_rows(mode)
        if ref.kind in PATH_KINDS:
            try:
                polyline = make_trajectory(ref, duration_s=cfg.duration_s).polyline_m()
            except ReferenceError:  # an older run whose path file is gone (read_run warns)
                mean_d = max_d = math.nan
            else:
                xyz = np.column_stack([pos["x"], pos["y"], pos["z"]])[sel]
                mean_d, max_d = path_deviation(xyz, polyline)
            add(SummaryRow("path", "mean_deviation", mean_d, "m"))
            add(SummaryRow("path", "max_deviation", max_d, "m"))
        sq = np.zeros(int(sel.sum()))
        for axis, _, _, ref_col, unit in _AXES:
            e = pos[axis][sel] - np.asarray(cols[ref_col], dtype=np.float64)[sel]
            if axis == "psi":
                e = np.asarray(wrap_angle_rad(e), dtype=np.float64)
            else:
                sq = sq + e * e
            add(SummaryRow(axis, "rmse", _rmse(e), unit))
        add(SummaryRow("xyz", "rmse", _rmse(np.sqrt(sq)), "m"))

    # obstacles: every flying tick, settle phase included
    flying = ~np.isin(mode, list(GROUND_MODES))
    xyz_all = np.column_stack([pos["x"], pos["y"], pos["z"]])[flying]
    for k, obstacle in enumerate(cfg.controller.obstacles):
        cs = clearance_stats(_relative_to_moving(xyz_all, obstacle, cols, flying, n), obstacle)
        add(SummaryRow(f"obstacle{k}", "min_clearance", cs["min_clearance_m"], "m"))
        add(SummaryRow(f"obstacle{k}", "clearance_violations", float(cs["violations"]),
                       "count"))

    # inputs
    u = np.column_stack([np.asarray(cols[c], dtype=np.float64) for _, c, _ in _INPUTS])[window]
    stats = input_stats(u, cfg.controller.u_min, cfg.controller.u_max)
    for i, (name, _, unit) in enumerate(_INPUTS):
        add(SummaryRow(name, "peak_abs", float(stats["peak_abs"][i]), unit))
        add(SummaryRow(name, "saturated_fraction", float(stats["saturated_fraction"][i]),
                       "fraction"))
    flags = [s for s in _strings(cols.get("cmd_saturated"), n)[window] if len(s) == 4]
    for i, name in enumerate(_PCMD):
        frac = sum(s[i] == "1" for s in flags) / len(flags) if flags else math.nan
        add(SummaryRow(name, "saturated_fraction", frac, "fraction"))

    # solver
    st = solver_stats(cols["solve_us"], _strings(cols.get("solver_status"), n))
    add(SummaryRow("solver", "solve_time_mean", st["mean_us"], "us"))
    add(SummaryRow("solver", "solve_time_p99", st["p99_us"], "us"))
    add(SummaryRow("solver", "solve_time_max", st["max_us"], "us"))
    add(SummaryRow("solver", "non_ok", float(st["non_ok"]), "count"))
    for status, count in st["by_status"].items():
        add(SummaryRow("solver", f"status_{status}", float(count), "count"))
    add(SummaryRow("solver", "solves", float(st["solves"]), "count"))
    # per solve: the tick's Newton iterations and ‖F‖ at its exit
    solved = np.isfinite(np.asarray(cols["solve_us"], dtype=np.float64))
    its = _per_solve(cols.get("newton_iterations"), solved)
    if its.size:
        add(SummaryRow("solver", "newton_iterations_mean", float(its.mean()), "count"))
        add(SummaryRow("solver", "newton_iterations_max", float(its.max()), "count"))
    res = _per_solve(cols.get("residual_norm"), solved)
    if res.size:
        add(SummaryRow("solver", "residual_p50", float(np.percentile(res, 50)), "norm"))
        add(SummaryRow("solver", "residual_max", float(res.max()), "norm"))

    # loop
    fallbacks = int(np.sum(window & (mode != "") & (mode != NOMINAL_MODE)))
    add(SummaryRow("loop", "fallbacks", float(fallbacks), "count"))
    # the supervisor's verdicts (safety.py): ticks per action, over the whole run
    for action in ("hold", "fallback", "hover", "land", "stop"):
        ticks = sum(1 for m in mode if m.startswith(action + "-") or m == action)
        add(SummaryRow("supervisor", f"{action}_ticks", float(ticks), "count"))
    late = np.asarray(cols.get("tick_late_ms", np.full(n, np.nan)), dtype=np.float64)
    pct = _percentiles(late)
    if pct is not None:
        add(SummaryRow("loop", "overruns", float(skipped_deadlines(t, cfg.loop.period_s)),
                       "count"))
        add(SummaryRow("loop", "tick_late_p50", pct[0], "ms"))
        add(SummaryRow("loop", "tick_late_p99", pct[1], "ms"))
        add(SummaryRow("loop", "tick_late_max", pct[2], "ms"))
    compute = np.asarray(cols.get("compute_us", np.full(n, np.nan)), dtype=np.float64)
    finite = compute[np.isfinite(compute)]
    if finite.size:
        add(SummaryRow("loop", "compute_mean", float(finite.mean()), "us"))
        add(SummaryRow("loop", "compute_p99", float(np.percentile(finite, 99)), "us"))
        add(SummaryRow("loop", "compute_max", float(finite.max()), "us"))

    # links
    for link in ("mocap", "navdata"):
        age = np.asarray(cols.get(f"{link}_age_ms", np.full(n, np.nan)), dtype=np.float64)
        pct = _percentiles(age)
        if pct is not None:
            add(SummaryRow(link, "age_p99", pct[1], "ms"))
            add(SummaryRow(link, "age_max", pct[2], "ms"))
        add(SummaryRow(link, "no_data_ticks", float(np.sum(np.isposinf(age))), "count"))
    return rows


# ----------------------------------------------------------------------------- files, tables


def write_run_summary(run_dir: str | Path) -> tuple[RunData, list[SummaryRow]]:
    """Read the run at ``run_dir`` back, summarise it and write its ``summary.csv`` (the
    last file of every run directory); returns the run and its rows."""
    run = read_run(run_dir)
    rows = summarise(run)
    write_summary(run_dir, rows)
    return run, rows


def format_value(value: float, unit: str) -> str:
    """A summary value as the tables show it: counts as integers, fractions with 3 decimals,
    the rest with 4 significant digits, NaN as —."""
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "—"
    if unit in ("count", "flag") and float(value).is_integer():
        return f"{int(value)}"
    if unit == "fraction":
        return f"{value:.3f}"
    return f"{value:.4g}"


def render_summary(rows: Sequence[SummaryRow], title: str | None = None) -> Table:
    """A ``rich`` table of summary rows: axis, metric, value, unit (NaN shown as —)."""
    from rich.table import Table

    table = Table(title=title)
    table.add_column("axis")
    table.add_column("metric")
    table.add_column("value", justify="right")
    table.add_column("unit")
    for r in rows:
        table.add_row(r.axis, r.metric, format_value(r.value, r.unit), r.unit)
    return table


def render_side_by_side(runs: Sequence[tuple[str, Sequence[SummaryRow]]],
                        title: str | None = None) -> Table:
    """A ``rich`` table comparing runs: one value column per ``(label, rows)`` run, one line
    per (axis, metric) in order of first appearance; a metric a run lacks is blank."""
    from rich.table import Table

    keys: dict[tuple[str, str], str] = {}
    values: list[dict[tuple[str, str], float]] = []
    for _, rows in runs:
        vals = {}
        for r in rows:
            keys.setdefault((r.axis, r.metric), r.unit)
            vals[(r.axis, r.metric)] = r.value
        values.append(vals)
    table = Table(title=title)
    table.add_column("axis")
    table.add_column("metric")
    table.add_column("unit")
    for label, _ in runs:
        table.add_column(label, justify="right")
    for (axis, metric), unit in keys.items():
        cells = [format_value(v[(axis, metric)], unit) if (axis, metric) in v else "" for v in values]
        table.add_row(axis, metric, unit, *cells)
    return table
