"""DelayPrediction's ring of inputs sent against the deque it replaced: the same inputs, in
the same order, reach the rollout — the same bits — whatever the delay set since."""

from __future__ import annotations

import copy
import pickle
from collections import deque

import numpy as np
import pytest

from ardrone_nmpc.control.kernels import rollout_rk4
from ardrone_nmpc.runtime.stages import DelayPrediction

PERIOD_S = 0.065


def _sent(pending: deque, n: int) -> np.ndarray:
    """The last ``n`` inputs of the deque, oldest first, zeros for those not sent yet."""
    sent = np.zeros((n, 4))
    last = list(pending)[-n:]
    sent[n - len(last):] = last
    return sent


def _reference(pending: deque, n: int, capacity: int, x: np.ndarray) -> np.ndarray:
    """The deque version: the last ``n`` inputs, zeros (hover) for those not sent yet."""
    sent = np.zeros((capacity, 4))[:n]
    last = list(pending)[-n:]
    missing = n - len(last)
    sent[:missing] = 0.0
    for k, u in enumerate(last):
        sent[missing + k] = u
    out = np.empty(7)
    rollout_rk4(x, sent, PERIOD_S, out)
    return out


def test_the_ring_feeds_the_rollout_what_the_deque_did():
    rng = np.random.default_rng(5)
    delay = DelayPrediction(0.2, PERIOD_S, max_delay_s=0.5)
    capacity = 8  # ceil(0.5 / 0.065)
    pending: deque = deque(maxlen=capacity)
    x = rng.normal(size=7)
    assert delay.predict(x) is x and delay.count == 0  # nothing sent yet
    for k in range(60):
        u = rng.normal(size=4) * 0.1
        delay.push(u)
        pending.append(u)
        if k % 7 == 3:
            delay.set_delay_s(float(rng.uniform(0.0, 0.6)))
        n = delay.delay_ticks
        # the attributes the control stage reads every tick: pending() and the lead
        ring, first, count = delay.pending()
        assert ring is delay.ring and (first, count) == (delay.first, delay.count)
        assert count == n and delay.lead_s == n * PERIOD_S
        if n:
            assert np.array_equal(ring[first:first + n], _sent(pending, n))
        got = delay.predict(x)
        if n == 0:
            assert got is x
        else:
            assert got.tobytes() == _reference(pending, n, capacity, x).tobytes()


@pytest.mark.parametrize("copier", [copy.deepcopy, lambda d: pickle.loads(pickle.dumps(d))])
def test_a_copied_delay_pushes_into_the_ring_it_predicts_from(copier):
    original = DelayPrediction(0.2, 0.065, max_delay_s=0.3)
    original.push(np.array([0.1, 0.02, -0.01, 0.3]))
    twin = copier(original)
    x = np.array([0.0, 0.1, 0.0, -0.1, 1.0, 0.0, 0.2])
    for k in range(6):  # past the capacity: every pair written
        u = np.array([0.2 * k, 0.01 * k, -0.02, 0.1])
        original.push(u)
        twin.push(u)
        assert twin.ring is twin._sent
        assert twin.ring.tolist() == original.ring.tolist()
        assert twin.predict(x).tolist() == original.predict(x).tolist()
