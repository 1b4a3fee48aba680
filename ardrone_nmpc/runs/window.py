"""Which rows of a run's ``log.csv`` a metric or a figure looks at.

The *experiment window* is the experiment itself: a run logs its settle phase before
experiment time 0 (``t_s < 0``), so the window is the rows with ``t_s ≥ 0`` — or, for a log
without any (ended during settling), every row with a time. The *flying* rows leave out the
ticks on the ground (taking off, landing, landed).
"""

from __future__ import annotations

import numpy as np

from ardrone_nmpc.core.modes import GROUND_MODES

__all__ = ["GROUND_MODES", "experiment_rows", "flying_rows"]


def experiment_rows(t_s: np.ndarray, *, among: np.ndarray | None = None) -> np.ndarray:
    """Boolean mask of the experiment window: rows with a finite ``t_s ≥ 0``, or every row
    with a finite ``t_s`` when none is. ``among`` (a mask) restricts both to those rows (e.g.
    the rows that hold a state estimate)."""
    t = np.asarray(t_s, dtype=np.float64)
    timed = np.isfinite(t) if among is None else np.isfinite(t) & among
    window = timed & (t >= 0.0)
    return window if window.any() else timed


def flying_rows(mode: np.ndarray) -> np.ndarray:
    """Boolean mask of the rows whose ``mode`` is not a ground mode (:data:`GROUND_MODES`);
    every row when the modes hold one value or none (such a column says nothing about the
    ground)."""
    mode = np.asarray(mode, dtype=object)
    if len(set(mode.tolist())) <= 1:
        return np.ones(mode.size, dtype=bool)
    return ~np.isin(mode, list(GROUND_MODES))
