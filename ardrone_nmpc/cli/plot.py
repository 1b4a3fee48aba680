"""``ardrone-nmpc plot``: a run directory's figures, or a sweep directory's heat map, as images.

* Run directory (holds ``log.csv``): ``--kind tracking|inputs|solver|path3d|all`` (default
  ``all``). ``all`` writes one image per kind — ``FILE-tracking.png``, ``FILE-inputs.png``,
  ``FILE-solver.png``, ``FILE-path3d.png`` for ``-o FILE.png`` — rather than one tall composite:
  each figure stays readable at its own size and can be opened on its own. Default output:
  ``RUN_DIR/plot-<kind>.png``; ``-o DIR`` (an existing directory) writes those names into DIR.
* Sweep directory (holds ``sweep.csv``): the heat map of ``--metric`` (default ``rmse_m``) over
  ``--x``/``--y`` (default: the first two swept parameters; any others are minimised over, as
  the title says). Default output: ``SWEEP_DIR/plot-heatmap-<metric>.png`` (or that name in
  ``-o DIR``).

The output format follows the file suffix (``.png`` when there is none). Errors are
:class:`~ardrone_nmpc.viz.plots.PlotError` or :class:`~ardrone_nmpc.runs.rundir.LogError`, one line.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from ardrone_nmpc.viz.plots import KINDS, SWEEP_FILE, PlotError

__all__ = ["MATPLOTLIB_MISSING", "PlotError", "plot_command", "run_plot_command"]

MATPLOTLIB_MISSING = "plotting needs matplotlib: pip install -e '.[plot]'"


def plot_command(*, path: Path, output: Path | None, kind: str | None, metric: str | None,
                 x: str | None, y: str | None, dpi: int) -> None:
    """The ``plot`` command: draw, then print ``plot: <file>`` per file written (notes about
    the data on stderr)."""
    import typer

    from ardrone_nmpc.cli.console import warn

    for file in run_plot_command(path=path, output=output, kind=kind, metric=metric, x=x,
                                 y=y, dpi=dpi, warn=warn):
        typer.echo(f"plot: {file}")


def _require_matplotlib() -> None:
    try:
        import matplotlib  # noqa: F401 - only checking that it is there
    except ImportError:
        raise PlotError(MATPLOTLIB_MISSING) from None


def _check_format(path: Path) -> Path:
    """``path`` with ``.png`` added when it has no suffix; PlotError for a format matplotlib
    cannot write (checked before any figure is drawn)."""
    from matplotlib.backend_bases import FigureCanvasBase

    if not path.suffix:
        path = path.with_suffix(".png")
    formats = FigureCanvasBase.get_supported_filetypes()
    if path.suffix[1:].lower() not in formats:
        raise PlotError(f"-o: cannot write {path.suffix!r} images (use one of "
                        f"{', '.join(sorted(formats))})")
    return path


def _check_target(target: Path) -> Path:
    """An image may go anywhere but inside a run directory — except the figures
    (``plot-*``) beside its files (:func:`~ardrone_nmpc.runs.outputs.check_output_file`)."""
    from ardrone_nmpc.runs.outputs import OutputError, check_output_file

    try:
        return check_output_file(target, option="-o", figures=True, replace=True)
    except OutputError as err:
        raise PlotError(str(err)) from None


def _save(fig, path: Path, dpi: int) -> Path:
    from ardrone_nmpc.viz.plots import save_figure

    try:
        return save_figure(fig, path, dpi=dpi)
    except OSError as err:
        raise PlotError(f"{path}: cannot write: {err.strerror or err}") from None


def run_plot_command(*, path: Path, output: Path | None = None, kind: str | None = None,
                     metric: str | None = None, x: str | None = None, y: str | None = None,
                     dpi: int = 100, warn: Callable[[str], None] | None = None) -> list[Path]:
    """Draw the figures of a run or sweep directory; return the files written.

    Parameters
    ----------
    path : a run directory, a sweep directory, a ``sweep.csv`` file, or a tune directory
        (``study.db``: its history and parameter importances).
    output : image file; with ``kind='all'`` the stem of one file per kind.
    kind : run figure (:data:`~ardrone_nmpc.viz.plots.KINDS` or ``all``; default ``all``).
    metric, x, y : sweep heat map only (see :func:`~ardrone_nmpc.viz.plots.sweep_grid`).
    dpi : resolution, pixels per inch.
    warn : called with notes on recoverable damage (a torn last log line).
    """
    from ardrone_nmpc.runs.tune_record import STUDY_FILE
    from ardrone_nmpc.viz.tune_figures import is_tune_dir, plot_tune_dir

    _require_matplotlib()
    path = Path(path)
    if path.is_file() and path.name == STUDY_FILE:  # a tune's study.db: its directory
        path = path.parent
    elif is_tune_dir(path) and (path / SWEEP_FILE).is_file():
        raise PlotError(f"{path}: holds a sweep ({SWEEP_FILE}) and a tune study ({STUDY_FILE});"
                        f" plot {path / SWEEP_FILE} for the heat map or {path / STUDY_FILE} for "
                        "the tune's history")
    if is_tune_dir(path):  # a tune directory: history and importances
        return plot_tune_dir(path, output=output, dpi=dpi, check=_check_target, warn=warn)
    if (path.is_file() and path.name == SWEEP_FILE) or (path / SWEEP_FILE).is_file():
        if kind not in (None, "heatmap"):
            raise PlotError(f"--kind: {path} is a sweep directory; it has one figure, the "
                            f"heat map (leave --kind out)")
        return [_plot_sweep(path, output=output, metric=metric or "rmse_m", x=x, y=y,
                            dpi=dpi, warn=warn)]
    if not path.is_dir():
        raise PlotError(f"{path}: no such directory")
    if not (path / "log.csv").is_file():
        raise PlotError(f"{path}: not a run directory (no log.csv) nor a sweep directory "
                        f"(no {SWEEP_FILE})")
    for option, value in (("--metric", metric), ("--x", x), ("--y", y)):
        if value is not None:
            raise PlotError(f"{option}: only for sweep directories; {path} is a run")
    return _plot_run(path, output=output, kind=kind or "all", dpi=dpi, warn=warn)


def _plot_run(path: Path, *, output: Path | None, kind: str, dpi: int,
              warn: Callable[[str], None] | None) -> list[Path]:
    from ardrone_nmpc.viz import plots
    from ardrone_nmpc.runs.rundir import read_run

    if kind not in (*KINDS, "all"):
        raise PlotError(f"--kind: unknown kind {kind!r}; choose from {', '.join(KINDS)}, all")
    kinds = KINDS if kind == "all" else (kind,)
    if output is None or output.is_dir():
        targets = [(output or path) / f"plot-{k}.png" for k in kinds]
    else:
        output = _check_format(output)
        targets = [output] if kind != "all" else \
            [output.with_name(f"{output.stem}-{k}{output.suffix}") for k in kinds]
    for target in targets:
        _check_target(target)
    run = read_run(path)
    for note in run.warnings:  # a torn last row: plot the rest, but say so
        if warn is not None:
            warn(note)
    return [_save(getattr(plots, f"figure_{k}")(run), target, dpi)
            for k, target in zip(kinds, targets)]


def _plot_sweep(path: Path, *, output: Path | None, metric: str, x: str | None,
                y: str | None, dpi: int, warn: Callable[[str], None] | None) -> Path:
    from ardrone_nmpc.viz.plots import figure_sweep_heatmap, read_sweep

    table = read_sweep(path)
    for note in table.warnings:
        if warn is not None:
            warn(note)
    sweep_dir = table.path.parent
    if output is None or output.is_dir():
        target = (output or sweep_dir) / f"plot-heatmap-{metric}.png"
    else:
        target = _check_format(output)
    _check_target(target)
    return _save(figure_sweep_heatmap(table, metric=metric, x=x, y=y), target, dpi)
