"""The lockstep wire sensors' shortcuts give the bits of the plain wire path they stand in for.

A flight with a sensor fault takes the wire path (``sim/sensors.py``): every mocap frame and
navdata packet through the faults to the receiving links. Its shortcuts — mocap frames
handed over decoded instead of as bytes, the ticks outside the faults' windows flown by one
compiled call (``sim/quiet_wire.py``) — are switched off for a reference flight of the same
config: the two must write the same rows and events and end alike.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import pytest

from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.runs.memory import MemoryRecorder
from ardrone_nmpc.runtime import lockstep
from ardrone_nmpc.runtime.lockstep import run_lockstep
from ardrone_nmpc.sim.quiet_wire import QuietWire
from ardrone_nmpc.links.mocap_link import MocapLink
from ardrone_nmpc.sim.sensors import _NAV, LockstepSensors, ObjectFrame
from tests.link_state import link_state

CONFIGS = Path(__file__).resolve().parents[2] / "configs"
WALL_TIME = {"solve_us", "compute_us", "tick_late_ms"}  # measured: differ between flights
SQUARE = ["duration_s=7", "sim.settle_s=1"]
# each kind of act on each stream (frames dropped, missing, zero, late, duplicated and
# reordered; packets lost, corrupted, duplicated and reordered; a blackout), a repeated
# dropout, the wire with a scripted second object and with the kit plant, the drone's own
# reports (SENSOR_FAULTS that act on the packets for the whole flight or from a time on)
FLIGHTS = {
    "dropout": ("square", ["faults.mocap_dropout.start_s=2",
                           "faults.mocap_dropout.duration_s=0.3"]),
    "repeated_dropout": ("square", ["faults.mocap_dropout.start_s=1",
                                    "faults.mocap_dropout.duration_s=0.1",
                                    "faults.mocap_dropout.repeat_every_s=1.5"]),
    "occlusion_zero": ("square", ["faults.mocap_occlusion.start_s=2",
                                  "faults.mocap_occlusion.duration_s=0.3",
                                  "faults.mocap_occlusion.zero_pose=true"]),
    "occlusion_missing": ("square", ["faults.mocap_occlusion.start_s=2",
                                     "faults.mocap_occlusion.duration_s=0.3"]),
    "latency": ("square", ["faults.mocap_latency.start_s=2", "faults.mocap_latency.duration_s=0.5",
                           "faults.mocap_latency.extra_latency_ms=120"]),
    "disorder_mocap": ("square", ["faults.disorder.start_s=1", "faults.disorder.duration_s=2",
                                  "faults.disorder.stream=mocap"]),
    "disorder_navdata": ("square", ["faults.disorder.start_s=1", "faults.disorder.duration_s=2",
                                    "faults.disorder.stream=navdata"]),
    "navdata_corrupt": ("square", ["faults.navdata_corrupt.start_s=2",
                                   "faults.navdata_corrupt.duration_s=0.2"]),
    "blackout": ("square", ["faults.blackout.start_s=2", "faults.blackout.duration_s=0.3"]),
    "target": ("follow_car", ["faults.mocap_dropout.start_s=2",
                              "faults.mocap_dropout.duration_s=0.2"]),
    "kit": ("square", ["sim.plant.profile=thesis_kit", "faults.mocap_dropout.start_s=2",
                       "faults.mocap_dropout.duration_s=0.2"]),
    "turbulence": ("square", ["sim.plant.turbulence_std_mps=0.3", "faults.mocap_dropout.start_s=2",
                              "faults.mocap_dropout.duration_s=0.2"]),
    # the compiled legs stop before a climb within reach of the cap, an emptying battery
    "altitude_cap": ("square", ["drone.altitude_max_m=1.1", "faults.navdata_loss.start_s=2"]),
    "low_battery": ("square", ["sim.plant.battery_start_pct=22",
                               "sim.plant.battery_drain_pct_per_min=30",
                               "faults.navdata_loss.start_s=2"]),
    # navdata at the mocap's rate: every packet ties with a frame (the frame first); 10 Hz
    # mocap: ticks without a frame
    "ties": ("square", ["sim.navdata_rate_hz=100", "faults.mocap_dropout.start_s=2",
                        "faults.mocap_dropout.duration_s=0.2"]),
    "slow_mocap": ("square", ["sim.mocap_rate_hz=10", "faults.navdata_loss.start_s=2",
                              "faults.navdata_loss.duration_s=0.2"]),
    # the drone's own reports, for the whole flight or from a time on (SENSOR_FAULTS: the
    # wire path all flight long): another firmware's ctrl_state codes (a take-off's and a
    # landing's ticks), fault bits from 3 s, a VBAT_LOW level the battery crosses mid-flight
    "ctrl_codes": ("square", ["faults.ctrl_codes.codes=fw2.4"]),
    "drone_faults": ("square", ["faults.drone_faults.bits=[MOTORS]",
                                "faults.drone_faults.start_s=3.0"]),
    "vbat_low": ("square", ["faults.vbat_low.threshold_pct=30", "sim.plant.battery_start_pct=32",
                            "sim.plant.battery_drain_pct_per_min=30"]),
    # 2 kHz mocap: more frames a tick than the events' first rows
    "fast_mocap": ("square", ["sim.mocap_rate_hz=2000", "faults.mocap_dropout.start_s=2",
                              "faults.mocap_dropout.duration_s=0.2"]),
}


def _fly(name: str) -> tuple:
    """Every row (but the wall-clock cells), every event (but its wall time) and the ending
    of the flight ``name``."""
    config, overrides = FLIGHTS[name]
    cfg = load_config(CONFIGS / f"{config}.yaml", SQUARE + overrides)
    memory = MemoryRecorder()
    result = run_lockstep(cfg, recorder=memory)
    rows = [{k: ("nan" if isinstance(v, float) and math.isnan(v) else v)
             for k, v in row.items() if k not in WALL_TIME} for row in memory.rows]
    events = [{k: _nan_free(v) for k, v in e.items() if k != "wall_s"}
              for e in memory.run_data(cfg, seed=0).events]
    return rows, events, (result.ticks, result.ending, result.final_mode, result.end_t_s)


def _nan_free(value):
    """``value`` with its NaNs as "nan", in lists too (a fault window's end: NaN for the
    faults that act all flight long — NaN equals nothing, itself included)."""
    if isinstance(value, float) and math.isnan(value):
        return "nan"
    if isinstance(value, (list, tuple)):
        return [_nan_free(v) for v in value]
    return value


@pytest.mark.parametrize("name", sorted(FLIGHTS))
def test_frames_handed_over_decoded_give_the_bytes_bits(name, monkeypatch):
    monkeypatch.setattr(LockstepSensors, "frames_as_bytes", True)
    reference = _fly(name)
    monkeypatch.setattr(LockstepSensors, "frames_as_bytes", False)
    fed = []  # the shortcut taken: frames reach the link decoded
    feed_frame = MocapLink.feed_frame

    def counted(self, frame, t_s, *args):
        fed.append(t_s)
        return feed_frame(self, frame, t_s, *args)

    monkeypatch.setattr(MocapLink, "feed_frame", counted)
    assert _fly(name) == reference
    assert fed


@pytest.mark.parametrize("name", sorted(FLIGHTS))
def test_quiet_ticks_compiled_give_the_python_wire_paths_bits(name, monkeypatch):
    monkeypatch.setattr(QuietWire, "enabled", False)
    reference = _fly(name)
    monkeypatch.setattr(QuietWire, "enabled", True)
    answers = []  # the ticks flown compiled (True), handed to the Python path (False)
    run = QuietWire.run

    def counted(self, t_s):
        answers.append(run(self, t_s))
        return answers[-1]

    monkeypatch.setattr(QuietWire, "run", counted)
    assert _fly(name) == reference
    assert True in answers  # (most ticks, as a rule: the cap's climbs are the Python's)


def _plain(obj) -> dict:
    """``obj``'s attributes of plain values (numbers, strings, tuples; a deque as a list)."""
    out = {}
    for key, value in vars(obj).items():
        if value.__class__.__name__ == "deque":
            value = list(value)
        if isinstance(value, (int, float, str, bool, tuple, list, type(None))):
            out[key] = value
    return out


