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
