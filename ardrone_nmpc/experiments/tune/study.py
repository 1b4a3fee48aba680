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

Reproducible: the sampler is told the results in trial order, and trial ``k`` is asked right
after trial ``k − ASK_AHEAD`` is told — whatever ``--jobs``, the engine or the machine's load,
the sampler sees the same history at every ask, so the same ``--seed`` asks for the same
trials. Up to :data:`ASK_AHEAD` trials fly at once (more workers than that idle).

``--storage URL`` mirrors every stored trial into a study of that name in another Optuna
storage (a database several tunes share with optuna-dashboard); ``DIR/study.db`` stays the
record ``--resume`` and ``plot`` read.
"""

from __future__ import annotations

import datetime as _dt
import hashlib
import json
import math
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ardrone_nmpc.config.io import config_to_dict, dump_config
from ardrone_nmpc.config.schema import ConfigError
from ardrone_nmpc.core.atomic import write_text_atomic
from ardrone_nmpc.experiments.tune.engine import (Scenario, TrialResult, TrialSpec, run_trial,
                                                  trial_result)
from ardrone_nmpc.experiments.tune.objective import METRICS, Objective
from ardrone_nmpc.experiments.tune.space import Param, config_with
from ardrone_nmpc.runs.sweep_table import write_csv_table
from ardrone_nmpc.errors import UserError
from ardrone_nmpc.runs.tune_record import (METRIC_NAME, RESULT_ATTR, STUDY_FILE, flat_metrics,
                                           result_of, study_name_in)
from ardrone_nmpc.runs.tune_record import checkpoint, close_storage, storage_errors
from ardrone_nmpc.runtime.signals import deferred_signals
from ardrone_nmpc.runs.tune_record import storage as record_storage

__all__ = ["ASK_AHEAD", "BEST_FILE", "STUDY_FILE", "TRIALS_FILE", "TuneStudy", "finished_trials",
           "open_study", "result_of", "run_study", "trial_row", "trial_rows", "trials_columns",
           "write_best", "write_trials_csv"]

#: Trials asked ahead of the last one told (and so at most in flight at once): the sampler's
#: history at each ask depends on this, never on --jobs (module docstring).
ASK_AHEAD = 8

TRIALS_FILE = "trials.csv"
BEST_FILE = "best.yaml"
_SIGNATURE = "tune_signature"
_OPENED = "tune_opened"  # when a run last opened the study


def signature(*, cfg, space: Mapping[str, Param], scenarios: Sequence[Scenario],
              objective: Objective) -> dict[str, Any]:
    """What a study optimises, as JSON-able data (compared on ``--resume``)."""
    data = json.dumps(config_to_dict(cfg), sort_keys=True, separators=(",", ":"))
    return {"config": cfg.name,
            "config_sha256": hashlib.sha256(data.encode("utf-8")).hexdigest()[:16],
            "space": {n: [p.low, p.high, p.log, p.kind] for n, p in space.items()},
            "scenarios": [[s.label, s.seed, list(s.overrides)] for s in scenarios],
            "objective": {**objective.weights, "worst": objective.worst}}


class StorageUrlError(UserError):
    """``--storage URL`` cannot be opened or written: one line naming it, exit 1."""


@dataclass
class TuneStudy:
    """The study of a tune run: ``record`` in ``DIR/study.db`` holds every finished trial
    (numbered as the sampler asked for them; a trial a signal stopped is stored as failed);
    ``search`` is its in-memory twin the sampler asks and is told — Optuna's SQLite storage
    costs milliseconds per stored parameter, on the process that feeds the workers, where a
    whole flight takes ~0.1 s; ``mirror`` the same study in ``--storage URL`` (or None)."""

    record: Any
    search: Any
    storage: Any = None
    db: Path | None = None
    mirror: Any = None
    mirror_url: str = ""

    def checkpoint(self) -> None:
        """``study.db`` alone holds every trial stored so far (see :func:`checkpoint`)."""
        if self.storage is not None:
            with deferred_signals(), storage_errors(self.db):
                checkpoint(self.storage)

    def close(self) -> None:
        """Close the storage, ``study.db`` self-contained (:func:`close_storage`)."""
        if self.storage is not None:
            with deferred_signals(), storage_errors(self.db):
                close_storage(self.storage, self.db)
            self.storage = None

    def add(self, trial) -> None:
        """Store a finished (or failed) trial in the record and the mirror; a signal waits
        for the writes."""
        with deferred_signals():
            with storage_errors(self.db):
                self.record.add_trial(trial)
            if self.mirror is not None:
                with mirror_errors(self.mirror_url):
                    self.mirror.add_trial(trial)


@contextmanager
def mirror_errors(url: str) -> Iterator[None]:
    """What opening or writing ``--storage URL`` raises, as one :class:`StorageUrlError`."""
    try:
        yield
    except (UserError, KeyboardInterrupt):
        raise
    except Exception as err:  # noqa: BLE001 - SQLAlchemy, drivers, Optuna: their words
        cause = getattr(err, "orig", None) or err.__cause__ or err
        text = " ".join(str(cause).split()) or type(cause).__name__
        raise StorageUrlError(f"--storage {url}: {text}") from None


def open_study(out_dir: Path, *, resume: bool, seed: int, sig: Mapping[str, Any],
               base_values: Mapping[str, float] | None = None, name: str = "tune",
               storage_url: str | None = None) -> TuneStudy:
    """Create the study ``name`` in ``out_dir`` (refusing an existing one that holds trials
    without ``resume``), or load it (refusing one that optimises something else; trials left
    running in the storage are marked failed); and its mirror in ``storage_url``. Raises
    :class:`ConfigError`, :class:`StorageUrlError`, or
    :class:`~ardrone_nmpc.runs.tune_record.StudyFileError` for a file SQLite cannot use; a
    ``study.db`` this call created is removed again if it fails."""
    import optuna

    db = out_dir / STUDY_FILE
    exists = db.is_file()
    with storage_errors(db):
        storage = record_storage(db)
        try:
            record = _open_record(storage, out_dir, exists=exists, resume=resume, sig=sig,
                                  name=name)
            mirror = (_open_mirror(storage_url, record, resume=resume)
                      if storage_url else None)
        except BaseException:
            storage.engine.dispose()
            if not exists:  # ours: no empty study left to block the next run
                for suffix in ("", "-wal", "-shm", "-journal"):
                    db.with_name(db.name + suffix).unlink(missing_ok=True)
            raise
    done = finished_trials(record)
    sampler = optuna.samplers.TPESampler(seed=seed + len(record.trials), multivariate=True)
    search = optuna.create_study(sampler=sampler, direction="minimize")
    # every stored trial, failed ones too: the next asked number is the next stored one
    search.add_trials(record.get_trials(deepcopy=False))
    if not done and base_values:
        search.enqueue_trial(dict(base_values))
    return TuneStudy(record, search, storage, db, mirror, storage_url or "")


def _open_record(storage, out_dir: Path, *, exists: bool, resume: bool,
                 sig: Mapping[str, Any], name: str):
    """Load the study of ``storage`` (refusing one that optimises something else) and mark
    its trials left running failed, or create it as ``name``; either writes, so a read-only
    file fails here, before anything flies. A study without any trial (a run stopped before
    its first) is taken over by a new run."""
    import optuna
    from optuna.trial import TrialState

    signature_data = json.loads(json.dumps(sig))
    record = None
    if exists:
        try:
            record = optuna.load_study(study_name=study_name_in(storage), storage=storage)
        except KeyError:
            raise ConfigError(f"--output {out_dir}: {STUDY_FILE} holds no study") from None
        if not resume:
            if record.trials:
                raise ConfigError(f"--output {out_dir}: holds a study already ({STUDY_FILE}); "
                                  "--resume continues it, or choose another --output")
            optuna.delete_study(study_name=record.study_name, storage=storage)
            record = None
    if record is None:
        record = optuna.create_study(study_name=name, storage=storage, direction="minimize")
        _name_metric(record)
        record.set_user_attr(_SIGNATURE, signature_data)
        return record
    recorded = record.user_attrs.get(_SIGNATURE)
    if recorded != signature_data:
        changed = [k for k in sig if (recorded or {}).get(k) != signature_data[k]]
        raise ConfigError(f"--resume: the study in {out_dir} optimises another "
                          f"{', '.join(changed) or 'setup'}; use another --output")
    # a real write (an unchanged value is not one): a read-only file fails here, not after a
    # trial has flown
    record.set_user_attr(_OPENED, _dt.datetime.now().astimezone().isoformat())
    if record.metric_names is None:  # a study of an earlier version
        _name_metric(record)
    for t in record.get_trials(deepcopy=False, states=(TrialState.RUNNING,)):
        storage.set_trial_state_values(t._trial_id, TrialState.FAIL)
    return record


def _name_metric(study) -> None:
    """Name the study's objective :data:`METRIC_NAME` (Optuna calls the API experimental:
    its warning would land in the middle of the progress bar)."""
    import warnings

    from optuna.exceptions import ExperimentalWarning

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ExperimentalWarning)
        study.set_metric_names([METRIC_NAME])


def _open_mirror(url: str, record, *, resume: bool):
    """The study of ``record``'s name in ``url``, created, or loaded and brought up to date
    (the trials the record holds beyond it added). Refuses a study there that holds trials
    the record does not (another tune's, or a new run's name clash)."""
    import optuna

    name = record.study_name
    with mirror_errors(url):
        mirror = optuna.create_study(study_name=name, storage=url, direction="minimize",
                                     load_if_exists=True)
        stored = len(mirror.trials)
        if stored and (not resume or stored > len(record.trials)):
            raise StorageUrlError(f"--storage {url}: holds a study {name!r} with {stored} "
                                  "trials of another run; name this one with --study")
        if mirror.metric_names is None:
            _name_metric(mirror)
        for key, value in record.user_attrs.items():
            mirror.set_user_attr(key, value)
        mirror.add_trials(record.get_trials(deepcopy=False)[stored:])
    return mirror


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


def run_study(study: TuneStudy, *, n_trials: int, executor,
              make_spec: Callable[[int, dict], TrialSpec], space: Mapping[str, Param],
              on_result: Callable[[TrialResult], None] | None = None,
              on_record: Callable[[Any], None] | None = None) -> int:
    """Fly trials until the record holds ``n_trials`` finished ones: ask up to
    :data:`ASK_AHEAD` ahead and submit them (the executor queues what its workers cannot
    start yet); as results come (``on_result``), tell the sampler and store the trials in
    trial-number order (``on_record`` with the stored trial), asking the next one after each
    tell — so the trials asked do not depend on which finished first (module docstring), and
    the record's numbers are the sampler's and ``--keep-runs``' folder names. Returns how
    many were flown now.

    Ctrl-C (or a terminating signal): nothing more is asked, the trials not started are
    cancelled, the running ones finish and are stored (a second Ctrl-C stops waiting); a trial
    that did not finish is stored as failed, keeping the numbering; then the interrupt is
    raised again.
    """
    from collections import deque

    from optuna.trial import TrialState

    todo = max(0, n_trials - len(finished_trials(study.record)))
    order: deque[int] = deque()                     # asked, not yet told, in ask order
    pending: dict[int, tuple[Any, TrialSpec, _dt.datetime]] = {}  # the same, by number
    finished: dict[int, tuple[TrialResult, _dt.datetime]] = {}    # result, when it came
    asked = flown = 0

    def fill() -> None:  # ask what the window allows (never depends on the workers)
        nonlocal asked
        while asked < todo and len(order) < ASK_AHEAD:
            trial = study.search.ask()
            spec = make_spec(trial.number, _suggest(trial, space))
            executor.submit(trial.number, run_trial, spec)
            order.append(trial.number)
            pending[trial.number] = (trial, spec, _now())
            asked += 1

    def finish(done) -> None:
        nonlocal flown
        _, spec, _ = pending[done.key]
        result = trial_result(spec, done.error, done.value)
        finished[done.key] = (result, _now())
        flown += 1
        if on_result is not None:
            on_result(result)

    def tell_in_order(*, unfinished_too: bool = False) -> None:
        """Tell and store the asked trials in ask order, up to the first still flying (or
        all: one that did not finish as failed, keeping the numbering), asking the next one
        after each."""
        while order and (unfinished_too or order[0] in finished):
            number = order.popleft()
            trial, _, started = pending.pop(number)
            if number in finished:
                result, ended = finished.pop(number)
                if math.isfinite(result.wall_s):  # its flights, not its wait in the queue
                    started = ended - _dt.timedelta(seconds=result.wall_s)
                attrs = _result_attr(result)
                trial.set_user_attr(RESULT_ATTR, attrs)
                told = study.search.tell(trial, result.score)
                stored = _stored(told.params, told.distributions, attrs, started, ended,
                                 value=result.score)
            else:
                study.search.tell(trial, state=TrialState.FAIL)
                stored = _stored(trial.params, trial.distributions,
                                 {"status": "failed", "message": "interrupted"}, started,
                                 _now(), state=TrialState.FAIL)
            study.add(stored)
            if on_record is not None:
                on_record(stored)
            if not unfinished_too:
                fill()

    try:
        fill()
        while executor.in_flight:
            finish(executor.next_done())
            tell_in_order()
    except KeyboardInterrupt:
        executor.cancel()
        try:
            while executor.in_flight:
                finish(executor.next_done())
        except KeyboardInterrupt:  # a second Ctrl-C: stop waiting
            pass
        tell_in_order(unfinished_too=True)
        raise
    return flown


def _now() -> _dt.datetime:
    return _dt.datetime.now()


def _result_attr(result: TrialResult) -> dict[str, Any]:
    return {"status": result.status, "message": result.message, "metrics": result.metrics,
            "wall_s": result.wall_s, "sim_s": result.sim_s}


def _stored(params, distributions, attrs: dict[str, Any], started: _dt.datetime,
            ended: _dt.datetime, **state):
    """The record's trial: the told values, the nested result and its metrics flat
    (:func:`~ardrone_nmpc.runs.tune_record.flat_metrics`), the time from its ask to its
    result (Optuna's duration)."""
    import optuna

    trial = optuna.trial.create_trial(params=params, distributions=distributions,
                                      user_attrs={RESULT_ATTR: attrs, **flat_metrics(attrs)},
                                      **state)
    trial.datetime_start, trial.datetime_complete = started, ended
    return trial


# ----------------------------------------------------------------------------- files


def trials_columns(space: Sequence[str], scenarios: Sequence[Scenario]) -> list[str]:
    """``trials.csv``'s header: trial, status, score, the parameters, wall_s, sim_s, then
    ``<scenario>:<metric>`` for every scenario and metric, then message."""
    return ["trial", "status", "score", *space, "wall_s", "sim_s",
            *(f"{s.label}:{m}" for s in scenarios for m in METRICS), "message"]


def _num(value: Any) -> str:
    from ardrone_nmpc.runs.rundir import format_number

    return "nan" if value is None else format_number(value)


def trial_row(t, space: Sequence[str], scenarios: Sequence[Scenario]) -> dict[str, str]:
    """The ``trials.csv`` row (text cells) of a finished trial."""
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
    return row


def trial_rows(study, space: Sequence[str], scenarios: Sequence[Scenario]) -> list[dict]:
    """One ``trials.csv`` row (text cells) per finished trial, in trial order."""
    return [trial_row(t, space, scenarios) for t in finished_trials(study)]


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
    return write_text_atomic(path, dump_config(best_cfg, header=header))


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
