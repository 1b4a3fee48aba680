"""Flying ``tune``'s trials: one trial = the config with the trial's values on every scenario,
in lockstep, scored; engines run several trials at once (ask/tell: a new trial is asked for
as soon as one finishes).

Scenarios are flight seeds × optional override sets (the plant profiles when the config
schema has ``sim.plant.profile``, or ``--variant`` sets). A trial writes no run directory
unless ``keep_dir`` is given: its flights are recorded in memory
(:class:`~ardrone_nmpc.runs.memory.MemoryRecorder`) and summarised from there.

Engines reuse the sweep's machinery (:mod:`ardrone_nmpc.experiments.sweep`): the pool forks
its workers from a forkserver that loaded the numba kernels once, and the Dask engine makes
its client the sweep's way.
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

__all__ = ["DaskEngine", "InlineEngine", "PoolEngine", "Scenario", "TrialResult",
           "TrialSpec", "make_engine", "plant_variants", "run_trial", "scenarios"]


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
    without abort; aborted; failed: a flight could not run), per-scenario metrics, the
    first problem's one-line ``message``, its wall time and the simulated time flown (s)."""

    number: int
    score: float
    status: str
    metrics: dict[str, dict[str, float]]
    message: str = ""
    wall_s: float = math.nan
    sim_s: float = 0.0


def _fly(cfg, keep_dir: str | None, number: int):
    """(metrics, simulated seconds) of one flight: recorded in memory, or with ``keep_dir``
    the way every caller records a run directory (:mod:`ardrone_nmpc.experiments.record`)."""
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
    return scenario_metrics(run, rows, ending=result.ending), result.ticks * cfg.loop.period_s


def run_trial(spec: TrialSpec) -> TrialResult:
    """Fly ``spec`` on each of its scenarios and score it. Never raises: a flight that
    cannot run (an invalid config, an exception) makes the trial ``failed`` with the
    objective's penalty."""
    from ardrone_nmpc.config.io import apply_overrides, resolve_data
    from ardrone_nmpc.config.schema import ConfigError

    wall0 = time.perf_counter()
    # the trial's values on the config as written: a scenario's plant profile still fills
    # every plant key the config leaves out
    data = apply_params(spec.base, spec.values, spec.space, resolved=spec.resolved)
    metrics, scores, messages, sim_s = {}, [], [], 0.0
    status = "ok"
    for sc in spec.scenarios:
        try:
            cfg = resolve_data(apply_overrides(data, [*sc.overrides, f"sim.seed={sc.seed}"]))
            m, flown_s = _fly(cfg, spec.keep_dir, spec.number)
            sim_s += flown_s
            if m["aborted"] and status == "ok":
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


def _failed(spec: TrialSpec, err: BaseException) -> TrialResult:
    metrics = {}
    for sc in spec.scenarios:
        m = dict(FAILED_METRICS)
        m["score"] = spec.objective.score(m)
        metrics[sc.label] = m
    return TrialResult(spec.number, spec.objective.combine([m["score"] for m in
                                                            metrics.values()]),
                       "failed", metrics, f"worker: {one_line(err)}")


# ----------------------------------------------------------------------------- engines


class InlineEngine:
    """Trials one after another in this process (``--jobs 1``)."""

    slots = 1

    def __init__(self) -> None:
        self._queue: list[TrialSpec] = []

    def submit(self, spec: TrialSpec) -> None:
        self._queue.append(spec)

    def next_result(self) -> TrialResult:
        return run_trial(self._queue.pop(0))

    def close(self) -> None:
        self._queue.clear()


class PoolEngine:
    """A pool of ``jobs`` worker processes forked from the sweep's warm forkserver. The
    forkserver warms up (loads the kernels, ~2 s) in the background from construction on,
    so the caller can open its study meanwhile; the first :meth:`submit` waits for it."""

    def __init__(self, jobs: int) -> None:
        import threading

        from ardrone_nmpc.experiments.sweep.engines import _pool_context, _start_forkserver

        self.slots = jobs
        self._ctx = _pool_context()
        # the workers end with this process, however it ends (the sweep's worker watch)
        self._alive_r, self._alive_w = self._ctx.Pipe(duplex=False)
        self._warm = None
        self._pool = None
        self._futures: dict[Any, TrialSpec] = {}

        def start() -> None:
            self._warm = _start_forkserver(self._ctx)

        self._starter = threading.Thread(target=start, name="tune-forkserver", daemon=True)
        self._starter.start()

    def _ready(self):
        if self._pool is None:
            from concurrent.futures import ProcessPoolExecutor

            from ardrone_nmpc.experiments.sweep.engines import _init_worker

            self._starter.join()
            self._pool = ProcessPoolExecutor(self.slots, mp_context=self._ctx,
                                             initializer=_init_worker,
                                             initargs=(self._alive_r,))
        return self._pool

    def submit(self, spec: TrialSpec) -> None:
        self._futures[self._ready().submit(run_trial, spec)] = spec

    def next_result(self) -> TrialResult:
        from concurrent.futures import FIRST_COMPLETED, wait

        done, _ = wait(list(self._futures), return_when=FIRST_COMPLETED)
        future = next(iter(done))
        spec = self._futures.pop(future)
        try:
            return future.result()
        except Exception as err:  # noqa: BLE001 - a dead worker fails its trial
            return _failed(spec, err)

    def close(self) -> None:
        self._starter.join()
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
        if self._warm is not None:
            self._warm.join()
        self._alive_r.close()
        self._alive_w.close()  # after the workers have ended: closing it would end them


class DaskEngine:
    """Trials on a Dask cluster: ``scheduler``'s, or a local cluster of ``jobs`` workers
    on 127.0.0.1 (made as the sweep makes it)."""

    def __init__(self, jobs: int, scheduler: str | None = None) -> None:
        import uuid

        from dask.distributed import as_completed

        from ardrone_nmpc.experiments.sweep.engines import _dask_client

        self._client, self._cluster = _dask_client(scheduler=scheduler, jobs=jobs)
        info = self._client.scheduler_info()
        workers = info.get("workers", {}) if isinstance(info, dict) else {}
        self.slots = max(1, sum(int(w.get("nthreads", 1)) for w in workers.values()) or jobs)
        self._token = uuid.uuid4().hex[:8]
        self._done = as_completed(loop=self._client.loop)
        self._specs: dict[str, TrialSpec] = {}
        self._futures: dict[str, Any] = {}

    def submit(self, spec: TrialSpec) -> None:
        key = f"tune-{self._token}-{spec.number}"
        self._specs[key] = spec
        self._futures[key] = self._client.submit(run_trial, spec, key=key, pure=False)
        self._done.add(self._futures[key])

    def next_result(self) -> TrialResult:
        future = next(self._done)
        spec = self._specs.pop(future.key)
        self._futures.pop(future.key, None)
        try:
            return future.result()
        except Exception as err:  # noqa: BLE001 - a lost worker fails its trial
            return _failed(spec, err)

    def close(self) -> None:
        try:
            self._client.cancel(list(self._futures.values()))
        finally:
            self._client.close()
            if self._cluster is not None:
                self._cluster.close()


def make_engine(engine: str, *, jobs: int, scheduler: str | None = None):
    """``local`` (inline for one job, else a pool) or ``dask``."""
    if engine == "dask":
        return DaskEngine(jobs, scheduler)
    return InlineEngine() if jobs == 1 else PoolEngine(jobs)
