"""A run's summary: the rows of ``summary.csv`` (docs/design.md §5), computed from a run read by
:func:`~ardrone_nmpc.runs.rundir.read_run` with the pure functions of
:mod:`ardrone_nmpc.runs.metrics`. ``summary.csv`` itself is written and read by
:mod:`ardrone_nmpc.runs.rundir`; the tables that print it are the command line's
(:mod:`ardrone_nmpc.cli.tables`).

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
from collections import Counter
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ardrone_nmpc.core.angles import wrap_angle_rad
from ardrone_nmpc.core.modes import SUPERVISOR_ACTIONS, Mode
from ardrone_nmpc.reference.trajectories import make_trajectory
from ardrone_nmpc.reference.waypoints import ReferenceError
from ardrone_nmpc.runs.metrics import (CLEARANCE_TOLERANCE_M, clearance_stats, input_stats,
                                       path_deviation, percentiles, rmse, skipped_deadlines,
                                       solver_stats, step_metrics)
from ardrone_nmpc.runs.rundir import RunData, SummaryRow, read_run, read_summary, write_summary
from ardrone_nmpc.runs.window import GROUND_MODES, experiment_rows, flying_rows

__all__ = [
    "CLEARANCE_TOLERANCE_M",  # the metric functions are re-exported from runs.metrics
    "GROUND_MODES",
    "PATH_KINDS",
    "SummaryRow",
    "clearance_stats",
    "input_stats",
    "path_deviation",
    "read_summary",
    "skipped_deadlines",
    "solver_stats",
    "step_metrics",
    "summarise",
    "write_run_summary",
]

#: Reference kinds measured by path deviation.
PATH_KINDS = frozenset({"square", "square_altitudes", "ellipse", "lorenz", "path"})

_INPUTS = (("u_zacc", "u_zacc_mps2", "m/s^2"), ("u_phi", "u_phi_rad", "rad"),
           ("u_theta", "u_theta_rad", "rad"), ("u_psirate", "u_psirate_radps", "rad/s"))
_PCMD = ("cmd_roll", "cmd_pitch", "cmd_gaz", "cmd_yaw")
_AXES = (("x", "x_m", "x_true_m", "x_ref_m", "m"), ("y", "y_m", "y_true_m", "y_ref_m", "m"),
         ("z", "z_m", "z_true_m", "z_ref_m", "m"),
         ("psi", "psi_rad", "psi_true_rad", "psi_ref_rad", "rad"))


@dataclass(frozen=True)
class _Run:
    """What every section of :func:`summarise` looks at: the run, its columns, times, the
    experiment window, the mode labels, and the positions tracking is measured on (the plant
    truth when logged)."""

    run: RunData
    cols: Mapping[str, np.ndarray]
    t: np.ndarray
    window: np.ndarray
    mode: np.ndarray
    truth: bool
    pos: dict[str, np.ndarray]

    @property
    def n(self) -> int:
        return self.t.size

    def column(self, name: str) -> np.ndarray:
        """A numeric column as float64 (NaN-filled when the log lacks it)."""
        return np.asarray(self.cols.get(name, np.full(self.n, np.nan)), dtype=np.float64)


def _strings(arr: np.ndarray | None, n: int) -> np.ndarray:
    if arr is None:
        return np.full(n, "", dtype=object)
    # (the types of the list's items: a third of the time of iterating the array itself)
    if isinstance(arr, np.ndarray) and arr.dtype == object and \
            set(map(type, arr.tolist())) <= {str}:
        return arr.copy()  # the string column of read_run / MemoryRecorder: text already
    return np.array(["" if v is None or (isinstance(v, float) and math.isnan(v)) else str(v)
                     for v in arr], dtype=object)


def _per_solve(column: np.ndarray | None, solved: np.ndarray) -> np.ndarray:
    """The finite values of ``column`` on the rows with a solve (empty without the column)."""
    if column is None:
        return np.zeros(0)
    v = np.asarray(column, dtype=np.float64)[solved]
    return v[np.isfinite(v)]


def _prepare(run: RunData) -> _Run:
    cols = run.columns
    t = np.asarray(cols["t_s"], dtype=np.float64)
    truth = all(c in cols and np.isfinite(cols[c]).any() for _, _, c, _, _ in _AXES)
    pos = {axis: np.asarray(cols[true if truth else meas], dtype=np.float64)
           for axis, meas, true, _, _ in _AXES}
    return _Run(run, cols, t, experiment_rows(t), _strings(cols.get("mode"), t.size), truth,
                pos)


def _run_rows(r: _Run) -> list[SummaryRow]:
    tw = r.t[r.window]
    return [SummaryRow("run", "ticks", float(r.n), "count"),
            SummaryRow("run", "duration", float(tw[-1] - tw[0]) if tw.size else math.nan, "s"),
            SummaryRow("run", "truth_source", 1.0 if r.truth else 0.0, "flag")]


def _step_rows(r: _Run) -> list[SummaryRow]:
    """Step metrics of every axis whose target differs from its start."""
    ref = r.run.config.reference
    rows = []
    starts = (*ref.start_m, ref.start_psi_rad)
    targets = (*ref.target_m, ref.target_psi_rad)
    for (axis, _, _, _, unit), y0, yf in zip(_AXES, starts, targets):
        if axis not in ref.stepped_axes:
            continue
        y = r.pos[axis][r.window]
        if axis == "psi":  # compare with the target the short way round
            y = yf + np.asarray(wrap_angle_rad(y - yf), dtype=np.float64)
        m = step_metrics(r.t[r.window], y, y0=y0, y_final=yf, t_step_s=ref.step_time_s)
        rows += [SummaryRow(axis, "rise_time", m["rise_time_s"], "s"),
                 SummaryRow(axis, "settling_time", m["settling_time_s"], "s"),
                 SummaryRow(axis, "overshoot", m["overshoot_pct"], "%"),
                 SummaryRow(axis, "steady_state_error", m["steady_state_error"], unit),
                 SummaryRow(axis, "rmse", m["rmse"], unit)]
    return rows


def _tracking_rows(r: _Run) -> list[SummaryRow]:
    """Path deviation (path kinds) and per-axis RMSE against the logged reference, over the
    experiment's flying ticks."""
    cfg = r.run.config
    sel = r.window & flying_rows(r.mode)
    rows = []
    if cfg.reference.kind in PATH_KINDS:
        try:
            polyline = make_trajectory(cfg.reference, duration_s=cfg.duration_s).polyline_m()
        except ReferenceError:  # an older run whose path file is gone (read_run warns)
            mean_d = max_d = math.nan
        else:
            xyz = np.column_stack([r.pos["x"], r.pos["y"], r.pos["z"]])[sel]
            mean_d, max_d = path_deviation(xyz, polyline)
        rows += [SummaryRow("path", "mean_deviation", mean_d, "m"),
                 SummaryRow("path", "max_deviation", max_d, "m")]
    sq = np.zeros(int(sel.sum()))
    for axis, _, _, ref_col, unit in _AXES:
        e = r.pos[axis][sel] - np.asarray(r.cols[ref_col], dtype=np.float64)[sel]
        if axis == "psi":
            e = np.asarray(wrap_angle_rad(e), dtype=np.float64)
        else:
            sq = sq + e * e
        rows.append(SummaryRow(axis, "rmse", rmse(e), unit))
    rows.append(SummaryRow("xyz", "rmse", rmse(np.sqrt(sq)), "m"))
    return rows


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


