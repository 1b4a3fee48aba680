"""What ``tune`` minimises: a weighted sum of a flight's metrics, over several scenarios.

Per scenario (one lockstep flight) the terms are, over the experiment window (``t_s ≥ 0``)
and with the plant truth (as :func:`~ardrone_nmpc.runs.summary.summarise`):

==============  ======================================================================  =====
term            value                                                                   unit
==============  ======================================================================  =====
``tracking``    path experiments: the mean deviation from the path
                (``path / mean_deviation``); others: RMSE of the 3-D distance from the
                logged reference over the flying ticks                                  m
``settling``    step: the worst stepped axis' settling time (2 % band); an axis that
                never settles counts the whole time after the step. Not a step: 0       s
``overshoot``   step: the worst stepped axis' overshoot. Not a step: 0                  %
``effort``      mean over the ticks of Σ cmd_*_frac² (the four PCMD fractions)          1
``solver``      ticks whose solver status is set and not ``ok`` (whole run)             ticks
``supervisor``  ticks of the window whose mode is not ``track`` (holds, fallbacks,
                hovers, landings: the supervisor acted)                                 ticks
``abort``       1 if the supervisor landed or stopped the flight, or it failed to run   1
``unclean``     1 if the flight is not clean as ``robustness`` judges it (a limit
                cycle, the supervisor, > 2 % of ticks with roll/pitch on ±1, or a
                steady error > 3 cm; docs/robustness.md §2)                             1
==============  ======================================================================  =====

score(scenario) = Σ weight·term; a trial's score = (1 − worst)·mean + worst·max over its
scenarios (``worst`` ∈ [0, 1] weighs the worst scenario: robustness across seeds and plants).

``--objective`` picks a preset and/or weights: ``default``, ``step``, ``tracking``,
``robust`` (``tune --robust``'s: the worst scenario alone, an unclean flight penalised), or
``PRESET,term=w,…`` / ``term=w,…`` (unnamed terms keep the preset's — ``default``'s —
weights). Presets (:data:`PRESETS`): failures always weigh heavily — 1 per solver-failed or
supervised tick, 1000 per aborted flight — so a trial that needs the safety net loses.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from ardrone_nmpc.config.schema import ConfigError
from ardrone_nmpc.core.modes import Mode

__all__ = ["FAILED_METRICS", "METRICS", "Objective", "PRESETS", "TERMS", "parse_objective",
           "scenario_metrics"]

TERMS: tuple[str, ...] = ("tracking", "settling", "overshoot", "effort", "solver",
                          "supervisor", "abort", "unclean")
_PENALTIES = {"solver": 1.0, "supervisor": 1.0, "abort": 1000.0, "unclean": 0.0}
PRESETS: dict[str, dict[str, float]] = {
    "default": {"tracking": 10.0, "settling": 1.0, "overshoot": 0.2, "effort": 1.0,
                **_PENALTIES, "worst": 0.5},
    "step": {"tracking": 2.0, "settling": 1.0, "overshoot": 0.5, "effort": 0.1,
             **_PENALTIES, "worst": 0.5},
    "tracking": {"tracking": 10.0, "settling": 0.0, "overshoot": 0.0, "effort": 0.0,
                 **_PENALTIES, "worst": 0.5},
    # tune --robust: a trial is as good as its worst plant of the grid
    "robust": {"tracking": 10.0, "settling": 1.0, "overshoot": 0.2, "effort": 1.0,
               **_PENALTIES, "unclean": 10.0, "worst": 1.0},
}
#: The metrics recorded per scenario (``trials.csv``), units in the names.
METRICS: tuple[str, ...] = ("score", "tracking_m", "rmse_m", "path_deviation_m", "settling_s",
                            "overshoot_pct", "effort", "solver_failures", "supervisor_ticks",
                            "aborted", "after_step_s", "unclean")
#: A flight that did not run: aborted, every other metric NaN.
FAILED_METRICS = {**{m: math.nan for m in METRICS}, "aborted": 1.0}


@dataclass(frozen=True)
class Objective:
    """Term weights (``weights[term]``) and the worst-scenario share ``worst``; ``text`` is
    the ``--objective`` it was parsed from."""

    weights: Mapping[str, float]
    worst: float = 0.5
    text: str = "default"

    def terms(self, m: Mapping[str, float]) -> dict[str, float]:
        """The term values of one scenario's metrics (see the module table)."""
        settling = m["settling_s"]
        if math.isnan(settling):  # never settled, or not a step
            settling = m["after_step_s"] if not math.isnan(m["after_step_s"]) else 0.0
        overshoot = 0.0 if math.isnan(m["overshoot_pct"]) else m["overshoot_pct"]
        return {"tracking": m["tracking_m"], "settling": settling, "overshoot": overshoot,
                "effort": m["effort"], "solver": m["solver_failures"],
                "supervisor": m["supervisor_ticks"], "abort": m["aborted"],
                "unclean": 0.0 if math.isnan(m["unclean"]) else m["unclean"]}

    def score(self, m: Mapping[str, float]) -> float:
        """Σ weight·term of one scenario; an aborted flight without metrics scores its
        abort penalty ×10 (a flight that could not even run is worse than any that did)."""
        if m["aborted"] and math.isnan(m["tracking_m"]):
            return 10.0 * self.weights["abort"]
        total = 0.0
        for term, value in self.terms(m).items():
            w = self.weights.get(term, 0.0)
            if w:
                total += w * (value if math.isfinite(value) else self.weights["abort"])
        return total

    def combine(self, scores: Sequence[float]) -> float:
        """A trial's score from its scenarios' scores."""
        s = np.asarray(scores, dtype=np.float64)
        return float((1.0 - self.worst) * s.mean() + self.worst * s.max())


