"""Every drone backend passes the same scenarios, the crazyswarm2 / cflib way: drivers behind
one interface, chosen by address, tested alike (links/backend.py, docs/architecture.md §4).

Backends: ``sim://lockstep`` (the simulated drone on a manual clock, as ``simulate`` flies
it), ``sim://loopback`` (the same simulated drone served over UDP, as ``fly --sim`` flies it)
and ``udp://127.0.0.1`` — an AR.Drone 2.0 over its protocol, here the SDK stand-in
(tests/standins/sdk_drone.py, written from the SDK, not from our simulator). The link
scenarios run on all three; the firmware scenarios (the altitude cap, the command watchdog) on
the two simulated ones — the one firmware both runners fly — because the stand-in models
neither. Only 127.0.0.1 is used; every wait has a timeout.
"""

from __future__ import annotations

import time
from contextlib import ExitStack

import numpy as np
import pytest

from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.core.types import FlightMode
from ardrone_nmpc.experiments.flight import run_flight
from ardrone_nmpc.experiments.record import record_lockstep
from ardrone_nmpc.links.backend import open_udp_drone
from ardrone_nmpc.links.drone_config import verify_config
from ardrone_nmpc.links.udp import open_udp
from ardrone_nmpc.runs.rundir import read_run
from ardrone_nmpc.sim.lockstep_drone import LockstepDrone
from ardrone_nmpc.sim.loopback import open_loopback_drone
from tests.standins.sdk_drone import SdkDrone

pytestmark = [pytest.mark.timeout(90), pytest.mark.usefixtures("loopback_only")]
CAP_M = 1.5
HOVER = (0.0, 0.0, 0.0, 0.0)


class Lockstep:
    """``sim://lockstep``: time passes when the harness says so, one 65 ms tick at a time, and
    the command is re-sent every tick, as the lockstep runner sends one."""

    def __init__(self, cfg):
        self.link = LockstepDrone(cfg)
        self.command = None

    def connect(self):
        self.link.connect()

    def send(self, *fractions):
        self.command = fractions
        self.link.set_command(*fractions)

    def wait(self, done, timeout_s):
        t_end = self.link.truth.t_s + timeout_s
        while not done():
            if self.link.truth.t_s >= t_end:
                return False
            self.link.advance_to(self.link.truth.t_s + 0.065)
            if self.command is not None:
                self.link.set_command(*self.command)
        return True

    def close(self):
        pass


class RealTime:
    """A backend on the wall clock; the command is set again every 65 ms, as the real-time
    loop sets one each tick (the link's keepalive repeats it in between)."""

    def __init__(self, opened, stack):
        self.link = opened.link
        self.stack = stack
        self.command = None

    def connect(self):
        self.link.connect(timeout_s=5.0)

    def send(self, *fractions):
        self.command = fractions
        self.link.set_command(*fractions)

    def wait(self, done, timeout_s):
        t_end = time.monotonic() + timeout_s
        next_tick = time.monotonic() + 0.065
        while not done():
            now = time.monotonic()
            if now >= t_end:
                return False
            if self.command is not None and now >= next_tick:
                self.link.set_command(*self.command)
                next_tick += 0.065
            time.sleep(0.01)
        return True

    def close(self):
        self.stack.close()


def _config(*overrides):
    return load_config(None, ["sim.seed=3", f"drone.altitude_max_m={CAP_M}", *overrides])


def open_backend(name):
    cfg = _config()
    if name == "sim://lockstep":
        return Lockstep(cfg)
    stack = ExitStack()
    if name == "sim://loopback":
        opened = stack.enter_context(open_loopback_drone(cfg, seed=3))
    else:
        drone = stack.enter_context(SdkDrone())
        probe = open_udp("127.0.0.1", 0, timeout_s=None)
        mocap_port = probe.getsockname()[1]
        probe.close()
        cfg = _config("mocap.bind_host=127.0.0.1", f"drone.control_port={drone.control_port}")
        opened = stack.enter_context(open_udp_drone(
            cfg, host="127.0.0.1", at_port=drone.at_port, navdata_port=drone.navdata_port,
            mocap_port=mocap_port))
    return RealTime(opened, stack)


ALL = ["sim://lockstep", "sim://loopback", "udp://127.0.0.1"]
SIMULATED = ["sim://lockstep", "sim://loopback"]


@pytest.fixture
def backend(request):
    harness = open_backend(request.param)
    try:
        yield harness
    finally:
        harness.close()