def _obstacle_rows(r: _Run) -> list[SummaryRow]:
    """Clearance of every obstacle over every flying tick, settle phase included."""
    if not r.run.config.controller.obstacles:  # (most runs: no rows, no masks to make)
        return []
    flying = ~np.isin(r.mode, list(GROUND_MODES))
    xyz_all = np.column_stack([r.pos["x"], r.pos["y"], r.pos["z"]])[flying]
    rows = []
    for k, obstacle in enumerate(r.run.config.controller.obstacles):
        cs = clearance_stats(_relative_to_moving(xyz_all, obstacle, r.cols, flying, r.n),
                             obstacle)
        rows += [SummaryRow(f"obstacle{k}", "min_clearance", cs["min_clearance_m"], "m"),
                 SummaryRow(f"obstacle{k}", "clearance_violations", float(cs["violations"]),
                            "count")]
    return rows


def _input_rows(r: _Run) -> list[SummaryRow]:
    """Input peaks and saturation over the experiment window, and PCMD saturation flags."""
    controller = r.run.config.controller
    u = np.column_stack([r.column(c) for _, c, _ in _INPUTS])[r.window]
    stats = input_stats(u, controller.u_min, controller.u_max)
    rows = []
    for i, (name, _, unit) in enumerate(_INPUTS):
        rows += [SummaryRow(name, "peak_abs", float(stats["peak_abs"][i]), unit),
                 SummaryRow(name, "saturated_fraction", float(stats["saturated_fraction"][i]),
                            "fraction")]
    # the few distinct flag texts, counted once (not four passes over the ticks)
    flags = Counter(_strings(r.cols.get("cmd_saturated"), r.n)[r.window].tolist())
    flags = {s: count for s, count in flags.items() if len(s) == 4}
    n_flags = sum(flags.values())
    for i, name in enumerate(_PCMD):
        set_ticks = sum(count for s, count in flags.items() if s[i] == "1")
        frac = set_ticks / n_flags if n_flags else math.nan
        rows.append(SummaryRow(name, "saturated_fraction", frac, "fraction"))
    return rows


