"""What a robustness grid says: the cells of its map and the region where the config flies
cleanly, in numbers (the CLI's table and docs/robustness.md)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from ardrone_nmpc.experiments.robustness.grid import RobustnessGrid
from ardrone_nmpc.experiments.robustness.run import FAILED, RobustnessRow

__all__ = ["SEVERITY", "Cell", "cells", "not_clean", "region_lines"]

#: Worse last: a cell shows its worst flight.
SEVERITY = ("clean", "settled", "limit cycle", "supervisor", "diverged", FAILED)


@dataclass(frozen=True)
class Cell:
    """The flights of one map cell (one x, y and panel value; every value of the other
    axes): how many, how many clean, and the worst one."""

    flights: int
    clean: int
    worst: RobustnessRow

    @property
    def label(self) -> str:
        return _label(self.worst)


def _label(row: RobustnessRow) -> str:
    return "clean" if row.verdict.clean else row.verdict.verdict


def _rank(row: RobustnessRow) -> tuple:
    v = row.verdict
    return (SEVERITY.index(_label(row)), v.saturation_frac if v.saturation_frac == v.saturation_frac
            else 1.0, v.steady_error_m if v.steady_error_m == v.steady_error_m else 1.0)


def cells(rows: Sequence[RobustnessRow], grid: RobustnessGrid
          ) -> dict[str, dict[tuple[str, str], Cell]]:
    """panel value text → (x text, y text) → :class:`Cell` (one panel '' without a panel)."""
    groups: dict[str, dict[tuple[str, str], list[RobustnessRow]]] = {}
    for row in rows:
        p = dict(row.params)
        key = (p[grid.x], p[grid.y])
        groups.setdefault(p.get(grid.panel, ""), {}).setdefault(key, []).append(row)
    return {panel: {key: Cell(len(rs), sum(r.verdict.clean for r in rs), max(rs, key=_rank))
                    for key, rs in by_xy.items()}
            for panel, by_xy in groups.items()}


def not_clean(rows: Sequence[RobustnessRow]) -> list[RobustnessRow]:
    return [r for r in rows if not r.verdict.clean]


def _span(texts: Sequence[str]) -> str:
    values = sorted(texts, key=_number)
    return values[0] if len(values) == 1 else f"{values[0]}–{values[-1]}"


def _number(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        return float("inf")


def region_lines(rows: Sequence[RobustnessRow], grid: RobustnessGrid) -> list[str]:
    """The clean region in words: the whole grid, or the flights that are not clean (each
    with its deviations and why)."""
    if not rows:
        return ["no flight judged"]
    spans = ", ".join(f"{path.rsplit('.', 1)[-1]} {_span([dict(r.params)[path] for r in rows])}"
                      for path, _ in grid.axes)
    bad = not_clean(rows)
    lines = [f"{len(rows) - len(bad)} of {len(rows)} flights clean over {spans}."]
    if not bad:
        lines.append("Clean everywhere on the grid.")
    for r in bad:
        where = ", ".join(f"{p.rsplit('.', 1)[-1]}={v}" for p, v in r.params)
        v = r.verdict
        lines.append(f"not clean: {where}: {v.verdict}"
                     + (f" ({v.reason})" if v.reason else ""))
    return lines
