"""No kernel escapes the pinned target (docs/solver-notes.md §9): in a process that asks numba
for an AVX-512 CPU with FMA, every numba-compiled object of the package is a CPU dispatcher of
the one pinned code generator and none runs in parallel threads; and that generator, handed
the kit's kernel and a dot product to compile afresh with ``fastmath`` (which allows
contraction into fused multiply-adds and vectorising), emits no FMA and no AVX register. A new kernel of
another kind (a cfunc, a ufunc, a parallel or non-CPU target, an intrinsic not listed) fails
here."""

from __future__ import annotations

import json
import os
import subprocess
import sys

from ardrone_nmpc.core.numerics import OPT_OUT_ENV, PINNED_CPU_FEATURES, PINNED_CPU_NAME

_PROBE = r"""
import importlib, json, pkgutil, re, sys, warnings
import ardrone_nmpc
import numba
import numpy as np
from numba.core.extending import _Intrinsic
from numba.core.registry import CPUDispatcher, cpu_target

modules = [m.name for m in pkgutil.walk_packages(ardrone_nmpc.__path__, "ardrone_nmpc.")]
for name in modules:
    importlib.import_module(name)
kernels, others, intrinsics = {}, [], set()
for name in modules:
    for attr, obj in vars(sys.modules[name]).items():
        kind = type(obj).__module__
        if isinstance(obj, CPUDispatcher):
            kernels[f"{obj.py_func.__module__}.{obj.py_func.__qualname__}"] = obj
        elif isinstance(obj, _Intrinsic):  # LLVM IR emitted inside its callers' compile
            intrinsics.add(f"{obj._defn.__module__}.{obj._defn.__qualname__}")
        elif kind.startswith("numba") and not isinstance(obj, type) and callable(obj):
            others.append(f"{name}.{attr}: {type(obj).__name__}")

# compiled afresh (cached copies hold no inspectable machine code): the kit's right-hand side,
# and a dot product an AVX-512 target would vectorise into ymm/zmm fused multiply-adds
from ardrone_nmpc.sim import plant_kit

def dot(a, b):
    s = 0.0
    for i in range(a.size):
        s += a[i] * b[i]
    return s

kit_args = ((0.0,) * 12, 0.3, -0.2, 0.1, 0.2, False, plant_kit.KIT.coefficients(0.5),
            np.zeros(3))
compiled, bad = 0, []
with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    for name, func, args in (("kit_rhs", plant_kit._kit_rhs.py_func, kit_args),
                             ("dot", dot, (np.ones(64), np.ones(64)))):
        copy = numba.njit(fastmath=True)(func)
        copy(*args)
        for sig in copy.signatures:
            compiled += 1
            if re.search(r"vfn?m(add|sub)|%[yz]mm", copy.inspect_asm(sig)):
                bad.append(name)
print(json.dumps({
    "kernels": len(kernels), "others": others, "intrinsics": sorted(intrinsics),
    "compiled": compiled, "bad_asm": bad,
    "parallel": [n for n, d in kernels.items() if d.targetoptions.get("parallel")],
    "targets": sorted({type(d.targetdescr).__name__ for d in kernels.values()}),
    "magic": list(cpu_target.target_context.codegen().magic_tuple()[1:]),
}))
"""


def test_every_kernel_is_a_pinned_cpu_kernel_without_fma_or_avx():
    env = {k: v for k, v in os.environ.items() if k != OPT_OUT_ENV}
    env.update(NUMBA_CPU_NAME="skylake-avx512", NUMBA_CPU_FEATURES="+avx512f,+avx2,+fma")
    out = subprocess.run([sys.executable, "-c", _PROBE], env=env, capture_output=True,
                         text=True, timeout=600, check=True).stdout
    found = json.loads(out.strip().splitlines()[-1])
    assert found["magic"] == [PINNED_CPU_NAME, PINNED_CPU_FEATURES]
    assert found["kernels"] >= 30 and found["others"] == [] and found["parallel"] == []
    # the intrinsics, each reviewed and listed here: a libc call (clock_gettime) in its
    # callers' code (core/monotonic.py); the response fit's two-lane SSE2 loops, IEEE
    # operations without fast-math flags (estimation/response_lanes.py: the asm check above
    # holds for their callers' code too — no FMA, no AVX register)
    assert found["intrinsics"] == ["ardrone_nmpc.core.monotonic.monotonic_ns",
                                   "ardrone_nmpc.estimation.response_lanes.fit_pairs",
                                   "ardrone_nmpc.estimation.response_lanes.fold_lags"]
    assert found["targets"] == ["CPUTarget"]
    assert found["compiled"] == 2 and found["bad_asm"] == []
