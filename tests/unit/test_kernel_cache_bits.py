"""A solver whose kernels were compiled in the process and one that loaded them from numba's
cache give the same bits (docs/solver-notes.md §9): two subprocesses on one empty
``NUMBA_CACHE_DIR``, the first compiling, the second loading, tick the uncondensed C/GMRES
solver (where the last bits of ‖F‖ once differed) from the same state and print every
residual norm and input in hex."""

from __future__ import annotations

import os
import subprocess
import sys

_TICKS = r"""
import numpy as np
from ardrone_nmpc.control.cgmres import CGMRESController
from ardrone_nmpc.control.ocp import OcpSpec

spec = OcpSpec()
solver = CGMRESController(spec, condensed=False)
x = np.array([0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0])
ref = np.tile([0.3, 0.0, -0.2, 0.0, 1.1, 0.0, 0.2], (spec.horizon_steps + 1, 1))
for k in range(20):
    result = solver.solve(k * solver.period_s, x, ref)
    print(result.residual_norm.hex(), *(float(u).hex() for u in result.u))
    x = x + 0.01 * k  # a new measurement each tick
"""


def _ticks(cache_dir) -> tuple[list[str], str]:
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache_dir), "NUMBA_DEBUG_CACHE": "1"}
    done = subprocess.run([sys.executable, "-c", _TICKS], env=env, capture_output=True,
                          text=True, timeout=600, check=True)
    rows = [line for line in done.stdout.splitlines() if not line.startswith("[cache]")]
    return rows, done.stdout


def test_a_cached_solver_gives_the_bits_of_a_freshly_compiled_one(tmp_path):
    cold, cold_log = _ticks(tmp_path)
    warm, warm_log = _ticks(tmp_path)
    assert "data saved to" in cold_log and "steps.cgmres_step" in cold_log
    assert "data saved to" not in warm_log  # the second loaded every kernel from the cache
    assert "steps.cgmres_step" in warm_log
    assert len(cold) == 20
    assert warm == cold
