"""The experiment schedule every runner follows: take off, settle, track, land.

One definition for the lockstep simulation, the real-time flight and ``replay --rerun``: how
many whole ticks of ``loop.period_s`` the settle phase and the experiment take, the
experiment time of tick k (0 = the start of the experiment; the settle phase is t < 0), the
phase label a tick is stepped with, the take-off and landing timeouts, and how events are
stamped into ``events.jsonl`` — on the experiment clock in every runner (:class:`EventClock`
for the real-time one).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from typing import Any

from ardrone_nmpc.core.modes import SETTLE, TRACK

#: Take-off must show the drone flying (navdata, or the simulated plant) within this (s).
TAKEOFF_TIMEOUT_S = 10.0
#: The simulated landing must show the drone on the ground within this (s); a real landing
#: has no timeout while navdata flows (the session lands until navdata confirms it).
LANDING_TIMEOUT_S = 15.0
#: A real landing without a single navdata packet: how long REF land is held before the
#: session stops waiting for a confirmation it cannot get (s; a landing from the 3 m default
#: ceiling takes about 5 s).
BLIND_LANDING_S = 10.0

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

    On a manual clock (lockstep, rerun) ``write`` is the recorder's ``event``; on the wall
    clock :meth:`EventClock.at`: ``t_s`` is the experiment time either way.
    """
    for event in events:
        fields = dict(event)
        write(t_exp_s, fields.pop("kind"), **fields)


class EventClock:
    """The stamps of a real-time run's events (docs/design.md §5): ``t_s`` on the experiment
    clock — as the log's rows, and as every lockstep run's events — and ``wall_s``, the
    run's own monotonic time since the clock was made.

    Events before experiment time 0 is known (connecting, configuring, pre-flight, take-off)
    are held until :meth:`start` stamps them, with negative ``t_s``; if it never comes (a
    refused take-off), :meth:`close` writes them with ``t_s`` NaN. Held events are in memory
    only: a SIGKILL before the experiment starts loses them (every other exit writes them).

    Parameters
    ----------
    write : ``write(t_s, kind, **fields)`` — the recorder's ``event``.
    clock : the monotonic clock the loop runs on (s).
    """

    def __init__(self, write: EventWriter, clock: Callable[[], float]) -> None:
        self._write = write
        self._clock = clock
        self._wall0_s = clock()
        self._t0_s: float | None = None
        self._held: list[tuple[float, str, dict]] = []

    def event(self, kind: str, **fields: Any) -> None:
        """An event that happens now."""
        now = self._clock()
        if self._t0_s is None:
            self._held.append((now, kind, fields))
        else:
            self._write(now - self._t0_s, kind, wall_s=now - self._wall0_s, **fields)

    def at(self, t_exp_s: float, kind: str, **fields: Any) -> None:
        """An event of experiment time ``t_exp_s`` (a tick's), written now."""
        self._write(t_exp_s, kind, wall_s=self._clock() - self._wall0_s, **fields)

    def start(self, t0_s: float) -> None:
        """Experiment time 0 is ``t0_s`` on the clock: the held events are written."""
        self._t0_s = t0_s
        self._flush(t0_s)

    def close(self) -> None:
        """Write what is still held (no experiment time: ``t_s`` NaN)."""
        self._flush(None)

    def _flush(self, t0_s: float | None) -> None:
        held, self._held = self._held, []
        for now, kind, fields in held:
            t_s = math.nan if t0_s is None else now - t0_s
            self._write(t_s, kind, wall_s=now - self._wall0_s, **fields)
