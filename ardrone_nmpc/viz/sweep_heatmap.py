"""The heat map of a sweep: :func:`read_sweep` reads a sweep directory's ``sweep.csv`` (with
the sweep's one reader), :func:`sweep_grid` lays one metric out over two swept parameters,
:func:`figure_sweep_heatmap` draws it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ardrone_nmpc.runs.sweep_table import SweepTable, SweepTableError
from ardrone_nmpc.runs.sweep_table import read_sweep as _read_sweep_table
from ardrone_nmpc.viz.figure import PlotError, new_figure

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

__all__ = ["SWEEP_METRICS", "SweepGrid", "figure_sweep_heatmap", "read_sweep", "sweep_grid"]

#: Metric columns of ``sweep.csv`` → (axis label with unit, short name). Lower is better for
#: all of them, which is why aggregating over extra parameters takes the minimum.
SWEEP_METRICS: dict[str, tuple[str, str]] = {
    "rmse_m": ("RMSE (m)", "RMSE"),
    "settling_s": ("settling time (s)", "settling time"),
    "overshoot_pct": ("overshoot (%)", "overshoot"),
    "path_deviation_m": ("mean path deviation (m)", "mean path deviation"),
    "solve_mean_us": ("mean solve time (µs)", "mean solve time"),
    "solve_p99_us": ("p99 solve time (µs)", "p99 solve time"),
    "fallbacks": ("fallback ticks (count)", "fallback ticks"),
}
#: Statuses whose metrics are shown as numbers; any other status marks the cell.
_OK_STATUSES = frozenset({"ok", ""})
#: Unit suffixes of dotted config names (docs/design.md §4) → the unit printed on an axis.
_UNIT_SUFFIXES = (("_per_s", "1/s"), ("_radps", "rad/s"), ("_mps2", "m/s²"), ("_mps", "m/s"),
                  ("_rad", "rad"), ("_pct", "%"), ("_us", "µs"), ("_ms", "ms"), ("_hz", "Hz"),
                  ("_s", "s"), ("_m", "m"))


def _unit_of(name: str) -> str:
    """The unit of a dotted config/metric name from its suffix (docs/design.md §4), or ''."""
    for suffix, unit in _UNIT_SUFFIXES:
        if name.endswith(suffix):
            return unit
    return ""


def _with_unit(name: str) -> str:
    unit = _unit_of(name)
    return f"{name} ({unit})" if unit else name


def read_sweep(path: str | Path) -> SweepTable:
    """``sweep.csv`` read back (:func:`ardrone_nmpc.runs.sweep_table.read_sweep`); its
    errors are :class:`PlotError` s."""
    try:
        return _read_sweep_table(path)
    except SweepTableError as err:
        raise PlotError(str(err)) from None


@dataclass(frozen=True)
class SweepGrid:
    """One metric of a sweep over two parameters (rows = y values, columns = x values).

    Attributes
    ----------
    metric, x, y : the metric and the parameters on the axes (``y`` None: one parameter).
    x_labels, y_labels : tick labels of the parameter values, in increasing order.
    values : (ny, nx) metric per cell — the minimum over the aggregated parameters of the
        cases with an ok status; NaN where there is none.
    status : (ny, nx) ``""`` for a cell with a value, else the (most common) non-ok status of
        its cases, ``"not run"`` without any case, ``"no value"`` for ok cases without the
        metric.
    n_bad : (ny, nx) number of non-ok cases behind each cell.
    bad_status : (ny, nx) the most common non-ok status behind each cell (``""``: none).
    aggregated : parameters minimised over (not on an axis).
    """

    metric: str
    x: str
    y: str | None
    x_labels: tuple[str, ...]
    y_labels: tuple[str, ...]
    values: np.ndarray
    status: np.ndarray
    n_bad: np.ndarray
    bad_status: np.ndarray
    aggregated: tuple[str, ...]


def _float_or_none(text: str) -> float | None:
    try:
        v = float(text)
    except ValueError:
        return None
    return v if math.isfinite(v) else None


def _axis_values(table: SweepTable, param: str) -> tuple[list[str], dict[str, int]]:
    """Distinct values of ``param`` in order (numeric order if all numeric) → tick labels and
    the cell index of each raw text (``0.1`` and ``0.10`` share a cell)."""
    texts = list(dict.fromkeys(r[param] for r in table.rows))
    nums = [_float_or_none(s) for s in texts]
    if all(v is not None for v in nums):
        distinct = sorted(set(nums))
        labels = [f"{v:g}" for v in distinct]
        return labels, {s: distinct.index(v) for s, v in zip(texts, nums)}
    return texts, {s: i for i, s in enumerate(texts)}


def sweep_grid(table: SweepTable, *, metric: str = "rmse_m", x: str | None = None,
               y: str | None = None) -> SweepGrid:
    """Lay ``metric`` out over parameters ``x`` and ``y`` (default: the first two swept).

    Parameters left off the axes are aggregated: a cell holds the minimum over them (every
    metric is lower-is-better). Raises :class:`PlotError` for an unknown metric or parameter.
    """
    if metric not in table.metrics:
        raise PlotError(f"--metric: {metric!r} is not a metric of {table.path} "
                        f"(choose from {', '.join(table.metrics)})")
    for option, name in (("--x", x), ("--y", y)):
        if name is not None and name not in table.params:
            raise PlotError(f"{option}: {name!r} was not swept (swept: "
                            f"{', '.join(table.params)})")
    if x is not None and x == y:
        raise PlotError("--x and --y must name different parameters")
    rest = [p for p in table.params if p not in (x, y)]
    x = x or rest.pop(0)
    y = y if y is not None else (rest.pop(0) if rest else None)
    x_labels, x_index = _axis_values(table, x)
    y_labels, y_index = _axis_values(table, y) if y else ([""], None)
    shape = (len(y_labels), len(x_labels))
    cells: dict[tuple[int, int], list[dict[str, str]]] = {}
    for row in table.rows:
        key = (y_index[row[y]] if y_index else 0, x_index[row[x]])
        cells.setdefault(key, []).append(row)
    values = np.full(shape, math.nan)
    status = np.full(shape, "not run", dtype=object)
    n_bad = np.zeros(shape, dtype=int)
    bad_status = np.full(shape, "", dtype=object)
    for (i, j), group in cells.items():
        values[i, j], status[i, j], n_bad[i, j], bad_status[i, j] = _cell(group, metric)
    return SweepGrid(metric=metric, x=x, y=y, x_labels=tuple(x_labels),
                     y_labels=tuple(y_labels), values=values, status=status, n_bad=n_bad,
                     bad_status=bad_status, aggregated=tuple(rest))


def _cell(group: list[dict[str, str]], metric: str) -> tuple[float, str, int, str]:
    """(value, status, non-ok count, most common non-ok status) of one cell's cases."""
    ok = [_float_or_none(r.get(metric, "")) for r in group if r.get("status", "") in _OK_STATUSES]
    bad = [r.get("status", "") for r in group if r.get("status", "") not in _OK_STATUSES]
    worst = max(sorted(set(bad)), key=bad.count) if bad else ""
    finite = [v for v in ok if v is not None]
    if finite:
        return min(finite), "", len(bad), worst
    if bad:
        return math.nan, worst, len(bad), worst
    return math.nan, "no value", 0, ""


