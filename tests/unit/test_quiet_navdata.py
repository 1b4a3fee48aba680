"""A quiet wire tick's navdata packets received as numbers read as the packet decodes.

``sim/quiet_wire.py`` sends a quiet tick's navdata packets as the numbers their receipt reads
(``wire_step.navdata_packets``: the state word, the demo sample through the float32 / mm
codec; ``LockstepSensors._receive_quiet``: the stats, the sample, the take-off guard's look).
The oracle is the protocol's own encoder and decoder (``encode_drone_navdata``,
``decode_navdata``) and the link's ``navdata_sample_of``; a flight's receipt is held to the
Python wire path's (``QuietWire.enabled`` False).
"""

from __future__ import annotations

import math
import struct
from pathlib import Path

import numpy as np
import pytest

from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.core.types import FlightMode, NavdataSample
from ardrone_nmpc.links.drone_link import navdata_sample_of
from ardrone_nmpc.protocol.navdata import DroneState, decode_navdata, encode_drone_navdata
from ardrone_nmpc.runtime import lockstep
from ardrone_nmpc.sim import wire_step as ws
from ardrone_nmpc.sim.lockstep_drone import LockstepDrone
from ardrone_nmpc.sim.quiet_wire import QuietWire
from ardrone_nmpc.sim.sensor_step import NAV
from ardrone_nmpc.sim.sensors import LockstepSensors
from tests.unit.test_wire_sensors import FLIGHTS, _fly, _plain

CONFIGS = Path(__file__).resolve().parents[2] / "configs"
LAST_CMD_T, COMWDG_S = 1.0, 0.05


def _edges(rng, n: int) -> np.ndarray:
    """``n`` navdata samples (battery, roll, pitch, yaw, altitude, forward, right, down):
    ordinary values and the codec's edges — float32 ties and subnormals, overflow, ±inf, NaN,
    half millimetres and percents, −0 mm, int32's ends."""
    out = np.empty((n, 8))
    out[:, 0] = rng.uniform(-10.0, 110.0, n)
    out[:, 1:4] = rng.uniform(-400.0, 400.0, (n, 3))
    out[:, 4] = rng.uniform(0.0, 5.0, n)
    out[:, 5:8] = rng.uniform(-3.0, 3.0, (n, 3))
    single = rng.uniform(-2e5, 2e5, n).astype(np.float32)
    ties = (single.astype(np.float64)
            + np.nextafter(single, np.float32(np.inf)).astype(np.float64)) / 2.0 / 1000.0
    floats = [3.4e35, 3.5e35, -3.5e35, math.inf, -math.inf, math.nan, 1e-45, -1e-44, 0.0,
              -0.0]
    for i in range(n):
        kind = i % 4
        if kind == 1:  # a float32 tie (×1000) in one of the six floats
            out[i, rng.choice([1, 2, 3, 5, 6, 7])] = ties[i]
        elif kind == 2:
            out[i, rng.choice([1, 2, 3, 5, 6, 7])] = rng.choice(floats)
        elif kind == 3:
            out[i, 4] = rng.choice([int(rng.integers(0, 5000)) / 1000.0 + 0.0005, -0.0001,
                                    -0.0005, 3e6, 2147483.647, -2147483.648, math.nan])
            out[i, 0] = rng.choice([int(rng.integers(0, 100)) + 0.5, math.nan, -0.0, 100.5])
    return out


@pytest.mark.parametrize("clear,latched,fault_bits,vbat_low_pct,mode", [
    ("any", False, 0, 30.0, FlightMode.FLYING),
    ("any", True, int(DroneState.MOTORS), 50.0, FlightMode.TAKING_OFF),
    ("comwdg", False, int(DroneState.VBAT_LOW), 20.0, FlightMode.LANDING),
    ("any", False, int(DroneState.EMERGENCY), 30.0, FlightMode.FLYING)])
