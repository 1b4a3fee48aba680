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
