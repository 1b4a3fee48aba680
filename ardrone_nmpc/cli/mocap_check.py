"""``ardrone-nmpc mocap-check CONFIG``: is the motion capture ready to fly? (docs/mocap-sources.md)

Connects to the configured source (``mocap.kind``), shows a live table of the tracked objects
(pose, fresh-pose rate, age, missing/zero/frozen frames) and guides the hand-carry axis test:
carry the drone ≥ 10 cm along +x (forward), +y (left), +z (up) and turn it ≥ 20°
counter-clockwise; each shows ✔ when the measured sign is right, ✘ when only the opposite
sign was seen (a mirrored or swapped axis, a wrong ``mocap.up_axis``). It ends with one line
per tracked object: ``<name>: x=<m> y=<m> z=<m> psi=<rad> rate=<Hz>`` (3 decimals), the
stream's quality (:func:`quality_line`: missing, zero and frozen frames of the controlled
object, the largest age a reader saw and the largest gap between fresh poses) and the axis
test; ``--json`` prints all of it as one JSON object instead.
"""

from __future__ import annotations

import json
import math
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import List, Optional

import typer

__all__ = ["AxisTest", "CheckResult", "register", "run_check", "final_line", "quality_line",
           "result_json"]

AXIS_STEP_M = 0.10      # a hand-carried move the test counts
YAW_STEP_RAD = 0.35     # ≈ 20°
_SAMPLE_S = 0.05        # how often the check reads the source (it never blocks on it)
_AXES = ("+x", "+y", "+z", "yaw CCW")


def _num(v: float) -> str:
    """3 decimals, never ``-0.000``."""
    s = f"{v:.3f}"
    return "0.000" if s == "-0.000" else s


@dataclass
class AxisTest:
    """The hand-carry test: each axis ✔ once a move of the right sign was seen (✘: only the
    wrong one). A translation counts when it is ≥ 10 cm and the largest of the three."""

    origin_m: tuple[float, float, float] | None = None
    origin_psi_rad: float = 0.0
    seen: dict[str, set[int]] = field(default_factory=lambda: {a: set() for a in _AXES})

    def update(self, position_m, psi_rad: float) -> None:
        p = tuple(float(v) for v in position_m)
        if self.origin_m is None:
            self.origin_m, self.origin_psi_rad = p, float(psi_rad)
            return
        d = [p[i] - self.origin_m[i] for i in range(3)]
        i = max(range(3), key=lambda k: abs(d[k]))
        if abs(d[i]) >= AXIS_STEP_M:
            self.seen[_AXES[i]].add(1 if d[i] > 0 else -1)
        from ardrone_nmpc.core.angles import wrap_angle_rad  # numpy: not at --help time

        dpsi = wrap_angle_rad(float(psi_rad) - self.origin_psi_rad)
        if abs(dpsi) >= YAW_STEP_RAD:
            self.seen["yaw CCW"].add(1 if dpsi > 0 else -1)

    def mark(self, axis: str) -> str:
        signs = self.seen[axis]
        return "✔" if 1 in signs else ("✘" if -1 in signs else "·")

    def line(self) -> str:
        return "axis test: " + "  ".join(f"{a} {self.mark(a)}" for a in _AXES)


@dataclass
class _Track:
    """What the check saw of one object."""

    name: str
    pose: object = None
    rx_t_s: float = -math.inf
    count0: int | None = None
    t0_s: float = math.nan
    count: int = 0
    t_s: float = math.nan
    window: list = field(default_factory=list)   # (t, count) of the last second
    max_age_s: float = math.nan    # the oldest the newest pose was at a sample, once seen

    def sample(self, source, now_s: float, main: bool) -> None:
        self.pose, self.rx_t_s = source.latest() if main else source.latest_of(self.name)
        self.count, self.t_s = source.fresh_count(self.name), now_s
        if self.pose is not None:
            age = now_s - self.rx_t_s
            self.max_age_s = age if math.isnan(self.max_age_s) else max(self.max_age_s, age)
        if self.count0 is None:
            self.count0, self.t0_s = self.count, now_s
        self.window.append((now_s, self.count))
        while self.window and self.window[0][0] < now_s - 1.0:
            self.window.pop(0)

    def rate_hz(self) -> float:
        """Fresh poses per second over the whole check."""
        span = self.t_s - self.t0_s
        return (self.count - self.count0) / span if span > 0 else 0.0

    def recent_rate_hz(self) -> float:
        (t0, c0), (t1, c1) = self.window[0], self.window[-1]
        return (c1 - c0) / (t1 - t0) if t1 > t0 else 0.0


