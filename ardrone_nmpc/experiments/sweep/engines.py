"""Where a sweep's cases run: this process, a pool of local worker processes, or Dask.

:func:`iter_local` (in this process with ``jobs=1``, else a pool of long-lived worker
processes forked from a forkserver that loaded the numba kernels once) and :func:`iter_dask`
(a Dask cluster) run the same :func:`~ardrone_nmpc.experiments.sweep.cases.run_case` and
yield :class:`~ardrone_nmpc.experiments.sweep.cases.CaseResult` s as cases finish. Local
workers end with the sweep's process, even a SIGKILLed one. Dask workers need this package
and the sweep directory at the same path (a shared filesystem for a multi-machine cluster);
configs travel with the cases, resolved.
"""

from __future__ import annotations

import os
import signal
import threading
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from ardrone_nmpc.experiments.record import one_line
from ardrone_nmpc.experiments.sweep.cases import CaseResult, nan_metrics, run_case, warm_up
from ardrone_nmpc.experiments.sweep.status import DIVERGE_M

if TYPE_CHECKING:  # pragma: no cover
    from multiprocessing.connection import Connection

    from ardrone_nmpc.experiments.sweep.grid import Case

#: Exit status of a worker that found the sweep's process gone.
ORPHAN_EXIT = 70


def _init_worker(sweep_alive: Connection) -> None:
    """Pool worker start: Ctrl-C is the parent's to handle (it cancels the pending cases and
    lets the running ones finish), so workers ignore SIGINT; the worker ends with the
    sweep's process (:func:`_exit_with_sweep`); then load the kernels (a no-op when forked
    from the warm forkserver)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _exit_with_sweep(sweep_alive)
    warm_up()


def _exit_with_sweep(sweep_alive: Connection) -> None:
    """End this worker as soon as the sweep's process is gone, SIGKILL included.

    ``sweep_alive`` is the read end of a pipe whose only write end the sweep's process holds
    and never writes to: end-of-file means that process has died. The worker's parent is the
    forkserver, not the sweep, so its parent id says nothing; and once every worker is gone
    the forkserver (and the resource tracker) see their own pipes close and end too.
    """
    def wait() -> None:
        try:
            sweep_alive.recv_bytes()
        except (EOFError, OSError):
            pass
        os._exit(ORPHAN_EXIT)  # nothing to clean up: a re-run clears the case's staging dir

    threading.Thread(target=wait, name="sweep-alive", daemon=True).start()


def _pool_context():
    """A forkserver whose process has imported and warmed the kernels (see
    :mod:`ardrone_nmpc.experiments._sweep_preload`): workers fork from it warm, without
    inheriting the parent's threads (numba and ``fork`` of a threaded process do not mix).
    Spawn where there is no forkserver (Windows)."""
    import multiprocessing

    if "forkserver" not in multiprocessing.get_all_start_methods():
        return multiprocessing.get_context("spawn")
    ctx = multiprocessing.get_context("forkserver")
    ctx.set_forkserver_preload(["ardrone_nmpc.experiments._sweep_preload"])
    return ctx


def _noop() -> None:
    """A process that does nothing (see :func:`_start_forkserver`)."""


def _start_forkserver(ctx):
    """Start the warm forkserver now and wait for its warm-up, by starting a process that
    does nothing through it. A Ctrl-C during the wait then leaves nothing half-started (the
    pool's first worker would be, and would print a traceback when it finds its pool gone).
    Returns the process (join it later), or None with another start method."""
    if ctx.get_start_method() != "forkserver":
        return None
    process = ctx.Process(target=_noop, name="sweep-forkserver-warm-up")
    process.start()  # returns once the forkserver has forked it: after its preload
    return process


def _failed(case: Case, err: BaseException) -> CaseResult:
    return CaseResult(case.case_id, "failed", f"worker: {one_line(err)}", nan_metrics(),
                      case.case_id)


def iter_local(cases: Sequence[Case], *, out_dir: str | Path, jobs: int,
               diverge_m: float = DIVERGE_M) -> Iterator[CaseResult]:
    """Run ``cases`` on this machine and yield their results as they finish.

    ``jobs == 1``: one after another in this process. Otherwise a pool of ``min(jobs,
    len(cases))`` long-lived worker processes. Closing the generator (or Ctrl-C while it
    waits) cancels the cases not started and waits for the running ones.
    """
    out = str(Path(out_dir).resolve())
    if jobs == 1:
        for case in cases:
            yield run_case(case, out_dir=out, diverge_m=diverge_m)
        return
    from concurrent.futures import ProcessPoolExecutor, as_completed

    ctx = _pool_context()
    warm = _start_forkserver(ctx)
    sweep_alive, alive_w = ctx.Pipe(duplex=False)  # alive_w: only this process holds it
    pool = ProcessPoolExecutor(max(1, min(jobs, len(cases))), mp_context=ctx,
                               initializer=_init_worker, initargs=(sweep_alive,))
    futures = {}
    try:
        for case in cases:
            futures[pool.submit(run_case, case, out_dir=out, diverge_m=diverge_m)] = case
        for future in as_completed(futures):
            try:
                yield future.result()
            except Exception as err:  # noqa: BLE001 - a dead worker fails its case
                yield _failed(futures[future], err)
    finally:
        pool.shutdown(wait=True, cancel_futures=True)
        if warm is not None:
            warm.join()
        sweep_alive.close()
        alive_w.close()  # after the workers have ended: closing it would end them


def _dask_client(*, scheduler: str | None, jobs: int):
    """(client, cluster or None): a client of ``scheduler``, or of a new local cluster of
    ``jobs`` single-threaded worker processes bound to 127.0.0.1 without a dashboard."""
    import logging

    from dask.distributed import Client, LocalCluster

    if scheduler is not None:
        return Client(scheduler, timeout="10s"), None
    cluster = LocalCluster(n_workers=jobs, threads_per_worker=1, processes=True,
                           host="127.0.0.1", dashboard_address=None,
                           silence_logs=logging.ERROR)
    try:
        return Client(cluster), cluster
    except BaseException:
        cluster.close()
        raise


def iter_dask(cases: Sequence[Case], *, out_dir: str | Path, jobs: int,
              scheduler: str | None = None,
              diverge_m: float = DIVERGE_M) -> Iterator[CaseResult]:
    """Run ``cases`` on a Dask cluster (``scheduler`` address, or a local cluster of
    ``jobs`` workers) and yield their results as they finish. ``out_dir`` must be reachable
    at the same path from every worker (a shared filesystem for a multi-machine cluster),
    and the workers need this package installed. Closing the generator cancels the rest."""
    import uuid

    from dask.distributed import as_completed

    out = str(Path(out_dir).resolve())
    client, cluster = _dask_client(scheduler=scheduler, jobs=max(1, min(jobs, len(cases))))
    token = uuid.uuid4().hex[:8]  # keys unique on a scheduler shared by several sweeps
    futures = {}
    try:
        for case in cases:
            future = client.submit(run_case, case, out_dir=out, diverge_m=diverge_m,
                                   key=f"sweep-{token}-{case.case_id}", pure=False)
            futures[future.key] = (future, case)
        for future in as_completed([f for f, _ in futures.values()]):
            try:
                yield future.result()
            except Exception as err:  # noqa: BLE001 - a lost worker fails its case
                yield _failed(futures[future.key][1], err)
    finally:
        client.cancel([f for f, _ in futures.values()])
        client.close()
        if cluster is not None:
            cluster.close()
