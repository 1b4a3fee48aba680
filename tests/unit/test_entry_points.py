"""core/entry_points: a kernel's compiled entry point only for argument kinds it was compiled
for — the dispatcher's own specialisation — and None for anything it does not vouch for."""

import numba
import numpy as np

from ardrone_nmpc.core.entry_points import entry_point, plain


def _kernel():
    @numba.njit
    def weigh(a, b, scale, flag, n):
        s = 0.0
        for i in range(a.shape[0]):
            s += a[i] * b[i, 0]
        return s * scale + (n if flag else 0)
    return weigh


def test_plain_is_numbas_c_array_of_the_dtype_and_dimension():
    a = np.arange(6.0)
    assert plain(a) and plain(a.reshape(2, 3), 2) and plain(np.zeros(3, np.int64), 1, np.int64)
    read_only = a.copy()
    read_only.flags.writeable = False
    for not_plain in (a[::2], np.asfortranarray(a.reshape(2, 3)), read_only,
                      a.astype(np.float32), a.view(np.matrix)[0]):
        assert not plain(not_plain, not_plain.ndim)
    assert not plain(a, 2) and not plain(a, 1, np.int64)


def test_the_entry_point_is_the_dispatchers_specialisation_for_those_kinds_only():
    weigh = _kernel()
    a, b = np.arange(4.0), np.ones((4, 2))
    args = (a, b, 0.5, True, 3)
    assert entry_point(weigh, *args) is None  # nothing compiled yet
    expected = weigh(*args)
    entry = entry_point(weigh, *args)
    assert entry is not None and entry is not weigh
    assert entry(*args) == expected
    assert entry_point(weigh, np.arange(4.0, 8.0), np.zeros((4, 2)), 2.0, False, 7) is entry
    # kinds not compiled, or not vouched for: the dispatcher is the caller's
    assert entry_point(weigh, a[::2], b, 0.5, True, 3) is None
    assert entry_point(weigh, a, np.asfortranarray(b), 0.5, True, 3) is None
    assert entry_point(weigh, a.astype(np.float32), b, 0.5, True, 3) is None
    assert entry_point(weigh, a, b, np.float64(0.5), True, 3) is None
    assert entry_point(weigh, a, b, 0.5, True, 1 << 63) is None
    assert entry_point(weigh, a.astype(">f8"), b, 0.5, True, 3) is None  # numba refuses it
    # a kind compiled later is found then (the miss before is not kept once it compiled)
    weigh(a.astype(np.float32), b, 0.5, True, 3)
    other = entry_point(weigh, a.astype(np.float32), b, 0.5, True, 3)
    assert other is not None and other is not entry


def test_no_entry_point_without_a_dispatcher():
    assert entry_point(lambda a: a, np.zeros(2)) is None


# ----------------------------------------------------------------------------- VettedCall
def _counted(kernel):
    """The dispatcher's calls counted (the entry point's are not)."""
    calls = []

    def dispatch(*args):
        calls.append(args)
        return kernel(*args)
    return dispatch, calls


def _weigh_call(weigh):
    from ardrone_nmpc.core.entry_points import ArrayKind, VettedCall

    dispatch, calls = _counted(weigh)
    return VettedCall(weigh, ArrayKind(1), ArrayKind(2), 0.0, False, 0, dispatch=dispatch), calls


def _vetted(n: int):
    """A call of a new kernel vetted for two arrays of ``n`` rows (seen twice)."""
    weigh = _kernel()
    call, calls = _weigh_call(weigh)
    a, b = np.arange(float(n)), np.ones((n, 2))
    for _ in range(2):
        call(a, b, 0.5, True, 3)
    assert call.entry is not None and len(calls) == 1
    return weigh, call, calls, a, b


