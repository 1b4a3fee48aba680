"""One floating-point answer on every x86-64 machine: the numba kernels' compilation target.

numba compiles for the host CPU by default, so an AVX-512 machine and an AVX2 machine fuse
multiply-adds and order vector lanes differently; the last bits of a solve differ, and a
limit-cycling flight amplifies them into whole percent of overshoot. The tool therefore
compiles its kernels for the baseline x86-64 target (``generic``: SSE2, no FMA, no host
features) unless the user opts out with ``ARDRONE_NMPC_NUMBA_CPU=host`` (faster on some
machines, no longer bit-reproducible across CPUs; ``docs/solver-notes.md`` §9).

:func:`pin_numba_target` runs from the package's ``__init__``, before any module imports
numba; it sets the environment (so worker processes inherit it) and, should numba already
be imported, its live configuration.
"""

from __future__ import annotations

import os
import sys

#: The opt-out: ``ARDRONE_NMPC_NUMBA_CPU=host`` compiles for this machine's CPU.
OPT_OUT_ENV = "ARDRONE_NMPC_NUMBA_CPU"
#: The pinned target: LLVM's baseline x86-64 CPU with no extra features.
PINNED_CPU_NAME = "generic"
PINNED_CPU_FEATURES = ""


def numba_target_pinned() -> bool:
    """True unless the user asked for the host CPU."""
    return os.environ.get(OPT_OUT_ENV, "").strip().lower() != "host"


def pin_numba_target() -> None:
    """Compile every numba kernel for :data:`PINNED_CPU_NAME` (module docstring)."""
    if not numba_target_pinned():
        return
    os.environ["NUMBA_CPU_NAME"] = PINNED_CPU_NAME
    os.environ["NUMBA_CPU_FEATURES"] = PINNED_CPU_FEATURES
    config = sys.modules.get("numba.core.config")
    if config is not None:  # numba came first: its configuration was read already
        config.CPU_NAME = PINNED_CPU_NAME
        config.CPU_FEATURES = PINNED_CPU_FEATURES


#: numba options of a kernel that only other kernels call (``njit(**INNER_KERNEL, …)``):
#: numba builds no wrapper for Python (nor a C-callable one, which nothing here uses) —
#: building them is a good part of a cold start's compile time (docs/benchmarks.md, "Cold
#: start without the wrappers"). Such a kernel cannot be called from Python: use
#: :func:`callable_from_python` for that.
INNER_KERNEL = {"no_cpython_wrapper": True, "no_cfunc_wrapper": True}
#: numba options of a kernel called from Python: no C-callable wrapper (nothing uses it).
OUTER_KERNEL = {"no_cfunc_wrapper": True}


def callable_from_python(kernel):
    """A twin of the :data:`INNER_KERNEL` ``kernel`` that Python can call (tests, the
    reference solver): the same source and options, so the same machine code, compiled only
    when first called from Python and cached under a name of its own (numba's cache index is
    keyed by the function's name, not its options: the twin must not share the kernel's)."""
    import types

    from numba import njit

    inner = kernel.py_func
    twin = types.FunctionType(inner.__code__, inner.__globals__, inner.__name__,
                              inner.__defaults__, inner.__closure__)
    twin.__qualname__ = f"{inner.__qualname__}_from_python"
    twin.__doc__ = inner.__doc__
    options = {k: v for k, v in kernel.targetoptions.items()
               if k not in INNER_KERNEL and k != "nopython"}  # njit sets nopython itself
    return njit(cache=True, **options, **OUTER_KERNEL)(twin)


def kernel_twin(kernel, name: str, **replaced):
    """A twin of the numba ``kernel`` calling other kernels in place of some it calls
    (``replaced``: global name → kernel): the same source and options, compiled and cached
    under ``name`` (numba's cache is keyed by the function's name; a kernel taking the callee
    as an argument would not be cached: a dispatcher's type differs in every process). Its
    globals are the kernel's module's as they are now, with ``replaced``."""
    options = {k: v for k, v in kernel.targetoptions.items() if k != "nopython"}
    return compiled_twin(kernel.py_func, name, options, **replaced)


def compiled_twin(function, name: str, options: dict, **replaced):
    """The Python ``function`` compiled with numba ``options`` (:data:`INNER_KERNEL`, …) and
    cached under ``name``, calling ``replaced`` (global name → kernel) in place of what it
    calls: one source for the Python path and the compiled one (:func:`kernel_twin`'s
    way)."""
    import types

    from numba import njit

    twin = types.FunctionType(function.__code__, {**function.__globals__, **replaced}, name,
                              function.__defaults__, function.__closure__)
    twin.__qualname__ = name
    twin.__doc__ = function.__doc__
    return njit(cache=True, **options)(twin)
