"""Shared test fixtures and helpers."""

from __future__ import annotations

import os

import numpy as np
import pytest
from hypothesis import settings

from ardrone_nmpc import model
import ardrone_nmpc.links.drone_link as drone_link_module

# Timings live in benchmarks, not in unit tests: Hypothesis' per-example deadline (200 ms)
# fails a correct test whenever the machine is loaded (or the first example JIT-compiles).
settings.register_profile("no-deadline", deadline=None)
settings.load_profile("no-deadline")

# No background compile (runtime/precompile.py) in the tests' flights and their subprocesses:
# a child outliving its test would write into a cache directory the test removes. Its own
# tests (tests/unit/test_precompile.py) turn it on where they mean to.
os.environ["ARDRONE_NMPC_PRECOMPILE"] = "0"


def thesis_cost(x0, ref, u, *, q, r, qf, dtau):
    """Thesis eq. 3.14 evaluated directly (forward Euler), for gradient checks.

    x0 (7,), ref (N+1, 7), u (N, 4).
    """
    x = np.array(x0, dtype=float)
    cost = 0.0
    for i in range(u.shape[0]):
        e = x - ref[i]
        cost += 0.5 * (e @ (q * e) + u[i] @ (r * u[i])) * dtau
        x = x + model.f(x, u[i]) * dtau
    e = x - ref[-1]
    return cost + 0.5 * e @ (qf * e)


def nan_equal(a, b) -> bool:
    """Equal, a float NaN equal to a float NaN (a row's cells, a record's fields: the compiled
    and the Python path of a stage compared)."""
    if isinstance(a, float) and isinstance(b, float):
        return a == b or (a != a and b != b)
    return a == b


class ManualClock:
    """A clock the test advances: ``clock()`` reads it, ``clock.sleep(dt)`` moves it on."""

    def __init__(self, t: float = 100.0):
        self.t = t

    def __call__(self) -> float:
        return self.t

    def sleep(self, dt: float) -> None:
        self.t += dt


@pytest.fixture
def rng():
    return np.random.default_rng(20191)


@pytest.fixture
def loopback_only(monkeypatch, tmp_path):
    """The link's lab defaults (all interfaces, local port 5556) become loopback/ephemeral,
    and the flight locks live in this test's directory."""
    class LoopbackLink(drone_link_module.DroneLink):
        def __init__(self, *args, **kwargs):
            kwargs.setdefault("bind_host", "127.0.0.1")
            kwargs["at_local_port"] = 0
            super().__init__(*args, **kwargs)

    monkeypatch.setattr(drone_link_module, "DroneLink", LoopbackLink)
    monkeypatch.setenv("XDG_RUNTIME_DIR", str(tmp_path / "run"))
    (tmp_path / "run").mkdir()
