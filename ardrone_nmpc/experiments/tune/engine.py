"""Flying ``tune``'s trials: one trial = the config with the trial's values on every scenario,
in lockstep, scored; engines run several trials at once (ask/tell: a new trial is asked for
as soon as one finishes).

Scenarios are flight seeds × optional override sets (the plant profiles when the config
schema has ``sim.plant.profile``, or ``--variant`` sets). A trial writes no run directory
unless ``keep_dir`` is given: its flights are recorded in memory
(:class:`~ardrone_nmpc.runs.memory.MemoryRecorder`) and summarised from there.

Trials run on the one parallel executor (:mod:`ardrone_nmpc.experiments.parallel`), as a
sweep's cases do: in this process, on a warm local pool, or on Dask.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ardrone_nmpc.experiments.record import one_line
from ardrone_nmpc.experiments.tune.objective import FAILED_METRICS, Objective
from ardrone_nmpc.experiments.tune.space import Param, apply_params
from ardrone_nmpc.runs.verdict import FAILED_VERDICTS, verdict_message

__all__ = ["Scenario", "TrialResult", "TrialSpec", "plant_variants", "run_trial", "scenarios",
           "trial_result"]


@dataclass(frozen=True)
class Scenario:
    """One flight of every trial: a seed and ``--set``-style overrides; ``label`` names it
    in ``trials.csv`` (``seed3``, ``seed3+fast``)."""

    label: str
    seed: int
    overrides: tuple[str, ...] = ()


def plant_variants() -> list[tuple[str, tuple[str, ...]]]:
    """(label, overrides) per plant profile, if the config schema has ``sim.plant.profile``
    with a fixed set of values; else none (every trial flies the config's plant)."""
    from ardrone_nmpc.config import schema

    if "profile" not in schema.PlantConfig.model_fields:
        return []
    return [(c, (f"sim.plant.profile={c}",)) for c in schema.PLANT_PROFILE_DEFAULTS]


def scenarios(*, base_seed: int, n_seeds: int,
              variants: Sequence[tuple[str, Sequence[str]]] = ()) -> list[Scenario]:
    """Seeds ``base_seed … base_seed + n_seeds − 1`` × ``variants`` (label, overrides)."""
    seeds = range(base_seed, base_seed + n_seeds)
    if not variants:
        return [Scenario(f"seed{s}", s) for s in seeds]
    return [Scenario(f"seed{s}+{label}", s, tuple(ov)) for label, ov in variants for s in seeds]


@dataclass(frozen=True)
class TrialSpec:
    """Everything a worker needs to fly one trial (travels pickled, configs as plain data)."""

    number: int
    values: Mapping[str, float]
    base: Mapping[str, Any] = field(repr=False)  # the tuned config as written (+ --set)
    space: Mapping[str, Param] = field(repr=False)
    scenarios: tuple[Scenario, ...]
    objective: Objective
    keep_dir: str | None = None  # write run directories under keep_dir/trial-NNNNN/
    resolved: Mapping[str, Any] | None = field(default=None, repr=False)  # base validated


@dataclass
class TrialResult:
    """A trial's ``score`` (lower is better), ``status`` (ok: every flight completed
    without abort; aborted; failed: a flight could not run, or ran to its end without doing
    its job — :mod:`ardrone_nmpc.runs.verdict`), per-scenario metrics, the
    first problem's one-line ``message``, its wall time and the simulated time flown (s)."""

    number: int
    score: float
    status: str
    metrics: dict[str, dict[str, float]]
    message: str = ""
    wall_s: float = math.nan
    sim_s: float = 0.0


def _fly(cfg, keep_dir: str | None, number: int):
    """(metrics, simulated seconds, ending) of one flight: recorded in memory, or with
    ``keep_dir`` the way every caller records a run directory
    (:mod:`ardrone_nmpc.experiments.record`)."""
    from ardrone_nmpc.experiments.tune.objective import scenario_metrics

    if keep_dir is None:
        from ardrone_nmpc.runs.memory import MemoryRecorder
        from ardrone_nmpc.runs.summary import summarise
        from ardrone_nmpc.runtime.lockstep import run_lockstep

        recorder = MemoryRecorder()
        result = run_lockstep(cfg, recorder=recorder)
        run = recorder.run_data(cfg, seed=cfg.sim.seed)
        rows = summarise(run)
    else:
        from ardrone_nmpc.experiments.record import record_lockstep

        rec = record_lockstep(cfg, Path(keep_dir) / f"trial-{number:05d}")
        result, run, rows = rec.result, rec.run, rec.summary
    return (scenario_metrics(run, rows, ending=result.ending), result.ticks * cfg.loop.period_s,
            result.ending)


def _scenario_data(data: Mapping[str, Any], sc: Scenario) -> Mapping[str, Any]:
    """``data`` with the scenario's overrides and its seed: what ``apply_overrides(data,
    [*sc.overrides, f"sim.seed={sc.seed}"])`` gives, for :func:`resolve_data` (which copies
    it before anything changes it). A scenario of a seed alone (an int: its text read back as
    YAML is that int) is set as it is, without a deep copy of ``data`` and a YAML parse."""
    from ardrone_nmpc.config.io import apply_overrides

    sim = data.get("sim", {})
    if sc.overrides or sc.seed.__class__ is not int or sim.__class__ is not dict:
        return apply_overrides(data, [*sc.overrides, f"sim.seed={sc.seed}"])
    return {**data, "sim": {**sim, "seed": sc.seed}}


def run_trial(spec: TrialSpec) -> TrialResult:
    """Fly ``spec`` on each of its scenarios and score it. Never raises: a flight that
    cannot run (an invalid config, an exception) makes the trial ``failed`` with the
    objective's penalty."""
    from ardrone_nmpc.config.io import resolve_data
    from ardrone_nmpc.config.schema import ConfigError

    wall0 = time.perf_counter()
    # the trial's values on the config as written: a scenario's plant profile still fills
    # every plant key the config leaves out
    data = apply_params(spec.base, spec.values, spec.space, resolved=spec.resolved)
    metrics, scores, messages, sim_s = {}, [], [], 0.0
    status = "ok"
    for sc in spec.scenarios:
        try:
            cfg = resolve_data(_scenario_data(data, sc))
            m, flown_s, ending = _fly(cfg, spec.keep_dir, spec.number)
            sim_s += flown_s
            if ending in FAILED_VERDICTS:  # flown to its end without doing its job
                m, status = dict(FAILED_METRICS), "failed"
                messages.insert(0, f"{sc.label}: {ending}: {verdict_message(ending)}")
            elif m["aborted"] and status == "ok":
                status = "aborted"
                messages.append(f"{sc.label}: aborted by the supervisor")
        except (ConfigError, Exception) as err:  # noqa: BLE001 - a failed flight is a result
            m, status = dict(FAILED_METRICS), "failed"
            text = "; ".join(err.messages) if isinstance(err, ConfigError) else one_line(err)
            messages.insert(0, f"{sc.label}: {text}")
        m["score"] = spec.objective.score(m)
        scores.append(m["score"])
        metrics[sc.label] = m
    return TrialResult(spec.number, spec.objective.combine(scores), status, metrics,
                       messages[0] if messages else "", time.perf_counter() - wall0, sim_s)


def _failed(spec: TrialSpec, err: BaseException | None) -> TrialResult:
    metrics = {}
    for sc in spec.scenarios:
        m = dict(FAILED_METRICS)
        m["score"] = spec.objective.score(m)
        metrics[sc.label] = m
    return TrialResult(spec.number, spec.objective.combine([m["score"] for m in
                                                            metrics.values()]),
                       "failed", metrics,
                       f"worker: {one_line(err)}" if err is not None else "not flown")


def trial_result(spec: TrialSpec, error: BaseException | None = None,
                 result: TrialResult | None = None) -> TrialResult:
    """What the executor returned for ``spec``: its result, or — the worker died, or the
    trial was interrupted or cancelled — a failed trial with the objective's penalty."""
    return result if error is None and result is not None else _failed(spec, error)
