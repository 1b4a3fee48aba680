"""How a sweep judges a finished case: its ``sweep.csv`` metrics and its status.

Status
------
``failed``: the simulation raised (``message`` holds the exception), or it flew to its end
without doing its job (a failed verdict of :mod:`ardrone_nmpc.runs.verdict`: no tracking tick,
or a followed object never seen). ``unstable``: the run
completed, but over the experiment window (``t_s ≥ 0``) one of these holds (``message`` says
which): a non-finite position; a position outside the geofence
(``safety.geofence_min_m``/``geofence_max_m``); a tick whose mode is a ground mode or names a
landing or emergency (the supervisor aborted the experiment); or a 3-D distance from the
reference above ``diverge_m`` (default 0.5 m) anywhere in the last quarter of the experiment
(it did not converge, or it oscillates). Otherwise ``ok``. Unstable cases are results.

Metrics (the names carry the units)
-----------------------------------
``rmse_m``: RMSE of the 3-D distance from the logged reference over the experiment's flying
ticks (the plant truth when logged, as in :func:`~ardrone_nmpc.runs.summary.summarise`; for path
experiments this is the summary's ``xyz rmse``). ``settling_s``, ``overshoot_pct``: the worst
stepped axis of the summary (NaN without a step, and ``settling_s`` NaN when an axis never
settles). ``path_deviation_m``: the summary's mean path deviation (NaN if not a path
experiment). ``solve_mean_us``, ``solve_p99_us``, ``fallbacks`` (ticks): the summary's solver
and loop rows. Everything but the solve times (measured wall time) is deterministic.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ardrone_nmpc.core.modes import Mode
from ardrone_nmpc.runs.window import experiment_rows, flying_rows

if TYPE_CHECKING:  # pragma: no cover
    from ardrone_nmpc.runs.rundir import RunData
    from ardrone_nmpc.runs.summary import SummaryRow

DIVERGE_M = 0.5
TAIL_FRACTION = 0.25  # the part of the experiment that must stay within diverge_m


@dataclass(frozen=True)
class _Window:
    """The experiment window of a run (``t_s ≥ 0``; all rows if none): times (s), positions
    and reference (K, 3) (m), mode, and which ticks were flying (not a ground mode)."""

    t_s: np.ndarray
    pos_m: np.ndarray
    ref_m: np.ndarray
    mode: np.ndarray
    flying: np.ndarray


def case_window(run: RunData) -> _Window:
    """The experiment window :func:`case_metrics` and :func:`classify` judge (made once for
    both by a sweep case: ~0.1 ms a flight)."""
    cols = run.columns
    t = np.asarray(cols["t_s"], dtype=np.float64)
    window = experiment_rows(t)
    labels = cols["mode"]
    labels = labels.tolist() if isinstance(labels, np.ndarray) else labels  # (faster to walk)
    mode = np.array(["" if not isinstance(m, str) else m for m in labels], dtype=object)[window]
    flying = flying_rows(mode)
    truth = all(np.isfinite(cols[c]).any() for c in ("x_true_m", "y_true_m", "z_true_m",
                                                      "psi_true_rad"))
    names = ("x_true_m", "y_true_m", "z_true_m") if truth else ("x_m", "y_m", "z_m")
    pos = np.column_stack([np.asarray(cols[c], dtype=np.float64)[window] for c in names])
    ref = np.column_stack([np.asarray(cols[c], dtype=np.float64)[window]
                           for c in ("x_ref_m", "y_ref_m", "z_ref_m")])
    return _Window(t[window], pos, ref, mode, flying)


def _row_value(rows: Sequence[SummaryRow], axis: str, metric: str) -> float:
    for r in rows:
        if r.axis == axis and r.metric == metric:
            return float(r.value)
    return math.nan


def _worst(rows: Sequence[SummaryRow], metric: str) -> float:
    """The largest ``metric`` over the stepped axes; NaN if none or if any is NaN."""
    values = [float(r.value) for r in rows if r.metric == metric
              and r.axis in ("x", "y", "z", "psi")]
    return max(values) if values and not any(math.isnan(v) for v in values) else math.nan


def case_metrics(*, run: RunData, rows: Sequence[SummaryRow],
                 window: _Window | None = None) -> dict[str, float]:
    """The ``sweep.csv`` metrics of a run (see the module docstring); ``window``: the run's
    :func:`case_window`, if made already."""
    w = case_window(run) if window is None else window
    dist = np.linalg.norm(w.pos_m[w.flying] - w.ref_m[w.flying], axis=1)
    dist = dist[np.isfinite(dist)]
    fallbacks = _row_value(rows, "loop", "fallbacks")
    return {
        "rmse_m": float(np.sqrt(np.mean(dist * dist))) if dist.size else math.nan,
        "settling_s": _worst(rows, "settling_time"),
        "overshoot_pct": _worst(rows, "overshoot"),
        "path_deviation_m": _row_value(rows, "path", "mean_deviation"),
        "solve_mean_us": _row_value(rows, "solver", "solve_time_mean"),
        "solve_p99_us": _row_value(rows, "solver", "solve_time_p99"),
        "fallbacks": fallbacks if math.isnan(fallbacks) else int(fallbacks),
    }


def _aborted(mode: np.ndarray) -> str | None:
    """The first mode label that aborts the flight, if any (each distinct label parsed once:
    a flight logs a handful of labels over ~1000 ticks)."""
    aborts = {label: Mode.parse(label).is_abort for label in set(mode)}
    return next((m for m in mode if aborts[m]), None)


def classify(*, run: RunData, diverge_m: float = DIVERGE_M,
             window: _Window | None = None) -> tuple[str, str]:
    """``("ok", "")`` or ``("unstable", reasons)`` for a completed run.

    Parameters
    ----------
    run : the run read back (:func:`~ardrone_nmpc.runs.rundir.read_run`).
    diverge_m : largest 3-D distance from the reference (m) allowed in the last quarter of
        the experiment window.
    window : the run's :func:`case_window`, if made already.

    The rule is the module docstring's; ``reasons`` joins every one that holds.
    """
    w = case_window(run) if window is None else window
    t, pos, ref = w.t_s[w.flying], w.pos_m[w.flying], w.ref_m[w.flying]
    reasons = []
    if not np.all(np.isfinite(pos)):
        reasons.append("non-finite position")
    safety = run.config.safety
    lo, hi = np.asarray(safety.geofence_min_m), np.asarray(safety.geofence_max_m)
    outside = np.any((pos < lo) | (pos > hi), axis=1)
    if outside.any():
        reasons.append(f"left the geofence at t = {t[np.argmax(outside)]:.2f} s")
    mode_hit = _aborted(w.mode)
    if mode_hit is not None:
        reasons.append(f"aborted (mode {mode_hit})")
    if t.size:
        tail = t >= t[-1] - TAIL_FRACTION * (t[-1] - t[0])
        dist = np.linalg.norm(pos[tail] - ref[tail], axis=1)
        worst = float(np.max(dist, initial=0.0, where=np.isfinite(dist)))
        if worst > diverge_m:
            reasons.append(f"{worst:.3g} m from the reference in the last "
                           f"{TAIL_FRACTION:.0%} (> {diverge_m:g} m)")
    return ("unstable", "; ".join(reasons)) if reasons else ("ok", "")
