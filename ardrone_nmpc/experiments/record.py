"""Fly a config into a run directory, then summarise it: the one recording of every caller.

``simulate``, ``sweep``, ``faults`` and ``reproduce`` fly the lockstep simulation through
:func:`record_lockstep`; ``fly`` records a real-time flight through :func:`record`
(:func:`~ardrone_nmpc.experiments.flight.run_flight`); ``replay --rerun`` records its
recomputed ticks through :func:`record`. A run directory's ``summary.csv`` is written last
(:func:`~ardrone_nmpc.runs.summary.write_run_summary`), so its presence marks a recording
that finished. A flight that raises leaves its partial run directory with a final
``exception`` event and no ``summary.csv`` (``fly`` summarises it all the same); one stopped
by Ctrl-C or a terminating signal, with a final ``interrupted`` event
(:mod:`ardrone_nmpc.runs.ending`).

The simulation and the summary are imported when a recording starts: ``sweep`` (and
``plot``, through the sweep table) import this module without loading the solver kernels.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Generic, TypeVar

from ardrone_nmpc.runs.ending import FAILED_EVENT, note_interrupted
from ardrone_nmpc.runs.rundir import RunRecorder
from ardrone_nmpc.runtime.schedule import Schedule

if TYPE_CHECKING:  # pragma: no cover
    from ardrone_nmpc.config.schema import ExperimentConfig
    from ardrone_nmpc.runs.rundir import RunData
    from ardrone_nmpc.runs.summary import SummaryRow
    from ardrone_nmpc.runtime.lockstep import SimResult

T = TypeVar("T")

#: The event that ends a lockstep recording (wall time, ticks, how it ended).
SIMULATED_EVENT = "simulated"
#: A lockstep recording hands its rows to the OS in blocks of up to this many (~1000 rows a
#: second of wall time: the block's text is printed by one call; ``RunRecorder.write_row``).
LOCKSTEP_ROWS_PER_WRITE = 64


@dataclass(frozen=True)
class Recording(Generic[T]):
    """A run directory as a recording left it.

    Attributes
    ----------
    path : the run directory.
    result : what the flight returned (a :class:`~ardrone_nmpc.runtime.lockstep.SimResult`
        for :func:`record_lockstep`); None if it raised.
    error : the flight's exception on one line (``Type: message``); empty if it flew.
    wall_s : wall time from the start of the recording to the end of the flight (s; the
        kernels' loading or compilation included).
    run : the run read back for the summary (None if the flight raised).
    summary : the rows written to ``summary.csv`` (empty if the flight raised).
    """

    path: Path
    result: T | None
    error: str = ""
    wall_s: float = math.nan
    run: RunData | None = None
    summary: list[SummaryRow] = field(default_factory=list)


def one_line(err: BaseException) -> str:
    """``Type: message`` with the message's whitespace (line breaks too) collapsed."""
    text = " ".join(str(err).split())
    return f"{type(err).__name__}: {text}" if text else type(err).__name__


def record(cfg: ExperimentConfig, log_dir: str | Path, *, seed: int | None,
           fly: Callable[[RunRecorder], T], catch: bool = False,
           summarise_failed: Callable[[Path], None] | None = None,
           rows_per_write: int = 1, durable: bool = True,
           name: str | None = None) -> Recording[T]:
    """Create a run directory for ``cfg`` under ``log_dir``, run ``fly(recorder)`` into it,
    then write its ``summary.csv``.

    If ``fly`` raises (an ``Exception``), the :data:`FAILED_EVENT` ends ``events.jsonl``
    (``t_s`` NaN), no summary is written — unless ``summarise_failed(path)`` writes one: a
    real flight's run directory is complete however it ended — and the exception propagates
    — or, with ``catch``, comes back as :attr:`Recording.error`. A Ctrl-C or terminating
    signal ends it with the ``interrupted`` event and propagates (never caught), carrying
    the run directory as ``run_dir``. ``rows_per_write``, ``durable`` and ``name``: see
    :meth:`~ardrone_nmpc.runs.rundir.RunRecorder.create`.
    """
    from ardrone_nmpc.runs.summary import write_run_summary  # when used (module docstring)

    wall0 = time.perf_counter()
    with RunRecorder.create(log_dir, cfg, seed=seed, rows_per_write=rows_per_write,
                            durable=durable, name=name) as recorder:
        try:
            result = fly(recorder)
        except BaseException as err:
            if isinstance(err, KeyboardInterrupt):  # Ctrl-C, or a signal (runtime/signals)
                note_interrupted(recorder, err)
                err.run_dir = recorder.path
            elif isinstance(err, Exception):
                recorder.event(math.nan, FAILED_EVENT, error=one_line(err))
            recorder.close()
            if summarise_failed is not None:
                summarise_failed(recorder.path)
            if not catch or not isinstance(err, Exception):
                raise
            return Recording(recorder.path, None, one_line(err), time.perf_counter() - wall0)
        wall_s = time.perf_counter() - wall0
    run, rows = write_run_summary(recorder.path, columns=recorder.kept_columns(),
                                  config=recorder.config, durable=durable)
    return Recording(recorder.path, result, "", wall_s, run, rows)


def record_lockstep(cfg: ExperimentConfig, log_dir: str | Path, *, seed: int | None = None,
                    progress: Callable[[float], None] | None = None,
                    catch: bool = False, live=None, plant=None,
                    name: str | None = None) -> Recording[SimResult]:
    """Fly ``cfg`` in the lockstep simulation into a new run directory under ``log_dir`` and
    summarise it (see :func:`record`).

    ``seed`` (default ``sim.seed``) is written into the run's ``config.yaml``, so the run
    directory reproduces the flight. ``events.jsonl`` ends with :data:`SIMULATED_EVENT`,
    stamped with the experiment time at which the simulation ended (touch-down, or rest
    after an emergency stop): ``wall_s``, ``ticks``, ``ending``, ``final_mode``.
    ``progress(fraction)`` is called every tick. ``live`` (a
    :class:`~ardrone_nmpc.viz.live.LiveView`) sees every row and event too. ``plant`` flies
    another airframe (see :func:`~ardrone_nmpc.runtime.lockstep.run_lockstep`). ``name``:
    the run directory's own name (:meth:`~ardrone_nmpc.runs.rundir.RunRecorder.create`).

    Raises :class:`~ardrone_nmpc.runtime.schedule.ScheduleError` before any directory is
    created for times that give no tick count, and
    :class:`~ardrone_nmpc.reference.trajectories.ReferenceError` for a reference that leaves
    the geofence.
    """
    from ardrone_nmpc.reference.experiment import experiment_trajectory
    from ardrone_nmpc.runtime import lockstep  # when used (module docstring)

    Schedule.from_config(cfg)  # refused before a run directory exists
    trajectory = experiment_trajectory(cfg)  # so is a reference outside the geofence
    if cfg.reference.kind == "follow":
        trajectory = None  # a live object, with its state: the flight makes its own
    seed = cfg.sim.seed if seed is None else seed
    if seed != cfg.sim.seed:
        cfg = cfg.model_copy(update={"sim": cfg.sim.model_copy(update={"seed": seed})})
    wall0 = time.perf_counter()

    def fly(recorder: RunRecorder) -> SimResult:
        sink = live.tee(recorder) if live is not None else recorder
        # the run flies its own copy of its input files (the path CSV in the run directory);
        # without any, the config itself, whose reference was made above
        same = recorder.config is cfg
        result = lockstep.run_lockstep(recorder.config, recorder=sink, seed=seed,
                                       progress=progress, plant=plant,
                                       trajectory=trajectory if same else None)
        recorder.event(result.end_t_s, SIMULATED_EVENT, wall_s=time.perf_counter() - wall0,
                       ticks=result.ticks, ending=result.ending,
                       final_mode=result.final_mode.value)
        return result

    # a simulation flies again bit for bit from its config.yaml: no fsync (RunRecorder.create)
    return record(cfg, log_dir, seed=seed, fly=fly, catch=catch,
                  rows_per_write=LOCKSTEP_ROWS_PER_WRITE, durable=False, name=name)