def test_the_packets_numbers_are_what_the_decoder_reads_of_the_packets_bytes(
        clear, latched, fault_bits, vbat_low_pct, mode):
    cfg = load_config(CONFIGS / "square.yaml", list(FLIGHTS["dropout"][1]))
    drone = LockstepDrone(cfg)
    quiet, fw = drone.sensors._quiet, drone.sensors.firmware
    assert isinstance(quiet, QuietWire)
    fw.plant._mode = mode
    fw.last_cmd_t, fw.comwdg_clear, fw.comwdg_latched = LAST_CMD_T, clear, latched
    fw.fault_bits, fw.vbat_low_pct = fault_bits, vbat_low_pct
    fw.config.bootstrap = False  # (navdata_demo written: the quiet ticks' packets)
    rng = np.random.default_rng(26)
    n = 400
    samples = _edges(rng, n)
    times = LAST_CMD_T + COMWDG_S + rng.uniform(-0.01, 0.01, n)  # the bit toggles
    fw.comwdg_s = COMWDG_S
    quiet.ev = np.zeros((n, ws.EV_WIDTH))
    for i in range(n):
        quiet.ev[i, ws.EV_KIND], quiet.ev[i, ws.EV_T] = NAV, times[i]
        quiet.ev[i, ws.EV_SAMPLE] = times[i] - 0.001  # (the plant's time: the packet's t_s)
        quiet.ev[i, ws.EV_SAMPLE + 1:ws.EV_SAMPLE + 9] = samples[i]
    sent = []
    drone.sensors.push_quiet_packet = lambda *packet: sent.append(packet)
    receipt = quiet._receipt(n)
    assert receipt
    checked = fallen_back = 0
    for i in range(n):
        t, row = times[i], quiet.ev[i].tolist()
        raw = NavdataSample.make(row[ws.EV_SAMPLE], mode, *samples[i])
        seq = fw.nav_seq + 1
        try:
            data = encode_drone_navdata(fw.status(t, raw.battery_pct), seq, raw,
                                        codes=fw.ctrl_codes,
                                        options_mask=fw.config.navdata_options, t_s=raw.t_s)
            packet = decode_navdata(data)
            expect = navdata_sample_of(packet, t)
        except (ValueError, OverflowError):
            packet = expect = None
        if not row[ws.EV_OK]:  # the Python's packet: one it refuses, or no finite number
            fallen_back += 1
            assert expect is None or not all(math.isfinite(v) for v in _values(expect)[3:])
            continue
        quiet._packet(receipt, t, row)
        arrival, sequence, state, major, sample = sent.pop()
        assert (arrival, sequence, major) == (t, packet.sequence, packet.demo.ctrl_major)
        assert state.__class__ is DroneState and int(state) == int(packet.state)
        assert _bits(sample) == _bits(expect)
        checked += 1
    assert checked > n // 2 and fallen_back > 10


def _values(sample: NavdataSample) -> list:
    return [getattr(sample, name) for name in NavdataSample.__slots__]


def _bits(sample: NavdataSample) -> list:
    """A sample's fields, its floats as their bytes (−0, NaN)."""
    return [struct.pack("<d", v) if isinstance(v, float) else (type(v), v)
            for v in _values(sample)]


def _receipts(name: str) -> tuple:
    """What the take-off guard was shown (the state's class, the word, the major) packet by
    packet, the sampler's navdata record after each tick's receipt, the stats at the end —
    and how many packets were received as numbers, in the flight ``name``."""
    shown, records, stats, quiet = [], [], [], [0]
    on_navdata, advance = LockstepDrone._on_navdata, LockstepSensors._advance_through_wire
    receive_quiet = LockstepSensors._receive_quiet

    def seen(self, state, major):
        shown.append((state.__class__, int(state), major))
        return on_navdata(self, state, major)

    def kept(self, t_s):
        advance(self, t_s)
        records.append((self.nav_rx_t_s, None if self.nav is None else _bits(self.nav)))
        stats[:] = [_plain(self.nav_stats), self.firmware.nav_seq]

    def counted(self, arrival_s, packet):
        quiet[0] += 1
        return receive_quiet(self, arrival_s, packet)

    with pytest.MonkeyPatch.context() as patched:
        patched.setattr(LockstepDrone, "_on_navdata", seen)
        patched.setattr(LockstepSensors, "_advance_through_wire", kept)
        patched.setattr(LockstepSensors, "_receive_quiet", counted)
        patched.setattr(lockstep, "BLOCK_TICKS", 0)  # (tick by tick: a block's receipt is
        _fly(name)                                   # test_tick_blocks')
    return (shown, records, stats), quiet[0]


