"""The flight's arithmetic does not depend on the code numpy and BLAS pick by CPU at run time
(docs/solver-notes.md §9): the attitude-response fit, run in a process whose numpy and
OpenBLAS are told to use their AVX2 code, gives this machine's bits. On an AVX-512 machine
numpy's own ``exp`` does not (the control case), so the test can fail there."""

from __future__ import annotations

import hashlib
import os
import subprocess
import sys

import numpy as np
from numpy._core._multiarray_umath import __cpu_features__

_FIT = """
import hashlib, math, sys
import numpy as np
from ardrone_nmpc.estimation.attitude_response import AttitudeResponseEstimator

rng = np.random.default_rng(7)
est = AttitudeResponseEstimator(math.radians(12.0), window_s=20.0)
t, y, delay_s, lag_s, gain = 0.0, np.zeros(2), 0.13, 0.11, 0.9
queue = []
for i in range(900):                   # 65 ms commands, 15 Hz navdata, a delayed lag
    t = round(i * 0.0650, 6)
    u = rng.uniform(-0.5, 0.5, 2)
    est.command(t, float(u[0]), float(u[1]))
    queue.append((t, u * math.radians(12.0) * gain))
    while queue and queue[0][0] <= t - delay_s:
        y = y + (queue.pop(0)[1] - y) * (1.0 - math.exp(-0.065 / lag_s))
    if i % 4 == 0:
        noisy = np.degrees(y) + rng.normal(0.0, 0.2, 2)
        est.navdata(t + 0.01, float(noisy[0]), float(noisy[1]))
e = est.estimate
digest = hashlib.sha256()
for a in (est._sx, est._sxx, est._sxy, est._res):
    digest.update(np.ascontiguousarray(a).tobytes())
digest.update(repr(e).encode())
print(digest.hexdigest())
print(hashlib.sha256(np.exp(np.linspace(-5.0, 5.0, 4001)).tobytes()).hexdigest())
"""


def _avx2_env() -> dict[str, str]:
    """This environment with numpy's and OpenBLAS' AVX-512 code switched off."""
    env = dict(os.environ)
    off = [f for f in ("X86_V4", "AVX512_ICL", "AVX512_SPR") if __cpu_features__.get(f)]
    if off:
        env["NPY_DISABLE_CPU_FEATURES"] = " ".join(off)
    if __cpu_features__.get("AVX2"):
        env["OPENBLAS_CORETYPE"] = "Haswell"
    return env


def _run(env: dict[str, str]) -> list[str]:
    done = subprocess.run([sys.executable, "-c", _FIT], env=env, capture_output=True,
                          text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    return done.stdout.split()


def test_the_attitude_fit_is_the_same_bits_with_numpys_avx2_code():
    native_fit, native_exp = _run(dict(os.environ))
    avx2_fit, avx2_exp = _run(_avx2_env())
    assert avx2_fit == native_fit
    # the control: numpy's exp itself changes when this machine has AVX-512 code to switch off
    has_avx512 = bool(__cpu_features__.get("X86_V4") or __cpu_features__.get("AVX512_SKX"))
    assert (avx2_exp != native_exp) == has_avx512
    # and this process (numpy already loaded with its default code) agrees with the child
    here = hashlib.sha256(np.exp(np.linspace(-5.0, 5.0, 4001)).tobytes()).hexdigest()
    assert here == native_exp
