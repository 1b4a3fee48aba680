"""A ``tune`` directory's record: the Optuna study in ``DIR/study.db`` and what each finished
trial carries.

``tune`` (:mod:`ardrone_nmpc.experiments.tune.study`) writes the record and ``plot``
(:mod:`ardrone_nmpc.viz.tune_figures`) reads it; this is their one definition of the file,
the study's name, the storage settings and the per-trial result attribute. Optuna is imported
when a record is opened.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

__all__ = ["RESULT_ATTR", "STUDY_FILE", "STUDY_NAME", "load_record", "result_of", "storage"]

STUDY_FILE = "study.db"
STUDY_NAME = "tune"
#: The user attribute of a finished trial: status, message, metrics (scenario → metric →
#: value), wall_s, sim_s.
RESULT_ATTR = "result"


def quiet_optuna():
    """Optuna, its INFO lines off (a line per trial would bury the progress bar)."""
    import optuna

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    return optuna


def storage(db: Path):
    """Optuna's SQLite storage of ``db`` in write-ahead-log mode without a sync per commit:
    Optuna commits every parameter and attribute it stores, and a synced commit costs
    milliseconds, on the process that also feeds the workers. A power cut may lose the last
    trials recorded (a resumed run flies others in their place); the file stays consistent."""
    import sqlite3

    optuna = quiet_optuna()
    path = str(Path(db).resolve())

    def connect():
        con = sqlite3.connect(path, check_same_thread=False, timeout=30.0)
        con.execute("PRAGMA journal_mode=WAL")
        con.execute("PRAGMA synchronous=NORMAL")
        return con

    return optuna.storages.RDBStorage(f"sqlite:///{path}", engine_kwargs={"creator": connect})


def load_record(out_dir: Path):
    """The study of the tune directory ``out_dir``. KeyError if ``study.db`` holds none."""
    optuna = quiet_optuna()
    return optuna.load_study(study_name=STUDY_NAME, storage=storage(Path(out_dir) / STUDY_FILE))


def result_of(trial) -> dict[str, Any]:
    """What a finished trial carries (:data:`RESULT_ATTR`); empty if nothing."""
    return trial.user_attrs.get(RESULT_ATTR, {})