@dataclass
class CheckResult:
    tracks: list[_Track]
    axes: AxisTest
    where: str
    names_seen: tuple[str, ...]
    missing: int = 0      # frames without the controlled object
    zero: int = 0         # frames with it all-zero or non-finite
    frozen: int = 0       # frames ignored as bit-identical repeats
    max_gap_s: float = 0.0  # the longest time between two fresh poses of it

    def read_counts(self, source) -> None:
        self.names_seen = source.names_seen
        self.missing, self.zero, self.frozen = (source.missing, source.zero_poses,
                                                source.repeats)
        self.max_gap_s = source.max_gap_s


def final_line(track: _Track) -> str:
    """``<name>: x=… y=… z=… psi=… rate=…`` of one object (``<name>: not seen``)."""
    p = track.pose
    if p is None:
        return f"{track.name}: not seen"
    x, y, z = (float(v) for v in p.position_m)
    return (f"{track.name}: x={_num(x)} y={_num(y)} z={_num(z)} psi={_num(p.psi_rad)} "
            f"rate={_num(track.rate_hz())}")


def _ms(seconds: float) -> str:
    return "—" if not math.isfinite(seconds) else f"{seconds * 1e3:.0f}"


def quality_line(result: CheckResult) -> str:
    """``stream: missing=… zero=… frozen=… max_age_ms=… max_gap_ms=…`` of the controlled
    object (``—``: no pose, or only one)."""
    main = result.tracks[0]
    gap = result.max_gap_s if result.max_gap_s > 0 else math.nan
    return (f"stream: missing={result.missing} zero={result.zero} frozen={result.frozen} "
            f"max_age_ms={_ms(main.max_age_s)} max_gap_ms={_ms(gap)}")


def _finite(v: float) -> float | None:
    return float(v) if math.isfinite(v) else None


def result_json(result: CheckResult, seconds: float) -> dict:
    """The check as JSON: every object's pose, rate and largest age; the stream's counts;
    the axis test (``ok``, ``wrong sign``, ``not done``). Units in the names; null where
    there is no value."""
    objects = []
    for tr in result.tracks:
        p = tr.pose
        pose = {} if p is None else {
            "x_m": float(p.position_m[0]), "y_m": float(p.position_m[1]),
            "z_m": float(p.position_m[2]), "psi_rad": float(p.psi_rad)}
        objects.append({"name": tr.name, "seen": p is not None, **pose,
                        "rate_hz": tr.rate_hz(), "fresh_poses": tr.count - (tr.count0 or 0),
                        "max_age_ms": _finite(tr.max_age_s * 1e3)})
    marks = {"✔": "ok", "✘": "wrong sign", "·": "not done"}
    return {"source": result.where, "seconds": seconds, "objects": objects,
            "stream_objects": list(result.names_seen),
            "missing_frames": result.missing, "zero_frames": result.zero,
            "frozen_frames": result.frozen,
            "max_gap_ms": _finite(result.max_gap_s * 1e3) if result.max_gap_s > 0 else None,
            "axis_test": {a: marks[result.axes.mark(a)] for a in _AXES}}


def _table(result: CheckResult, source, now_s: float, seconds_left: float):
    from rich.table import Table

    table = Table(title=f"mocap {result.where} — {seconds_left:.0f} s left (Ctrl-C ends)",
                  caption=f"stream objects: {', '.join(result.names_seen) or '(none)'};  "
                          f"{result.axes.line()}")
    for col in ("object", "x m", "y m", "z m", "ψ rad", "rate Hz", "age ms",
                "missing/zero/frozen"):
        table.add_column(col, justify="left" if col == "object" else "right")
    for k, tr in enumerate(result.tracks):
        p = tr.pose
        pos = ["—"] * 4 if p is None else \
            [_num(float(v)) for v in p.position_m] + [_num(p.psi_rad)]
        age = (now_s - tr.rx_t_s) * 1e3
        counts = f"{source.missing}/{source.zero_poses}/{source.repeats}" if k == 0 else ""
        table.add_row(tr.name, *pos, f"{tr.recent_rate_hz():.1f}",
                      "never" if not math.isfinite(age) else f"{age:.0f}", counts)
    return table


