"""The one parallel executor (experiments/parallel.py): results in submission order, errors as
results, cancellation, the worker watch, Dask's connect timeout; and deferred signals."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from ardrone_nmpc.experiments import parallel
from ardrone_nmpc.experiments.parallel import ExecutorError, open_executor
from ardrone_nmpc.runtime.signals import Terminated, deferred_signals


def _wait_then(item: tuple[str, str | None, str | None]) -> str:
    """Wait for the file ``after`` (if any), then create ``make`` (if any); return ``name``."""
    name, after, make = item
    deadline = time.monotonic() + 60
    while after is not None and not Path(after).exists():
        if time.monotonic() > deadline:
            raise TimeoutError(f"{after} never appeared")
        time.sleep(0.01)
    if make is not None:
        Path(make).touch()
    return name


def _fails(item: str) -> str:
    if item == "bad":
        raise ValueError("a bad case")
    return item.upper()


@pytest.mark.timeout(120)
@pytest.mark.parametrize("jobs", [1, 2])
def test_map_yields_in_submission_order_whatever_finishes_first(tmp_path, jobs):
    first_done = tmp_path / "second-finished"
    # on two workers the first case cannot finish before the second has
    items = [("first", str(first_done) if jobs > 1 else None, None),
             ("second", None, str(first_done))]
    with open_executor("local", jobs=jobs) as executor:
        done = list(executor.map(_wait_then, items, key=lambda i: i[0]))
    assert [(d.key, d.value, d.error) for d in done] == [("first", "first", None),
                                                        ("second", "second", None)]
    assert first_done.exists()


@pytest.mark.timeout(120)
@pytest.mark.parametrize("jobs", [1, 2])
def test_an_exception_in_a_case_is_its_result_not_the_callers(jobs):
    with open_executor("local", jobs=jobs) as executor:
        done = {d.key: d for d in executor.map(_fails, ["a", "bad", "c"])}
    assert done["a"].value == "A" and done["c"].value == "C"
    assert isinstance(done["bad"].error, ValueError) and done["bad"].value is None


@pytest.mark.timeout(120)
def test_cancel_drops_the_cases_not_started_and_the_running_one_finishes(tmp_path):
    release = tmp_path / "release"
    items = [(f"case{i}", str(release), str(tmp_path / f"ran{i}")) for i in range(6)]
    with open_executor("local", jobs=1) as inline:  # one after another: none has started
        for item in items:
            inline.submit(item[0], _wait_then, item)
        assert sorted(inline.cancel()) == [i[0] for i in items] and inline.in_flight == 0
    with open_executor("local", jobs=2) as pool:
        for item in items:
            pool.submit(item[0], _wait_then, item)
        while not any(p.name.startswith("ran") for p in tmp_path.iterdir()) and \
                not _workers_busy(pool):
            time.sleep(0.01)
        cancelled = pool.cancel()
        release.touch()
        finished = [pool.next_done() for _ in range(pool.in_flight)]
    assert cancelled and not set(cancelled) & {d.key for d in finished}
    assert all(d.error is None for d in finished)
    ran = {p.name for p in tmp_path.iterdir() if p.name.startswith("ran")}
    assert ran == {f"ran{k[4:]}" for k in (d.key for d in finished)}  # cancelled: never ran


def _parent_pid(_item) -> int:
    return os.getppid()


@pytest.mark.timeout(120)
def test_a_pool_forks_its_workers_from_the_forkserver_started_early():
    """start_forkserver (the entry point's early start) and a pool opened later: one
    forkserver, the workers' parent."""
    from multiprocessing import forkserver

    parallel.start_forkserver()
    server = forkserver._forkserver._forkserver_pid
    assert server is not None
    with open_executor("local", jobs=2) as pool:
        parents = {d.value for d in pool.map(_parent_pid, range(4))}
    assert parents == {server} and forkserver._forkserver._forkserver_pid == server


def _workers_busy(pool) -> bool:
    return sum(f.running() for f in pool._futures) >= 2


def test_a_pool_worker_ends_when_its_parent_s_pipe_closes():
    """The watch: running while the parent holds the pipe's write end, exit ORPHAN_EXIT once
    it is closed (what the kernel does when the parent dies, SIGKILL included)."""
    code = ("import sys, time\n"
            "from multiprocessing.connection import Connection\n"
            "from ardrone_nmpc.experiments.parallel import _exit_with_parent\n"
            "_exit_with_parent(Connection(int(sys.argv[1]), writable=False))\n"
            "print('watching', flush=True)\n"
            "time.sleep(120)\n")
    read_fd, write_fd = os.pipe()
    worker = subprocess.Popen([sys.executable, "-c", code, str(read_fd)], pass_fds=(read_fd,),
                              stdout=subprocess.PIPE)
    os.close(read_fd)
    try:
        assert worker.stdout.readline() == b"watching\n"
        os.close(write_fd)
        write_fd = None
        assert worker.wait(timeout=60) == parallel.ORPHAN_EXIT
    finally:
        if write_fd is not None:
            os.close(write_fd)
        if worker.poll() is None:
            worker.kill()
        worker.stdout.close()


@pytest.mark.timeout(60)
def test_a_dask_scheduler_that_accepts_and_never_answers_times_out(monkeypatch):
    import socket

    monkeypatch.setattr(parallel, "CONNECT_TIMEOUT_S", 1.0)
    with socket.socket() as silent:
        silent.bind(("127.0.0.1", 0))
        silent.listen()
        address = f"tcp://127.0.0.1:{silent.getsockname()[1]}"
        with pytest.raises(ExecutorError, match="no answer within 1 s"):
            with open_executor("dask", jobs=1, scheduler=address):
                pass


@pytest.mark.parametrize("sig, raised", [(signal.SIGINT, KeyboardInterrupt),
                                         (signal.SIGTERM, Terminated)])
def test_a_signal_inside_deferred_signals_waits_for_the_block_to_end(sig, raised):
    steps = []
    before = signal.getsignal(sig)
    with pytest.raises(raised):
        with deferred_signals():
            os.kill(os.getpid(), sig)
            time.sleep(0.05)   # a handler would have run by now
            steps.append("the write completed")
    assert steps == ["the write completed"]
    assert signal.getsignal(sig) is before  # the handler in force before is back
