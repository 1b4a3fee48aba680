"""The monotonic clock read inside compiled code (core/monotonic.py): the clock of
``time.perf_counter_ns``, in the same nanoseconds, and a kernel reading it is cached as any."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
import time

import pytest
from numba import njit

from ardrone_nmpc.core.monotonic import CLOCK_MONOTONIC, SAME_CLOCK, monotonic_ns


@njit
def _read():
    return monotonic_ns()


@njit
def _elapsed_ns(n):
    t0 = monotonic_ns()
    s = 0.0
    for i in range(n):
        s += i ** 0.5
    return monotonic_ns() - t0, s


# where the clock is not read (SAME_CLOCK False: not 64-bit Linux) the kernel answers −1
_LINUX = pytest.mark.skipif(not SAME_CLOCK, reason="the clock is read on (64-bit) Linux only")


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="CLOCK_MONOTONIC is Linux'")
def test_it_is_the_clock_of_perf_counter_ns():
    assert SAME_CLOCK and time.CLOCK_MONOTONIC == CLOCK_MONOTONIC
    _read()  # compiled first
    for _ in range(1000):  # each reading between Python's before and after it
        before = time.perf_counter_ns()
        now = _read()
        after = time.perf_counter_ns()
        assert before <= now <= after
        before = time.clock_gettime_ns(time.CLOCK_MONOTONIC)
        now = _read()
        assert before <= now <= time.clock_gettime_ns(time.CLOCK_MONOTONIC)


@_LINUX
def test_it_times_work_inside_a_kernel_in_nanoseconds():
    _elapsed_ns(10)
    before = time.perf_counter_ns()
    inside, _ = _elapsed_ns(2_000_000)
    outside = time.perf_counter_ns() - before
    assert 0 < inside <= outside  # the work alone: inside the call Python timed


_KERNEL = """
import time
from numba import njit
from ardrone_nmpc.core.monotonic import monotonic_ns

@njit(cache=True)
def now():
    return monotonic_ns()

before = time.perf_counter_ns()
t = now()
print("BRACKETED", before <= t <= time.perf_counter_ns())
"""


@_LINUX
def test_a_kernel_reading_it_is_cached_and_loads(tmp_path):
    (tmp_path / "clock_user.py").write_text(textwrap.dedent(_KERNEL))
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache"), "NUMBA_DEBUG_CACHE": "1",
           "PYTHONPATH": os.pathsep.join([str(tmp_path), *sys.path])}
    logs = [subprocess.run([sys.executable, "-c", "import clock_user"], env=env, cwd=tmp_path,
                           capture_output=True, text=True, timeout=300, check=True).stdout
            for _ in range(2)]
    assert "data saved to" in logs[0] and "BRACKETED True" in logs[0]
    assert "data saved to" not in logs[1] and "data loaded from" in logs[1]
    assert "BRACKETED True" in logs[1]  # the loaded code reads the clock too


def test_where_it_is_not_the_clock_no_call_is_emitted(monkeypatch):
    """Elsewhere (Windows: no clock_gettime, whose unresolved symbol kills the process when
    the kernel is linked; macOS: clock id 1 is none) the kernel answers −1 without a call."""
    from ardrone_nmpc.core import monotonic

    monkeypatch.setattr(monotonic, "SAME_CLOCK", False)

    @njit
    def read():  # compiled now, with the flag False
        return monotonic_ns()

    assert read() == -1
    assert "clock_gettime" not in read.inspect_llvm(read.signatures[0])
