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

:class:`VettedCall` is the one way a caller takes it: the dispatcher until the arrays of a call
are vetted (plain, of the kinds the caller declared, compiled), then the entry point while the
same array objects come — bound once for a caller whose arrays are its own for life
(:meth:`VettedCall.bind`), or checked by identity every call for a caller handed arrays
(calling the :class:`VettedCall`).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

__all__ = ["ArrayKind", "VettedCall", "entry_point", "plain"]

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


class ArrayKind(NamedTuple):
    """An array argument in a :class:`VettedCall`'s kinds: a :func:`plain` array of ``ndim``
    dimensions and ``dtype``."""

    ndim: int = 1
    dtype: np.dtype = _F64


class VettedCall:
    """A caller's calls of the numba dispatcher ``kernel`` with arguments of ``kinds`` — an
    :class:`ArrayKind` for each array, and for each number a float, bool or int whose class is
    the one the caller passes (or one ``float``/truth/``int`` converts to the same value): its
    compiled entry point once the arrays of a call are vetted for it (:meth:`entry_for`), the
    dispatcher ``dispatch`` (default ``kernel``) otherwise.

    An array is vetted once, by its identity: it must not be retyped, reshaped to another
    dimension or re-strided in place (``a.dtype = …``, ``a.shape = …``) while it is fed.

    * :meth:`bind` — for a caller whose arrays are its own for life: the call to keep, the
      entry point at once if the kernel is compiled, else a first call that rebinds it. Holds
      no state: one module-level :class:`VettedCall` serves every such caller.
    * calling the :class:`VettedCall` — for a caller handed arrays: the entry point while the
      arrays are the vetted ones (by identity); arrays not vetted go to the dispatcher and are
      vetted when the same ones come a second time in a row (a caller with new arrays every
      call pays no vetting). Holds the vetted arrays: one instance per caller; a copy or an
      unpickled one starts afresh (an entry point does not pickle; the arrays are copied apart).
    """

    __slots__ = ("kernel", "kinds", "dispatch", "_at", "entry", "vetted", "_seen")

    def __init__(self, kernel, *kinds, dispatch=None) -> None:
        self.kernel = kernel
        self.kinds = kinds
        self.dispatch = kernel if dispatch is None else dispatch
        #: the array arguments' positions in ``kinds``
        self._at = tuple(i for i, k in enumerate(kinds) if k.__class__ is ArrayKind)
        self.entry = None  # the entry point, for the arrays ``vetted``
        self.vetted: tuple = ()
        self._seen: tuple = ()  # the arrays of the last call not vetted

    def __reduce__(self):
        return _fresh, (self.kernel, self.kinds, self.dispatch)

    def __copy__(self) -> "VettedCall":
        return _fresh(self.kernel, self.kinds, self.dispatch)

    def __deepcopy__(self, memo) -> "VettedCall":
        return _fresh(self.kernel, self.kinds, self.dispatch)  # the kernel is shared, as a function

    def entry_for(self, *arrays):
        """The entry point for ``arrays`` (the array arguments, in order) and the numbers'
        kinds, or None: an array not plain of its :class:`ArrayKind`, or the kinds not compiled
        (yet) — the dispatcher compiles or loads them on the caller's first call."""
        kinds = list(self.kinds)
        for i, a in zip(self._at, arrays, strict=True):
            kind = kinds[i]
            if not plain(a, kind.ndim, kind.dtype):
                return None
            kinds[i] = a
        return entry_point(self.kernel, *kinds)

    def bind(self, owner, name: str, *arrays) -> None:
        """Set ``owner.<name>`` to the call for the owner's own ``arrays``: the entry point if
        known now, else a first call through ``dispatch`` that binds the entry point once
        known (a number of another kind than ``kinds`` may have had the dispatcher compile
        another specialisation: asked again on the next call). The owner drops ``name`` when
        pickled or copied and binds it again for its copies of the arrays."""
        entry = self.entry_for(*arrays)
        if entry is not None:
            setattr(owner, name, entry)
            return
        dispatch, at = self.dispatch, self._at

        def first(*args):
            answer = dispatch(*args)
            if all(args[i] is a for i, a in zip(at, arrays)):
                entry = self.entry_for(*arrays)
                if entry is not None:
                    setattr(owner, name, entry)
            return answer

        setattr(owner, name, first)

    def __call__(self, *args):
        """``kernel(*args)``: by the entry point if the arrays of ``args`` are the vetted ones,
        else by ``dispatch`` (the arrays vetted if they came the call before)."""
        arrays = tuple(args[i] for i in self._at)
        entry = self.entry
        if entry is not None and _same(arrays, self.vetted):
            return entry(*args)
        if _same(arrays, self._seen):
            entry = self.entry_for(*arrays)
            if entry is not None:
                self.entry, self.vetted, self._seen = entry, arrays, ()
                return entry(*args)
        self._seen = arrays
        return self.dispatch(*args)


def _fresh(kernel, kinds: tuple, dispatch) -> VettedCall:
    """A :class:`VettedCall` with nothing vetted (a copy's, an unpickled one's)."""
    return VettedCall(kernel, *kinds, dispatch=None if dispatch is kernel else dispatch)


def _same(arrays: tuple, others: tuple) -> bool:
    """The same array objects, one for one (``==`` would compare their elements)."""
    return len(arrays) == len(others) and all(a is b for a, b in zip(arrays, others))
