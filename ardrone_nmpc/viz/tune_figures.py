"""Figures of a ``tune`` directory: the optimisation history and the parameter importances.

A tune directory holds ``study.db`` (the Optuna study) and ``trials.csv``. Both figures read
the study: :func:`figure_history` plots every finished trial's score against its number with
the best so far; :func:`figure_importance` the parameters' importances by Optuna's default
evaluator (:func:`optuna.importance.get_param_importances`, fANOVA), largest on top, over at
least :data:`MIN_IMPORTANCE_TRIALS` finished trials (fewer rank noise: a forest fitted on ten
points of an 11-parameter space ranks whatever it happened to split on). Like the
other figures (:mod:`ardrone_nmpc.viz.figure`): object-oriented matplotlib on an Agg canvas,
no pyplot. The record is read through :mod:`ardrone_nmpc.runs.tune_record`.
"""

from __future__ import annotations

import math
from pathlib import Path

from ardrone_nmpc.runs.tune_record import STUDY_FILE, load_record, result_of
from ardrone_nmpc.viz.figure import PlotError, new_figure, save_figure

__all__ = ["MIN_IMPORTANCE_TRIALS", "figure_history", "figure_importance", "is_tune_dir",
           "load_study", "plot_tune_dir"]

#: The fewest finished trials the parameter importances are drawn from (docs/tuning.md §4).
MIN_IMPORTANCE_TRIALS = 20

_STATUS_COLOURS = {"ok": "tab:blue", "aborted": "tab:orange", "failed": "tab:red"}


def is_tune_dir(path: Path) -> bool:
    return Path(path).is_dir() and (Path(path) / STUDY_FILE).is_file()


def load_study(path: Path):
    """The Optuna study of a tune directory. PlotError if Optuna is missing or the file holds
    no tune study."""
    try:
        import optuna  # noqa: F401 - only checking that it is there
    except ImportError:
        raise PlotError("a tune directory's plots need Optuna: pip install -e '.[tune]'") from None
    try:
        return load_record(path)
    except KeyError:
        raise PlotError(f"{path}: {STUDY_FILE} holds no study") from None


def _finished(study) -> list:
    from optuna.trial import TrialState

    return study.get_trials(deepcopy=False, states=(TrialState.COMPLETE,))


def figure_history(study):
    """Score of each finished trial (dots coloured by status) and the best so far (step
    line); a log scale when every score is positive and they span more than a decade."""
    trials = _finished(study)
    if not trials:
        raise PlotError("the study has no finished trial yet")
    fig = new_figure(9.0, 5.0)
    ax = fig.add_subplot()
    for status, colour in _STATUS_COLOURS.items():
        pts = [(t.number, t.value) for t in trials if result_of(t).get("status") == status]
        if pts:
            ax.scatter(*zip(*pts), s=18, color=colour, label=f"trial ({status})", zorder=3)
    best, line = math.inf, []
    for t in trials:
        best = min(best, t.value)
        line.append((t.number, best))
    ax.step(*zip(*line), where="post", color="black", label="best so far")
    values = [t.value for t in trials]
    if min(values) > 0 and max(values) / min(values) > 10:
        ax.set_yscale("log")
    ax.set_xlabel("trial")
    ax.set_ylabel("score (lower is better)")
    ax.set_title(f"optimisation history: {len(trials)} trials, best {best:.4g}")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="upper right")
    return fig


def figure_importance(study):
    """Horizontal bars of the parameter importances (they sum to 1)."""
    import optuna

    trials = _finished(study)
    if len(trials) < MIN_IMPORTANCE_TRIALS:
        raise PlotError(f"parameter importances need at least {MIN_IMPORTANCE_TRIALS} "
                        f"finished trials; the study has {len(trials)} (tune --resume "
                        "--trials N adds more)")
    try:
        imp = optuna.importance.get_param_importances(study)
    except (RuntimeError, ValueError) as err:
        raise PlotError(f"parameter importances: {' '.join(str(err).split())}") from None
    names = list(imp)[::-1]  # the largest on top
    fig = new_figure(8.0, max(3.0, 0.4 * len(names) + 1.5))
    ax = fig.add_subplot()
    ax.barh(range(len(names)), [imp[n] for n in names], color="tab:blue")
    ax.set_yticks(range(len(names)), names)
    ax.set_xlabel(f"importance (fANOVA over {len(trials)} finished trials, sums to 1)")
    ax.set_title(f"parameter importances over {len(trials)} trials")
    ax.grid(True, axis="x", alpha=0.3)
    return fig


def plot_tune_dir(path: Path, *, output: Path | None = None, dpi: int = 100,
                  check=None, warn=None) -> list[Path]:
    """Write ``plot-history.png`` and ``plot-importance.png`` (or ``FILE-history.png``,
    ``FILE-importance.png`` for ``output=FILE.png``); returns the files. ``check(target)``
    is called on every file before anything is drawn. Below :data:`MIN_IMPORTANCE_TRIALS`
    finished trials the importances are not drawn: ``warn(line)`` says why."""
    path = Path(path)
    if output is None:
        targets = {k: path / f"plot-{k}.png" for k in ("history", "importance")}
    else:
        output = Path(output) if Path(output).suffix else Path(output).with_suffix(".png")
        targets = {k: output.with_name(f"{output.stem}-{k}{output.suffix}")
                   for k in ("history", "importance")}
    for target in targets.values():
        if check is not None:
            check(target)
    study = load_study(path)
    written = [save_figure(figure_history(study), targets["history"], dpi=dpi)]
    n = len(_finished(study))
    if n < MIN_IMPORTANCE_TRIALS:
        if warn is not None:
            warn(f"{targets['importance']}: not drawn: parameter importances need at least "
                 f"{MIN_IMPORTANCE_TRIALS} finished trials, the study has {n}")
        return written
    return written + [save_figure(figure_importance(study), targets["importance"], dpi=dpi)]