def _ended_in(name: str, monkeypatch) -> dict:
    """What the sampler's receiving links, the firmware and the faults hold at the end of
    the flight ``name``."""
    samplers = []
    init = LockstepSensors.__init__

    def kept(self, *args, **kwargs):
        init(self, *args, **kwargs)
        samplers.append(self)

    monkeypatch.setattr(LockstepSensors, "__init__", kept)
    _fly(name)
    monkeypatch.setattr(LockstepSensors, "__init__", init)
    sensors = samplers[-1]
    plant = sensors.plant
    name = sensors.object_name  # (a quiet tick's frame on its way: the frame it stands for)
    queue = [item if item[3].__class__ is not ObjectFrame else item[:3] + (item[3].frame(name),)
             for item in sorted(sensors._queue)]
    return {"link": link_state(sensors.mocap), "mocap_stats": _plain(sensors.mocap.stats),
            "nav_stats": _plain(sensors.nav_stats), "nav_malformed": sensors.nav_malformed,
            "queue": queue, "firmware": _plain(sensors.firmware),
            "faults": sensors.drone.faults.counters,
            "plant": (plant._state, plant._steps, plant._battery, plant._vel_bias,
                      plant._yaw_bias_deg)}


@pytest.mark.parametrize("name", ["dropout", "disorder_navdata", "altitude_cap", "target"])
def test_quiet_ticks_leave_the_links_firmware_and_faults_as_the_python_path(name,
                                                                             monkeypatch):
    monkeypatch.setattr(QuietWire, "enabled", False)
    reference = _ended_in(name, monkeypatch)
    monkeypatch.setattr(QuietWire, "enabled", True)
    bulk = []  # the quiet ticks' frames received in bulk (ObjectFrame)
    feed = MocapLink.feed_object_frames

    def counted(self, frames, *args):
        bulk.extend(frames)
        return feed(self, frames, *args)

    monkeypatch.setattr(MocapLink, "feed_object_frames", counted)
    ended = _ended_in(name, monkeypatch)
    assert ended == reference
    assert ended["mocap_stats"]["_packets"] > 100  # (frames went through the link)
    assert len(bulk) > (100 if name != "target" else -1)  # (the target's: frame by frame)


