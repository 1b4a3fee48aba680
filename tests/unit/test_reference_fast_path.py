"""The references' fast path for the horizon's times (a 1-D C-contiguous float64 array, issue
26) gives the bits of the general path it skips, for every trajectory kind of
``reference/`` and the settle phase's :class:`HoldStartThen` around each: the general path is
forced by making :func:`is_times` answer no."""

from __future__ import annotations

import typing

import numpy as np
import pytest

from ardrone_nmpc.config.schema import ReferenceConfig
from ardrone_nmpc.reference import experiment, trajectories
from ardrone_nmpc.reference.experiment import HoldStartThen
from ardrone_nmpc.reference.trajectories import Hover, is_times, make_trajectory

KINDS = typing.get_args(ReferenceConfig.model_fields["kind"].annotation)


def _trajectory(kind, tmp_path):
    if kind == "path":
        path = tmp_path / "path.csv"
        path.write_text("t_s,x_m,y_m,z_m,psi_rad\n0,0,0,1,0\n2,1,0,1,0.5\n3.5,1,-1,1.2,3\n")
        return make_trajectory(ReferenceConfig(kind=kind, path_file=str(path)))
    traj = make_trajectory(ReferenceConfig(kind=kind), duration_s=20.0)
    if kind == "follow":  # a live object, seen moving
        from ardrone_nmpc.core.types import MocapPose

        traj.observe(MocapPose(1.0, np.array([0.5, -0.25, 1.1]), np.zeros(3), 0.3),
                     t_pose_s=1.0, age_ms=0.0)
        traj.observe(MocapPose(1.1, np.array([0.52, -0.2, 1.1]), np.zeros(3), 0.31),
                     t_pose_s=1.1, age_ms=0.0)
    return traj


def _times_to_try():
    rng = np.random.default_rng(3)
    offsets = 0.03 * np.arange(17, dtype=np.float64)
    out = [np.add(t + 0.06, offsets) for t in (-2.0, -0.07, -0.03, 0.0, 1e-9, 4.99, 12.3)]
    for h in out:
        h[0] -= 0.06  # the horizon's first time is the tick's own (runtime/stages.py)
    out += [rng.uniform(-3.0, 25.0, 200), np.array([np.nan, np.inf, -np.inf, -0.0, 0.0, 5.0]),
            np.array([0.5]), np.empty(0)]
    return out


def _general(monkeypatch, call):
    with monkeypatch.context() as m:
        m.setattr(trajectories, "is_times", lambda t_s: False)
        m.setattr(experiment, "is_times", lambda t_s: False)
        return call()


@pytest.mark.parametrize("kind", KINDS)
def test_fast_path_is_the_general_path_bit_for_bit(kind, tmp_path, monkeypatch):
    traj = _trajectory(kind, tmp_path)
    candidates = [traj]
    if kind != "follow":  # the runners hold a configured trajectory's start through settling
        candidates.append(HoldStartThen(traj))
    for ref in candidates:
        for t in _times_to_try():
            if kind == "follow" and not t.size:
                continue
            assert is_times(t)
            try:
                general = _general(monkeypatch, lambda: ref.state_at(t))
            except ValueError as err:  # no times for a Lorenz path: the same error either way
                with pytest.raises(type(err)):
                    ref.state_at(t)
                continue
            fast = ref.state_at(t)
            assert fast.dtype == general.dtype and fast.shape == general.shape
            assert fast.tobytes() == general.tobytes(), (kind, type(ref).__name__, t)
            # and what other callers pass: lists, scalars, strided views
            assert ref.state_at(t.tolist()).tobytes() == general.tobytes()
            assert ref.state_at(np.repeat(t, 2)[::2]).tobytes() == general.tobytes()
            fast[...] = 7.0  # a fresh array each call: writing it changes nothing held
            assert ref.state_at(t).tobytes() == general.tobytes()


def test_is_times_only_passes_what_needs_no_conversion():
    t = np.linspace(0.0, 1.0, 5)
    assert is_times(t) and is_times(np.add(1.0, t))
    for other in (t.tolist(), 0.5, np.float64(0.5), np.array(0.5), t[::2], t[None, :],
                  t.astype(np.float32), t.astype(">f8"), t.astype(np.int64)):
        assert not is_times(other)


def test_hover_rows_are_np_tile_of_its_state():
    hover = Hover((0.3, -0.0, 1.1), -0.0)
    for n in (0, 1, 17):
        expected = np.tile(hover._state, (n, 1))
        got = hover.state_at(np.zeros(n))
        assert got.tobytes() == expected.tobytes() and got.shape == expected.shape
        assert got.flags.c_contiguous and got.flags.writeable
