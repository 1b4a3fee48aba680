"""Attributes that a compiled path holds in its arrays between its runs.

While :class:`~ardrone_nmpc.sim.lockstep_legs.CompiledLegs` flies a plant tick after tick,
the plant's state lives in the kernel's arrays: writing it back to the plant's attributes
and packing it again every tick cost more than the physics. So the legs take the attributes
out of the instance's ``__dict__`` and set its ``_held_by`` to themselves; a
:class:`HeldInArrays` of the same name on the class — a non-data descriptor, so an
attribute in the instance's ``__dict__`` always wins and costs nothing extra — answers a
read of one that is missing by calling the holder's ``release()``, which writes them all
back (keeping any written meanwhile), and returns the value. Any reader — the plant's own
Python path, the firmware, a fault, a test — sees what the attribute would have held.

A copy, a deep copy or a pickle reads the instance's ``__dict__`` without the descriptors: the
owner class's ``__getstate__ = released_state`` writes the held attributes back first, so the
copy has them (and no holder: it is nobody's). :func:`holds_in_arrays` declares a class's held
attributes: the stand-ins, their names (what a holder takes) and that ``__getstate__``.
"""

from __future__ import annotations

__all__ = ["HeldInArrays", "holds_in_arrays", "overrides_none", "released_state"]


def holds_in_arrays(*names: str):
    """Class decorator: ``names`` may be held in a holder's arrays — each a
    :class:`HeldInArrays` on the class, the tuple as ``cls.HELD_IN_ARRAYS`` (what the holder
    takes; a subclass's adds its names to its base's), and ``__getstate__ = released_state``
    (a copy or pickle while held: the attributes, no holder)."""
    def decorate(cls):
        for name in names:
            stand_in = HeldInArrays()
            stand_in.__set_name__(cls, name)
            setattr(cls, name, stand_in)
        cls.HELD_IN_ARRAYS = getattr(cls, "HELD_IN_ARRAYS", ()) + names
        cls.__getstate__ = released_state
        return cls
    return decorate


class HeldInArrays:
    """A class-level stand-in for an instance attribute while a holder keeps it in arrays
    (module docstring)."""

    __slots__ = ("name",)

    def __init__(self) -> None:
        self.name = ""

    def __set_name__(self, owner, name: str) -> None:
        self.name = name

    def __get__(self, obj, owner=None):
        if obj is None:
            return self
        holder = obj.__dict__.get("_held_by")
        if holder is None:
            raise AttributeError(f"{type(obj).__name__!r} object has no attribute "
                                 f"{self.name!r}")
        holder.release()
        try:
            return obj.__dict__[self.name]
        except KeyError:  # a holder not holding obj (a clone of vars(obj) while held)
            raise AttributeError(f"{type(obj).__name__!r} object has no attribute "
                                 f"{self.name!r}") from None


def released_state(obj):
    """``obj``'s ``__getstate__`` (copy, deepcopy, pickle): object's own, with the held
    attributes written back first (module docstring)."""
    holder = obj.__dict__.get("_held_by")
    if holder is not None:
        holder.release()
        if obj.__dict__.get("_held_by") is not None:  # a holder not holding obj (a clone
            obj.__dict__["_held_by"] = None           # of vars(obj) while held): nobody's
    return object.__getstate__(obj)


def overrides_none(obj, base: type, names) -> bool:
    """``obj`` is a ``base`` whose class overrides none of ``names`` (what a compiled path
    does in its place: an override would be skipped)."""
    kind = type(obj)
    return isinstance(obj, base) and all(getattr(kind, n) is getattr(base, n) for n in names)
