"""The one parallel executor of the commands that fly many lockstep cases (``sweep``, ``tune``,
``faults --jobs``): in this process, on a pool of local worker processes, or on Dask.

    with open_executor("local", jobs=4) as ex:          # or "dask", scheduler=…
        for done in ex.map(run_case, cases, key=lambda c: c.case_id, out_dir=out):
            ...            # in the order of `cases`: done.key, done.value or done.error

or, for work that is asked for as slots free up (``tune``'s ask/tell), :meth:`Executor.submit`
and :meth:`Executor.next_done` (completion order). A function and its arguments must be
picklable (a top-level function); an exception in it, or a worker that died, comes back as
:attr:`Done.error` rather than being raised.

Leaving the ``with`` block — normally, on an error, or on Ctrl-C / SIGTERM (which the command
line turns into ``KeyboardInterrupt``) — cancels what has not started and waits for what is
running on the pool (its workers ignore SIGINT: a case in flight finishes and is kept), cancels
everything on Dask; :meth:`Executor.cancel` does the first part on demand.

* ``local``, ``jobs == 1``: one case after another in this process.
* ``local``, ``jobs > 1``: long-lived worker processes forked from a forkserver that loaded the
  numba kernels once (warmed in the background from :func:`open_executor` on, so the caller can
  prepare meanwhile — or from :func:`start_forkserver` on, earlier still); they end with this
  process, even a SIGKILLed one.
* ``dask``: a Dask cluster (``scheduler``'s address, or a local cluster of ``jobs`` workers on
  127.0.0.1). Connecting gives up after :data:`CONNECT_TIMEOUT_S` — also on a port that accepts
  and never answers — with a :class:`ExecutorError`. The workers need this package, and any
  output directory at the same path.
"""

from __future__ import annotations

import os
import queue
import signal
import threading
from collections import deque
from collections.abc import Callable, Hashable, Iterable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

from ardrone_nmpc.errors import UserError

__all__ = ["CONNECT_TIMEOUT_S", "ENGINES", "Done", "Executor", "ExecutorError", "ORPHAN_EXIT",
           "engine_errors", "open_executor", "start_forkserver"]

ENGINES = ("local", "dask")
#: How long a Dask scheduler has to answer (s).
CONNECT_TIMEOUT_S = 10.0
#: Exit status of a pool worker that found its parent process gone.
ORPHAN_EXIT = 70
_PRELOAD = "ardrone_nmpc.experiments._sweep_preload"
#: How often a pool waiting for a result looks for one whose notice an interrupt took (s).
_RESCAN_S = 1.0
_GONE = object()


class ExecutorError(UserError, RuntimeError):
    """The engine cannot run (no Dask scheduler at the address, …): one line, exit 1."""


@dataclass(frozen=True)
class Done:
    """A finished case: its ``key``, what the function returned (``value``), or why it has
    none (``error``: the function's exception, a dead worker, a cancellation)."""

    key: Hashable
    value: Any = None
    error: BaseException | None = None

    @classmethod
    def of_future(cls, key: Hashable, future) -> Done:
        """The case ``key`` of a finished pool future: its result, or the exception it raised
        (a dead or lost worker, a cancellation fails its case)."""
        try:
            return cls(key, future.result())
        except Exception as err:  # noqa: BLE001 - whatever ended the worker fails the case
            return cls(key, error=err)


def engine_errors(*, engine: str, scheduler: str | None) -> list[str]:
    """The ``--engine`` / ``--scheduler`` mistakes, one ``--option: message`` line each."""
    import importlib.util

    errors = []
    if engine not in ENGINES:
        errors.append(f"--engine: unknown engine {engine!r}; choose {', '.join(ENGINES)}")
    if scheduler is not None and engine != "dask":
        errors.append("--scheduler: only with --engine dask")
    if engine == "dask" and importlib.util.find_spec("distributed") is None:
        errors.append("--engine dask: needs dask.distributed "
                      "(pip install 'ardrone-nmpc[distributed]')")
    return errors