def run_check(source, names: list[str], seconds: float, *, live=None,
              clock=time.monotonic) -> CheckResult:
    """Sample the started ``source`` for ``seconds``; ``live(renderable)`` shows the table."""
    tracks = [_Track(n) for n in names]
    result = CheckResult(tracks, AxisTest(), source.where, ())
    t_end = clock() + seconds
    try:
        while True:
            now = clock()
            for k, tr in enumerate(tracks):
                tr.sample(source, now, main=k == 0)
            result.read_counts(source)
            if tracks[0].pose is not None:
                result.axes.update(tracks[0].pose.position_m, tracks[0].pose.psi_rad)
            if live is not None:
                live(_table(result, source, now, max(t_end - now, 0.0)))
            if now >= t_end:
                return result
            time.sleep(min(_SAMPLE_S, max(t_end - now, 0.0)))
    except KeyboardInterrupt:
        return result


def register(app: typer.Typer) -> None:
    """Add the ``mocap-check`` command to ``app``."""

    @app.command("mocap-check")
    def mocap_check(
        config: Path = typer.Argument(..., help="Experiment YAML file (its mocap section)."),
        seconds: float = typer.Option(10.0, "--seconds", min=0.1, max=3600.0, help="How long to watch (s)."),
        set_: List[str] = typer.Option([], "--set", help="Override a config value before validation: dotted.path=value (repeatable)."),
        live: Optional[bool] = typer.Option(None, "--live/--no-live", help="Live table and axis test (default: on a terminal)."),
        as_json: bool = typer.Option(False, "--json", help="Print the result as one JSON object (poses, rates, ages, the stream's counts, the axis test) instead of lines."),
    ) -> None:
        """Check the motion capture before a flight: a live table of the tracked objects (rate,
        age, occlusion), the hand-carry axis test (+x, +y, +z, yaw CCW → ✔), and one final line
        per object: <name>: x=<m> y=<m> z=<m> psi=<rad> rate=<Hz>, then the stream's counts
        (stream: missing= zero= frozen= max_age_ms= max_gap_ms=) and the axis test; --json
        for all of it as JSON."""
        from ardrone_nmpc.config.schema import ConfigError, tracked_object
        from ardrone_nmpc.config.io import load_config
        from ardrone_nmpc.links.mocap_factory import open_mocap_source

        try:
            cfg = load_config(config, set_)
        except ConfigError as err:
            for line in err.messages:
                typer.echo(f"error: {line}", err=True)
            raise typer.Exit(code=1)
        names = [cfg.mocap.object_name]
        second = tracked_object(cfg)
        if second and second not in names:
            names.append(second)
        show = sys.stderr.isatty() if live is None else live
        try:
            with open_mocap_source(cfg.mocap, other_objects=tuple(names[1:])) as source:
                result = _watch(source, names, seconds, show)
        except (RuntimeError, OSError, ValueError) as err:  # connect, missing extra, bind
            typer.echo(f"error: {err}", err=True)
            raise typer.Exit(code=1)
        if as_json:
            typer.echo(json.dumps(result_json(result, seconds), allow_nan=False))
        else:
            for tr in result.tracks:
                typer.echo(final_line(tr))
            typer.echo(quality_line(result))
            typer.echo(result.axes.line())
        if result.tracks[0].pose is None:
            seen = ", ".join(result.names_seen) or "no objects"
            typer.echo(f"error: object {names[0]!r} not seen from {result.where} in "
                       f"{seconds:g} s (stream: {seen})", err=True)
            raise typer.Exit(code=1)


def _watch(source, names: list[str], seconds: float, show: bool) -> CheckResult:
    if not show:
        return run_check(source, names, seconds)
    from rich.console import Console
    from rich.live import Live

    with Live(console=Console(stderr=True), refresh_per_second=8, transient=True) as view:
        return run_check(source, names, seconds, live=view.update)
