"""The monotonic clock read inside compiled code: :func:`monotonic_ns`, the clock of
``time.perf_counter_ns`` (and ``time.monotonic_ns``) on Linux — ``CLOCK_MONOTONIC`` —, so a
kernel can time a part of itself (the solver inside the controller's one call,
``runtime/control_tick.py``) in the same nanoseconds a Python caller times a call.

The call is ``clock_gettime(CLOCK_MONOTONIC, &ts)`` by its symbol name, which the C library
gives every process: no host-specific instruction (a kernel using it runs on any x86-64), and
numba caches the kernel as it does any other (the symbol is looked up when the cached code is
loaded). :func:`monotonic_ns` answers −1 if the call fails (it does not, for this clock, on
Linux). Python's ``time.perf_counter_ns`` reads the same clock only where it is
``CLOCK_MONOTONIC``: :data:`SAME_CLOCK` says so for this platform. Elsewhere the call is not
emitted and :func:`monotonic_ns` answers −1: a C library without ``clock_gettime`` (Windows)
would leave the symbol unresolved, which kills the process when the kernel is linked, and
macOS numbers its clocks otherwise (id 1 is not a clock there) — a caller times in Python
where it is False (``runtime/control_tick``: the two calls around the solve).
"""

from __future__ import annotations

import sys
import time

from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic

__all__ = ["CLOCK_MONOTONIC", "SAME_CLOCK", "monotonic_ns"]

#: Linux' clock id of CLOCK_MONOTONIC (``time.CLOCK_MONOTONIC``)
CLOCK_MONOTONIC = 1
#: ``time.perf_counter_ns`` reads CLOCK_MONOTONIC here (Linux: ``perf_counter`` is
#: ``monotonic``), a 64-bit one (``struct timespec`` two int64s): a kernel's
#: :func:`monotonic_ns` and a Python caller's times compare; False: it answers −1
SAME_CLOCK = (sys.platform.startswith("linux") and sys.maxsize > 2 ** 32
              and getattr(time, "CLOCK_MONOTONIC", None) == CLOCK_MONOTONIC
              and time.get_clock_info("perf_counter").implementation
              == "clock_gettime(CLOCK_MONOTONIC)")


@intrinsic
def monotonic_ns(typingctx):
    """``CLOCK_MONOTONIC`` in ns (an int64), read inside compiled code (module docstring)."""
    sig = types.int64()

    def codegen(context, builder, signature, args):
        i64, i32 = ir.IntType(64), ir.IntType(32)
        if not SAME_CLOCK:  # no call emitted (module docstring): "no clock"
            return ir.Constant(i64, -1)
        timespec = ir.LiteralStructType([i64, i64])  # struct timespec on x86-64 Linux
        fnty = ir.FunctionType(i32, [i32, timespec.as_pointer()])
        clock_gettime = cgutils.get_or_insert_function(builder.module, fnty, "clock_gettime")
        ts = cgutils.alloca_once(builder, timespec)
        failed = builder.call(clock_gettime, [ir.Constant(i32, CLOCK_MONOTONIC), ts])
        sec = builder.load(cgutils.gep_inbounds(builder, ts, 0, 0))
        nsec = builder.load(cgutils.gep_inbounds(builder, ts, 0, 1))
        ns = builder.add(builder.mul(sec, ir.Constant(i64, 1_000_000_000)), nsec)
        return builder.select(builder.icmp_signed("!=", failed, ir.Constant(i32, 0)),
                              ir.Constant(i64, -1), ns)

    return sig, codegen