class Executor:
    """Runs ``fn(*args, **kwargs)`` on ``slots`` workers (see the module docstring).

    A case leaves :attr:`in_flight` the moment the engine hands it over, in one step, so an
    interrupt at any point can lose at most the one result being handed over — never leave a
    case counted that will not come (a caller draining after Ctrl-C would wait for ever).
    """

    slots = 1

    def submit(self, key: Hashable, fn: Callable[..., Any], *args: Any, **kwargs: Any) -> None:
        """Start ``fn(*args, **kwargs)`` (queued when every worker is busy); ``key`` names it
        in :class:`Done` and must be unique among the cases in flight."""
        self._submit(key, fn, args, kwargs)

    @property
    def in_flight(self) -> int:
        """Cases submitted and not yet handed over by :meth:`next_done` (or cancelled)."""
        raise NotImplementedError

    def next_done(self) -> Done:
        """The next case to finish (blocks). ValueError when none is in flight."""
        if not self.in_flight:
            raise ValueError("no case in flight")
        return self._next()

    def map(self, fn: Callable[..., Any], items: Iterable[Any], *,
            key: Callable[[Any], Hashable] | None = None, **kwargs: Any) -> Iterator[Done]:
        """Submit ``fn(item, **kwargs)`` for every item (named ``key(item)``, default the item
        itself) and yield the results in the items' order: a case that finished early waits
        for the ones before it, while every worker stays busy."""
        order = []
        for item in items:
            name = item if key is None else key(item)
            self.submit(name, fn, item, **kwargs)
            order.append(name)
        waiting: dict[Hashable, Done] = {}
        for name in order:
            while name not in waiting:
                done = self.next_done()
                waiting[done.key] = done
            yield waiting.pop(name)

    def cancel(self) -> list[Hashable]:
        """Cancel the cases that have not started; return their keys."""
        return self._cancel()

    def close(self) -> None:
        """Cancel what has not started, wait for what runs (pool) or cancel it (Dask)."""

    # the engines
    def _submit(self, key, fn, args, kwargs) -> None:
        raise NotImplementedError

    def _next(self) -> Done:
        raise NotImplementedError

    def _cancel(self) -> list[Hashable]:
        return []


class _Inline(Executor):
    """One case after another in this process, each run by :meth:`next_done`."""

    def __init__(self) -> None:
        self._queue: deque[tuple] = deque()

    @property
    def in_flight(self) -> int:
        return len(self._queue)

    def _submit(self, key, fn, args, kwargs) -> None:
        self._queue.append((key, fn, args, kwargs))

    def _next(self) -> Done:
        key, fn, args, kwargs = self._queue.popleft()  # a Ctrl-C in fn: no longer in flight
        try:
            return Done(key, fn(*args, **kwargs))
        except Exception as err:  # noqa: BLE001 - a failed case is a result
            return Done(key, error=err)

    def _cancel(self) -> list[Hashable]:
        keys = [item[0] for item in self._queue]
        self._queue.clear()
        return keys

    def close(self) -> None:
        self.cancel()


# ----------------------------------------------------------------------------- local pool


def _init_worker(parent_alive) -> None:
    """Pool worker start: Ctrl-C is the parent's to handle (it cancels the pending cases and
    lets the running ones finish), so workers ignore SIGINT; the worker ends with the parent
    (:func:`_exit_with_parent`); then the kernels are loaded (the preload module: a no-op when
    forked from the warm forkserver, which imported it already)."""
    import importlib

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _exit_with_parent(parent_alive)
    importlib.import_module(_PRELOAD)


def _exit_with_parent(parent_alive) -> None:
    """End this worker as soon as the parent process is gone, SIGKILL included.

    ``parent_alive`` is the read end of a pipe whose only write end the parent holds and never
    writes to: end-of-file means it has died. The worker's parent is the forkserver, not the
    command, so its parent id says nothing; once every worker is gone the forkserver (and the
    resource tracker) see their own pipes close and end too.
    """
    def wait() -> None:
        try:
            parent_alive.recv_bytes()
        except (EOFError, OSError):
            pass
        os._exit(ORPHAN_EXIT)  # nothing to clean up: a re-run clears a case's staging dir

    threading.Thread(target=wait, name="parent-alive", daemon=True).start()


def _pool_context():
    """A forkserver whose process has imported and warmed the kernels: workers fork from it
    warm, without inheriting the parent's threads (numba and ``fork`` of a threaded process
    do not mix). Spawn where there is no forkserver (Windows)."""
    import multiprocessing

    if "forkserver" not in multiprocessing.get_all_start_methods():
        return multiprocessing.get_context("spawn")
    ctx = multiprocessing.get_context("forkserver")
    ctx.set_forkserver_preload([_PRELOAD])
    return ctx