@pytest.mark.parametrize("name", ["dropout", "vbat_low", "drone_faults", "ctrl_codes",
                                  "disorder_navdata"])
def test_a_flights_quiet_packets_received_as_numbers_leave_what_the_packets_leave(
        name, monkeypatch):
    monkeypatch.setattr(QuietWire, "enabled", False)
    reference, none = _receipts(name)
    monkeypatch.setattr(QuietWire, "enabled", True)
    ended, quiet = _receipts(name)
    assert none == 0 and quiet > 50  # (as numbers: most packets)
    assert ended == reference
    assert len(reference[0]) > 50 and reference[2][0]["_packets"] > 50


def _flip(name: str):
    """A change of the firmware's ``name`` (or its config's, its plant's) that ``status``
    shows."""
    from ardrone_nmpc.protocol.navdata import CtrlCodes
    return {
        "pcmd": lambda fw: setattr(fw, "pcmd", (1, 0.1, 0.0, 0.0, 0.0)),
        "alt_capped": lambda fw: setattr(fw, "alt_capped", True),
        "lost_com_hover": lambda fw: setattr(fw, "lost_com_hover", True),
        "user_emergency": lambda fw: setattr(fw, "user_emergency", True),
        "ref_start": lambda fw: setattr(fw, "ref_start", not fw.ref_start),
        "ack": lambda fw: setattr(fw, "ack", True),
        "demo": lambda fw: setattr(fw.config, "demo", not fw.config.demo),
        "navdata_options": lambda fw: setattr(fw.config, "navdata_options", 0),
        "comwdg_latched": lambda fw: setattr(fw, "comwdg_latched", not fw.comwdg_latched),
        "link_lost": lambda fw: setattr(fw, "link_lost", True),
        "fault_bits": lambda fw: setattr(fw, "fault_bits", int(DroneState.CUTOUT)),
        "ctrl_codes": lambda fw: setattr(fw, "ctrl_codes", CtrlCodes.FIRMWARE_2_4),
        "mode": lambda fw: setattr(fw.plant, "_mode", FlightMode.LANDING),
        "bootstrap": lambda fw: setattr(fw.config, "bootstrap", True),
    }[name]


@pytest.mark.parametrize("name", ["pcmd", "alt_capped", "lost_com_hover", "user_emergency",
                                  "ref_start", "ack", "demo", "navdata_options",
                                  "comwdg_latched", "link_lost", "fault_bits",
                                  "ctrl_codes", "mode", "bootstrap"])
def test_the_tick_state_kept_across_ticks_follows_what_the_firmware_reports(name):
    """``QuietWire._status`` (kept while the firmware's status inputs stay) against
    ``DroneFirmware.status`` itself after a change of each of them."""
    from ardrone_nmpc.protocol.navdata import OptionTag

    cfg = load_config(CONFIGS / "square.yaml", list(FLIGHTS["dropout"][1]))
    drone = LockstepDrone(cfg)
    quiet, fw = drone.sensors._quiet, drone.sensors.firmware
    # (a phase in which the change shows: the codes a transition's, the user's emergency
    # an emergency's)
    fw.plant._mode = {"ctrl_codes": FlightMode.TAKING_OFF,
                      "user_emergency": FlightMode.EMERGENCY}.get(name, FlightMode.FLYING)
    fw.config.bootstrap, fw.last_cmd_t = False, 0.0  # (a command heard: a quiet tick's)

    def fresh():
        status = fw.status(-math.inf, math.inf)
        return (int(status.state_bits()), status.ctrl_state(fw.ctrl_codes),
                bool(not status.demo or fw.config.navdata_options & (1 << OptionTag.DEMO)))

    before = quiet._status(fw)
    assert before == fresh()
    _flip(name)(fw)
    assert fresh() != before  # (the change shows in the status)
    assert quiet._status(fw) == fresh()
