"""The map of a robustness grid: stability over two plant deviations (command delay ×
attitude gain by default), one panel per value of a third (the wind), each cell coloured by
the worst flight of the other axes and labelled with its clean count (docs/robustness.md).

Reads the rows of ``robustness.csv`` (text cells, as the CSV holds them); knows nothing of
how they were flown.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from ardrone_nmpc.viz.figure import PlotError, new_figure

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.figure import Figure

__all__ = ["VERDICT_COLOURS", "figure_robustness_map", "read_robustness_csv"]

#: Cell colours, best first; a cell shows its worst flight.
VERDICT_COLOURS: dict[str, str] = {
    "clean": "#2e9d4a", "settled": "#e3c441", "limit cycle": "#f28e2b",
    "supervisor": "#8e6bbf", "diverged": "#d62728", "failed": "#555555"}


def read_robustness_csv(path: str | Path) -> list[dict[str, str]]:
    import csv

    try:
        with open(path, newline="", encoding="utf-8") as f:
            return list(csv.DictReader(f))
    except OSError as err:
        raise PlotError(f"{path}: cannot read: {err.strerror or err}") from None


def _label(row: Mapping[str, str]) -> str:
    return "clean" if row.get("clean") == "true" else row.get("verdict", "failed")


def _sorted(texts) -> list[str]:
    def key(t: str):
        try:
            return (0, float(t), t)
        except ValueError:
            return (1, 0.0, t)
    return sorted(set(texts), key=key)


def _panel_title(path: str, text: str) -> str:
    name = path.rsplit(".", 1)[-1]
    if text.startswith("["):  # a vector (the wind): its magnitude
        try:
            values = [float(v) for v in text.strip("[]").split(",")]
            return f"{name} |·| = {sum(v * v for v in values) ** 0.5:.2g}"
        except ValueError:
            pass
    return f"{name} = {text}"


def figure_robustness_map(rows: Sequence[Mapping[str, str]], *, x: str, y: str,
                          panel: str = "", title: str = "") -> Figure:
    """One panel per value of ``panel`` (one panel without), x and y the two axes' values
    as categories; a cell's colour is its worst flight (:data:`VERDICT_COLOURS`), its text
    ``clean/flights``."""
    if not rows:
        raise PlotError("robustness map: no flights")
    order = list(VERDICT_COLOURS)
    panels = _sorted(r.get(panel, "") for r in rows) if panel else [""]
    xs, ys = _sorted(r[x] for r in rows), _sorted(r[y] for r in rows)
    fig = new_figure(1.0 + 3.2 * len(panels), 3.6)
    axes = fig.subplots(1, len(panels), squeeze=False)[0]
    for ax, pv in zip(axes, panels):
        for i, xv in enumerate(xs):
            for j, yv in enumerate(ys):
                cell = [r for r in rows if r[x] == xv and r[y] == yv
                        and (not panel or r.get(panel, "") == pv)]
                if not cell:
                    continue
                worst = max((_label(r) for r in cell), key=order.index)
                clean = sum(_label(r) == "clean" for r in cell)
                ax.add_patch(_square(i, j, VERDICT_COLOURS[worst]))
                ax.text(i, j, f"{clean}/{len(cell)}", ha="center", va="center", fontsize=8,
                        color="white" if worst != "settled" else "black")
        ax.set_xlim(-0.5, len(xs) - 0.5)
        ax.set_ylim(-0.5, len(ys) - 0.5)
        ax.set_xticks(range(len(xs)), xs)
        ax.set_yticks(range(len(ys)), ys)
        ax.set_xlabel(x.rsplit(".", 1)[-1])
        ax.set_ylabel(y.rsplit(".", 1)[-1])
        ax.set_title(_panel_title(panel, pv) if panel else "", fontsize=9)
        ax.set_aspect("equal")
    from matplotlib.patches import Patch

    present = [k for k in order if any(_label(r) == k for r in rows)]
    fig.legend(handles=[Patch(color=VERDICT_COLOURS[k], label=k) for k in present],
               loc="outside lower center", ncol=len(present), fontsize=8)
    if title:
        fig.suptitle(title, fontsize=10)
    return fig


def _square(i: int, j: int, colour: str):
    from matplotlib.patches import Rectangle

    return Rectangle((i - 0.48, j - 0.48), 0.96, 0.96, color=colour)
