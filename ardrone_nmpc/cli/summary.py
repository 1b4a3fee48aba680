"""``ardrone-nmpc summary``: the metrics of one run or of many, as tables or CSV.

Layouts, chosen so that every run name is shown whole and every value as a number:

* one run: its table (axis, metric, value, unit);
* several runs that fit the width (the terminal's, or 150 columns when piped): side by side,
  one value column per run;
* more runs than fit: the long layout, one line per (metric, run) with the run's full name,
  grouped by metric so the runs can be compared metric by metric;
* ``--csv``: ``run,axis,metric,value,unit`` lines (values at full precision) for scripts.

Warnings about a run (a torn last line; a run that did not finish: interrupted, failed,
killed) go to stderr; a single run's table names how it ended in its title too.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import typer

__all__ = ["fits_side_by_side", "render_long", "summary_command"]


def _labels(run_dirs: Sequence[Path]) -> list[str]:
    """Each run's directory name; the path as given where two names are the same."""
    names = [Path(d).name for d in run_dirs]
    return [name if names.count(name) == 1 else str(d) for name, d in zip(names, run_dirs)]


def fits_side_by_side(runs, width: int) -> bool:
    """Whether the side-by-side table of ``runs`` (``(label, rows)``) fits ``width``
    columns without cutting a name or a value."""
    from ardrone_nmpc.cli.tables import format_value

    keys = {(r.axis, r.metric, r.unit) for _, rows in runs for r in rows}
    fixed = [max((len(k[i]) for k in keys), default=0) for i in range(3)]
    widths = fixed + [max([len(label)] + [len(format_value(r.value, r.unit)) for r in rows])
                      for label, rows in runs]
    return sum(widths) + 3 * len(widths) + 1 <= width  # "│ " + cell + " " per column


def render_long(runs, title: str | None = None):
    """One line per (metric, run): axis, metric, unit, run (full name), value; the runs of
    one metric together, metrics in order of first appearance."""
    from rich.table import Table

    from ardrone_nmpc.cli.tables import format_value

    order: dict[tuple[str, str], str] = {}
    for _, rows in runs:
        for r in rows:
            order.setdefault((r.axis, r.metric), r.unit)
    values = [{(r.axis, r.metric): r.value for r in rows} for _, rows in runs]
    table = Table(title=title)
    for name, justify in (("axis", "left"), ("metric", "left"), ("unit", "left"),
                          ("run", "left"), ("value", "right")):
        table.add_column(name, justify=justify, no_wrap=name != "run", overflow="fold")
    for (axis, metric), unit in order.items():
        present = [(label, v[(axis, metric)]) for (label, _), v in zip(runs, values)
                   if (axis, metric) in v]
        for i, (label, value) in enumerate(present):
            table.add_row(axis if i == 0 else "", metric if i == 0 else "",
                          unit if i == 0 else "", label, format_value(value, unit),
                          end_section=i == len(present) - 1)
    return table


def _print_csv(runs) -> None:
    import csv
    import io

    from ardrone_nmpc.runs.rundir import format_number

    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(("run", "axis", "metric", "value", "unit"))
    for label, rows in runs:
        writer.writerows((label, r.axis, r.metric, format_number(r.value), r.unit)
                         for r in rows)
    typer.echo(buffer.getvalue(), nl=False)


def summary_command(*, run_dirs: Sequence[Path], csv: bool = False, console=None) -> None:
    """Print the summaries of ``run_dirs`` (see the module docstring). LogError for a run
    directory that cannot be read."""
    from ardrone_nmpc.cli.console import run_notes, stdout_console
    from ardrone_nmpc.runs.rundir import read_run
    from ardrone_nmpc.cli.tables import render_side_by_side, render_summary
    from ardrone_nmpc.runs.summary import summarise

    runs, endings = [], []
    for label, run_dir in zip(_labels(run_dirs), run_dirs):
        run = read_run(run_dir)
        endings.append(run_notes(run, label=label))
        runs.append((label, summarise(run)))
    if csv:
        _print_csv(runs)
        return
    console = console or stdout_console()
    if len(runs) == 1:
        title = runs[0][0] + (f" — {endings[0]}" if endings[0] else "")
        console.print(render_summary(runs[0][1], title=title))
    elif fits_side_by_side(runs, console.width):
        console.print(render_side_by_side(runs))
    else:
        console.print(render_long(runs))
