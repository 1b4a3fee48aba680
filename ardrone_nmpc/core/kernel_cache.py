"""numba's on-disk cache kept true to the sources: a kernel's cached machine code is flushed
when any kernel source of the package changed, not only its own file.

numba keys a cached kernel on its own file's time stamp, but its machine code includes what it
calls from other files (``sim/plant_step`` runs ``sim/airframe``'s RK4, the offset-free
integrator ``core/angle_kernels``' wrap, the lookups ``core/sorted_search``) and the constants
it reads (``core/types``). Edit one of those and the callers' caches would keep running the old
code. Each kernel module calls :func:`flush_stale_caches` once it has defined its kernels:
one digest over every file in :data:`KERNEL_SOURCES` (``tests/unit/test_kernel_cache.py``
checks the list is whole), and the module's cached kernels are flushed — recompiled on their
next call — when it differs from the digest they were cached under.
"""

from __future__ import annotations

import hashlib
import sys
from pathlib import Path

#: Every file whose text reaches compiled code: the modules that define kernels and the ones
#: whose functions or constants kernels use (paths relative to the package).
KERNEL_SOURCES = (
    "model.py", "core/numerics.py", "core/types.py", "core/angles.py", "core/angle_kernels.py",
    "core/sorted_search.py", "control/gmres.py", "control/obstacles.py",
    "control/kernels/layout.py", "control/kernels/residual.py", "control/kernels/solve.py",
    "control/kernels/steps.py", "sim/airframe.py", "sim/plant_step.py", "sim/plant_kit.py",
    "reference/kernels.py", "estimation/response_kernels.py", "estimation/disturbance.py",
)
_PACKAGE = Path(__file__).resolve().parents[1]
_digest: str | None = None


def sources_digest() -> str:
    """SHA-256 over :data:`KERNEL_SOURCES` (read once per process)."""
    global _digest
    if _digest is None:
        h = hashlib.sha256()
        for rel in KERNEL_SOURCES:
            h.update(rel.encode())
            h.update((_PACKAGE / rel).read_bytes())
        _digest = h.hexdigest()
    return _digest


def flush_stale_caches(*module_names: str) -> int:
    """Flush the cached kernels found in these modules if the kernel sources changed since they
    were cached; returns how many were flushed (0 when the cache is current)."""
    from numba.core.dispatcher import Dispatcher

    kernels = {id(v): v for name in module_names for v in vars(sys.modules[name]).values()
               if isinstance(v, Dispatcher) and hasattr(getattr(v, "_cache", None), "cache_path")}
    if not kernels:
        return 0
    first = next(iter(kernels.values()))
    stamp = Path(first._cache.cache_path) / f"{module_names[0]}.kernel-sources.sha256"
    try:
        if stamp.read_text() == sources_digest():
            return 0
    except OSError:
        pass
    for kernel in kernels.values():
        kernel._cache.flush()
    try:
        stamp.write_text(sources_digest())
    except OSError:
        pass  # a read-only tree: numba cannot cache there either
    return len(kernels)
