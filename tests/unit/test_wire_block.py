"""What a block of the wire's ticks says the links hold (``sim/wire_block._links_hold``)
against the links themselves: over random streams of frames — new poses, bit-identical
repeats, zero (±0.0), non-finite and overflowing ones — received by a ``MocapLink`` tick by
tick (its bulk receipt, the flight's), every tick the block calls usual holds the link's
newest pose bit for bit (position through the wire's mm, heading, receipt time); and a
packet whose alarm bits differ from the block's, or whose numbers do not stand for it,
ends the block."""

from __future__ import annotations

import math
import random
import struct

import numpy as np
import pytest

from ardrone_nmpc.core.numerics import callable_from_python
from ardrone_nmpc.links.mocap_link import MocapLink
from ardrone_nmpc.protocol.mocap import rotation_heading_rad
from ardrone_nmpc.sim import sensor_step as ks
from ardrone_nmpc.sim import wire_block as wb
from ardrone_nmpc.sim import wire_step as ws

NAME = "ardrone"
SENDER = ("lockstep", 0)
PERIOD_S, TICK_S, LATENCY_S = 0.01, 0.065, 0.0175
links_hold = callable_from_python(wb._links_hold)  # (an inner kernel: no Python wrapper)


def _pose(rng: random.Random, last):
    """A pose (position m, rotation rad, a repeat): mostly new, sometimes the last again
    (often several times), zero, non-finite or too large for the wire's mm."""
    roll = rng.random()
    if last is not None and (roll < 0.04 or (last[2] and roll < 0.6)):
        return (*last[:2], True)  # (a run of repeats: past the link's repeat limit too)
    if roll < 0.06:
        z = rng.choice([0.0, -0.0])
        return [z, 0.0, z], [0.0, z, 0.0], False
    if roll < 0.075:
        return ([rng.uniform(-2, 2), math.nan, 1.0], [0.0, 0.0, rng.choice([math.inf, 0.1])],
                False)
    if roll < 0.09:
        return [1e308, 0.5, 1.0], [0.1, 0.2, 0.3], False
    return ([rng.uniform(-2, 2) for _ in range(3)], [rng.uniform(-0.3, 0.3) for _ in range(3)],
            False)


def _d(cap: int) -> np.ndarray:
    d = wb.wire_d(cap)
    d[wb.D_LATENCY] = LATENCY_S
    d[wb.W_LAST:wb.W_LAST + 6] = math.nan
    return d


def _frame_row(row, k: int, position_m, rotation) -> None:
    row[ws.EV_KIND], row[ws.EV_T], row[ws.EV_K] = ks.MOCAP, k * PERIOD_S, k
    s = row[ws.EV_SAMPLE:]
    s[1:4], s[4:7] = position_m, rotation
    s[7] = rotation_heading_rad(*rotation)  # (the legs' _mocap_pose draws it so)


def _held(d) -> list:
    return [struct.pack("<d", float(v)) for v in
            (d[wb.D_PX], d[wb.D_PY], d[wb.D_PZ], d[wb.D_PSI], d[wb.D_POSE_RX], d[wb.D_POSE_T])]


def _latest(link) -> list:
    pose, rx = link.latest()
    x, y, z = pose.position_m.tolist()
    return [struct.pack("<d", float(v)) for v in (x, y, z, pose.psi_rad, rx, pose.t_s)]


@pytest.mark.parametrize("seed", range(12))
def test_a_usual_tick_holds_the_links_newest_pose(seed):
    rng = random.Random(seed)
    link = MocapLink("127.0.0.1", 0, object_name=NAME)  # (never opened)
    link.feed_object_frames([(0, 0.0, [0.5, 0.5, 1.0], [0.0, 0.0, 0.1])], SENDER)  # (locked)
    cap = 800
    d = _d(cap)
    rows = d[wb.W_ROWS:].reshape((cap, ws.EV_WIDTH))
    k, last, usual_ticks, odd_ticks, arrived = 1, None, 0, 0, []
    for tick in range(1, 80):
        t_s = tick * TICK_S
        lo = int(d[wb.W_N])
        while k * PERIOD_S <= t_s:  # the tick's frames, sampled on their grid
            last = _pose(rng, last)
            _frame_row(rows[int(d[wb.W_N])], k, *last[:2])
            arrived.append((k, k * PERIOD_S + LATENCY_S, list(last[0]), list(last[1])))
            d[wb.W_N] += 1
            k += 1
        usual = links_hold(d, rows, lo, int(d[wb.W_N]), t_s)
        now = [f for f in arrived if f[1] <= t_s + 1e-12]
        arrived = arrived[len(now):]
        link.feed_object_frames(now, SENDER)  # (the flight's receipt of the tick's)
        if usual:
            usual_ticks += 1
            assert _held(d) == _latest(link), f"tick {tick}"
        else:
            odd_ticks += 1
    assert usual_ticks > 5 and odd_ticks > 5  # (the streams have both)


