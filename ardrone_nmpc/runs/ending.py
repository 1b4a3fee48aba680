"""How a run directory's recording ended, read from its events: the one answer every reader
(``summary``, ``replay``, ``export``, ``plot``) prints, so a run cut short never passes for a
finished one.

* ``interrupted`` — Ctrl-C or a terminating signal stopped the recording:
  ``{"t_s": <last logged tick>, "kind": "interrupted", "signal": "SIGINT", "wall_time": …}``,
  written before the process exits (:func:`note_interrupted`);
* ``exception`` — the flight raised (``error``: its one line);
* a ``landing`` whose ``reason`` is a signal — a real flight landed because of it;
* none of these and no ``summary.csv`` — the process was killed (SIGKILL, power) or is still
  writing.
"""

from __future__ import annotations

import datetime as _dt
import math
from collections.abc import Mapping, Sequence
from typing import Any

__all__ = ["FAILED_EVENT", "INTERRUPTED_EVENT", "ending_note", "note_interrupted"]

#: The event that ends the events of a flight that raised (``error``: the exception, one line).
FAILED_EVENT = "exception"
#: The event a recording stopped by Ctrl-C or a signal ends with.
INTERRUPTED_EVENT = "interrupted"


def note_interrupted(recorder, interrupt: BaseException) -> None:
    """Write the :data:`INTERRUPTED_EVENT` of ``interrupt`` (a ``KeyboardInterrupt``: Ctrl-C,
    or :class:`~ardrone_nmpc.runtime.signals.Terminated`) into ``recorder``, stamped with the
    time of the last tick it logged; never raises (the interrupt is what must go on)."""
    import signal

    signum = getattr(interrupt, "signum", int(signal.SIGINT))
    try:
        recorder.event(getattr(recorder, "last_t_s", math.nan), INTERRUPTED_EVENT,
                       signal=signal.Signals(signum).name,
                       wall_time=_dt.datetime.now().astimezone().isoformat(timespec="seconds"))
    except Exception:  # noqa: BLE001 - a full disk must not hide the interrupt
        pass


def _when(event: Mapping[str, Any]) -> str:
    t = event.get("t_s")
    return f"t = {t:.2f} s" if isinstance(t, (int, float)) and math.isfinite(t) else \
        "take-off (no tick logged)"


def ending_note(events: Sequence[Mapping[str, Any]], *, summarised: bool) -> str | None:
    """One line saying how an unfinished recording ended, or None for one that finished.
    ``summarised``: the run directory holds ``summary.csv``."""
    for event in reversed(events):
        kind = event.get("kind")
        if kind == INTERRUPTED_EVENT:
            return (f"interrupted at {_when(event)} ({event.get('signal', 'SIGINT')}): the "
                    "run stops there")
        if kind == FAILED_EVENT:
            return f"failed: {event.get('error', '')}".rstrip(": ")
        if kind == "landing" and str(event.get("reason", "")).startswith("SIG"):
            return f"landed on {event['reason']} at {_when(event)}: the experiment stops there"
    if not summarised:
        return ("unfinished: no summary.csv and no end event (the process was killed, or is "
                "still running)")
    return None
