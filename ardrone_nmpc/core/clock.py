"""Absolute-deadline loop timing: no drift, lateness measured, overruns counted."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Callable


@dataclass
class Rate:
    """Wake every ``period_s`` on absolute deadlines ``t0 + k·period_s``.

    :meth:`sleep` returns the lateness of the wake-up (s). Every deadline that passes while the
    tick is still running is an *overrun*: it is counted and skipped (no burst of catch-up
    ticks); the loop waits for the next future deadline. :attr:`index` is the number of the
    deadline the last :meth:`sleep` woke for (0, 1, 2, … with gaps after overruns), so loop
    time derived from it stays wall time.
    """

    period_s: float
    clock: Callable[[], float] = time.monotonic
    sleep_fn: Callable[[float], None] = time.sleep
    overruns: int = 0
    lateness_s: list = field(default_factory=list)

    def __post_init__(self):
        if not (self.period_s > 0 and math.isfinite(self.period_s)):
            raise ValueError(f"period_s: must be positive, got {self.period_s}")
        self._next = self.clock() + self.period_s
        self._k = 0  # index of the deadline self._next
        self.index = -1  # index of the deadline the last sleep() woke for

    @property
    def next_deadline_s(self) -> float:
        return self._next

    def sleep(self) -> float:
        """Sleep until the next deadline; return how late the wake-up was (s, ≥ 0)."""
        now = self.clock()
        if now > self._next:  # the tick ran past its deadline(s): skip and count them
            missed = math.floor((now - self._next) / self.period_s) + 1
            self.overruns += missed
            self._next += missed * self.period_s
            self._k += missed
        remaining = self._next - now
        if remaining > 0:
            self.sleep_fn(remaining)
        woke = self.clock()
        late = max(0.0, woke - self._next)
        self.lateness_s.append(late)
        self.index = self._k
        self._k += 1
        self._next += self.period_s
        return late

    def jitter_ms(self) -> dict:
        """p50 / p99 / max of the wake-up lateness (ms) so far."""
        if not self.lateness_s:
            return {"p50": math.nan, "p99": math.nan, "max": math.nan}
        ordered = sorted(self.lateness_s)
        pick = lambda q: ordered[min(len(ordered) - 1, int(q * (len(ordered) - 1) + 0.5))]
        return {"p50": pick(0.5) * 1e3, "p99": pick(0.99) * 1e3, "max": ordered[-1] * 1e3}
