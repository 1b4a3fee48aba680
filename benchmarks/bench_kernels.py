"""Micro-benchmarks of the solver kernels (pytest-benchmark); not part of the test suite.

    python -m pytest benchmarks/bench_kernels.py --benchmark-only

Hot-cache figures of single kernels; the closed-loop figures that matter for a flight are
``ardrone-nmpc bench`` (see docs/benchmarks.md).
"""

import numpy as np
import pytest

from ardrone_nmpc.control import kernels as K
from ardrone_nmpc.control.cgmres import CGMRESController
from ardrone_nmpc.control.ocp import OcpSpec

X = np.array([0.1, 0.2, -0.1, 0.0, 1.1, 0.05, 0.2])
TARGET = np.array([1.0, 0, 1.0, 0, 2.0, 0, 1.0])


@pytest.fixture(scope="module")
def solver():
    s = CGMRESController(OcpSpec())
    s.solve(0.0, X, np.tile(TARGET, (16, 1)))
    return s


def test_residual(benchmark, solver):
    ref = np.tile(TARGET, (16, 1))
    out = np.zeros(solver.U.size)
    xs, trig = np.zeros((16, 7)), np.zeros((16, 5))
    benchmark(K.residual, solver.U, 4, X, ref, 0.1, solver.memory.weights, 0.01, 0.0,
              K.NO_ACTIVE, xs, trig, out)


def test_cgmres_update(benchmark, solver):
    ref = np.tile(TARGET, (16, 1))
    solver.memory.period_s = 0.0  # do not move U: every call is the same update
    benchmark(solver.memory.cgmres_step, X, ref, False)


def test_solve_call(benchmark, solver):
    ref = np.tile(TARGET, (16, 1))
    solver.memory.period_s = 0.0
    benchmark(solver.solve, 1.0, X, ref)