def mode_is(harness, mode):
    return lambda: harness.link.navdata is not None and harness.link.navdata.mode is mode


# ----------------------------------------------------------------------------- the link
@pytest.mark.parametrize("backend", ALL, indirect=True)
def test_it_holds_the_limits_it_was_given(backend):
    backend.connect()
    written = backend.link.configure_limits(euler_angle_max_rad=0.2, control_vz_max_mps=0.8,
                                            control_yaw_radps=1.5, altitude_max_m=CAP_M)
    held = backend.link.read_config(timeout_s=2.0)
    assert written["control:altitude_max"] == "1500"
    assert verify_config(written, held) == []


@pytest.mark.parametrize("backend", ALL, indirect=True)
def test_it_takes_off_flies_and_lands_on_ref(backend):
    backend.connect()
    assert backend.wait(mode_is(backend, FlightMode.LANDED), 2.0)
    backend.link.takeoff()
    assert backend.wait(mode_is(backend, FlightMode.FLYING), 10.0), backend.link.navdata
    backend.send(*HOVER)
    assert backend.wait(lambda: False, 0.3) is False  # flies on
    assert backend.link.navdata.mode is FlightMode.FLYING
    backend.link.land()
    assert backend.wait(mode_is(backend, FlightMode.LANDED), 10.0), backend.link.navdata
    assert backend.link.self_landing is None  # it landed because it was told to


# ----------------------------------------------------------------------------- the firmware
def _airborne_at_cap(backend):
    backend.connect()
    backend.link.configure_limits(euler_angle_max_rad=0.2, control_vz_max_mps=0.8,
                                  control_yaw_radps=1.5, altitude_max_m=CAP_M)
    backend.link.takeoff()
    assert backend.wait(mode_is(backend, FlightMode.FLYING), 10.0)


@pytest.mark.parametrize("backend", SIMULATED, indirect=True)
def test_the_altitude_cap_stops_a_full_climb(backend):
    _airborne_at_cap(backend)
    top = []
    backend.send(0.0, 0.0, 1.0, 0.0)  # full climb, for 5 s
    backend.wait(lambda: top.append(backend.link.navdata.altitude_m) and False, 5.0)
    assert CAP_M - 0.15 <= max(top) <= CAP_M + 0.1, max(top)


@pytest.mark.parametrize("backend", SIMULATED, indirect=True)
def test_a_controller_gone_silent_leaves_the_drone_hovering(backend):
    """A progressive command not renewed for 250 ms gives way to hover: the firmware's
    watchdog in lockstep, where nothing else sends; over UDP the link's stale-command rule
    (its keepalive goes on) — the drone stops either way (docs/protocol.md)."""
    _airborne_at_cap(backend)

    def mean_vz_mps(seconds):  # navdata's ż over the last half of ``seconds`` (down > 0)
        samples = {}
        t_half = seconds / 2
        backend.wait(lambda: False, t_half)
        backend.wait(lambda: samples.setdefault(backend.link.navdata.t_s,
                                                backend.link.navdata.vz_mps) and False, t_half)
        return sum(samples.values()) / len(samples)

    backend.send(0.0, 0.0, -0.5, 0.0)     # descending, renewed every tick …
    assert mean_vz_mps(2.0) > 0.25        # (the take-off's climb stops first)
    backend.command = None                # … then the controller goes silent
    assert abs(mean_vz_mps(2.0)) < 0.08


@pytest.mark.timeout(120)
def test_simulate_and_fly_sim_fly_the_same_altitude_cap(tmp_path):
    """The thesis' z step to 2.5 m with ``drone.altitude_max_m`` 1.5: ``simulate`` (lockstep)
    stops where ``fly --sim`` (the same drone over UDP) does — at the firmware's cap, not at
    the reference."""
    cfg = load_config("configs/step_z.yaml", [
        "duration_s=6", "sim.settle_s=2", f"drone.altitude_max_m={CAP_M}",
        "reference.target_m=[0,0,2.5]"])
    lockstep = read_run(record_lockstep(cfg, tmp_path / "simulate").path)
    loopback = read_run(run_flight(cfg=cfg, sim=True, log_dir=tmp_path / "fly", seed=None))
    tops = [float(np.nanmax(run.columns["z_m"])) for run in (lockstep, loopback)]
    assert CAP_M - 0.1 <= min(tops) and max(tops) <= CAP_M + 0.1, tops
    assert abs(tops[0] - tops[1]) < 0.03, tops
