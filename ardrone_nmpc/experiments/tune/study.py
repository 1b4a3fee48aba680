"""The Optuna study of a ``tune`` run, its files in ``DIR`` and the ask/tell loop.

``DIR/study.db`` (SQLite) is the study's own storage: every finished trial is in it with
its parameters, score and, as user attributes, its status, message and per-scenario
metrics, so ``--resume`` continues where a stopped run left off — trials finished are never
flown again; trials that were running when it stopped are marked failed and replaced. The
study also records what it optimises (config, space, scenarios, objective): resuming with
different ones is refused. ``DIR/trials.csv`` and ``DIR/best.yaml`` are rewritten from the
storage as trials finish.

Sampler: Optuna's TPE (multivariate), seeded with ``--seed`` plus the number of trials
already in the study (a resumed run does not replay the first run's random start). A new
study first flies the config's own values (when they lie in the space), so the best found is
never worse than the start.
"""

from __future__ import annotations

import csv
import datetime as _dt
import hashlib
import json
import math
import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict
from pathlib import Path
from typing import Any

from ardrone_nmpc.config.schema import ConfigError, config_to_dict, dump_config
from ardrone_nmpc.experiments.tune.engine import Scenario, TrialResult, TrialSpec
from ardrone_nmpc.experiments.tune.objective import METRICS, Objective
from ardrone_nmpc.experiments.tune.space import Param, config_with

__all__ = ["BEST_FILE", "STUDY_FILE", "STUDY_NAME", "TRIALS_FILE", "finished_trials",
           "open_study", "run_study", "trial_rows", "trials_columns", "write_best",
           "write_trials_csv"]

STUDY_FILE = "study.db"
TRIALS_FILE = "trials.csv"
BEST_FILE = "best.yaml"
STUDY_NAME = "tune"
_SIGNATURE = "tune_signature"


def _quiet_optuna() -> None:
    import optuna

    optuna.logging.set_verbosity(optuna.logging.WARNING)


def signature(*, cfg, space: Mapping[str, Param], scenarios: Sequence[Scenario],
              objective: Objective) -> dict[str, Any]:
    """What a study optimises, as JSON-able data (compared on ``--resume``)."""
    data = json.dumps(config_to_dict(cfg), sort_keys=True, separators=(",", ":"))
    return {"config": cfg.name,
            "config_sha256": hashlib.sha256(data.encode("utf-8")).hexdigest()[:16],
            "space": {n: [p.low, p.high, p.log, p.kind] for n, p in space.items()},
            "scenarios": [[s.label, s.seed, list(s.overrides)] for s in scenarios],
            "objective": {**objective.weights, "worst": objective.worst}}


def open_study(out_dir: Path, *, resume: bool, seed: int, sig: Mapping[str, Any],
               base_values: Mapping[str, float] | None = None):
    """Create the study in ``out_dir`` (refusing an existing one without ``resume``), or
    load it (refusing one that optimises something else). Running trials of a stopped
    run are marked failed. Raises :class:`ConfigError`."""
    import optuna
    from optuna.trial import TrialState

    _quiet_optuna()
    db = out_dir / STUDY_FILE
    exists = db.is_file()
    if exists and not resume:
        raise ConfigError(f"--out {out_dir}: holds a study already ({STUDY_FILE}); "
                          "--resume continues it, or choose another --out")
    storage = optuna.storages.RDBStorage(f"sqlite:///{db.resolve()}")
    n_before = 0
    if exists:
        try:
            old = optuna.load_study(study_name=STUDY_NAME, storage=storage)
        except KeyError:
            raise ConfigError(f"--out {out_dir}: {STUDY_FILE} holds no '{STUDY_NAME}' "
                              "study") from None
        recorded = old.user_attrs.get(_SIGNATURE)
        if recorded != json.loads(json.dumps(sig)):
            changed = [k for k in sig if (recorded or {}).get(k) != json.loads(
                json.dumps(sig[k]))]
            raise ConfigError(f"--resume: the study in {out_dir} optimises another "
                              f"{', '.join(changed) or 'setup'}; use another --out")
        for t in old.get_trials(deepcopy=False, states=(TrialState.RUNNING,)):
            storage.set_trial_state_values(t._trial_id, TrialState.FAIL)
        n_before = len(old.trials)
    sampler = optuna.samplers.TPESampler(seed=seed + n_before, multivariate=True)
    study = optuna.create_study(study_name=STUDY_NAME, storage=storage, sampler=sampler,
                                direction="minimize", load_if_exists=True)
    if not exists:
        study.set_user_attr(_SIGNATURE, json.loads(json.dumps(sig)))
        if base_values:
            study.enqueue_trial(dict(base_values))
    return study


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


def run_study(study, *, n_trials: int, engine, make_spec: Callable[[int, dict], TrialSpec],
              space: Mapping[str, Param],
              on_result: Callable[[TrialResult], None] | None = None) -> int:
    """Fly trials until the study has ``n_trials`` finished ones, keeping ``engine.slots``
    in flight (ask, submit; tell as each finishes). Returns how many were flown now.
    Ctrl-C stops asking; the trials in flight are then left running in the storage (marked
    failed on ``--resume``)."""
    todo = max(0, n_trials - len(finished_trials(study)))
    asked, in_flight, flown = 0, {}, 0
    while asked < todo or in_flight:
        while asked < todo and len(in_flight) < engine.slots:
            trial = study.ask()
            values = _suggest(trial, space)
            engine.submit(make_spec(trial.number, values))
            in_flight[trial.number] = trial
            asked += 1
        result = engine.next_result()
        trial = in_flight.pop(result.number)
        trial.set_user_attr("status", result.status)
        trial.set_user_attr("message", result.message)
        trial.set_user_attr("metrics", result.metrics)
        trial.set_user_attr("wall_s", result.wall_s)
        trial.set_user_attr("sim_s", result.sim_s)
        study.tell(trial, result.score)
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
        row = {"trial": str(t.number), "status": t.user_attrs.get("status", ""),
               "score": _num(t.value)}
        row.update({n: _num(t.params.get(n)) for n in space})
        row["wall_s"] = _num(t.user_attrs.get("wall_s"))
        row["sim_s"] = _num(t.user_attrs.get("sim_s"))
        metrics = t.user_attrs.get("metrics", {})
        for s in scenarios:
            for m in METRICS:
                row[f"{s.label}:{m}"] = _num(metrics.get(s.label, {}).get(m))
        row["message"] = t.user_attrs.get("message", "")
        rows.append(row)
    return rows


def write_trials_csv(path: Path, columns: Sequence[str], rows: Sequence[Mapping]) -> None:
    """Write ``trials.csv`` atomically."""
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "w", newline="", encoding="utf-8") as f:
        writer = csv.DictWriter(f, fieldnames=list(columns))
        writer.writeheader()
        writer.writerows(rows)
    os.replace(tmp, path)


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
        f"(status {best.user_attrs.get('status', '?')}).",
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


def spec_factory(*, cfg, space: Mapping[str, Param], scenarios: Sequence[Scenario],
                 objective: Objective, keep_dir: Path | None) -> Callable[[int, dict], TrialSpec]:
    """``make_spec(number, values)`` for :func:`run_study`."""
    base = config_to_dict(cfg)
    keep = None if keep_dir is None else str(Path(keep_dir).resolve())
    return lambda number, values: TrialSpec(number, values, base, dict(space),
                                            tuple(scenarios), objective, keep)


def space_as_dict(space: Mapping[str, Param]) -> dict[str, dict]:
    return {n: asdict(p) for n, p in space.items()}
