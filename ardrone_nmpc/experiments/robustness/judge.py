"""How ``robustness`` judges one flight: settled, limit cycle, supervisor or diverged.

Over the experiment window (``t_s ≥ 0``) with the plant truth (docs/robustness.md §2):

* **diverged** — a non-finite position, a position outside the geofence, the flight landed or
  stopped (by the supervisor or by itself), or in the steady window more than
  :data:`DIVERGE_M` from the reference;
* **supervisor** — otherwise, any tick whose mode is not ``track`` (the supervisor held,
  hovered or fell back to the P controller);
* **limit cycle** — otherwise, in the steady window an axis oscillates about its mean with
  an amplitude (half its peak-to-peak) above :data:`CYCLE_AMPLITUDE_M` and crosses it, with
  hysteresis, at least :data:`CYCLE_CROSSINGS` times (two periods);
* **settled** — none of these.

The *steady window* is the last :data:`STEADY_FRACTION` of the experiment, at least
:data:`STEADY_MIN_S`. A flight is **clean** when it settled with at most
:data:`CLEAN_SATURATION` of its ticks with roll or pitch on ±1 and a steady error (the mean
error of each of x, y, z over the steady window) of at most :data:`CLEAN_ERROR_M`.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from ardrone_nmpc.estimation.disturbance import SATURATION_FRAC
from ardrone_nmpc.core.modes import NOMINAL_MODES, Mode
from ardrone_nmpc.runs.window import experiment_rows

__all__ = ["CLASSES", "CLEAN_ERROR_M", "CLEAN_SATURATION", "CYCLE_AMPLITUDE_M",
           "FlightVerdict", "judge_columns"]

CLASSES = ("settled", "limit cycle", "supervisor", "diverged")
DIVERGE_M = 0.5
CYCLE_AMPLITUDE_M = 0.02
CYCLE_CROSSINGS = 4
STEADY_FRACTION = 0.3
STEADY_MIN_S = 5.0
CLEAN_SATURATION = 0.02
CLEAN_ERROR_M = 0.03


@dataclass(frozen=True)
class FlightVerdict:
    """One flight's class (:data:`CLASSES`), whether it is clean, and the figures behind it:
    the largest oscillation amplitude (m) and its period (s; NaN without a cycle) over x, y,
    z in the steady window, the share of ticks with roll or pitch on ±1, the largest steady
    error (m), the ticks the supervisor acted on, and a one-line reason."""

    verdict: str
    clean: bool
    amplitude_m: float
    period_s: float
    saturation_frac: float
    steady_error_m: float
    supervisor_ticks: int
    reason: str = ""

    def as_row(self) -> dict:
        return asdict(self)


def _crossings(e: np.ndarray, band: float) -> np.ndarray:
    """Indices where ``e`` (mean removed) crosses 0 with hysteresis ±``band``."""
    state, out = 0, []
    for i, v in enumerate(e):
        side = 1 if v > band else (-1 if v < -band else 0)
        if side and side != state:
            if state:
                out.append(i)
            state = side
    return np.asarray(out, dtype=int)


def _oscillation(t: np.ndarray, e: np.ndarray) -> tuple[float, float]:
    """(amplitude, period) of one axis' steady error; period NaN without enough crossings."""
    if e.size < 3:
        return 0.0, math.nan
    d = e - e.mean()
    amplitude = 0.5 * float(d.max() - d.min())
    idx = _crossings(d, 0.5 * amplitude)
    if idx.size < CYCLE_CROSSINGS:
        return amplitude, math.nan
    return amplitude, float(2.0 * np.mean(np.diff(t[idx])))


def _column(cols, name: str, window: np.ndarray) -> np.ndarray:
    return np.asarray(cols[name], dtype=np.float64)[window]


def judge_columns(cols, *, geofence_min_m, geofence_max_m, ending: str = "completed"
                  ) -> FlightVerdict:
    """The verdict of a run's log columns (``RunData.columns``); ``ending`` is the runner's
    (a landing or stop that ended the run early is a divergence)."""
    t_all = np.asarray(cols["t_s"], dtype=np.float64)
    window = experiment_rows(t_all)
    t = t_all[window]
    mode = np.array(["" if not isinstance(m, str) else m for m in cols["mode"]],
                    dtype=object)[window]
    truth = all(np.isfinite(np.asarray(cols[f"{a}_true_m"], dtype=float)).any() for a in "xyz")
    names = [f"{a}_true_m" if truth else f"{a}_m" for a in "xyz"]
    pos = np.column_stack([_column(cols, n, window) for n in names])
    ref = np.column_stack([_column(cols, f"{a}_ref_m", window) for a in "xyz"])
    roll = _column(cols, "cmd_roll_frac", window)
    pitch = _column(cols, "cmd_pitch_frac", window)
    saturated = (np.abs(roll) >= SATURATION_FRAC) | (np.abs(pitch) >= SATURATION_FRAC)
    sat = float(saturated.mean()) if saturated.size else math.nan
    off_nominal = ~np.isin(mode, NOMINAL_MODES)
    supervisor = int(off_nominal.sum())
    span = t[-1] - t[0] if t.size else 0.0
    steady = t >= (t[-1] - max(STEADY_MIN_S, STEADY_FRACTION * span)) if t.size else t > 0
    err = pos[steady] - ref[steady]
    steady_error = float(np.max(np.abs(np.nanmean(err, axis=0)))) if err.size else math.nan
    osc = [_oscillation(t[steady], err[:, i]) for i in range(3)] if err.size else []
    amplitude = max((a for a, _ in osc), default=math.nan)
    cycling = [(a, p) for a, p in osc if a > CYCLE_AMPLITUDE_M and not math.isnan(p)]
    period = max(cycling)[1] if cycling else math.nan

    def verdict(kind: str, reason: str = "") -> FlightVerdict:
        clean = (kind == "settled" and sat <= CLEAN_SATURATION
                 and steady_error <= CLEAN_ERROR_M)
        if kind == "settled" and not clean:
            reason = (f"saturated {sat:.1%}" if sat > CLEAN_SATURATION
                      else f"steady error {steady_error * 100:.1f} cm")
        return FlightVerdict(kind, clean, amplitude, period, sat, steady_error, supervisor,
                             reason)

    lo, hi = np.asarray(geofence_min_m), np.asarray(geofence_max_m)
    aborts = {m: Mode.parse(m).is_abort for m in set(mode)}  # each distinct label once
    aborted = next((m for m in mode if aborts[m]), None)
    if not t.size or not np.all(np.isfinite(pos)):
        return verdict("diverged", "non-finite position")
    if np.any((pos < lo) | (pos > hi)):
        return verdict("diverged", "left the geofence")
    if ending != "completed" or aborted is not None:
        return verdict("diverged", f"ended {aborted or ending}")
    worst = float(np.max(np.linalg.norm(err, axis=1)))
    if worst > DIVERGE_M:
        return verdict("diverged", f"{worst:.2f} m from the reference at the end")
    if supervisor:
        modes = sorted(set(mode[off_nominal].tolist()))
        return verdict("supervisor", f"{supervisor} ticks {'/'.join(modes)}")
    if cycling:
        return verdict("limit cycle", f"±{max(cycling)[0] * 100:.1f} cm, {period:.2f} s")
    return verdict("settled")