def test_a_vetted_call_takes_the_entry_point_while_the_same_plain_arrays_come():
    weigh = _kernel()
    call, calls = _weigh_call(weigh)
    a, b = np.arange(4.0), np.ones((4, 2))
    assert call(a, b, 0.5, True, 3) == weigh.py_func(a, b, 0.5, True, 3)
    assert len(calls) == 1 and call.entry is None  # new arrays: the dispatcher, not vetted
    assert call(a, b, 2.0, False, 1) == weigh.py_func(a, b, 2.0, False, 1)
    assert len(calls) == 1 and call.entry is entry_point(weigh, a, b, 0.5, True, 3)
    assert call.vetted[0] is a and call.vetted[1] is b
    for k in range(3):  # the same arrays: the entry point, with any numbers
        assert call(a, b, 0.25 * k, k % 2 == 0, k) == weigh.py_func(a, b, 0.25 * k, k % 2 == 0, k)
    assert len(calls) == 1
    # an equal copy is not the vetted array: the dispatcher (and vetted in its turn)
    c = a.copy()
    call(c, b, 0.5, True, 3)
    assert len(calls) == 2 and call.vetted[0] is a
    call(c, b, 0.5, True, 3)
    assert len(calls) == 2 and call.vetted[0] is c
    call(a, b, 0.5, True, 3)  # the first arrays are no longer the vetted ones
    assert len(calls) == 3


def test_a_vetted_call_leaves_arrays_of_other_kinds_to_the_dispatcher():
    _, call, calls, a, b = _vetted(8)
    vetted = call.entry
    others = [(a.astype(np.float32), b), (a.reshape(2, 4), b), (a[::2], b),
              (a, np.asfortranarray(b)), (a, b.reshape(16))]
    for x, y in others:
        n = len(calls)
        for _ in range(3):  # seen again and again: never vetted, the dispatcher each call
            try:
                call(x, y, 0.5, True, 3)
            except Exception:  # (numba's own refusal of a kind it cannot type: still its call)
                pass
        assert len(calls) == n + 3, (x.shape, x.dtype, y.shape)
        assert call.entry is vetted and call.vetted[0] is a


def test_a_vetted_call_copied_or_pickled_starts_afresh_with_the_same_kernel():
    import copy
    import pickle

    weigh, call, calls, a, b = _vetted(4)
    for twin in (copy.copy(call), copy.deepcopy(call)):
        assert twin.entry is None and twin.vetted == () and twin.kernel is weigh
        assert twin.dispatch is call.dispatch and twin.kinds == call.kinds
        twin(a, b, 0.5, True, 3)
        assert len(calls) == 2 and twin.entry is None  # a first sight: the dispatcher
        del calls[1:]
    from ardrone_nmpc.runtime.estimate import _STEP  # a module-level kernel pickles
    twin = pickle.loads(pickle.dumps(_STEP))
    assert twin.kernel is _STEP.kernel and twin.kinds == _STEP.kinds and twin.entry is None


class _Owner:
    pass


def test_bind_sets_the_entry_point_or_a_first_call_that_binds_it(monkeypatch):
    from ardrone_nmpc.core import entry_points

    weigh = _kernel()
    call, calls = _weigh_call(weigh)
    a, b = np.arange(4.0), np.ones((4, 2))
    owner = _Owner()
    call.bind(owner, "step", a, b)  # nothing compiled: the first call
    first = owner.step
    assert first(a, b, 0.5, True, 3) == weigh.py_func(a, b, 0.5, True, 3) and len(calls) == 1
    entry = entry_point(weigh, a, b, 0.5, True, 3)
    assert entry is not None and owner.step is entry
    # compiled already: the entry point at once
    other = _Owner()
    call.bind(other, "step", a, b)
    assert other.step is entry
    # a first call with other arrays than the owner's binds nothing
    monkeypatch.setattr(entry_points, "entry_point", lambda *args: None)
    call.bind(other, "step", a, b)
    monkeypatch.undo()
    first = other.step
    first(a.copy(), b, 0.5, True, 3)
    assert other.step is first and len(calls) == 2
    # arrays not plain are never bound
    strided = a[::2]
    call.bind(other, "step", strided, b)
    first = other.step
    assert first is not entry
    for _ in range(2):
        assert first(strided, b, 0.5, True, 3) == weigh.py_func(strided, b, 0.5, True, 3)
    assert other.step is first and len(calls) == 4
