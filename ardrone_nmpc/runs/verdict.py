"""A flight's verdict: did a run that reached its end do its job?

A runner's ending says how the flight stopped (``completed``, ``land-<reason>``,
``stop-<reason>``). Reaching the end is not enough to be *completed*: a run whose experiment
window (``t_s ≥ 0``) held no tracking tick — every tick hovering on a supervisor limit, say —
or a ``follow`` run that never saw its target flew nothing of the experiment. Those get their
own verdict (:data:`NO_TRACKING`, :data:`NO_TARGET`): ``simulate`` and ``fly`` exit 1 on them,
a sweep case or a tune trial is ``failed`` (docs/design.md §5).

A tracking tick is one flown by a controller towards the reference: mode ``track`` (the NMPC)
or ``fallback-*`` (the P controller). :class:`VerdictTally` counts them row by row as a runner
writes its log, so the verdict needs no second pass over the log.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

__all__ = ["COMPLETED", "FAILED_VERDICTS", "NO_TARGET", "NO_TRACKING", "VerdictTally",
           "is_tracking", "verdict_message"]

COMPLETED = "completed"
#: The experiment window held no tracking tick.
NO_TRACKING = "failed-no-tracking"
#: A ``follow`` run never saw the object it follows.
NO_TARGET = "failed-no-target"
#: Verdicts of a run that reached its end without doing its job.
FAILED_VERDICTS = frozenset({NO_TRACKING, NO_TARGET})

_MESSAGES = {
    NO_TRACKING: "no tick of the experiment window was flown by the controller (every one "
                 "held, hovered or landed on a supervisor limit: see the mode column and "
                 "events.jsonl) — the flight did not do its job",
    NO_TARGET: "the followed object was never seen (reference.kind follow: check its mocap "
               "name and that it is in the volume) — the flight did not do its job",
}


def is_tracking(mode: str) -> bool:
    """Whether a tick of this mode label was flown by a controller towards the reference."""
    return mode == "track" or mode.startswith("fallback")


def verdict_message(verdict: str) -> str:
    """The one-line explanation of a failed verdict (empty for any other)."""
    return _MESSAGES.get(verdict, "")


class VerdictTally:
    """Counts, row by row, what the verdict needs; ``follow``: the run follows an object."""

    def __init__(self, *, follow: bool) -> None:
        self.follow = follow
        self.tracking_ticks = 0
        self.target_seen = False
        self._mode: str | None = None  # the last mode add_tick judged, and its judgement
        self._tracking = False

    def add(self, row: Mapping[str, Any]) -> None:
        """One logged tick (``t_s``, ``mode``, and ``target_age_ms`` when it saw the target)."""
        self.add_tick(row["t_s"], str(row["mode"]))
        age = row.get("target_age_ms", math.nan)
        if math.isfinite(age):
            self.target_seen = True

    def add_tick(self, t_s: float, mode: str) -> None:
        """:meth:`add` of a row without ``target_age_ms`` given as its ``t_s`` and ``mode``
        (the lockstep runner's usual NMPC tick: no dict built for it). A mode is judged
        when it is not the last one's object (tick after tick the same label: no call)."""
        if t_s >= 0:
            if mode is not self._mode:
                self._mode, self._tracking = mode, is_tracking(mode)
            if self._tracking:
                self.tracking_ticks += 1

    def add_ticks(self, times_s: list[float], mode: str) -> None:
        """:meth:`add_tick` of ticks at ``times_s``, all of ``mode`` (a block of ticks)."""
        counted = sum(t_s >= 0 for t_s in times_s)
        if counted:
            if mode is not self._mode:
                self._mode, self._tracking = mode, is_tracking(mode)
            if self._tracking:
                self.tracking_ticks += counted

    def verdict(self, ending: str) -> str:
        """``ending`` unless it is :data:`COMPLETED` and the run did not do its job."""
        if ending != COMPLETED:
            return ending
        if self.follow and not self.target_seen:
            return NO_TARGET
        if self.tracking_ticks == 0:
            return NO_TRACKING
        return ending
