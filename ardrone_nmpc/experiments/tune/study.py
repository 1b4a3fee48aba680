"""The Optuna study of a ``tune`` run, its files in ``DIR`` and the ask/tell loop.

``DIR/study.db`` (SQLite) is the study's own storage: every finished trial is in it with
its parameters, score and, as a user attribute, its status, message and per-scenario
metrics, so ``--resume`` continues where a stopped run left off — trials finished are never
flown again; trials in flight when it stopped are lost and replaced. The sampler works on an
in-memory twin of the study, loaded from the file on ``--resume`` (see :class:`TuneStudy`). The
study also records what it optimises (config, space, scenarios, objective): resuming with
different ones is refused. ``DIR/trials.csv`` and ``DIR/best.yaml`` are rewritten from the
storage as trials finish.

Sampler: Optuna's TPE (multivariate), seeded with ``--seed`` plus the number of trials
already in the study (a resumed run does not replay the first run's random start). A new
study first flies the config's own values (when they lie in the space), so the best found is
never worse than the start.
"""

from __future__ import annotations

import datetime as _dt
import hashlib
import json
import math
import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ardrone_nmpc.config.io import config_to_dict, dump_config
from ardrone_nmpc.config.schema import ConfigError
from ardrone_nmpc.experiments.tune.engine import Scenario, TrialResult, TrialSpec
from ardrone_nmpc.experiments.tune.objective import METRICS, Objective
from ardrone_nmpc.experiments.tune.space import Param, config_with
from ardrone_nmpc.runs.sweep_table import write_csv_table
from ardrone_nmpc.runs.tune_record import RESULT_ATTR, STUDY_FILE, STUDY_NAME, result_of
from ardrone_nmpc.runs.tune_record import storage as record_storage

__all__ = ["BEST_FILE", "STUDY_FILE", "STUDY_NAME", "TRIALS_FILE", "TuneStudy", "finished_trials",
           "open_study", "result_of", "run_study", "trial_rows", "trials_columns", "write_best",
           "write_trials_csv"]

TRIALS_FILE = "trials.csv"
BEST_FILE = "best.yaml"
_SIGNATURE = "tune_signature"


def signature(*, cfg, space: Mapping[str, Param], scenarios: Sequence[Scenario],
              objective: Objective) -> dict[str, Any]:
    """What a study optimises, as JSON-able data (compared on ``--resume``)."""
    data = json.dumps(config_to_dict(cfg), sort_keys=True, separators=(",", ":"))
    return {"config": cfg.name,
            "config_sha256": hashlib.sha256(data.encode("utf-8")).hexdigest()[:16],
            "space": {n: [p.low, p.high, p.log, p.kind] for n, p in space.items()},
            "scenarios": [[s.label, s.seed, list(s.overrides)] for s in scenarios],
            "objective": {**objective.weights, "worst": objective.worst}}


@dataclass
class TuneStudy:
    """The study of a tune run: ``record`` in ``DIR/study.db`` holds every finished trial
    (numbered in the order they finished); ``search`` is its in-memory twin the sampler asks
    and is told — Optuna's SQLite storage costs milliseconds per stored parameter, on the
    process that feeds the workers, where a whole flight takes ~0.1 s."""

    record: Any
    search: Any


def open_study(out_dir: Path, *, resume: bool, seed: int, sig: Mapping[str, Any],
               base_values: Mapping[str, float] | None = None) -> TuneStudy:
    """Create the study in ``out_dir`` (refusing an existing one without ``resume``), or
    load it (refusing one that optimises something else; trials left running in the
    storage are marked failed). Raises :class:`ConfigError`."""
    import optuna
    from optuna.trial import TrialState

    db = out_dir / STUDY_FILE
    exists = db.is_file()
    if exists and not resume:
        raise ConfigError(f"--out {out_dir}: holds a study already ({STUDY_FILE}); "
                          "--resume continues it, or choose another --out")
    storage = record_storage(db)
    if exists:
        try:
            record = optuna.load_study(study_name=STUDY_NAME, storage=storage)
        except KeyError:
            raise ConfigError(f"--out {out_dir}: {STUDY_FILE} holds no '{STUDY_NAME}' "
                              "study") from None
        recorded = record.user_attrs.get(_SIGNATURE)
        if recorded != json.loads(json.dumps(sig)):
            changed = [k for k in sig if (recorded or {}).get(k) != json.loads(
                json.dumps(sig[k]))]
            raise ConfigError(f"--resume: the study in {out_dir} optimises another "
                              f"{', '.join(changed) or 'setup'}; use another --out")
        for t in record.get_trials(deepcopy=False, states=(TrialState.RUNNING,)):
            storage.set_trial_state_values(t._trial_id, TrialState.FAIL)
    else:
        record = optuna.create_study(study_name=STUDY_NAME, storage=storage,
                                     direction="minimize")
        record.set_user_attr(_SIGNATURE, json.loads(json.dumps(sig)))
    done = finished_trials(record)
    sampler = optuna.samplers.TPESampler(seed=seed + len(record.trials), multivariate=True)
    search = optuna.create_study(sampler=sampler, direction="minimize")
    search.add_trials(done)
    if not done and base_values:
        search.enqueue_trial(dict(base_values))
    return TuneStudy(record, search)


def finished_trials(study) -> list:
    """The study's completed trials (flown and told), in trial order."""
    from optuna.trial import TrialState

    return study.get_trials(deepcopy=False, states=(TrialState.COMPLETE,))