def start_forkserver() -> None:
    """Start the warm forkserver now: its preload (~0.7 s on cached kernels, most of it
    imports and numba's own set-up) runs on another core while this process goes on, and a
    pool opened later forks its workers from it. For a command that will open a local pool,
    as early as it knows so (``cli/launch.py``); harmless when none is opened after all: the
    forkserver ends when this process exits (:func:`_end_unused_forkserver`). Nothing to
    start where workers spawn (no forkserver)."""
    ctx = _pool_context()
    if ctx.get_start_method() == "forkserver":
        import atexit
        from multiprocessing import forkserver

        forkserver.ensure_running()
        atexit.register(_end_unused_forkserver)


#: Whether this process opened a local pool (:class:`_Pool`): its forkserver is in use.
_pool_opened = False


def _end_unused_forkserver() -> None:
    """At exit, end the forkserver :func:`start_forkserver` started if no pool used it: it
    holds this process's stdout and stderr, so a caller reading them through a pipe would
    otherwise wait out its preload (seconds on a cold numba cache) after a command that
    stopped at once. SIGTERM: the preload (_sweep_preload) ends on it, cleaning up."""
    from multiprocessing import forkserver

    pid = forkserver._forkserver._forkserver_pid
    if _pool_opened or pid is None:
        return
    try:
        if os.waitpid(pid, os.WNOHANG)[0] == 0:  # our child, running (so not a reused pid)
            os.kill(pid, signal.SIGTERM)
    except OSError:  # not our child (any more)
        pass


def _noop() -> None:
    """A process that does nothing (see :meth:`_Pool._start`)."""


class _Pool(Executor):
    """``slots`` worker processes forked from a warm forkserver."""

    def __init__(self, jobs: int) -> None:
        global _pool_opened
        _pool_opened = True  # its forkserver stays (_end_unused_forkserver)
        self.slots = jobs
        self._ctx = _pool_context()
        self._alive_r, self._alive_w = self._ctx.Pipe(duplex=False)  # only we hold _w
        self._warm = None
        self._pool = None
        self._futures: dict[Any, Hashable] = {}
        self._finished: queue.SimpleQueue = queue.SimpleQueue()  # futures, as they finish
        self._starter = threading.Thread(target=self._start, name="forkserver-warm-up",
                                         daemon=True)
        self._starter.start()

    def _start(self) -> None:
        """Start the warm forkserver and wait for its preload, by starting a process that
        does nothing through it (a Ctrl-C meanwhile then leaves nothing half-started)."""
        if self._ctx.get_start_method() == "forkserver":
            process = self._ctx.Process(target=_noop, name="forkserver-warm-up")
            process.start()  # returns once the forkserver has forked it: after its preload
            self._warm = process

    def _ready(self):
        if self._pool is None:
            from concurrent.futures import ProcessPoolExecutor

            self._starter.join()
            self._pool = ProcessPoolExecutor(self.slots, mp_context=self._ctx,
                                             initializer=_init_worker,
                                             initargs=(self._alive_r,))
        return self._pool

    @property
    def in_flight(self) -> int:
        return len(self._futures)

    def _submit(self, key, fn, args, kwargs) -> None:
        future = self._ready().submit(fn, *args, **kwargs)
        self._futures[future] = key
        future.add_done_callback(self._finished.put)

    def _next(self) -> Done:
        while True:
            try:
                future = self._finished.get(timeout=_RESCAN_S)
            except queue.Empty:  # a notice taken by a Ctrl-C before it was handled: look
                future = next((f for f in list(self._futures) if f.done()), None)
            key = self._futures.pop(future, _GONE) if future is not None else _GONE
            if key is not _GONE:  # (a cancelled future is reported too: not ours any more)
                break
        return Done.of_future(key, future)

    def _cancel(self) -> list[Hashable]:
        cancelled = [f for f in self._futures if f.cancel()]
        return [self._futures.pop(f) for f in cancelled]

    def close(self) -> None:
        self._starter.join()
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
        if self._warm is not None:
            self._warm.join()
        self._alive_r.close()
        self._alive_w.close()  # after the workers have ended: closing it would end them


# ----------------------------------------------------------------------------- Dask