def test_a_packet_the_block_cannot_stand_for_ends_it():
    d = _d(8)
    rows = d[wb.W_ROWS:].reshape((8, ws.EV_WIDTH))
    alarm = 1 << 15
    d[wb.W_ALARM], d[wb.W_BITS] = alarm, 0
    row = rows[0]
    row[ws.EV_KIND], row[ws.EV_T], row[ws.EV_OK], row[ws.EV_STATE] = ks.NAV, 0.06, 1.0, 0x301
    row[ws.EV_DEMO:ws.EV_DEMO + 8] = (80.0, 1.5, -2.0, 30.0, 1.0, 0.25, -0.125, 0.0)
    assert links_hold(d, rows, 0, 1, 0.065)
    assert d[wb.D_T_NAV] == d[wb.D_NAV_T] == 0.06 and d[wb.D_BATTERY] == 80.0
    assert (d[wb.D_NAV_ROLL], d[wb.D_NAV_PITCH]) == (1.5, -2.0)
    assert (d[wb.D_NAV_VX], d[wb.D_NAV_VY], d[wb.D_NAV_STATE]) == (0.25, -0.125, 0x301)
    row[ws.EV_STATE] = 0x301 | alarm  # (the battery's alarm bit: the controller's to see)
    assert not links_hold(d, rows, 0, 1, 0.065)
    row[ws.EV_STATE], row[ws.EV_OK] = 0x301, 0.0  # (numbers the wire would refuse)
    assert not links_hold(d, rows, 0, 1, 0.065)
    row[ws.EV_STATE], row[ws.EV_OK] = 0x301 | (1 << 30), 1.0  # (no alarm: the com watchdog)
    assert links_hold(d, rows, 0, 1, 0.065)


class _Quiet:
    dropout_scan = (0, 0, False, math.nan)


@pytest.mark.parametrize("seed", range(6))
def test_the_first_dropped_frame_asked_once_per_frame_is_the_scans(seed):
    """``_first_dropped`` (each frame asked once across the blocks' bounds) against asking
    every frame from ``k``: the same first dropped frame, or the end; a frame not dropped
    asked once while the clock stays."""
    rng = random.Random(seed)
    period, start, duration, every = 0.01, rng.uniform(0, 3), rng.uniform(0.02, 0.4), \
        rng.choice([None, 1.0, 2.5])
    asked = []

    def rule(t_s):  # (FaultSchedule.mocap_dropped's)
        phase = t_s - start
        if phase < 0:
            return False
        return (phase % every if every else phase) < duration

    def dropped(t_s):
        asked.append(round(t_s / period))
        return rule(t_s)

    quiet, k, t_zero = _Quiet(), 0, 0.0
    for _ in range(60):
        k += rng.randrange(0, 40)
        end = k + rng.randrange(1, 600)
        expected = next((j for j in range(k, end) if rule(j * period - t_zero)), end)
        found = wb._first_dropped(quiet, dropped, k, end, period, t_zero)
        assert found == expected or (found > end and expected == end)
        if k < found < end:
            k = found  # (the flight reaches the dropped frame: asked again from there)
    assert len(asked) <= len(set(asked)) + 60  # (once a frame; a dropped one once a query)
    quiet.dropout_scan = (0, 10 ** 6, False, 5.0)  # (another clock: asked afresh)
    assert wb._first_dropped(quiet, dropped, 0, 10 ** 6, period, 0.0) < 10 ** 6