def figure_sweep_heatmap(table: SweepTable, *, metric: str = "rmse_m", x: str | None = None,
                         y: str | None = None) -> Figure:
    """Heat map of one sweep metric over two swept parameters (see :func:`sweep_grid`).

    Cells are annotated with their value; cells whose cases were unstable or failed are grey
    and hatched with the status; the best cell is outlined. The title names the parameters
    aggregated (minimum over them) when more than two were swept.
    """
    from matplotlib import colormaps
    from matplotlib.patches import Patch, Rectangle

    grid = sweep_grid(table, metric=metric, x=x, y=y)
    ny, nx = grid.values.shape
    fig = new_figure(max(7.0, 1.2 * nx + 4.0), max(4.5, 0.75 * ny + 3.0))
    ax = fig.add_subplot()
    cmap = colormaps["viridis"].with_extremes(bad="white")
    masked = np.ma.masked_invalid(grid.values)
    image = ax.imshow(masked, origin="lower", cmap=cmap, aspect="auto")
    label, short = SWEEP_METRICS.get(grid.metric, (_with_unit(grid.metric), grid.metric))
    fig.colorbar(image, ax=ax, label=label)
    _annotate_cells(ax, grid, image, Rectangle)
    ax.set_xticks(range(nx), grid.x_labels)
    ax.set_yticks(range(ny), grid.y_labels)
    ax.set_xlabel(_with_unit(grid.x))
    ax.set_ylabel(_with_unit(grid.y) if grid.y else "(one parameter swept)")
    handles = []
    if np.isin(grid.status, ["", "not run", "no value"], invert=True).any():
        handles.append(Patch(facecolor="lightgrey", hatch="///", edgecolor="dimgrey",
                             label="no value: unstable / failed"))
    if np.isfinite(grid.values).any():
        handles.append(Patch(facecolor="none", edgecolor="red", linewidth=2, label="best"))
    if handles:  # below the x label, out of the cells' way
        ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(0.0, -0.14 if ny > 1
                                                                      else -0.3),
                  ncols=2, fontsize="small", frameon=False)
    title = f"{short} over {grid.x}" + (f" × {grid.y}" if grid.y else "")
    if grid.aggregated:
        title += f"\nbest (minimum) over {', '.join(grid.aggregated)}"
    ax.set_title(f"{title}\n{table.path.parent.name}/{table.path.name}")
    return fig


def _annotate_cells(ax: Axes, grid: SweepGrid, image: Any, rectangle: Any) -> None:
    """Value text per cell (colour chosen for contrast), hatched status cells, best outlined."""
    ny, nx = grid.values.shape
    finite = np.isfinite(grid.values)
    best = np.unravel_index(np.nanargmin(np.where(finite, grid.values, np.inf)),
                            grid.values.shape) if finite.any() else None
    for i in range(ny):
        for j in range(nx):
            v = grid.values[i, j]
            if math.isfinite(v):
                r, g, b, _ = image.cmap(image.norm(v))
                dark = 0.299 * r + 0.587 * g + 0.114 * b < 0.5
                text = f"{v:.3g}"
                if grid.n_bad[i, j]:  # aggregated cell: some of its cases gave no value
                    text += f"\n(+{grid.n_bad[i, j]} {grid.bad_status[i, j]})"
                ax.text(j, i, text, ha="center", va="center", fontsize="medium",
                        color="white" if dark else "black")
                continue
            hatch = grid.status[i, j] not in ("not run", "no value")  # unstable/failed
            ax.add_patch(rectangle((j - 0.5, i - 0.5), 1, 1, facecolor="lightgrey" if hatch
                                   else "white", hatch="///" if hatch else None,
                                   edgecolor="dimgrey", linewidth=0.5))
            ax.text(j, i, grid.status[i, j], ha="center", va="center", fontsize="medium",
                    color="black", bbox={"facecolor": "white", "alpha": 0.8, "linewidth": 0})
    if best is not None:
        i, j = best
        ax.add_patch(rectangle((j - 0.5, i - 0.5), 1, 1, facecolor="none", edgecolor="red",
                               linewidth=2.5))
