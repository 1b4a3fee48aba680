"""The command line's tables of summary rows (``summary``, ``simulate``, ``replay``): one run,
or several side by side. The rows come from :mod:`ardrone_nmpc.runs.summary`."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # pragma: no cover
    from rich.table import Table

    from ardrone_nmpc.runs.rundir import SummaryRow

__all__ = ["format_value", "render_side_by_side", "render_summary"]


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