def _suggest(trial, space: Mapping[str, Param]) -> dict[str, float]:
    values = {}
    for name, p in space.items():
        if p.kind == "int":
            values[name] = trial.suggest_int(name, int(math.ceil(p.low)), int(math.floor(p.high)),
                                             log=p.log)
        else:
            values[name] = trial.suggest_float(name, p.low, p.high, log=p.log)
    return values


def run_study(study: TuneStudy, *, n_trials: int, engine,
              make_spec: Callable[[int, dict], TrialSpec], space: Mapping[str, Param],
              on_result: Callable[[TrialResult], None] | None = None) -> int:
    """Fly trials until the record holds ``n_trials`` finished ones, keeping
    ``engine.slots`` in flight (ask, submit; tell as each finishes, then store it in the
    record). Returns how many were flown now. Ctrl-C stops it; trials in flight are lost
    (never recorded: a resumed run flies others in their place)."""
    import optuna

    todo = max(0, n_trials - len(finished_trials(study.record)))
    asked, in_flight, flown = 0, {}, 0

    def fill() -> None:  # keep every worker busy
        nonlocal asked
        while asked < todo and len(in_flight) < engine.slots:
            trial = study.search.ask()
            engine.submit(make_spec(trial.number, _suggest(trial, space)))
            in_flight[trial.number] = trial
            asked += 1

    fill()
    while in_flight:
        result = engine.next_result()
        trial = in_flight.pop(result.number)
        attrs = {RESULT_ATTR: {"status": result.status, "message": result.message,
                            "metrics": result.metrics, "wall_s": result.wall_s,
                            "sim_s": result.sim_s}}
        trial.set_user_attr(RESULT_ATTR, attrs[RESULT_ATTR])
        frozen = study.search.tell(trial, result.score)
        fill()  # before the slow SQLite write: the freed worker starts at once
        study.record.add_trial(optuna.trial.create_trial(
            params=frozen.params, distributions=frozen.distributions, value=result.score,
            user_attrs=attrs))
        flown += 1
        if on_result is not None:
            on_result(result)
    return flown


# ----------------------------------------------------------------------------- files


def trials_columns(space: Sequence[str], scenarios: Sequence[Scenario]) -> list[str]:
    """``trials.csv``'s header: trial, status, score, the parameters, wall_s, sim_s, then
    ``<scenario>:<metric>`` for every scenario and metric, then message."""
    return ["trial", "status", "score", *space, "wall_s", "sim_s",
            *(f"{s.label}:{m}" for s in scenarios for m in METRICS), "message"]


def _num(value: Any) -> str:
    from ardrone_nmpc.runs.rundir import format_number

    return "nan" if value is None else format_number(value)


def trial_rows(study, space: Sequence[str], scenarios: Sequence[Scenario]) -> list[dict]:
    """One ``trials.csv`` row (text cells) per finished trial, in trial order."""
    rows = []
    for t in finished_trials(study):
        res = result_of(t)
        row = {"trial": str(t.number), "status": res.get("status", ""), "score": _num(t.value)}
        row.update({n: _num(t.params.get(n)) for n in space})
        row["wall_s"] = _num(res.get("wall_s"))
        row["sim_s"] = _num(res.get("sim_s"))
        metrics = res.get("metrics", {})
        for s in scenarios:
            for m in METRICS:
                row[f"{s.label}:{m}"] = _num(metrics.get(s.label, {}).get(m))
        row["message"] = res.get("message", "")
        rows.append(row)
    return rows


def write_trials_csv(path: Path, columns: Sequence[str], rows: Sequence[Mapping]) -> None:
    """Write ``trials.csv`` atomically."""
    write_csv_table(path, columns, rows)


def write_best(path: Path, study, *, cfg, space: Mapping[str, Param], command: str,
               objective: Objective, scenarios: Sequence[Scenario]) -> Path | None:
    """Write the best trial's config (``cfg`` with its values) as a complete config YAML
    with a header saying how it was found. None if no trial finished."""
    trials = finished_trials(study)
    if not trials:
        return None
    best = study.best_trial
    best_cfg = config_with(cfg, best.params, space)
    now = _dt.datetime.now().astimezone().isoformat(timespec="seconds")
    items = [f"{n} = {v:.6g}" for n, v in best.params.items()]
    changed = ",\n  ".join(", ".join(items[i:i + 4]) for i in range(0, len(items), 4))
    header = "\n".join([
        f"Found by `{command}` on {now}:",
        f"Optuna TPE, trial {best.number} of {len(trials)}, score {best.value:.6g} "
        f"(status {result_of(best).get('status', '?')}).",
        f"Objective: {objective.text} = " + ", ".join(
            f"{k} {w:g}" for k, w in objective.weights.items()) + f", worst {objective.worst:g}.",
        "Scenarios: " + ", ".join(s.label for s in scenarios) + ".",
        f"Tuned:\n  {changed}.",
    ])
    text = dump_config(best_cfg, header=header)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, path)
    return path


def spec_factory(*, cfg, written: Mapping[str, Any], space: Mapping[str, Param],
                 scenarios: Sequence[Scenario], objective: Objective,
                 keep_dir: Path | None) -> Callable[[int, dict], TrialSpec]:
    """``make_spec(number, values)`` for :func:`run_study`; ``written`` is the config as
    written (:func:`~ardrone_nmpc.experiments.tune.space.written_config`), ``cfg`` it
    validated."""
    resolved = config_to_dict(cfg)
    keep = None if keep_dir is None else str(Path(keep_dir).resolve())
    return lambda number, values: TrialSpec(number, values, written, dict(space),
                                            tuple(scenarios), objective, keep, resolved)
