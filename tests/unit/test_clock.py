"""Rate on a manual clock: deadlines are absolute, overruns skip and count."""

import pytest

from ardrone_nmpc.core.clock import Rate
from tests.conftest import ManualClock


def test_deadlines_do_not_drift_with_work_time():
    clock = ManualClock()
    rate = Rate(0.065, clock=clock, sleep_fn=clock.sleep)
    wakes = []
    for k in range(100):
        rate.sleep()
        wakes.append(clock.t)
        clock.t += 0.01 + 0.001 * (k % 7)  # variable work inside the tick
    assert wakes[-1] == pytest.approx(100.0 + 100 * 0.065, abs=1e-9)
    assert rate.overruns == 0
    assert max(rate.lateness_s) == pytest.approx(0.0, abs=1e-12)


def test_overrun_skips_missed_deadlines_and_counts_them():
    clock = ManualClock()
    rate = Rate(0.1, clock=clock, sleep_fn=clock.sleep)
    rate.sleep()  # wakes at 100.1
    clock.t += 0.35  # the tick took 3.5 periods: deadlines 100.2, 100.3, 100.4 are gone
    rate.sleep()
    assert rate.overruns == 3
    assert clock.t == pytest.approx(100.5, abs=1e-9)  # no burst: the next live deadline
    assert rate.index == 4  # deadlines 1, 2, 3 were skipped: loop time stays wall time


def test_jitter_reports_lateness_in_ms():
    clock = ManualClock()
    late_sleep = lambda dt: clock.sleep(dt + 0.002)  # an OS that wakes 2 ms late
    rate = Rate(0.065, clock=clock, sleep_fn=late_sleep)
    for _ in range(10):
        rate.sleep()
    assert rate.jitter_ms()["p50"] == pytest.approx(2.0, abs=1e-6)


def test_bad_period_is_rejected():
    with pytest.raises(ValueError, match="period_s"):
        Rate(0.0)