def _solver_rows(r: _Run) -> list[SummaryRow]:
    """Solve times, failed solves per status, and per solve the iterations and ‖F‖."""
    st = solver_stats(r.cols["solve_us"], _strings(r.cols.get("solver_status"), r.n))
    rows = [SummaryRow("solver", "solve_time_mean", st["mean_us"], "us"),
            SummaryRow("solver", "solve_time_p99", st["p99_us"], "us"),
            SummaryRow("solver", "solve_time_max", st["max_us"], "us"),
            SummaryRow("solver", "non_ok", float(st["non_ok"]), "count")]
    rows += [SummaryRow("solver", f"status_{status}", float(count), "count")
             for status, count in st["by_status"].items()]
    rows.append(SummaryRow("solver", "solves", float(st["solves"]), "count"))
    solved = np.isfinite(r.column("solve_us"))
    its = _per_solve(r.cols.get("newton_iterations"), solved)
    if its.size:
        rows += [SummaryRow("solver", "newton_iterations_mean", float(its.mean()), "count"),
                 SummaryRow("solver", "newton_iterations_max", float(its.max()), "count")]
    res = _per_solve(r.cols.get("residual_norm"), solved)
    if res.size:
        rows += [SummaryRow("solver", "residual_p50", float(np.percentile(res, 50)), "norm"),
                 SummaryRow("solver", "residual_max", float(res.max()), "norm")]
    return rows


def _loop_rows(r: _Run) -> list[SummaryRow]:
    """Fallbacks in the window, the supervisor's ticks per action, overruns, lateness and
    compute time."""
    # each distinct label parsed once, then looked up per tick
    counts = Counter(r.mode)
    modes = {label: Mode.parse(label) for label in counts}
    fallback = {label: mode.is_fallback for label, mode in modes.items()}
    fallbacks = int(np.sum(r.window & np.fromiter(map(fallback.__getitem__, r.mode.tolist()),
                                                  dtype=bool, count=r.mode.size)))
    rows = [SummaryRow("loop", "fallbacks", float(fallbacks), "count")]
    # the supervisor's verdicts (safety.py): ticks per action, over the whole run
    for action in SUPERVISOR_ACTIONS:
        ticks = sum(count for label, count in counts.items() if modes[label].action == action)
        rows.append(SummaryRow("supervisor", f"{action}_ticks", float(ticks), "count"))
    pct = percentiles(r.column("tick_late_ms"))
    if pct is not None:
        overruns = skipped_deadlines(r.t, r.run.config.loop.period_s)
        rows += [SummaryRow("loop", "overruns", float(overruns), "count"),
                 SummaryRow("loop", "tick_late_p50", pct[0], "ms"),
                 SummaryRow("loop", "tick_late_p99", pct[1], "ms"),
                 SummaryRow("loop", "tick_late_max", pct[2], "ms")]
    compute = r.column("compute_us")
    finite = compute[np.isfinite(compute)]
    if finite.size:
        rows += [SummaryRow("loop", "compute_mean", float(finite.mean()), "us"),
                 SummaryRow("loop", "compute_p99", float(np.percentile(finite, 99)), "us"),
                 SummaryRow("loop", "compute_max", float(finite.max()), "us")]
    return rows


def _link_rows(r: _Run) -> list[SummaryRow]:
    """Mocap and navdata ages (p99, max) and the ticks without any sample yet."""
    rows = []
    for link in ("mocap", "navdata"):
        age = r.column(f"{link}_age_ms")
        pct = percentiles(age)
        if pct is not None:
            rows += [SummaryRow(link, "age_p99", pct[1], "ms"),
                     SummaryRow(link, "age_max", pct[2], "ms")]
        rows.append(SummaryRow(link, "no_data_ticks", float(np.sum(np.isposinf(age))), "count"))
    return rows


def summarise(run: RunData) -> list[SummaryRow]:
    """The metrics of a run as :class:`SummaryRow` s (see the module docstring for which rows
    each metric uses). Needs the columns :func:`~ardrone_nmpc.runs.rundir.read_run` provides."""
    r = _prepare(run)
    tracking = _step_rows if run.config.reference.kind == "step" else _tracking_rows
    return [row for section in (_run_rows, tracking, _obstacle_rows, _input_rows,
                                _solver_rows, _loop_rows, _link_rows) for row in section(r)]


def write_run_summary(run_dir: str | Path, *, columns: dict[str, np.ndarray] | None = None,
                      config=None, durable: bool = True) -> tuple[RunData, list[SummaryRow]]:
    """Read the run at ``run_dir`` back, summarise it and write its ``summary.csv`` (the
    last file of every run directory); returns the run and its rows. ``columns`` and
    ``config``: the recorder's :meth:`~ardrone_nmpc.runs.rundir.RunRecorder.kept_columns`
    and :attr:`~ardrone_nmpc.runs.rundir.RunRecorder.config`, taken instead of parsing
    ``log.csv`` and ``config.yaml`` again (:func:`~ardrone_nmpc.runs.rundir.read_run`);
    ``durable``: see :func:`~ardrone_nmpc.runs.rundir.write_summary`."""
    run = read_run(run_dir, columns=columns, config=config)
    rows = summarise(run)
    write_summary(run_dir, rows, durable=durable)
    return run, rows
