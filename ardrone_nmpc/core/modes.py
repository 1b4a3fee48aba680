"""The grammar of the log's ``mode`` column: one parser for every reader of a run.

A tick's mode label is one of

* ``settle`` / ``track`` — the runner's nominal labels (before / from experiment time 0);
* ``<action>-<reason>`` — the supervisor stepped in (``safety.py``): ``hold``, ``fallback``,
  ``hover``, ``land`` or ``stop``, and why (``hold-stale-mocap``, ``land-geofence``,
  ``stop-emergency``, …); a bare ``<action>`` has no reason;
* ``landing``, ``landed``, ``taking_off`` — the drone on its way down, on the ground, on its
  way up (the runner's label for its descent after a landing decision is ``landing``);
* ``""`` — no label (a row written before any tick).

:class:`Mode` parses a label once; summaries, sweep status, the fault matrix, tune's
objective, replay and the figures ask it rather than matching strings.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

__all__ = ["GROUND_MODES", "LANDING", "Mode", "NOMINAL_MODES", "SETTLE", "SUPERVISOR_ACTIONS",
           "TRACK"]

SETTLE = "settle"
TRACK = "track"
#: The runner's label for the ticks of its descent after a landing decision.
LANDING = "landing"
#: Modes in which the drone is not under the experiment's control.
GROUND_MODES = frozenset({"landed", "taking_off", LANDING})
#: The supervisor's actions, in the order of the summary's ``supervisor`` rows.
SUPERVISOR_ACTIONS = ("hold", "fallback", "hover", "land", "stop")
#: The runner's own labels: the controller flies the experiment (no intervention).
NOMINAL_MODES = (TRACK, SETTLE)
_NOMINAL = frozenset(NOMINAL_MODES)
_AIRBORNE_ACTIONS = frozenset({"hold", "fallback", "hover"})
_ABORTING_ACTIONS = frozenset({"land", "stop"})


@dataclass(frozen=True)
class Mode:
    """A parsed mode label: ``action`` (``track``, ``hover``, ``landing``, …) and ``reason``
    (the part after the first ``-``; empty for the runner's labels)."""

    action: str
    reason: str = ""

    @staticmethod
    @lru_cache(maxsize=256)
    def parse(label: object) -> Mode:
        """The mode of a log cell (anything that is not a string — NaN, None — is ``""``)."""
        text = label if isinstance(label, str) else ""
        if text in _NOMINAL or text in GROUND_MODES or "-" not in text:
            return Mode(text)
        action, reason = text.split("-", 1)
        return Mode(action, reason)

    @property
    def label(self) -> str:
        """The label as the log writes it."""
        return f"{self.action}-{self.reason}" if self.reason else self.action

    @property
    def is_set(self) -> bool:
        return bool(self.action)

    @property
    def is_nominal(self) -> bool:
        """No intervention: settling, tracking, or no label at all."""
        return self.action in _NOMINAL or not self.action

    @property
    def is_tracking(self) -> bool:
        return self.action == TRACK

    @property
    def is_fallback(self) -> bool:
        """A labelled tick that is not tracking the experiment (what the summary counts as
        ``loop / fallbacks`` inside the experiment window)."""
        return self.is_set and not self.is_tracking

    @property
    def is_ground(self) -> bool:
        """Taking off, landing or landed: not under the experiment's control."""
        return self.action in GROUND_MODES

    @property
    def is_landing(self) -> bool:
        """The supervisor's landing decision or the descent after it."""
        return self.action in ("land", LANDING)

    @property
    def is_airborne(self) -> bool:
        """In the air and commanded: nominal, or held, falling back, hovering."""
        return self.action in _NOMINAL or self.action in _AIRBORNE_ACTIONS

    @property
    def is_abort(self) -> bool:
        """The experiment was given up: a landing or stop decision, the drone on (or on its
        way to) the ground, or any label naming an emergency."""
        return self.action in _ABORTING_ACTIONS or self.is_ground or "emergency" in self.label

    @property
    def is_emergency_stop(self) -> bool:
        return self.action == "stop" and self.reason == "emergency"
