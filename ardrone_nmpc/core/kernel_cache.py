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

:func:`load_cached_callees` is the other half: a process that loads a kernel from the cache
runs the machine code a process that compiled it runs (numba's weak callee copies,
docs/solver-notes.md §9).
"""

from __future__ import annotations

import hashlib
import sys
from pathlib import Path

#: Every file whose text reaches compiled code: the modules that define kernels and the ones
#: whose functions or constants kernels use (paths relative to the package).
KERNEL_SOURCES = (
    "model.py", "core/numerics.py", "core/types.py", "core/angles.py", "core/angle_kernels.py",
    "core/sorted_search.py", "core/python_floats.py", "core/monotonic.py", "control/gmres.py",
    "control/obstacles.py", "control/proportional.py",
    "control/kernels/layout.py", "control/kernels/residual.py", "control/kernels/solve.py",
    "control/kernels/steps.py", "sim/airframe.py", "sim/plant_step.py", "sim/plant_kit.py",
    "sim/sensor_step.py", "sim/wire_step.py", "sim/drone_block.py", "sim/wire_block.py",
    "sim/target.py",
    "runs/path_kernels.py",
    "runs/block_row.py", "reference/kernels.py", "reference/live.py",
    "estimation/response_kernels.py", "estimation/response_lanes.py", "estimation/disturbance.py",
    "runtime/tick_kernels.py", "runtime/after_solve.py", "runtime/before_solve.py",
    "runtime/control_tick.py", "runtime/lockstep_block.py", "runtime/second_object.py",
    "runtime/p_tick.py", "runtime/control_tick_p.py",
)
_PACKAGE = Path(__file__).resolve().parents[1]
_digest: str | None = None
_preloaded: set[int] = set()  # entry points whose callees this process has loaded
_warmed: set[int] = set()  # the kernels a warm-up has run in this process (first_warm_up)


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


def load_cached_callees(kernel) -> None:
    """Load from numba's cache every specialisation of every kernel ``kernel`` calls, callees
    first, before ``kernel`` itself runs — so that a process which loads ``kernel`` from the
    cache runs the same machine code as one that compiled it.

    numba links a copy of each callee into its caller (a weak symbol, re-optimised with the
    caller: under fast-math its last bits can differ from the callee's own compilation). A
    process that compiles the caller has already loaded the callee's own, strong definition,
    and the caller's calls resolve to it; a process that loads the caller from the cache alone
    ran the weak copies. Loading the callees first makes both resolve to the callees' own code
    (docs/solver-notes.md §9). A no-op on an empty cache: compiling loads them anyway; and
    once per process and entry point (each solver built reads no cache index again)."""
    if id(kernel) in _preloaded:
        return
    _preloaded.add(id(kernel))
    for callee in _callees_post_order(kernel, set()):
        if callee.targetoptions.get("inline") != "always":  # an inlined one has no symbol
            _load_cached(callee)


def first_warm_up(kernel) -> bool:
    """A module's ``warm_up_kernels`` preamble: True the first time in this process a warm-up
    asks for ``kernel`` — its callees then loaded from the cache (:func:`load_cached_callees`)
    for the warm-up to call it once, loading (or compiling) it before the first tick aloft —,
    False after (warmed already)."""
    if id(kernel) in _warmed:
        return False
    _warmed.add(id(kernel))
    load_cached_callees(kernel)
    return True


def warmed(kernel) -> bool:
    """A warm-up has run ``kernel`` in this process (:func:`first_warm_up`)."""
    return id(kernel) in _warmed


def _callees_post_order(kernel, seen: set):
    """The numba kernels ``kernel`` names, transitively, each after the ones it names."""
    from numba.core.dispatcher import Dispatcher

    func = kernel.py_func
    for name in func.__code__.co_names:
        callee = func.__globals__.get(name)
        if isinstance(callee, Dispatcher) and id(callee) not in seen:
            seen.add(id(callee))
            yield from _callees_post_order(callee, seen)
            yield callee

def load_cached(kernel) -> bool:
    """``kernel``'s specialisations in numba's cache loaded now, its callees' first
    (:func:`load_cached_callees`) — nothing compiled that the cache does not hold: whether
    ``kernel`` has machine code in this process now."""
    if not kernel.overloads:
        load_cached_callees(kernel)
        _load_cached(kernel)
    return bool(kernel.overloads)


def _load_cached(kernel) -> None:
    """Every specialisation of ``kernel`` in its cache index for this target, loaded."""
    cache = getattr(kernel, "_cache", None)
    cache_file = getattr(cache, "_cache_file", None)
    if cache_file is None:  # not a cached kernel
        return
    magic = kernel.targetctx.codegen().magic_tuple()
    for key in cache_file._load_index():
        signature, key_magic = key[0], key[1]
        if key_magic == magic and signature not in kernel.overloads:
            kernel.compile(signature)
