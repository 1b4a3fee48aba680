"""numba's cache follows the kernel sources across files (core/kernel_cache.py): edit the
airframe's RK4 and the flying plant's cached advance, in another file, runs the new code."""

from __future__ import annotations

import ast
import os
import shutil
import subprocess
import sys
from pathlib import Path

from ardrone_nmpc.core.kernel_cache import KERNEL_SOURCES

PACKAGE = Path(__file__).resolve().parents[2] / "ardrone_nmpc"


def _defines_kernels(path: Path) -> bool:
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Call) and getattr(node.func, "id", "") == "njit":
            return True
        if isinstance(node, ast.Name) and node.id == "njit" and isinstance(node.ctx, ast.Load):
            return True
    return False


def test_every_file_that_defines_kernels_is_a_kernel_source_and_flushes_its_cache():
    kernel_files = {str(p.relative_to(PACKAGE)) for p in PACKAGE.rglob("*.py")
                    if _defines_kernels(p)}
    kernel_files -= {"core/numerics.py"}  # njit there builds the twins; it is listed anyway
    assert len(kernel_files) >= 10
    assert kernel_files <= set(KERNEL_SOURCES), kernel_files - set(KERNEL_SOURCES)
    assert all((PACKAGE / rel).is_file() for rel in KERNEL_SOURCES)
    for rel in kernel_files:
        text = (PACKAGE / rel).read_text(encoding="utf-8")
        flushes = "flush_stale_caches(__name__" in text or rel.startswith("control/kernels/")
        assert flushes, f"{rel} defines kernels but does not flush their stale caches"


_ADVANCE = """
import sys
sys.path.insert(0, sys.argv[1])
sys.meta_path[:] = [f for f in sys.meta_path if "editable" not in repr(f).lower()]
import numpy as np
import ardrone_nmpc
assert ardrone_nmpc.__file__.startswith(sys.argv[1]), ardrone_nmpc.__file__
from ardrone_nmpc.sim.plant_step import flying_advance
from ardrone_nmpc.sim.plant import PlantParams
p = PlantParams()
x = np.zeros(10); x[2] = 1.0
out = flying_advance(x, np.zeros((0, 5)), 0, 0.2, 0.1, 0.3, 0.0, False,
                     p.rhs_coefficients, (0.0, 0.0, 1.0), 0.005, 4, 100.0, 0.0, 1.0, 0.0,
                     np.zeros(3), 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)
print(repr(out[3].tolist()))
"""


def _advance(root: Path, cache: Path) -> str:
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache)}
    done = subprocess.run([sys.executable, "-c", _ADVANCE, str(root)], env=env,
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    return done.stdout.strip().splitlines()[-1]


def test_an_edit_of_the_airframe_reaches_the_flying_plants_cached_advance(tmp_path):
    """flying_advance (sim/plant_step.py) compiles sim/airframe.py's RK4 into itself: after
    a warm run, an edit of airframe.py alone (the vertical wind dropped) must change what it
    computes — without the flush, numba's cache of plant_step.py would still hold the old."""
    root, cache = tmp_path / "tree", tmp_path / "cache"
    shutil.copytree(PACKAGE, root / "ardrone_nmpc",
                    ignore=shutil.ignore_patterns("__pycache__", "*.nbi", "*.nbc"))
    before = _advance(root, cache)
    assert _advance(root, cache) == before  # warm: loaded from the cache, the same
    airframe = root / "ardrone_nmpc" / "sim" / "airframe.py"
    text = airframe.read_text(encoding="utf-8")
    wind_term = "gaz * vz_gain - vz * inv_tau_vz + kd * w[2]"
    assert text.count(wind_term) == 1
    airframe.write_text(text.replace(wind_term, "gaz * vz_gain - vz * inv_tau_vz"),
                        encoding="utf-8")
    assert _advance(root, cache) != before


def test_first_warm_up_answers_once_per_kernel_after_loading_its_callees(monkeypatch):
    """A warm-up's preamble: True the first time a kernel is asked for (its callees loaded
    from the cache then), False after; each kernel on its own."""
    import numba

    from ardrone_nmpc.core import kernel_cache

    loaded = []
    monkeypatch.setattr(kernel_cache, "load_cached_callees", loaded.append)
    one, other = numba.njit(lambda a: a), numba.njit(lambda a: a + 1)
    assert not kernel_cache.warmed(one)
    assert kernel_cache.first_warm_up(one) and loaded == [one] and kernel_cache.warmed(one)
    assert not kernel_cache.first_warm_up(one) and loaded == [one]
    assert not kernel_cache.warmed(other)
    assert kernel_cache.first_warm_up(other) and loaded == [one, other]
    assert not kernel_cache.first_warm_up(other) and kernel_cache.warmed(other)