def _dask_client(*, scheduler: str | None, jobs: int):
    """(client, cluster or None): a client of ``scheduler`` — :class:`ExecutorError` if it
    does not answer within :data:`CONNECT_TIMEOUT_S` — or of a new local cluster of ``jobs``
    single-threaded worker processes bound to 127.0.0.1 without a dashboard."""
    import logging

    from dask.distributed import Client, LocalCluster

    if scheduler is None:
        cluster = LocalCluster(n_workers=jobs, threads_per_worker=1, processes=True,
                               host="127.0.0.1", dashboard_address=None,
                               silence_logs=logging.ERROR)
        try:
            return Client(cluster), cluster
        except BaseException:
            cluster.close()
            raise
    # Client's own timeout does not cover a port that accepts and never answers: wait for it
    # on a thread that is left behind (a daemon) if the scheduler never answers
    box: dict[str, Any] = {}

    def connect() -> None:
        try:
            box["client"] = Client(scheduler, timeout=f"{CONNECT_TIMEOUT_S:g}s")
        except BaseException as err:  # noqa: BLE001 - reported on the caller's thread
            box["error"] = err

    thread = threading.Thread(target=connect, name="dask-connect", daemon=True)
    thread.start()
    thread.join(CONNECT_TIMEOUT_S + 5.0)
    if "client" in box:
        return box["client"], None
    err = box.get("error")
    why = (" ".join(str(err).split()) or type(err).__name__) if err is not None else \
        f"no answer within {CONNECT_TIMEOUT_S:g} s"
    raise ExecutorError(f"--engine dask: no Dask scheduler answers at {scheduler}: {why}")


class _Dask(Executor):
    """Cases on a Dask cluster; its slots are the cluster's worker threads."""

    def __init__(self, jobs: int, scheduler: str | None) -> None:
        import uuid  # here: the entry point imports this module first (cli/launch.py)

        from dask.distributed import as_completed

        self._client, self._cluster = _dask_client(scheduler=scheduler, jobs=jobs)
        info = self._client.scheduler_info()
        workers = info.get("workers", {}) if isinstance(info, dict) else {}
        self.slots = max(1, sum(int(w.get("nthreads", 1)) for w in workers.values()) or jobs)
        self._token = uuid.uuid4().hex[:8]  # keys unique on a scheduler shared by commands
        self._done = as_completed(loop=self._client.loop)
        self._futures: dict[str, tuple[Any, Hashable]] = {}

    @property
    def in_flight(self) -> int:
        return len(self._futures)

    def _submit(self, key, fn, args, kwargs) -> None:
        name = f"{getattr(fn, '__name__', 'case')}-{self._token}-{key}"
        future = self._client.submit(fn, *args, key=name, pure=False, **kwargs)
        self._futures[name] = (future, key)
        self._done.add(future)

    def _next(self) -> Done:
        while True:
            if all(f.done() for f, _ in self._futures.values()):  # (after a cancel) no wait
                future = next(iter(self._futures.values()))[0]
            else:
                future = next(self._done)
            entry = self._futures.pop(future.key, None)
            if entry is not None:  # (one taken before, or cancelled: skipped)
                key = entry[1]
                break
        return Done.of_future(key, future)

    def _cancel(self) -> list[Hashable]:
        futures = [f for f, _ in self._futures.values() if not f.done()]
        self._client.cancel(futures)
        keys = [self._futures.pop(f.key)[1] for f in futures]
        return keys

    def close(self) -> None:
        try:
            self._client.cancel([f for f, _ in self._futures.values()])
        finally:
            self._client.close()
            if self._cluster is not None:
                self._cluster.close()


@contextmanager
def open_executor(engine: str = "local", *, jobs: int = 1,
                  scheduler: str | None = None) -> Iterator[Executor]:
    """The executor of ``engine`` with ``jobs`` workers, closed on leaving (module docstring).
    Raises :class:`ExecutorError` when a Dask scheduler cannot be reached."""
    if engine == "dask":
        try:
            executor: Executor = _Dask(jobs, scheduler)
        except (OSError, TimeoutError, ValueError) as err:
            raise ExecutorError(f"--engine dask: {' '.join(str(err).split())}") from None
    else:
        executor = _Inline() if jobs == 1 else _Pool(jobs)
    try:
        yield executor
    finally:
        executor.close()