def parse_objective(text: str | None) -> Objective:
    """``--objective``: a preset name and/or ``term=weight`` items, comma-separated.

    Raises :class:`ConfigError` (one ``--objective: …`` line per problem).
    """
    text = (text or "default").strip()
    items = [t.strip() for t in text.split(",") if t.strip()]
    weights = dict(PRESETS["default"])
    errors = []
    if items and "=" not in items[0]:
        name = items.pop(0)
        if name not in PRESETS:
            errors.append(f"--objective: unknown preset {name!r}; choose "
                          f"{', '.join(PRESETS)} (or term=weight items)")
        else:
            weights = dict(PRESETS[name])
    for item in items:
        term, sep, value = item.partition("=")
        term = term.strip()
        if not sep or term not in (*TERMS, "worst"):
            errors.append(f"--objective: {item!r}: expected term=weight with term one of "
                          f"{', '.join(TERMS)}, worst")
            continue
        try:
            w = float(value)
        except ValueError:
            errors.append(f"--objective: {term}: {value.strip()!r} is not a number")
            continue
        if not math.isfinite(w) or w < 0 or (term == "worst" and w > 1):
            errors.append(f"--objective: {term}: must be "
                          + ("in [0, 1]" if term == "worst" else "a finite weight ≥ 0"))
            continue
        weights[term] = w
    if errors:
        raise ConfigError(errors)
    worst = weights.pop("worst")
    return Objective(weights, worst, text)


def _summary_value(rows, axis: str, metric: str) -> float:
    return next((float(r.value) for r in rows if r.axis == axis and r.metric == metric),
                math.nan)


def _worst_step(rows, metric: str) -> float:
    values = [float(r.value) for r in rows
              if r.metric == metric and r.axis in ("x", "y", "z", "psi")]
    if not values:
        return math.nan
    return math.nan if any(math.isnan(v) for v in values) else max(values)


def scenario_metrics(run, rows, *, ending: str = "completed") -> dict[str, float]:
    """The :data:`METRICS` of one flight (``score`` left NaN: the objective fills it).

    ``run`` is a RunData (read back or from :class:`~ardrone_nmpc.runs.memory.MemoryRecorder`),
    ``rows`` its :func:`~ardrone_nmpc.runs.summary.summarise` rows, ``ending`` the runner's
    ``SimResult.ending``.
    """
    from ardrone_nmpc.experiments.robustness.judge import judge_columns
    from ardrone_nmpc.experiments.sweep import case_metrics
    from ardrone_nmpc.runs.window import experiment_rows

    cols = run.columns
    t = np.asarray(cols["t_s"], dtype=np.float64)
    window = experiment_rows(t)
    cmd = np.column_stack([np.asarray(cols[c], dtype=np.float64)[window] for c in
                           ("cmd_roll_frac", "cmd_pitch_frac", "cmd_gaz_frac", "cmd_yaw_frac")])
    sq = np.sum(np.nan_to_num(cmd) ** 2, axis=1)
    sweep = case_metrics(run=run, rows=rows)  # rmse_m and path deviation, as sweep.csv has them
    path_dev = sweep["path_deviation_m"]
    ref = run.config.reference
    after = (float(t[window][-1]) - ref.step_time_s
             if ref.kind == "step" and window.any() else math.nan)
    # each distinct label once: a flight logs a handful of labels over ~1000 ticks
    aborted = ending != "completed" or any(Mode.parse(m).is_abort
                                           for m in set(cols["mode"][window]))
    safety = run.config.safety
    verdict = judge_columns(cols, geofence_min_m=safety.geofence_min_m,
                            geofence_max_m=safety.geofence_max_m, ending=ending)
    return {
        "score": math.nan,
        "tracking_m": path_dev if not math.isnan(path_dev) else sweep["rmse_m"],
        "rmse_m": sweep["rmse_m"],
        "path_deviation_m": path_dev,
        "settling_s": _worst_step(rows, "settling_time"),
        "overshoot_pct": _worst_step(rows, "overshoot"),
        "effort": float(sq.mean()) if sq.size else math.nan,
        "solver_failures": _summary_value(rows, "solver", "non_ok"),
        "supervisor_ticks": _summary_value(rows, "loop", "fallbacks"),
        "aborted": 1.0 if aborted else 0.0,
        "after_step_s": after,
        "unclean": 0.0 if verdict.clean else 1.0,
    }
