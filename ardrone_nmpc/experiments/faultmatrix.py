"""The fault matrix (``ardrone-nmpc faults``): each injected fault against each experiment kind,
in lockstep simulation, with the outcome the supervisor reached and whether the log survived.

Per case: a normal run directory (``<log_dir>/<case>/…``), then

* ``outcome`` — ``completed`` (flew to the end, tracking again), ``hovered`` (ended hovering
  by policy), ``landed`` (the supervisor landed it; touch-down confirmed), ``stopped``
  (the drone itself cut its motors — the emergency fault; the tool stopped sending and
  reported — or reported a motor fault bit and the tool cut them), ``refused`` (the pre-flight
  check refused the take-off: the run directory holds its ``takeoff_refused`` event and no
  flight), ``crashed`` (the truth hit the ground outside a landing, or an emergency nobody
  injected), a failed verdict (``failed-no-tracking``, ``failed-no-target``: it reached its
  end without doing its job), ``exception`` (the tool raised otherwise);
* ``max_dev_m`` — the largest distance between the faulted flight's true position and the
  fault-free flight's (same seed, same tick), until a landing began;
* ``recover_s`` — for flights that went on: seconds from the fault's start until that
  distance fell below :data:`RECOVERED_M` for good (NaN if it never did; not applicable to
  landings);
* ``log_complete`` — config.yaml, log.csv without torn rows, one row per tick flown,
  events.jsonl whose flight ends in ``landed``/``stopped`` (then the recording's
  ``simulated``), summary.csv; for a refusal: config.yaml and events.jsonl with the refusal,
  no take-off and no row;
* ``nonfinite_cmds`` — rows whose PCMD fractions are not finite (must be 0).

A case *passes* when its outcome is the policy's (anything but ``crashed``/``exception``;
``refused`` only for the rows of :data:`REQUIRED_OUTCOME` that ask for it), the log is
complete and no non-finite command was sent.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from ardrone_nmpc.core.atomic import write_text_atomic
from ardrone_nmpc.core.modes import Mode

#: experiment kind → (config file, overrides)
EXPERIMENTS: dict[str, tuple[str, tuple[str, ...]]] = {
    "hover": ("hover.yaml", ("duration_s=12",)),
    "step": ("step_x.yaml", ("duration_s=12",)),
    "square": ("square.yaml", ()),
}

_T0 = "2.0"  # fault start (s, experiment time): inside the step's transient (step at 1 s)

#: fault case → ``--set`` overrides
FAULT_CASES: dict[str, tuple[str, ...]] = {
    "mocap_dropout_bursts": (f"faults.mocap_dropout.start_s={_T0}", "faults.mocap_dropout.duration_s=0.4",
                             "faults.mocap_dropout.repeat_every_s=3"),
    "mocap_lost": (f"faults.mocap_dropout.start_s={_T0}", "faults.mocap_dropout.duration_s=3"),
    "mocap_occlusion": (f"faults.mocap_occlusion.start_s={_T0}", "faults.mocap_occlusion.duration_s=0.5"),
    "mocap_latency_spike": (f"faults.mocap_latency.start_s={_T0}", "faults.mocap_latency.duration_s=1",
                            "faults.mocap_latency.extra_latency_ms=200"),
    "navdata_loss": (f"faults.navdata_loss.start_s={_T0}", "faults.navdata_loss.duration_s=1"),
    "navdata_bad_checksum": (f"faults.navdata_corrupt.start_s={_T0}", "faults.navdata_corrupt.duration_s=0.3",
                             "faults.navdata_corrupt.kind=checksum"),
    "navdata_truncated": (f"faults.navdata_corrupt.start_s={_T0}", "faults.navdata_corrupt.duration_s=0.3",
                          "faults.navdata_corrupt.kind=truncated"),
    "navdata_zero_option": (f"faults.navdata_corrupt.start_s={_T0}", "faults.navdata_corrupt.duration_s=0.3",
                            "faults.navdata_corrupt.kind=zero_option"),
    "mocap_dup_reorder": (f"faults.disorder.start_s={_T0}", "faults.disorder.duration_s=3",
                          "faults.disorder.stream=mocap"),
    "navdata_dup_reorder": (f"faults.disorder.start_s={_T0}", "faults.disorder.duration_s=3",
                            "faults.disorder.stream=navdata"),
    "at_loss": (f"faults.at_loss.start_s={_T0}", "faults.at_loss.duration_s=0.5"),
    "solver_diverge": (f"faults.solver_diverge.start_s={_T0}", "faults.solver_diverge.duration_s=1"),
    "battery_floor": (f"faults.battery_floor.start_s={_T0}",),
    "emergency": (f"faults.emergency.start_s={_T0}",),
    "wind_gust": (f"faults.wind_gust.start_s={_T0}", "faults.wind_gust.duration_s=1",
                  "faults.wind_gust.velocity_mps=[1.5,0,0]"),
    "wind_constant": ("faults.wind.velocity_mps=[0.5,0.3,0]",),
    "delay_jump": (f"faults.delay_jump.start_s={_T0}", "faults.delay_jump.delay_s=0.5"),
    # a drone that behaves like firmware (issue 17 item 6); required outcomes below
    "ctrl_codes_fw24": ("faults.ctrl_codes.codes=fw2.4",),
    "foreign_session": ("faults.foreign_session.session_id=d2e081a3",),
    "control_port_silent": ("faults.control_port_drop.mode=silent",),
    "self_land": (f"faults.self_land.start_s={_T0}",),
    # the drone's own alarms, its profiles and its link (issue 21)
    "cutout": (f"faults.drone_faults.start_s={_T0}", "faults.drone_faults.bits=[CUTOUT]"),
    "motors": (f"faults.drone_faults.start_s={_T0}", "faults.drone_faults.bits=[MOTORS]"),
    "software_fault": (f"faults.drone_faults.start_s={_T0}",
                       "faults.drone_faults.bits=[SOFTWARE_FAULT]"),
    "faults_at_power_on": ("faults.drone_faults.start_s=null",
                           "faults.drone_faults.bits=[MOTORS,SOFTWARE_FAULT,ULTRASOUND]"),
    "vbat_low_at_power_on": ("faults.drone_faults.start_s=null",
                             "faults.drone_faults.bits=[VBAT_LOW]"),
    "vbat_low_threshold": ("faults.vbat_low.threshold_pct=30",
                           f"faults.battery_floor.start_s={_T0}",
                           "faults.battery_floor.level_pct=25"),
    "blackout": (f"faults.blackout.start_s={_T0}", "faults.blackout.duration_s=3"),
    "session_ignores_config": ("faults.foreign_session.ignores_plain_config=true",),
    "outdoor_profile": ("faults.outdoor_profile.euler_angle_max_rad=0.35",),
}

#: Rows whose required outcome is narrower than "any policy outcome": the lockstep runner
#: refuses take-off when the read-back differs from what was written or cannot be read, and
#: ends the run without taking off again once the drone landed by itself (issue 17 items 1-2);
#: it refuses a drone that reports fault bits, lands on SOFTWARE_FAULT / VBAT_LOW in flight
#: and cuts on CUTOUT / MOTORS (issue 21).
REQUIRED_OUTCOME: dict[str, frozenset[str]] = {
    "ctrl_codes_fw24": frozenset({"completed"}),  # 7/9 instead of 6/8 must change nothing
    "foreign_session": frozenset({"refused"}),    # read back 0.52 / 2000 / 6.11: no take-off
    "control_port_silent": frozenset({"refused"}),  # nothing read back: no take-off
    "self_land": frozenset({"landed"}),   # stays down (zero take-offs after touch-down)
    "cutout": frozenset({"stopped"}),     # a motor fault bit in flight: the tool cuts
    "motors": frozenset({"stopped"}),
    "software_fault": frozenset({"landed"}),
    "faults_at_power_on": frozenset({"refused"}),   # naming the bits
    "vbat_low_at_power_on": frozenset({"refused"}),
    "vbat_low_threshold": frozenset({"landed"}),    # bit 15 at 25 %, above the 20 % floor
    "blackout": frozenset({"landed"}),
    "session_ignores_config": frozenset({"refused"}),  # no ACK without its ids: no take-off
    "outdoor_profile": frozenset({"completed"}),  # outdoor FALSE first, then the limits
}

RECOVERED_M = 0.10  # back "on track": within 10 cm of the fault-free flight
POLICY_OUTCOMES = frozenset({"completed", "hovered", "landed", "stopped"})


@dataclass
class CaseResult:
    experiment: str
    fault: str
    outcome: str
    ending: str
    max_dev_m: float
    recover_s: float
    log_complete: bool
    nonfinite_cmds: int
    passed: bool
    run_dir: str
    message: str = ""

    def as_dict(self) -> dict:
        return asdict(self)


def _positions(run, upto_landing: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """(t_s, (n, 3) true positions) of the rows before any landing began."""
    c = run.columns
    t = c["t_s"]
    keep = np.ones(len(t), dtype=bool)
    if upto_landing:
        keep = np.array([not Mode.parse(m).is_landing for m in c["mode"]], dtype=bool)
    p = np.column_stack([c["x_true_m"], c["y_true_m"], c["z_true_m"]])
    return t[keep], p[keep]


def deviation_from(run, baseline) -> tuple[np.ndarray, np.ndarray]:
    """(t_s, ‖p − p_baseline‖) on the ticks both runs flew (aligned by tick time)."""
    t, p = _positions(run)
    tb, pb = _positions(baseline, upto_landing=False)
    index = {round(v, 6): i for i, v in enumerate(tb)}
    rows = [(i, index[round(v, 6)]) for i, v in enumerate(t) if round(v, 6) in index]
    if not rows:
        return np.empty(0), np.empty(0)
    a, b = (np.array(x) for x in zip(*rows))
    return t[a], np.linalg.norm(p[a] - pb[b], axis=1)


def recovery_time_s(t: np.ndarray, dev: np.ndarray, t_fault_s: float) -> float:
    """Seconds from ``t_fault_s`` until ``dev`` stays below :data:`RECOVERED_M` (NaN: never)."""
    after = t >= t_fault_s
    if not np.any(after):
        return math.nan
    t, dev = t[after], dev[after]
    bad = np.nonzero(dev >= RECOVERED_M)[0]
    if len(bad) == 0:
        return 0.0
    if bad[-1] == len(dev) - 1:
        return math.nan
    return float(t[bad[-1] + 1] - t_fault_s)


def refused(run) -> bool:
    """The run directory holds a refused take-off: the refusal event, no take-off, no row."""
    from ardrone_nmpc.runtime.lockstep import REFUSED_EVENT

    kinds = {e.get("kind") for e in run.events}
    return REFUSED_EVENT in kinds and "takeoff" not in kinds and run.n_rows == 0


def classify(run, ending: str, fault: str) -> str:
    """The outcome label of a finished (or refused) run (see the module docstring)."""
    from ardrone_nmpc.runs.verdict import FAILED_VERDICTS

    if refused(run):
        return "refused"
    if ending in FAILED_VERDICTS:  # flown to its end without doing its job: no policy outcome
        return ending
    modes = [Mode.parse(m) for m in run.columns["mode"]]
    z = run.columns["z_true_m"]
    t = run.columns["t_s"]
    flying = np.array([m.is_airborne for m in modes], dtype=bool)
    if np.any(flying & (t >= 0) & (z <= 0.02)):
        return "crashed"
    end = Mode.parse(ending)
    if end.action == "stop":  # the drone's emergency, or a motor fault bit it was cut for
        return "stopped" if fault == "emergency" or not end.is_emergency_stop else "crashed"
    if end.action == "land" and end.reason:
        landed = any(e.get("kind") == "landed" for e in run.events)
        return "landed" if landed else "crashed"
    last = next((m for m in reversed(modes) if m.is_set), Mode(""))
    return "hovered" if last.action == "hover" else "completed"


def _shown(run_dir: Path) -> str:
    """A run directory as the report names it: relative to the working directory when inside
    it (the committed report names no machine's folders), else as given."""
    try:
        return str(Path(run_dir).resolve().relative_to(Path.cwd().resolve()))
    except ValueError:
        return str(run_dir)


def log_complete(run_dir: Path, ticks_expected: int) -> tuple[bool, str]:
    """Whether the run directory holds everything the log contract asks for: the flight's
    events end in ``landed``/``stopped`` (the recording's own ``simulated`` event aside)."""
    from ardrone_nmpc.experiments.record import SIMULATED_EVENT
    from ardrone_nmpc.runs.rundir import LogError, read_run

    for name in ("config.yaml", "events.jsonl"):
        if not (run_dir / name).is_file():
            return False, f"{name} missing"
    try:
        run = read_run(run_dir)
    except LogError as err:
        return False, str(err)
    if run.warnings:
        return False, "; ".join(run.warnings)
    if refused(run):   # nothing flew: nothing more to log (no rows, no summary)
        return True, ""
    for name in ("log.csv", "summary.csv"):
        if not (run_dir / name).is_file():
            return False, f"{name} missing"
    if run.n_rows < ticks_expected:
        return False, f"{run.n_rows} rows for {ticks_expected} ticks"
    flight = [e["kind"] for e in run.events if e["kind"] != SIMULATED_EVENT]
    last = flight[-1] if flight else ""
    if last not in ("landed", "stopped"):
        return False, f"events end with {last!r}"
    return True, ""


def _fault_start_s(cfg) -> float:
    from ardrone_nmpc.sim.faults import FaultSchedule

    starts = [w[1] for w in FaultSchedule(cfg.faults).windows()]
    return max(min(starts), 0.0) if starts else 0.0


def run_case(*, config_dir: Path, log_dir: Path, experiment: str, fault: str | None,
             seed: int) -> tuple[Path | None, str, int, str]:
    """Fly one case into ``log_dir``; ``(run_dir, ending, ticks_flown, error)``. An
    exception is a result of the matrix: ending ``exception``, its one line in ``error``."""
    from ardrone_nmpc.config.io import load_config
    from ardrone_nmpc.experiments.record import record_lockstep

    file, overrides = EXPERIMENTS[experiment]
    cfg = load_config(config_dir / file, [*overrides, *(FAULT_CASES[fault] if fault else ())])
    cfg = cfg.model_copy(update={"name": f"{experiment}-{fault or 'baseline'}"})
    recording = record_lockstep(cfg, log_dir, seed=seed, catch=True)
    if recording.result is None:
        return recording.path, "exception", 0, recording.error
    return recording.path, recording.result.ending, recording.result.ticks, ""


def evaluate(*, run_dir: Path, baseline_dir: Path, experiment: str, fault: str, ending: str,
             rows: int, error: str) -> CaseResult:
    from ardrone_nmpc.config.io import load_config
    from ardrone_nmpc.runs.rundir import read_run

    complete, why = log_complete(run_dir, rows)
    run = read_run(run_dir) if complete else None
    if error and run is not None and refused(run):
        required = REQUIRED_OUTCOME.get(fault, POLICY_OUTCOMES)
        return CaseResult(experiment, fault, "refused", "refused", math.nan, math.nan, complete,
                          0, "refused" in required, _shown(run_dir), error)
    if error:
        return CaseResult(experiment, fault, "exception", ending, math.nan, math.nan, complete,
                          0, False, _shown(run_dir), error)
    base = read_run(baseline_dir)
    outcome = classify(run, ending, fault)
    t, dev = deviation_from(run, base)
    t_fault = _fault_start_s(load_config(run_dir / "config.yaml"))
    window = t >= min(t_fault, 0.0)
    max_dev = float(np.max(dev[window])) if np.any(window) else math.nan
    recover = (recovery_time_s(t, dev, t_fault) if outcome in ("completed", "hovered")
               else math.nan)
    cmds = np.column_stack([run.columns[c] for c in ("cmd_roll_frac", "cmd_pitch_frac",
                                                     "cmd_gaz_frac", "cmd_yaw_frac")])
    nonfinite = int(np.sum(~np.all(np.isfinite(cmds), axis=1)))
    required = REQUIRED_OUTCOME.get(fault, POLICY_OUTCOMES)
    passed = outcome in required and complete and nonfinite == 0
    return CaseResult(experiment, fault, outcome, ending, max_dev, recover, complete, nonfinite,
                      passed, _shown(run_dir), why)


def _fly(case: tuple[str, str | None], **options) -> tuple[Path | None, str, int, str]:
    """:func:`run_case` of one ``(experiment, fault or None)`` (an executor's work item)."""
    return run_case(experiment=case[0], fault=case[1], **options)


def run_matrix(*, config_dir: Path, log_dir: Path, experiments: list[str], faults: list[str],
               seed: int = 0, progress: Callable[[str], None] | None = None,
               jobs: int = 1) -> list[CaseResult]:
    """Every fault × experiment (plus one fault-free baseline per experiment), flown on
    ``jobs`` workers (:mod:`ardrone_nmpc.experiments.parallel`) and evaluated in that order."""
    from ardrone_nmpc.experiments.parallel import open_executor

    cases = [(e, f) for e in experiments for f in (None, *faults)]
    results, baselines = [], {}
    with open_executor("local", jobs=max(1, min(jobs, len(cases)))) as executor:
        for done in executor.map(_fly, cases, config_dir=Path(config_dir).resolve(),
                                 log_dir=Path(log_dir).resolve(), seed=seed):
            experiment, fault = done.key
            if done.error is not None:
                raise done.error
            run_dir, ending, rows, error = done.value
            if progress:
                progress(f"{experiment} × {fault}" if fault else f"{experiment} baseline")
            if fault is None:
                if error or ending != "completed":
                    raise RuntimeError(f"the fault-free {experiment} run did not complete: "
                                       f"{error or ending}")
                baselines[experiment] = run_dir
                continue
            results.append(evaluate(run_dir=run_dir, baseline_dir=baselines[experiment],
                                    experiment=experiment, fault=fault, ending=ending,
                                    rows=rows, error=error))
    return results


# ----------------------------------------------------------------------------- reports
def _fmt(v: float, digits: int = 2) -> str:
    return "–" if not math.isfinite(v) else f"{v:.{digits}f}"


def render_table(results: list[CaseResult]):
    """A rich table, one row per case."""
    from rich.table import Table

    table = Table(title="fault matrix (lockstep simulation)")
    for name, justify in (("experiment", "left"), ("fault", "left"), ("outcome", "left"),
                          ("supervisor", "left"), ("max dev m", "right"),
                          ("recover s", "right"), ("log", "center"),
                          ("non-finite cmds", "right"), ("pass", "center")):
        table.add_column(name, justify=justify)
    for r in results:
        table.add_row(r.experiment, r.fault, r.outcome, r.ending, _fmt(r.max_dev_m),
                      _fmt(r.recover_s, 1), "ok" if r.log_complete else "INCOMPLETE",
                      str(r.nonfinite_cmds), "✔" if r.passed else "✘")
    return table


def render_markdown(results: list[CaseResult], *, command: str) -> str:
    """docs/fault-matrix.md."""
    n_pass = sum(r.passed for r in results)
    lines = [
        "# Fault matrix",
        "",
        f"Generated by `{command}` (lockstep simulation, seed 0). Each fault starts at "
        f"t = {_T0} s of the experiment (hover: 12 s; step: x step of −1.5 m at 1 s, 12 s; "
        "square: 25 s); `ardrone_nmpc/experiments/faultmatrix.py` lists the exact overrides.",
        "",
        "Outcome: `completed` (flew to the end), `hovered` (ended hovering by policy), "
        "`landed` (the supervisor landed it, touch-down confirmed), `stopped` (the drone cut "
        "its motors itself — the emergency fault; nothing more is sent — or reported a motor "
        "fault bit, CUTOUT or MOTORS, and the tool cut them), `refused` (the pre-flight check "
        "refused the take-off: the drone holds other limits, its configuration could not be "
        "read back or written, or it reports a fault bit; nothing took off), `crashed`, "
        "`failed-no-tracking` / `failed-no-target` (it reached its end without doing its "
        "job), `exception`. The drone's own alarms (`cutout`, `motors`, `software_fault`, "
        "`faults_at_power_on`, `vbat_low_*`), a Wi-Fi `blackout`, a session that ignores plain "
        "CONFIG and a drone last flown outdoors are rows of their own; what only a link shows "
        "— the bootstrap answer after a blackout, a second AT client — is tested against the "
        "loopback drone and the SDK stand-in (tests/integration). *Max dev*: largest distance "
        "between the faulted flight's true position "
        "and the fault-free flight's (same seed, same tick) until a landing began. *Recover*: "
        f"seconds from the fault's start until that distance stays below {RECOVERED_M:g} m "
        "(– for landings, or never). *Supervisor*: how the run ended (`completed`, or the "
        "latched `land-<reason>` / `stop-<reason>` mode).",
        "",
        f"**{n_pass} of {len(results)} cases pass** (policy outcome, complete log, no "
        "non-finite command sent).",
        "",
        "| experiment | fault | outcome | supervisor | max dev (m) | recover (s) | log complete "
        "| non-finite cmds | pass |",
        "|---|---|---|---|---:|---:|---|---:|---|",
    ]
    lingering = [r for r in results if r.outcome in ("completed", "hovered")
                 and not math.isfinite(r.recover_s)]
    for r in results:
        lines.append(f"| {r.experiment} | {r.fault} | {r.outcome} | {r.ending} | "
                     f"{_fmt(r.max_dev_m)} | {_fmt(r.recover_s, 1)} | "
                     f"{'yes' if r.log_complete else 'NO: ' + r.message} | {r.nonfinite_cmds} | "
                     f"{'✔' if r.passed else '✘'} |")
    if lingering:
        lines += ["", "## Flights that completed but never came back within "
                  f"{RECOVERED_M:g} m of the fault-free flight", ""]
        for r in lingering:
            lines.append(f"* {r.experiment} × {r.fault}: largest deviation {_fmt(r.max_dev_m)} m")
        lines += ["", "A constant wind leaves a steady offset: the NMPC has no integral action "
                  "and its model has no drag or wind, so a steady push is met by a steady "
                  "tilt that only a position error commands. A command-delay jump beyond the "
                  "delay the prediction compensates (`controller.delay_compensation_s`) "
                  "brings back the limit cycle of the delay-free prediction (see "
                  "docs/thesis-reproduction.md). Neither crosses a supervisor limit, so the "
                  "flight goes on; tighter `safety.max_speed_mps` or a geofence would stop it."]
    return "\n".join(lines) + "\n"


def _choose(text: str | None, known, what: str) -> list[str]:
    if text is None:
        return list(known)
    names = [n.strip() for n in text.split(",") if n.strip()]
    unknown = [n for n in names if n not in known]
    if unknown or not names:
        raise ValueError(f"--{what}: unknown {', '.join(unknown) or '(empty)'}; "
                         f"choose from {', '.join(known)}")
    return names


def run_faults_command(*, json_out: Path | None, markdown: Path | None, experiments: str,
                       only: str | None, config_dir: Path, log_dir: Path | None,
                       seed: int, jobs: int = 1) -> bool:
    """The ``faults`` command: run, print, write the reports; True if every case passed."""
    import datetime as dt
    import json
    import sys

    from rich.console import Console

    kinds = _choose(experiments, EXPERIMENTS, "experiments")
    cases = _choose(only, FAULT_CASES, "faults")
    for kind in kinds:
        if not (config_dir / EXPERIMENTS[kind][0]).is_file():
            raise ValueError(f"--config-dir: {config_dir / EXPERIMENTS[kind][0]} not found")
    log_dir = log_dir or Path("logs") / dt.datetime.now().strftime("faults-%Y%m%d-%H%M%S")
    console = Console(stderr=True)
    total = len(kinds) * (len(cases) + 1)
    done = [0]

    def progress(label: str) -> None:
        done[0] += 1
        console.print(f"[{done[0]}/{total}] {label}", highlight=False)

    results = run_matrix(config_dir=config_dir, log_dir=log_dir, experiments=kinds,
                         faults=cases, seed=seed, progress=progress, jobs=jobs)
    Console().print(render_table(results))
    n_pass = sum(r.passed for r in results)
    print(f"{n_pass}/{len(results)} cases pass; run directories under {log_dir}")
    if json_out is not None:
        write_text_atomic(json_out, json.dumps([r.as_dict() for r in results], indent=1,
                                       allow_nan=True) + "\n")
    if markdown is not None:
        command = "ardrone-nmpc faults " + " ".join(sys.argv[2:]) if len(sys.argv) > 1 else \
            "ardrone-nmpc faults"
        write_text_atomic(markdown, render_markdown(results, command=command.strip()))
    return n_pass == len(results)
