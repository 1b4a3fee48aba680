"""A ``tune`` directory's record: the Optuna study in ``DIR/study.db`` and what each finished
trial carries.

The file holds one study, named after the config (``tune --study`` names it otherwise; runs
before that named it ``tune``): a reader loads whichever one it holds. Each finished trial
carries its score as the study's one objective (metric name :data:`METRIC_NAME`), the nested
:data:`RESULT_ATTR` this tool reads back, and every metric again as a flat number (what
optuna-dashboard sorts and plots; :func:`flat_metrics`).

``tune`` (:mod:`ardrone_nmpc.experiments.tune.study`) writes the record and ``plot``
(:mod:`ardrone_nmpc.viz.tune_figures`) reads it; this is their one definition of the file,
the study's name, the storage settings and the per-trial result attribute. Optuna is imported
when a record is opened.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from ardrone_nmpc.errors import UserError

__all__ = ["METRIC_NAME", "RESULT_ATTR", "STUDY_FILE", "StudyFileError", "checkpoint",
           "close_storage", "flat_metrics", "load_record", "result_of", "storage",
           "storage_errors", "stored_trials", "study_name_in"]

STUDY_FILE = "study.db"
#: The name of the study's one objective (Optuna's metric name; the dashboard's axis label).
METRIC_NAME = "score"
#: The user attribute of a finished trial: status, message, metrics (scenario → metric →
#: value), wall_s, sim_s.
RESULT_ATTR = "result"


class StudyFileError(UserError):
    """``study.db`` cannot be read or written (not a database, read-only, disk full): one
    line naming the file, exit 1."""


@contextmanager
def storage_errors(db: Path) -> Iterator[None]:
    """Turn what SQLite, SQLAlchemy or Optuna's storage raise about ``db`` into one
    :class:`StudyFileError` line (SQLite's own words: Optuna wraps a failed commit, SQLAlchemy
    the driver's error)."""
    import sqlite3

    from optuna.exceptions import StorageInternalError
    from sqlalchemy.exc import SQLAlchemyError

    try:
        yield
    except (SQLAlchemyError, sqlite3.Error, StorageInternalError) as err:
        cause = err
        while isinstance(cause, StorageInternalError) and cause.__cause__ is not None:
            cause = cause.__cause__
        cause = getattr(cause, "orig", None) or cause
        text = " ".join(str(cause).split()) or type(cause).__name__
        raise StudyFileError(f"{db}: {text}") from None


def quiet_optuna():
    """Optuna, its INFO lines off (a line per trial would bury the progress bar)."""
    import optuna

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    return optuna


def storage(db: Path, *, read_only: bool = False):
    """Optuna's SQLite storage of ``db`` (``read_only``: as it is, for reading — no journal
    change, no write) or, to record, in write-ahead-log mode without a sync per commit:
    Optuna commits every parameter and attribute it stores, and a synced commit costs
    milliseconds, on the process that also feeds the workers. A power cut may lose the last
    trials recorded (a resumed run flies others in their place); the file stays consistent."""
    import sqlite3

    optuna = quiet_optuna()
    path = str(Path(db).resolve())

    def connect():
        con = sqlite3.connect(path, check_same_thread=False, timeout=30.0)
        if read_only:
            con.execute("PRAGMA query_only=ON")
        else:
            con.execute("PRAGMA journal_mode=WAL")
            con.execute("PRAGMA synchronous=NORMAL")
        return con

    return optuna.storages.RDBStorage(f"sqlite:///{path}", engine_kwargs={"creator": connect})


def checkpoint(store) -> None:
    """Copy the write-ahead log into ``study.db`` itself, so that the file alone holds every
    trial recorded so far (a copy of it without ``study.db-wal`` is not missing any)."""
    with store.engine.connect() as con:
        con.exec_driver_sql("PRAGMA wal_checkpoint(TRUNCATE)")


def close_storage(store, db: Path) -> None:
    """Close the storage and leave ``study.db`` self-contained: the log checkpointed into it
    and the journal back in rollback mode (``study.db-wal`` and ``-shm`` removed; a resumed
    run switches to WAL again)."""
    import sqlite3

    store.remove_session()
    store.engine.dispose()
    con = sqlite3.connect(str(db), timeout=30.0)
    try:
        con.execute("PRAGMA journal_mode=DELETE")
    finally:
        con.close()


def study_name_in(store) -> str:
    """The name of the one study ``store`` holds; KeyError if it holds none."""
    optuna = quiet_optuna()
    names = optuna.study.get_all_study_names(store)
    if not names:
        raise KeyError("no study")
    return names[0]


def load_record(out_dir: Path):
    """The study of the tune directory ``out_dir``: KeyError if ``study.db`` holds none,
    :class:`StudyFileError` if it cannot be read."""
    optuna = quiet_optuna()
    db = Path(out_dir) / STUDY_FILE
    with storage_errors(db):
        store = storage(db, read_only=True)
        return optuna.load_study(study_name=study_name_in(store), storage=store)


def stored_trials(out_dir: Path) -> int:
    """How many trials the study in ``out_dir`` holds (0 without ``study.db`` or a study in
    it); :class:`StudyFileError` if the file cannot be read."""
    db = Path(out_dir) / STUDY_FILE
    if not db.is_file():
        return 0
    try:
        record = load_record(out_dir)
    except KeyError:
        return 0
    with storage_errors(db):
        return len(record.trials)


def flat_metrics(result: dict[str, Any]) -> dict[str, float]:
    """A trial's :data:`RESULT_ATTR` as flat numeric user attributes: each metric's mean over
    the scenarios (``settling_s``), each scenario's (``seed0+ardrone:settling_s``), ``wall_s``
    and ``sim_s``. Values that are not finite numbers are left out (JSON has no NaN)."""
    import math

    flat: dict[str, float] = {}
    per_metric: dict[str, list[float]] = {}
    for label, metrics in (result.get("metrics") or {}).items():
        for name, value in metrics.items():
            if isinstance(value, (int, float)) and math.isfinite(value):
                flat[f"{label}:{name}"] = float(value)
                per_metric.setdefault(name, []).append(float(value))
    means = {name: sum(v) / len(v) for name, v in per_metric.items()}
    extra = {k: float(result[k]) for k in ("wall_s", "sim_s")
             if isinstance(result.get(k), (int, float)) and math.isfinite(result[k])}
    return {**means, **extra, **flat}


def result_of(trial) -> dict[str, Any]:
    """What a finished trial carries (:data:`RESULT_ATTR`); empty if nothing."""
    return trial.user_attrs.get(RESULT_ATTR, {})
