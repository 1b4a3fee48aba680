"""The whole state of a receiving link, as bits: the one home of the tests that compare a
bulk receipt (``MocapLink.feed_object_frames``, ``LinkStats.record_numbered``) with the
frame-by-frame one it stands for (test_mocap_bulk_receipt, test_wire_sensors)."""

from __future__ import annotations

import struct
import threading

import numpy as np

_SKIPPED = (threading.Lock().__class__, threading.Thread, threading.Event)


def bits(value):
    """``value`` as something ``==`` compares bit for bit (floats as their bytes, arrays as
    dtype, flags and bytes, records and containers item by item)."""
    if isinstance(value, float):
        return ("f", struct.pack("<d", value))
    if isinstance(value, np.ndarray):
        return ("a", value.dtype.str, value.shape, value.flags.writeable, value.tobytes())
    if isinstance(value, dict):
        return ("d", [(bits(k), bits(v)) for k, v in value.items()])
    if isinstance(value, (list, tuple, set, frozenset)) or value.__class__.__name__ == "deque":
        items = sorted(value, key=repr) if isinstance(value, (set, frozenset)) else value
        return (value.__class__.__name__, [bits(v) for v in items])
    if hasattr(value, "__dataclass_fields__"):
        return (value.__class__.__name__,
                [(k, bits(getattr(value, k))) for k in value.__dataclass_fields__])
    slots = getattr(value.__class__, "__slots__", None)
    if slots is not None and not isinstance(value, (str, bytes, int)):
        return (value.__class__.__name__, [(k, bits(getattr(value, k))) for k in slots])
    return value


def link_state(link) -> dict:
    """Every attribute of a mocap link (or source) and of its :class:`LinkStats`, as
    :func:`bits` (locks, threads and the clock left out)."""
    def attrs(obj) -> dict:
        return {k: bits(v) for k, v in vars(obj).items()
                if not isinstance(v, _SKIPPED) and k not in ("stats", "_clock")}

    return {"link": attrs(link), "stats": attrs(link.stats)}
