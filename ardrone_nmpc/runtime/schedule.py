"""The experiment schedule every runner follows: take off, settle, track, land.

One definition for the lockstep simulation, the real-time flight and ``replay --rerun``: how
many whole ticks of ``loop.period_s`` the settle phase and the experiment take, the
experiment time of tick k (0 = the start of the experiment; the settle phase is t < 0), the
phase label a tick is stepped with, the take-off and landing timeouts, and how events that
happen at an experiment time are stamped into ``events.jsonl``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from typing import Any

#: Take-off must show the drone flying (navdata, or the simulated plant) within this (s).
TAKEOFF_TIMEOUT_S = 10.0
#: The simulated landing must show the drone on the ground within this (s); a real landing
#: has no timeout while navdata flows (the session lands until navdata confirms it).
LANDING_TIMEOUT_S = 15.0
#: A real landing without a single navdata packet: how long REF land is held before the
#: session stops waiting for a confirmation it cannot get (s; a landing from the 3 m default
#: ceiling takes about 5 s).
BLIND_LANDING_S = 10.0

SETTLE = "settle"
TRACK = "track"

#: Largest tick count a schedule takes: tick times ``k · period`` stay exact doubles.
MAX_TICKS = 2 ** 53

#: ``write(t_exp_s, kind, **fields)``: where a runner's experiment-time events go.
EventWriter = Callable[..., None]


class ScheduleError(ValueError):
    """Times that give no tick count (not finite, negative, or too many ticks): one line."""


def phase(t_exp_s: float) -> str:
    """The mode a tick at experiment time ``t_exp_s`` is stepped with: ``settle`` before the
    experiment starts (t < 0), ``track`` from t = 0."""
    return SETTLE if t_exp_s < 0 else TRACK


def _ticks(name: str, value_s: float, period_s: float, count: Callable[[float], int]) -> int:
    """``count(value_s / period_s)``, refused unless finite, ≥ 0 and at most MAX_TICKS."""
    if not (math.isfinite(value_s) and value_s >= 0):
        raise ScheduleError(f"{name} = {value_s!r}: must be a finite number of seconds ≥ 0")
    ratio = value_s / period_s
    if not ratio < MAX_TICKS:
        raise ScheduleError(f"{name} = {value_s:g} s: more ticks of loop.period_s = "
                            f"{period_s:g} s than a run can count ({MAX_TICKS:.3g})")
    return count(ratio)


@dataclass(frozen=True)
class Schedule:
    """The ticks of one run: ``n_settle`` ticks of settling, then the experiment.

    Tick k (0-based, from the first tick after take-off) runs at experiment time
    :meth:`t_exp_s` ``(k) = (k − n_settle) · period_s``; the run is ``n_ticks`` ticks long,
    the last one at t = ``duration_s`` rounded to a whole tick.
    """

    period_s: float
    n_settle: int
    n_ticks: int

    @classmethod
    def of(cls, *, settle_s: float, duration_s: float, period_s: float) -> Schedule:
        """The schedule of a settle phase of at least ``settle_s`` (whole ticks, rounded up)
        and an experiment of ``duration_s`` (rounded to whole ticks), ticking every
        ``period_s``. Raises :class:`ScheduleError` for times that give no tick count."""
        if not (math.isfinite(period_s) and period_s > 0):
            raise ScheduleError(f"loop.period_s = {period_s!r}: must be a finite number of "
                                f"seconds > 0")
        n_settle = _ticks("sim.settle_s", settle_s, period_s,
                          lambda r: math.ceil(r - 1e-9))  # 0.3 / 0.1 = 3.0000000000000004: 3 ticks
        n_track = _ticks("duration_s", duration_s, period_s, lambda r: int(round(r)))
        n_ticks = n_settle + n_track + 1  # + the tick at t = duration_s
        if n_ticks > MAX_TICKS:
            raise ScheduleError(f"sim.settle_s + duration_s = {settle_s + duration_s:g} s: "
                                f"more ticks of loop.period_s = {period_s:g} s than a run "
                                f"can count ({MAX_TICKS:.3g})")
        return cls(period_s, n_settle, n_ticks)

    @classmethod
    def from_config(cls, cfg) -> Schedule:
        """The schedule of an experiment config (``sim.settle_s``, ``duration_s``,
        ``loop.period_s``)."""
        return cls.of(settle_s=cfg.sim.settle_s, duration_s=cfg.duration_s,
                      period_s=cfg.loop.period_s)

    @property
    def settle_span_s(self) -> float:
        """How long the settle phase lasts: from the first tick to experiment time 0 (s)."""
        return self.n_settle * self.period_s

    def t_exp_s(self, k: int) -> float:
        """Experiment time of tick ``k`` (s; negative while settling)."""
        return (k - self.n_settle) * self.period_s

    def fraction_done(self, k: int) -> float:
        """The fraction of the run done once tick ``k`` has run."""
        return (k + 1) / self.n_ticks


def write_events(write: EventWriter, t_exp_s: float,
                 events: Iterable[Mapping[str, Any]]) -> None:
    """Write ``events`` (dicts with a ``kind``: a tick's mode changes, injected faults) that
    happened at experiment time ``t_exp_s`` through ``write(t_exp_s, kind, **fields)``.

    On a manual clock (lockstep, rerun) ``write`` is the recorder's ``event``: ``t_s`` is
    the experiment time. On the wall clock use :func:`on_wall_clock`.
    """
    for event in events:
        fields = dict(event)
        write(t_exp_s, fields.pop("kind"), **fields)


def on_wall_clock(event: Callable[..., None]) -> EventWriter:
    """The writer of a run on the wall clock, whose ``event(kind, **fields)`` stamps
    ``t_s`` with the wall time (the real-time flight: its session events come before
    experiment time 0 exists): the experiment time goes into the field ``t_exp_s``."""
    return lambda t_exp_s, kind, **fields: event(kind, t_exp_s=t_exp_s, **fields)