@pytest.mark.parametrize("name", ["_advance_through_wire", "_mocap_frame", "_send_frame",
                                  "_push", "_receive", "push_object_frame", "_run_to",
                                  "_receive_quiet", "push_quiet_packet"])
def test_a_sampler_that_overrides_what_the_quiet_ticks_do_keeps_the_python_wire_path(
        name, monkeypatch):
    """The quiet ticks stand in for the sampler's wire legs and sends: a sampler class
    overriding one of those flies every tick on the Python path, so its override runs."""
    from ardrone_nmpc.sim import lockstep_drone as lockstep_module
    from ardrone_nmpc.sim.lockstep_drone import LockstepDrone

    config, overrides = FLIGHTS["dropout"]
    cfg = load_config(CONFIGS / f"{config}.yaml", overrides)
    assert LockstepDrone(cfg).sensors._quiet is not None
    member = LockstepSensors.__dict__[name]
    kind = type("Overriding", (LockstepSensors,),
                {name: lambda self, *a, _m=member, **k: _m(self, *a, **k)})
    monkeypatch.setattr(lockstep_module, "LockstepSensors", kind)
    drone = LockstepDrone(cfg)
    assert isinstance(drone.sensors, kind) and drone.sensors.wire
    assert drone.sensors._quiet is None and drone.sensors._legs is None


@pytest.mark.parametrize("owner,name", [
    ("drone", "navdata_datagrams"), ("firmware", "packet"), ("firmware", "status"),
    ("faults", "mocap_frame"), ("faults", "quiet_until_s")])
def test_a_drone_that_overrides_what_the_quiet_ticks_do_keeps_the_python_wire_path(
        owner, name):
    """… and so does a drone, firmware or faults class overriding what they stand in for."""
    from ardrone_nmpc.sim.drone import SimulatedDrone
    from ardrone_nmpc.sim.drone_firmware import DroneFirmware
    from ardrone_nmpc.sim.fault_injection import ServerFaults

    config, overrides = FLIGHTS["dropout"]
    cfg = load_config(CONFIGS / f"{config}.yaml", overrides)
    drone = SimulatedDrone.from_config(cfg)
    assert QuietWire.eligible(drone)
    base = {"drone": SimulatedDrone, "firmware": DroneFirmware, "faults": ServerFaults}[owner]
    member = base.__dict__[name]
    kind = type("Overriding", (base,),
                {name: lambda self, *a, _m=member, **k: _m(self, *a, **k)})
    target = {"drone": drone, "firmware": drone.firmware, "faults": drone.faults}[owner]
    target.__class__ = kind
    assert not QuietWire.eligible(drone)


def _latches(name: str, monkeypatch) -> list:
    """The firmware's com-watchdog latch after every tick's wire advance of the flight
    ``name`` (with ``comwdg_clear`` "any" the state bit is the latch or the silence, so the
    latch shows in no row or packet: the firmware's state itself is compared)."""
    latches = []
    advance = LockstepSensors._advance_through_wire

    def kept(self, t_s):
        advance(self, t_s)
        latches.append((t_s, self.firmware.comwdg_latched))

    monkeypatch.setattr(LockstepSensors, "_advance_through_wire", kept)
    monkeypatch.setattr(lockstep, "BLOCK_TICKS", 0)  # (tick by tick: blocks of quiet ticks
    _fly(name)                                       # write it back: test_tick_blocks)
    monkeypatch.setattr(LockstepSensors, "_advance_through_wire", advance)
    return latches


