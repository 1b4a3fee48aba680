"""The per-tick records of ``core/types.py`` keep the dataclass's behaviour with their faster
``__init__`` (issue 26): each is compared with a twin built by ``dataclasses`` itself from the
same fields — signature, stored values, repr, equality and hash, ``replace``, pickling — and
stays frozen."""

from __future__ import annotations

import copy
import dataclasses
import inspect
import math
import pickle

import numpy as np
import pytest

from ardrone_nmpc.core.types import (AttitudeCommand, FlightMode, MocapPose, NavdataSample,
                                     PlantTruth, TickInputs)

POSE = MocapPose(1.0, np.array([0.1, 0.2, 1.0]), np.zeros(3), 0.3)
NAV = NavdataSample(1.0, FlightMode.FLYING, 55.0, 1.0, -2.0, 30.0, 0.9, 0.1, -0.2, 0.05)

# a record's positional arguments (the optional ones left out) and its optional ones
CASES = {
    AttitudeCommand: ((0.1, -0.0, 0.3, math.nan), {}),
    PlantTruth: ((2.0, np.arange(3.0), np.ones(3), 0.1, -0.2, 0.3, 0.0, FlightMode.FLYING, 80.0),
                 {}),
    MocapPose: ((1.0, np.array([0.1, 0.2, 1.0]), np.zeros(3), 0.3), {}),
    NavdataSample: ((1.0, FlightMode.LANDED, 55.0, 1.0, -2.0, 30.0, 0.0, 0.1, -0.2, 0.05),
                    {"ctrl_state": 0x20000, "state_bits": 7}),
    TickInputs: ((3.0, POSE, 2.99, NAV, 2.98), {"target": POSE, "target_rx_t_s": 2.5}),
}


def _twin(cls):
    """``cls`` as ``dataclasses`` alone builds it (its generated ``__init__``)."""
    params = cls.__dataclass_params__
    specs = [(f.name, f.type, dataclasses.field(default=f.default))
             for f in dataclasses.fields(cls)]
    return dataclasses.make_dataclass(cls.__name__, specs, frozen=True, slots=True,
                                      eq=params.eq)


@pytest.mark.parametrize("cls", list(CASES), ids=lambda c: c.__name__)
def test_records_build_as_their_dataclass_twin(cls):
    twin = _twin(cls)
    assert str(inspect.signature(cls)) == str(inspect.signature(twin))
    assert str(inspect.signature(cls.make)) == str(inspect.signature(twin))
    args, optional = CASES[cls]
    names = [f.name for f in dataclasses.fields(cls)]
    for kwargs in ({}, optional):
        rec, ref = cls(*args, **kwargs), twin(*args, **kwargs)
        by_name = cls(**dict(zip(names, args)), **kwargs)
        made = cls.make(*args, **kwargs)  # the hot callers' constructor: the same record
        assert type(made) is cls and not hasattr(made, "__dict__")
        for name in names:  # the very objects given (or the same defaults)
            assert (getattr(rec, name) is getattr(ref, name) is getattr(by_name, name)
                    is getattr(made, name))
        assert repr(rec) == repr(ref) == repr(made)
        if cls.__dataclass_params__.eq:
            assert rec == cls(*args, **kwargs) and hash(rec) == hash(cls(*args, **kwargs))
            assert rec != cls(*args[:-1], -1.0, **kwargs)
        else:  # vectors inside: compared by identity
            assert rec != cls(*args, **kwargs) and rec == rec
        with pytest.raises(dataclasses.FrozenInstanceError):
            setattr(rec, names[0], 5.0)
        changed = dataclasses.replace(rec, **{names[0]: 5.0})
        assert type(changed) is cls and getattr(changed, names[0]) == 5.0
        assert repr(pickle.loads(pickle.dumps(rec))) == repr(rec)
        assert repr(copy.copy(rec)) == repr(rec)
    for build in (cls, cls.make):
        with pytest.raises(TypeError):
            build(*args[:-1])
        with pytest.raises(TypeError):
            build(*args, nonsense=1)


def test_a_default_factory_gives_each_record_its_own_value():
    """``slot_init`` on a record with a ``default_factory`` (the tick's ``TickOutput`` and its
    ``events``): the dataclass's signature, a new value for each record left without one,
    the value given otherwise — as the dataclass's own ``__init__``."""
    from ardrone_nmpc.control.mapping import PcmdCommand
    from ardrone_nmpc.runtime.tick import TickOutput
    from ardrone_nmpc.safety import Action

    specs = [(f.name, f.type,
              dataclasses.field(default=f.default, default_factory=f.default_factory))
             for f in dataclasses.fields(TickOutput)]
    twin = dataclasses.make_dataclass("TickOutput", specs, frozen=True, slots=True)
    assert str(inspect.signature(TickOutput)) == str(inspect.signature(twin))
    pcmd = PcmdCommand(0.0, 0.0, 0.0, 0.0, (False,) * 4)
    a, b = TickOutput(pcmd, True, {}), TickOutput(pcmd, True, {})
    assert a.events == [] and b.events == [] and a.events is not b.events
    c, d = TickOutput.make(pcmd, True, {}), TickOutput.make(pcmd, True, {})
    assert c.events == [] and d.events == [] and c.events is not d.events
    assert TickOutput.make(pcmd, False, {}, events=[{"kind": "x"}]).events == [{"kind": "x"}]
    assert a.action is Action.CONTROL
    given = [{"kind": "x"}]
    assert TickOutput(pcmd, False, {}, Action.LAND, given).events is given
    assert TickOutput(pcmd, False, {}, events=given).events is given
    assert repr(a) == repr(twin(pcmd, True, {}))
    with pytest.raises(dataclasses.FrozenInstanceError):
        a.events = []


@pytest.mark.parametrize("cls", list(CASES), ids=lambda c: c.__name__)
def test_a_record_is_its_class_and_a_subclass_record_stays_the_subclass(cls):
    """The fast ``__init__`` lends the record a twin class while it fills the slots: the
    record comes out as ``cls``, without a ``__dict__``; a subclass's record (slots of its
    own or none, ``__init__`` inherited or called through ``super()``) keeps its class."""
    args, _ = CASES[cls]
    rec = cls(*args)
    assert type(rec) is cls and not hasattr(rec, "__dict__")

    class NoSlots(cls):
        pass

    class SameSlots(cls):
        __slots__ = ()

        def __init__(self, *a):
            super().__init__(*a)

    for sub in (NoSlots, SameSlots):
        rec = sub(*args)
        assert type(rec) is sub
        for f, arg in zip(dataclasses.fields(cls), args):
            assert getattr(rec, f.name) is arg
        with pytest.raises(dataclasses.FrozenInstanceError):
            setattr(rec, dataclasses.fields(cls)[0].name, 5.0)
