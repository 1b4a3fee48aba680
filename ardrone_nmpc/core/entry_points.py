"""A numba kernel's compiled entry point, for a caller that calls it every tick with arguments
of one kind: the dispatcher's own machine code without the dispatcher.

Calling a dispatcher looks up every argument's type (~55 ns an array, ~150 ns a call) to pick
the compiled specialisation; ``dispatcher.overloads[signature].entry_point`` is that
specialisation's own wrapper, which only unboxes — about 30 % of a call less. It checks
nothing: an array of another dtype, dimension or layout than its signature's is read as if it
were one (undefined behaviour), so a caller takes it only for arguments whose kinds it has
proved fixed or checked once (:func:`plain`). A float64 parameter is unboxed by ``float()``
(``PyNumber_Float``), an int64 one by ``int()``, a boolean by truth — any number a caller
passes is converted as those do.

:func:`entry_point` answers for the kinds of the arguments a call has just had (the dispatcher
compiled or loaded them first): the specialisation the dispatcher itself picks for them, or
None — not compiled for them, no JIT (``NUMBA_DISABLE_JIT``), or an argument of a kind it does
not vouch for (an array not :func:`plain`, a number not a float, bool or int64-range int).
"""

from __future__ import annotations

import numpy as np

__all__ = ["entry_point", "plain"]

_F64 = np.dtype(np.float64)
_NDARRAY = np.ndarray
_INT64_MIN, _INT64_MAX = -(1 << 63), (1 << 63) - 1
#: by (kernel, the arguments' kinds): (its entry point or None, how many specialisations the
#: kernel had then) — numba's type look-up (~4 µs an array) once per process and kind, and a
#: miss again only once the kernel compiled more
_found: dict = {}


def plain(a, ndim: int = 1, dtype: np.dtype = _F64) -> bool:
    """``a`` is an ndarray (not a subclass) of ``dtype``, ``ndim``-D, C-contiguous, aligned and
    writeable: numba's ``array(<dtype>, <ndim>d, C)`` — the one kind of array an entry point
    compiled for such an array may be handed."""
    return (a.__class__ is _NDARRAY and (a.dtype is dtype or a.dtype == dtype)
            and a.ndim == ndim and a.flags.carray)


def _kind(a):
    """What decides ``numba.typeof(a)`` for the arguments :func:`entry_point` vouches for
    (ndarray: dtype and dimension of a :func:`plain` one; float, bool, int64-range int: the
    class); None for any other."""
    cls = a.__class__
    if cls is _NDARRAY:
        return (a.dtype, a.ndim) if a.flags.carray else None
    if cls is float or cls is bool:
        return cls
    if cls is int and _INT64_MIN <= a <= _INT64_MAX:
        return int
    return None


def entry_point(kernel, *args):
    """The compiled entry point of the numba dispatcher ``kernel`` for the types of ``args``
    (module docstring), or None. Call the dispatcher with arguments of these kinds first: only
    what it has compiled or loaded is found."""
    overloads = getattr(kernel, "overloads", None)
    if not overloads:  # not compiled yet, or no JIT (a plain function)
        return None
    kinds = tuple(map(_kind, args))
    if None in kinds:
        return None
    key = (kernel, kinds)
    found = _found.get(key)
    if found is None or (found[0] is None and found[1] != len(overloads)):
        found = _found[key] = (_look_up(overloads, args), len(overloads))
    return found[0]


def _look_up(overloads, args):
    """The entry point of the specialisation compiled for ``args``' numba types, or None."""
    from numba import typeof
    from numba.core.errors import NumbaError

    try:
        compiled = overloads.get(tuple(typeof(a) for a in args))
    except (NumbaError, ValueError, TypeError):  # a dtype numba does not take ('>f8' …)
        return None
    return None if compiled is None else compiled.entry_point