def test_quiet_ticks_latch_the_com_watchdog_tick_by_tick_as_the_python_path(monkeypatch):
    """The latch the Python path's watchdogs set on the way (a command every tick clears
    it: the flight's end alone does not show a latch left unset mid-flight)."""
    monkeypatch.setattr(QuietWire, "enabled", False)
    reference = _latches("dropout", monkeypatch)
    monkeypatch.setattr(QuietWire, "enabled", True)
    assert _latches("dropout", monkeypatch) == reference
    assert sum(latched for _, latched in reference) > len(reference) // 2  # (most ticks)


def _packets(name: str, monkeypatch) -> list:
    """Every navdata packet the sampler received in the flight ``name``: its arrival, and
    what a receiver reads of it — the header's state and sequence, the demo option's
    fields with their types, the other options' tags and payloads (a packet that does not
    decode: its bytes)."""
    from ardrone_nmpc.protocol.navdata import Navdata, NavdataError, decode_navdata

    packets = []
    receive = LockstepSensors._receive

    def kept(self, arrival_s, stream, data):
        if stream == _NAV:
            packet = data
            if data.__class__ is not Navdata:
                try:
                    packet = decode_navdata(data)
                except NavdataError:
                    packet = None
            packets.append((arrival_s, bytes(data) if packet is None else (
                int(packet.state), packet.sequence,
                None if packet.demo is None else [(type(v).__name__, v) for v in
                                                  _fields_of(packet.demo)],
                [(o.tag, o.payload) for o in packet.options])))
        return receive(self, arrival_s, stream, data)

    monkeypatch.setattr(LockstepSensors, "_receive", kept)
    _fly(name)
    monkeypatch.setattr(LockstepSensors, "_receive", receive)
    return packets


def _fields_of(record) -> list:
    """A (slotted) dataclass' field values in order."""
    return [getattr(record, f.name) for f in dataclasses.fields(record)]


@pytest.mark.parametrize("name", ["ctrl_codes", "drone_faults", "vbat_low", "dropout"])
def test_quiet_ticks_send_the_python_paths_navdata_packets(name, monkeypatch):
    """The packets a quiet tick hands over built (``DroneFirmware.packet_of``) read as the
    Python path's bytes do, packet by packet — the firmware's options for the whole flight
    too (another firmware's ctrl_state codes show in no row: the packets are compared)."""
    monkeypatch.setattr(QuietWire, "enabled", False)
    reference = _packets(name, monkeypatch)
    monkeypatch.setattr(QuietWire, "enabled", True)
    assert _packets(name, monkeypatch) == reference
    assert len(reference) > 50  # (the shortest: the VBAT_LOW landing)


@pytest.mark.parametrize("name", ["latency", "disorder_mocap"])
def test_quiet_frames_kept_off_the_queue_take_their_places_behind_late_datagrams(
        name, monkeypatch):
    # a quiet tick's frames that arrive within it skip the queue; a delayed or held-back
    # datagram of the Python path's on its way puts them back in their places (the order
    # the queue gives): links, firmware and faults end as the Python path leaves them
    monkeypatch.setattr(QuietWire, "enabled", False)
    reference = _ended_in(name, monkeypatch)
    monkeypatch.setattr(QuietWire, "enabled", True)
    queued = []
    queue_arrived = LockstepSensors._queue_arrived

    def counted(self):
        queued.append(len(self._arrived))
        return queue_arrived(self)

    monkeypatch.setattr(LockstepSensors, "_queue_arrived", counted)
    assert _ended_in(name, monkeypatch) == reference
    assert queued and min(queued) > 0  # (the branch taken, with frames to place)


def test_a_quiet_ticks_frames_go_to_the_link_together_across_its_navdata_packets(monkeypatch):
    # navdata at the mocap's rate: packets arrive between a tick's frames; the frames are
    # received in one bulk call a tick all the same, and the flight's bits are the Python
    # path's (test_quiet_ticks_compiled_give_the_python_wire_paths_bits' "ties")
    calls, packets = [], []
    feed, receive = MocapLink.feed_object_frames, LockstepSensors._receive

    def fed(self, frames, *args):
        calls.append([t for _, t, _, _ in frames])
        return feed(self, frames, *args)

    def received(self, arrival_s, stream, data):
        if stream == _NAV:
            packets.append(arrival_s)
        return receive(self, arrival_s, stream, data)

    monkeypatch.setattr(MocapLink, "feed_object_frames", fed)
    monkeypatch.setattr(LockstepSensors, "_receive", received)
    _fly("ties")
    assert any(times[0] < t < times[-1] for times in calls for t in packets)
