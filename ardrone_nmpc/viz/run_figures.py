"""Figures of a run directory (``run`` is a :class:`~ardrone_nmpc.runs.rundir.RunData`).

* :func:`figure_tracking` — x, y, z, ψ measured vs reference (and the simulator's truth), and
  the estimator's ż against the true ż; experiment time from t = 0 (the settle phase of a
  simulated run, t < 0, is left out); ticks in a fallback mode are shaded.
* :func:`figure_inputs` — the NMPC inputs z̈, φ, θ, ψ̇ with ``controller.u_min``/``u_max`` and
  the command at PCMD ±1 (tilt ``drone.euler_angle_max_rad``, yaw rate
  ``drone.control_yaw_radps``; 1 under the kit's convention), and the PCMD fractions sent, saturated ticks marked.
* :func:`figure_solver` — solve and tick compute time, residual ‖F‖, iterations, mocap/navdata
  ages with the supervisor's thresholds; every row, the settle phase shaded.
* :func:`figure_path3d` — the flown path in 3-D and from above, with the reference polyline.

A bound far outside the data (more than :data:`OFF_SCALE_FACTOR` × the data's extent) is not
allowed to squash the data into a flat line: the view stays on the data and the bound's legend
entry says "off scale".
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ardrone_nmpc.control.mapping import command_scales
from ardrone_nmpc.core.angles import unwrap_near_turns
from ardrone_nmpc.runs.window import experiment_rows, flying_rows
from ardrone_nmpc.viz.figure import PlotError, new_figure

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

    from ardrone_nmpc.runs.rundir import RunData

__all__ = ["KINDS", "OFF_SCALE_FACTOR", "figure_inputs", "figure_path3d", "figure_solver",
           "figure_tracking"]

#: The run figures by ``--kind`` name.
KINDS = ("tracking", "inputs", "solver", "path3d")
#: A bound further from zero than this many times the data's largest magnitude is off scale.
OFF_SCALE_FACTOR = 3.0
#: Modes that are not fallbacks (docs/design.md §2: anything else is the supervisor stepping in).
_NOMINAL_MODES = frozenset({"track", "settle", ""})

_TRUTH = ("x_true_m", "y_true_m", "z_true_m", "psi_true_rad")
_REF_STYLE = {"color": "black", "linestyle": "--", "linewidth": 1.2}
_TRUTH_STYLE = {"color": "tab:orange", "linestyle": ":", "linewidth": 1.6}
_BOUND_STYLE = {"color": "tab:red", "linestyle": "--", "linewidth": 1.0}
_LIMIT_STYLE = {"color": "tab:purple", "linestyle": "-.", "linewidth": 1.0}
_LEGEND = {"loc": "upper left", "bbox_to_anchor": (1.01, 1.0), "fontsize": "small",
           "borderaxespad": 0.0}


# ============================================================================= helpers


def _col(run: RunData, name: str) -> np.ndarray:
    """A numeric column as float64 (NaN-filled when the log lacks it)."""
    n = run.n_rows
    values = run.columns.get(name)
    if values is None:
        return np.full(n, math.nan)
    return np.asarray(values, dtype=np.float64)


def _strings(run: RunData, name: str) -> np.ndarray:
    values = run.columns.get(name)
    if values is None:
        return np.full(run.n_rows, "", dtype=object)
    return np.array(["" if not isinstance(v, str) else v for v in values], dtype=object)


def _has(values: np.ndarray) -> bool:
    return bool(np.isfinite(values).any())


def _experiment(run: RunData) -> np.ndarray:
    """Rows of the experiment: t ≥ 0 (a simulation's settle phase is t < 0); all if none."""
    if run.n_rows == 0:
        raise PlotError(f"{run.path}: log.csv has no rows to plot")
    t = _col(run, "t_s")
    if not np.isfinite(t).any():
        raise PlotError(f"{run.path}: log.csv has no row with a time (t_s)")
    return experiment_rows(t)


def _has_truth(run: RunData) -> bool:
    """A simulated run: the plant truth of every position axis is logged (as in summary)."""
    return all(_has(_col(run, c)) for c in _TRUTH)


def _spans(flags: np.ndarray) -> list[tuple[int, int]]:
    """Index ranges [i, j] (inclusive) of consecutive True ``flags``."""
    edges = np.flatnonzero(np.diff(np.concatenate(([0], flags.astype(np.int8), [0]))))
    return [(int(a), int(b) - 1) for a, b in zip(edges[::2], edges[1::2])]


def _shade_fallbacks(axes: Sequence[Axes], t: np.ndarray, mode: np.ndarray) -> None:
    """Shade ticks whose mode is a fallback (hover, p, land…) on every axis; legend on top."""
    bad = np.array([m not in _NOMINAL_MODES for m in mode], dtype=bool)
    period = float(np.median(np.diff(t))) if t.size > 1 else 0.0
    for k, ax in enumerate(axes):
        labelled = set()  # one legend entry per mode, on the top panel only
        for i, j in _spans(bad):
            label = f"fallback ({mode[i]})"
            show = k == 0 and label not in labelled
            ax.axvspan(t[i], t[j] + period, color="tab:red", alpha=0.12, linewidth=0,
                       label=label if show else None)
            labelled.add(label)


def _off_scale_view(data: np.ndarray, bounds: Sequence[float]) -> tuple[tuple[float, float],
                                                                          set[float]]:
    """y-limits showing ``data`` and the ``bounds`` that are not far outside it.

    Returns the limits and the set of bounds left off scale (beyond
    :data:`OFF_SCALE_FACTOR` × the data's largest magnitude, measured from zero: inputs, ages
    and fractions are all centred on or start at zero).
    """
    finite = data[np.isfinite(data)]
    lo, hi = (float(finite.min()), float(finite.max())) if finite.size else (0.0, 0.0)
    reach = max(abs(lo), abs(hi))
    off = set()
    for b in bounds:
        if reach > 0 and abs(b) <= OFF_SCALE_FACTOR * reach:
            lo, hi = min(lo, b), max(hi, b)
        else:
            off.add(b)
    pad = 0.08 * (hi - lo) if hi > lo else max(1e-3, 0.1 * abs(hi))
    return (lo - pad, hi + pad), off


def _bounded(ax: Axes, data: np.ndarray, lines: Sequence[tuple[float, float, str, dict]]) -> None:
    """Draw horizontal bound pairs ``(low, high, label, style)`` and set a readable y-view."""
    view, off = _off_scale_view(data, [b for lo, hi, _, _ in lines for b in (lo, hi)])
    for lo, hi, label, style in lines:
        note = " (off scale)" if lo in off and hi in off else ""
        ax.axhline(lo, label=label + note, **style)
        ax.axhline(hi, **style)
    ax.set_ylim(*view)


def _min_span(ax: Axes, span: float) -> None:
    """Widen the y-view to at least ``span`` around its centre, so sensor noise of a
    millimetre does not fill a panel and read as an oscillation."""
    lo, hi = ax.get_ylim()
    if hi - lo < span:
        mid = (lo + hi) / 2
        ax.set_ylim(mid - span / 2, mid + span / 2)


def _no_data(ax: Axes, text: str) -> None:
    ax.text(0.5, 0.5, text, transform=ax.transAxes, ha="center", va="center", color="grey")


def _run_title(run: RunData, what: str) -> str:
    return f"{run.config.name} — {what}\n{Path(run.path).name}"


# ============================================================================= tracking


def _psi_near(psi: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """ψ shifted by whole turns to lie within π of the (continuous) reference, so a wrapped
    heading does not jump by 2π across the plot; kept as it is where either is not finite."""
    out = np.array(psi, dtype=float)
    both = np.isfinite(out - ref)
    out[both] = unwrap_near_turns(out[both], ref[both])
    return out


#: Smallest y-extent of the tracking panels: 5 cm and 0.05 rad (≈ 3°).
_TRACK_MIN_SPAN = {"x": 0.05, "y": 0.05, "z": 0.05, "psi": 0.05}
_TRACK_AXES = (("x", "x_m", "x_ref_m", "x_true_m", "x position", "x (m)"),
               ("y", "y_m", "y_ref_m", "y_true_m", "y position", "y (m)"),
               ("z", "z_m", "z_ref_m", "z_true_m", "altitude z", "z (m)"),
               ("psi", "psi_rad", "psi_ref_rad", "psi_true_rad", "heading ψ", "ψ (rad)"))


def figure_tracking(run: RunData) -> Figure:
    """Position and heading against the reference per axis, and the estimator's ż.

    Panels: x, y, z (m) and ψ (rad) — measured (the mocap values the controller used), the
    reference, and in simulation the plant's truth; then ż (m/s): the estimator's value and, in
    simulation, the true ż. Experiment rows only (t ≥ 0 s). ψ is drawn within π of the
    reference (whole turns removed), as the controller compares them.

    Returns
    -------
    Figure : 11 × 12.5 in (1100 × 1250 px at 100 dpi).
    """
    rows = _experiment(run)
    t = _col(run, "t_s")[rows]
    truth = _has_truth(run)
    fig = new_figure(11, 12.5)
    axes = fig.subplots(5, 1, sharex=True)
    for ax, (axis, meas, ref, true, title, ylabel) in zip(axes, _TRACK_AXES):
        r = _col(run, ref)[rows]
        y = _col(run, meas)[rows]
        if axis == "psi":
            y = _psi_near(y, r)
        ax.plot(t, y, color="tab:blue", linewidth=1.4, label="measured")
        if truth:
            yt = _col(run, true)[rows]
            ax.plot(t, _psi_near(yt, r) if axis == "psi" else yt, label="truth (sim)",
                    **_TRUTH_STYLE)
        ax.plot(t, r, label="reference", **_REF_STYLE)
        ax.set_title(title, loc="left")
        ax.set_ylabel(ylabel)
        _min_span(ax, _TRACK_MIN_SPAN[axis])
    _vz_panel(axes[4], run, rows, t, truth)
    _finish_time_panels(fig, axes, run, rows, t, "tracking")
    return fig


def _finish_time_panels(fig: Figure, axes, run: RunData, rows: np.ndarray, t: np.ndarray,
                        what: str) -> None:
    """Shared finish of the stacked time panels: fallback shading, grids, legends, the time
    axis over the experiment, the title."""
    _shade_fallbacks(axes, t, _strings(run, "mode")[rows])
    for ax in axes:
        ax.grid(True, alpha=0.3)
        ax.legend(**_LEGEND)
    axes[-1].set_xlabel("t (s)")
    if t.size > 1:
        axes[-1].set_xlim(t[0], t[-1])
    fig.suptitle(_run_title(run, what))


def _vz_panel(ax: Axes, run: RunData, rows: np.ndarray, t: np.ndarray, truth: bool) -> None:
    """ż: the estimator (Kalman/Luenberger/difference, per the config) against the truth."""
    ax.plot(t, _col(run, "vz_mps")[rows], color="tab:green", linewidth=1.2,
            label=f"estimate ({run.config.estimator.kind})")
    vz_true = _col(run, "vz_true_mps")[rows]
    if truth and _has(vz_true):
        ax.plot(t, vz_true, label="truth (sim)", **_TRUTH_STYLE)
    ax.set_title("vertical speed ż: estimator" + (" vs truth" if truth else ""), loc="left")
    ax.set_ylabel("ż (m/s)")


# ============================================================================= inputs


def figure_inputs(run: RunData) -> Figure:
    """The controller's inputs with their bounds, and the PCMD fractions sent to the drone.

    Panels: z̈ (m/s²), φ (rad), θ (rad), ψ̇ (rad/s) with ``controller.u_min``/``u_max`` and, for
    φ, θ, ψ̇, the command at PCMD ±1 (``drone.euler_angle_max_rad``,
    ``drone.control_yaw_radps``, or 1 under the kit's ``drone.command_convention``); then the four PCMD fractions on [−1, 1] with the ticks whose
    command was saturated marked. Experiment rows only (t ≥ 0 s).

    Returns
    -------
    Figure : 11 × 12.5 in (1100 × 1250 px at 100 dpi).
    """
    rows = _experiment(run)
    t = _col(run, "t_s")[rows]
    cfg = run.config
    u_min, u_max = cfg.controller.u_min, cfg.controller.u_max
    scales = command_scales(cfg.drone)  # the command at PCMD ±1 (its convention)
    tilt, yaw = scales.euler_angle_max_rad, scales.control_yaw_radps
    panels = (("u_zacc_mps2", "vertical acceleration input z̈", "z̈ (m/s²)", "m/s²", None),
              ("u_phi_rad", "roll input φ", "φ (rad)", "rad", tilt),
              ("u_theta_rad", "pitch input θ", "θ (rad)", "rad", tilt),
              ("u_psirate_radps", "yaw-rate input ψ̇", "ψ̇ (rad/s)", "rad/s", yaw))
    fig = new_figure(11, 12.5)
    axes = fig.subplots(5, 1, sharex=True)
    for i, (ax, (name, title, ylabel, unit, limit)) in enumerate(zip(axes, panels)):
        u = _col(run, name)[rows]
        ax.plot(t, u, color="tab:blue", linewidth=1.2, label="input")
        lines = [(u_min[i], u_max[i], f"bounds {_interval(u_min[i], u_max[i])} {unit}",
                  _BOUND_STYLE)]
        if limit is not None:  # the drone's own limit: PCMD ±1 (docs/design.md §4)
            lines.append((-limit, limit, f"drone limit ±{limit:.3g} {unit}", _LIMIT_STYLE))
        _bounded(ax, u, lines)
        ax.set_title(title, loc="left")
        ax.set_ylabel(ylabel)
    _pcmd_panel(axes[4], run, rows, t)
    _finish_time_panels(fig, axes, run, rows, t, "inputs")
    return fig


def _interval(lo: float, hi: float) -> str:
    return f"±{hi:g}" if lo == -hi else f"[{lo:g}, {hi:g}]"


_PCMD = (("cmd_roll_frac", "roll", "tab:blue"), ("cmd_pitch_frac", "pitch", "tab:orange"),
         ("cmd_gaz_frac", "gaz", "tab:green"), ("cmd_yaw_frac", "yaw", "tab:purple"))


def _pcmd_panel(ax: Axes, run: RunData, rows: np.ndarray, t: np.ndarray) -> None:
    """PCMD fractions on their fixed [−1, 1] scale; saturated ticks (cmd_saturated) marked."""
    flags = _strings(run, "cmd_saturated")[rows]
    for k, (name, label, color) in enumerate(_PCMD):
        v = _col(run, name)[rows]
        ax.plot(t, v, color=color, linewidth=1.1, label=label)
        hit = np.array([len(f) == 4 and f[k] == "1" for f in flags], dtype=bool)
        if hit.any():
            ax.plot(t[hit], v[hit], linestyle="none", marker="x", color=color, markersize=5,
                    label=f"{label} saturated ({int(hit.sum())} ticks)")
    ax.axhline(-1.0, label="full deflection ±1", **_BOUND_STYLE)
    ax.axhline(1.0, **_BOUND_STYLE)
    ax.set_ylim(-1.15, 1.15)
    ax.set_title("PCMD commands sent (fraction of full deflection)", loc="left")
    ax.set_ylabel("command (fraction)")


# ============================================================================= solver


def figure_solver(run: RunData) -> Figure:
    """Solver and link health over every logged tick (the settle phase t < 0 s shaded).

    Panels: solve time and tick compute time (µs) with non-``ok`` solver statuses marked; the
    residual ‖F‖ (log scale); GMRES and Newton iterations; mocap and navdata ages (ms) — and
    the tick lateness of real-time runs — with the supervisor's thresholds.

    Returns
    -------
    Figure : 11 × 11 in (1100 × 1100 px at 100 dpi).
    """
    _experiment(run)  # raises for a log without rows
    t = _col(run, "t_s")
    fig = new_figure(11, 11)
    axes = fig.subplots(4, 1, sharex=True)
    _timing_panel(axes[0], run, t)
    _residual_panel(axes[1], run, t)
    _iterations_panel(axes[2], run, t)
    _ages_panel(axes[3], run, t)
    if np.nanmin(t) < 0:  # the settle phase of a simulated run
        for k, ax in enumerate(axes):
            ax.axvspan(np.nanmin(t), 0.0, color="grey", alpha=0.15, linewidth=0,
                       label="settle (t < 0)" if k == 0 else None)
    _shade_fallbacks(axes, t, _strings(run, "mode"))
    for ax in axes:
        ax.grid(True, alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(**_LEGEND)
    axes[-1].set_xlabel("t (s)")
    if t.size > 1:
        axes[-1].set_xlim(np.nanmin(t), np.nanmax(t))
    fig.suptitle(_run_title(run, "solver and links"))
    return fig


def _timing_panel(ax: Axes, run: RunData, t: np.ndarray) -> None:
    solve = _col(run, "solve_us")
    compute = _col(run, "compute_us")
    ax.set_title("solve time per tick", loc="left")
    ax.set_ylabel("time (µs)")
    if not (_has(solve) or _has(compute)):
        _no_data(ax, "no solve times logged (P controller?)")
        return
    if _has(solve):
        mean, p99 = np.nanmean(solve), np.nanpercentile(solve, 99)
        ax.plot(t, solve, color="tab:blue", linewidth=1.0,
                label=f"solve (mean {mean:.0f} µs, p99 {p99:.0f} µs)")
    if _has(compute):
        ax.plot(t, compute, color="tab:grey", linewidth=0.9, alpha=0.8,
                label=f"whole tick compute (mean {np.nanmean(compute):.0f} µs)")
    status = _strings(run, "solver_status")
    bad = np.array([s not in ("", "ok") for s in status], dtype=bool)
    if bad.any():
        y = np.where(np.isfinite(solve), solve, np.nanmax(np.r_[solve, compute, 0.0]))
        ax.plot(t[bad], y[bad], linestyle="none", marker="x", color="tab:red",
                label=f"status ≠ ok ({int(bad.sum())} ticks)")
    ax.set_ylim(bottom=0.0)


def _residual_panel(ax: Axes, run: RunData, t: np.ndarray) -> None:
    res = _col(run, "residual_norm")
    ax.set_title("optimality residual ‖F‖ after each solve", loc="left")
    ax.set_ylabel("‖F‖ (log scale)")
    positive = np.where(res > 0, res, np.nan)  # a log axis cannot show 0
    if not _has(positive):
        _no_data(ax, "no residuals logged")
        return
    ax.plot(t, positive, color="tab:blue", linewidth=1.0,
            label=f"‖F‖ (median {np.nanmedian(positive):.2g})")
    ax.set_yscale("log")


def _iterations_panel(ax: Axes, run: RunData, t: np.ndarray) -> None:
    ax.set_title("solver iterations per tick", loc="left")
    ax.set_ylabel("iterations (count)")
    drawn = False
    for name, label, color in (("gmres_iterations", "GMRES", "tab:blue"),
                               ("newton_iterations", "Newton", "tab:orange")):
        v = _col(run, name)
        if _has(v):
            ax.step(t, v, where="post", color=color, linewidth=1.0, label=label)
            drawn = True
    if not drawn:
        _no_data(ax, "no iteration counts logged")
    else:
        ax.set_ylim(bottom=0.0)


def _ages_panel(ax: Axes, run: RunData, t: np.ndarray) -> None:
    """Link ages (ms); ``inf`` (no sample yet) is counted in the legend, not drawn."""
    safety = run.config.safety
    shown = []
    for name, label, color in (("mocap_age_ms", "mocap age", "tab:blue"),
                               ("navdata_age_ms", "navdata age", "tab:green"),
                               ("tick_late_ms", "tick lateness", "tab:grey")):
        v = _col(run, name)
        missing = int(np.isposinf(v).sum())
        v = np.where(np.isfinite(v), v, np.nan)
        if not _has(v):
            continue
        note = f" ({missing} ticks without data)" if missing else ""
        ax.plot(t, v, color=color, linewidth=1.0, label=label + note)
        shown.append(v)
    ax.set_title("link ages and loop lateness, with the supervisor's thresholds", loc="left")
    ax.set_ylabel("age (ms)")
    if not shown:
        _no_data(ax, "no link ages logged")
        return
    thresholds = ((safety.mocap_hold_ms, "mocap hold", _LIMIT_STYLE),
                  (safety.mocap_hover_ms, "mocap hover", _BOUND_STYLE),
                  (safety.navdata_land_ms, "navdata land", _REF_STYLE))
    (_, hi), off = _off_scale_view(np.concatenate(shown), [v for v, _, _ in thresholds])
    for value, label, style in thresholds:
        note = " (off scale)" if value in off else ""
        ax.axhline(value, label=f"{label} {value:g} ms{note}", **style)
    ax.set_ylim(0.0, hi)


# ============================================================================= path


def _reference_polyline(run: RunData, rows: np.ndarray) -> tuple[np.ndarray, str]:
    """The reference path: the trajectory's polyline, or the logged reference if the
    trajectory cannot be rebuilt here (e.g. its waypoint file is on another machine)."""
    from ardrone_nmpc.reference.trajectories import ReferenceError, make_trajectory

    cfg = run.config
    logged = np.column_stack([_col(run, c)[rows] for c in ("x_ref_m", "y_ref_m", "z_ref_m")])
    if cfg.reference.kind == "follow":  # a live reference: only the log knows where it went
        return logged, "reference (follow, logged)"
    try:
        return make_trajectory(cfg.reference, duration_s=cfg.duration_s).polyline_m(), \
            f"reference ({cfg.reference.kind})"
    except (ReferenceError, OSError, ValueError):
        return logged, "reference (logged)"


def _flown(run: RunData) -> tuple[np.ndarray, str]:
    """Flown positions of the experiment's flying ticks; the truth in simulation (the same
    choice as the summary's path deviation), the mocap measurement otherwise."""
    rows = _experiment(run) & flying_rows(_strings(run, "mode"))
    names = _TRUTH[:3] if _has_truth(run) else ("x_m", "y_m", "z_m")
    xyz = np.column_stack([_col(run, c)[rows] for c in names])
    source = "sim truth" if names[0] == "x_true_m" else "measured"
    return xyz[np.all(np.isfinite(xyz), axis=1)], source


def _centre_half(*arrays: np.ndarray, min_span: float) -> tuple[float, float]:
    """Centre and half-width (10 % margin) covering ``arrays``, at least ``min_span`` wide."""
    data = np.concatenate([a[np.isfinite(a)] for a in arrays])
    lo, hi = float(data.min()), float(data.max())
    return (lo + hi) / 2, max(hi - lo, min_span) / 2 * 1.1


def _path_limits(ax3: Axes, ax2: Axes, xyz: np.ndarray, ref: np.ndarray) -> None:
    """x and y on one scale in both views, each at least 0.5 m wide (a hover's
    sub-millimetre wander stays a dot); z has its own (altitudes vary less)."""
    cx, hx = _centre_half(xyz[:, 0], ref[:, 0], min_span=0.5)
    cy, hy = _centre_half(xyz[:, 1], ref[:, 1], min_span=0.5)
    half = max(hx, hy)
    for ax in (ax3, ax2):
        ax.set_xlim(cx - half, cx + half)
        ax.set_ylim(cy - half, cy + half)
    cz, hz = _centre_half(xyz[:, 2], ref[:, 2], min_span=0.5)
    ax3.set_zlim(cz - hz, cz + hz)
    ax2.set_aspect("equal", adjustable="box")  # equal ranges: a square box


def figure_path3d(run: RunData) -> Figure:
    """The flown path against the reference: 3-D view and top-down (x–y, equal scale).

    The flown path is the experiment's flying ticks (truth in simulation, else measured); the
    title gives the mean deviation from the reference polyline for path references (m).

    Returns
    -------
    Figure : 13 × 6.5 in (1300 × 650 px at 100 dpi).
    """
    from ardrone_nmpc.runs.summary import PATH_KINDS, path_deviation

    xyz, source = _flown(run)
    if xyz.shape[0] == 0:
        raise PlotError(f"{run.path}: no finite positions to draw a path from")
    ref, ref_label = _reference_polyline(run, _experiment(run))
    fig = new_figure(13, 6.5)
    ax3 = fig.add_subplot(1, 2, 1, projection="3d")
    ax2 = fig.add_subplot(1, 2, 2)
    # a set point (hover) or a step is one or two points: mark them, a dash alone is invisible
    ref_style = {**_REF_STYLE, "marker": "x" if ref.shape[0] <= 2 else None}
    for ax, dims in ((ax3, (0, 1, 2)), (ax2, (0, 1))):
        ax.plot(*(ref[:, d] for d in dims), label=ref_label, **ref_style)
        ax.plot(*(xyz[:, d] for d in dims), color="tab:blue", linewidth=1.4,
                label=f"flown ({source})")
        ax.plot(*(xyz[:1, d] for d in dims), "o", color="tab:green", label="start")
        ax.plot(*(xyz[-1:, d] for d in dims), "s", color="tab:red", label="end")
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
    target = np.column_stack([_col(run, c) for c in ("target_x_m", "target_y_m", "target_z_m")
                              if c in run.columns] or [np.empty(0)])
    if target.shape[1:] == (3,) and np.isfinite(target).any():  # the followed object
        target = target[_experiment(run) & np.all(np.isfinite(target), axis=1)]
        # top-down only: the object drives below the flight altitude, off the 3-D z range
        ax2.plot(target[:, 0], target[:, 1], color="tab:orange", linewidth=1.0, alpha=0.8,
                 label="followed object")
        ax2.legend(**_LEGEND)
    _path_limits(ax3, ax2, xyz, ref)
    ax3.set_zlabel("z (m)")
    ax3.set_box_aspect(None, zoom=0.85)  # room for the z label next to the top-down view
    ax3.set_title("3-D path")
    ax2.grid(True, alpha=0.3)
    ax2.set_title("top-down view (x forward, y left)")
    ax2.legend(**_LEGEND)
    what = "path"
    if run.config.reference.kind in PATH_KINDS:
        mean_m, max_m = path_deviation(xyz, ref)
        what = (f"path — deviation from the reference: mean {mean_m:.3f} m, "
                f"max {max_m:.3f} m ({source})")
    fig.suptitle(_run_title(run, what))
    return fig
