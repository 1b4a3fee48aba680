"""The numba kernels compile for the pinned baseline target (docs/solver-notes.md §9), so the
same config gives the same bits on AVX2 and AVX-512 machines; the opt-out compiles for the
host."""

import os
import subprocess
import sys

import pytest

from ardrone_nmpc.core.numerics import OPT_OUT_ENV, PINNED_CPU_FEATURES, PINNED_CPU_NAME

_PROBE = ("import ardrone_nmpc.control.solver, numba.core.config as c;"
          "from numba.core.registry import cpu_target;"
          "t = cpu_target.target_context.codegen().magic_tuple();"
          "print(t[1]); print(repr(t[2]))")


def _target(env: dict) -> tuple[str, str]:
    out = subprocess.run([sys.executable, "-c", _PROBE], env=env, capture_output=True,
                         text=True, timeout=120, check=True).stdout.split("\n")
    return out[0], out[1]


def _env(**extra) -> dict:
    env = {k: v for k, v in os.environ.items()
           if k not in (OPT_OUT_ENV, "NUMBA_CPU_NAME", "NUMBA_CPU_FEATURES")}
    env.update(extra)
    return env


def test_kernels_compile_for_the_pinned_target():
    assert _target(_env()) == (PINNED_CPU_NAME, repr(PINNED_CPU_FEATURES))


@pytest.mark.parametrize("user_cpu", ["skylake-avx512", "haswell"])
def test_a_users_numba_cpu_name_does_not_change_the_target(user_cpu):
    assert _target(_env(NUMBA_CPU_NAME=user_cpu)) == (PINNED_CPU_NAME, repr(PINNED_CPU_FEATURES))


def test_the_opt_out_compiles_for_the_host():
    name, features = _target(_env(**{OPT_OUT_ENV: "host"}))
    assert name != PINNED_CPU_NAME and features != repr(PINNED_CPU_FEATURES)


def test_numba_imported_first_is_pinned_too():
    probe = "import numba;" + _PROBE
    out = subprocess.run([sys.executable, "-c", probe], env=_env(), capture_output=True,
                         text=True, timeout=120, check=True).stdout.split("\n")
    assert (out[0], out[1]) == (PINNED_CPU_NAME, repr(PINNED_CPU_FEATURES))


def test_an_inner_kernel_and_its_python_twin_give_the_same_bits():
    """Inner kernels compile without numba's Python wrapper (the cold start); Python calls a
    twin of the same source and options, cached under a name of its own."""
    from numba import njit

    from ardrone_nmpc.control import kernels
    from ardrone_nmpc.control.kernels.residual import bound_gradient as inner
    from ardrone_nmpc.core.numerics import INNER_KERNEL

    assert all(inner.targetoptions[k] == v for k, v in INNER_KERNEL.items())
    twin = kernels.bound_gradient
    assert twin is not inner
    assert twin.py_func.__qualname__ != inner.py_func.__qualname__  # numba's cache key
    assert not twin.targetoptions.get("no_cpython_wrapper", False)
    through_a_kernel = njit(lambda s: inner(s))
    for s in (-2.0, -0.999, -0.4, 0.0, 1e-9, 0.5, 0.99899, 1.5):
        assert twin(s).hex() == through_a_kernel(s).hex()
