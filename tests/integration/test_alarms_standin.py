"""Issue 21's ``fly`` against the SDK stand-in (tests/standins/sdk_drone.py: written from
ARDroneLib's documented behaviour, importing nothing of this project), over UDP/TCP on
127.0.0.1, through the command line: ``fly`` reads the drone's fault bits (refusals naming the
bit, VBAT_LOW above the tool's floor, a landing on SOFTWARE_FAULT, a cut on CUTOUT), holds the
navdata freshness rule during take-off, answers bootstrap after a Wi-Fi blackout, writes the
outdoor key before the limits, ends a landing it cannot confirm in bounded time with its run
directory complete and its flight lock released, and — a second AT client — an operator's
``emergency`` cuts a drone a running ``fly`` holds, and that ``fly`` cuts too.

Every wait has a timeout; tests wait for states, not wall time.
"""

from __future__ import annotations

import time
from pathlib import Path

import pytest

from ardrone_nmpc.links.flight_lock import FlightLock
from tests.integration.test_fly_standin import events
from tests.integration.test_fly_standin import fly as fly_standin
from tests.integration.test_operator_standin import (  # noqa: F401 - fixtures used here
    loopback_only, operator, refs, short_blind_landing)
from tests.integration.test_session_standin import wait_until
from tests.standins.sdk_drone import (CUTOUT, INDOOR_PROFILE, REF_EMERGENCY, REF_TAKEOFF,
                                      SOFTWARE_FAULT, ULTRASOUND, MocapStandIn, SdkDrone)

ROOT = Path(__file__).parents[2]
HOVER = str(ROOT / "configs" / "hover.yaml")
pytestmark = pytest.mark.timeout(90)


# ----------------------------------------------------------------------------- fly
def fly(tmp_path, drone, *sets, duration_s=3.0):
    """``fly`` in-process against the stand-in (test_fly_standin's), timed."""
    t0 = time.monotonic()
    result, run = fly_standin(tmp_path, drone, *sets, duration_s=duration_s)
    result.took_s = time.monotonic() - t0
    return result, run


def assert_ended_cleanly(result, run, drone):
    """An ``error:`` line saying why (after the session's own notices, if any), no
    traceback, a complete run directory, the flight lock free."""
    assert "Traceback" not in result.stderr
    assert any(line.startswith("error: ") for line in result.stderr.splitlines())
    assert (run / "summary.csv").read_text().startswith("axis,metric,value,unit")
    kinds = [e["kind"] for e in events(run)]
    assert "session_end" in kinds  # the session's exit ran; after it at most the verdict and
    assert set(kinds[kinds.index("session_end") + 1:]) <= {"verdict", "exception"}  # the error
    if kinds[-1] == "exception":
        assert ": " in events(run)[-1]["error"] and "\n" not in events(run)[-1]["error"]
    assert FlightLock("127.0.0.1", drone.at_port).holder() is None


@pytest.mark.parametrize("options, bit, name", [
    ({}, CUTOUT | ULTRASOUND, "CUTOUT (state bit 22"),
    ({"battery_pct": 25, "vbat_low_pct": 30}, 0, "VBAT_LOW (state bit 15"),  # above our 20 %
])
def test_fly_refuses_a_drone_that_reports_a_fault_bit(tmp_path, options, bit, name):
    with SdkDrone(**options) as drone:
        drone.fault_bits = bit
        result, run = fly(tmp_path, drone)
        assert result.exit_code == 1
        assert result.stderr.startswith(f"error: the drone reports {name}")
        assert [a for _, a in refs(drone)] == [] and drone.takeoffs == 0
        assert "Traceback" not in result.stderr


@pytest.mark.parametrize("bit, mode, phase", [(SOFTWARE_FAULT, "land-software-fault", "landed"),
                                              (CUTOUT, "stop-cutout", "emergency")])
def test_a_fault_bit_in_flight_lands_or_cuts(tmp_path, bit, mode, phase):
    with SdkDrone(land_by_itself_after_s=None) as drone:
        import threading

        def raise_bit():
            if wait_until(lambda: drone.phase == "hovering", 20.0):
                time.sleep(1.0)
                drone.fault_bits = bit
        threading.Thread(target=raise_bit, daemon=True).start()
        result, run = fly(tmp_path, drone, duration_s=15.0)
        assert result.exit_code == 1 and mode in result.stderr, result.stderr
        assert drone.phase == phase
        if phase == "emergency":   # cut by the tool: an edge of bit 8, no take-off since
            assert any(a & REF_EMERGENCY for _, a in refs(drone))
        modes = [e for e in events(run) if e["kind"] == "mode"]
        assert modes[-1]["mode"] == mode
        assert_ended_cleanly(result, run, drone)


def test_navdata_lost_during_take_off_fails_it_in_one_line_and_lands(tmp_path):
    with SdkDrone(navdata_gap_at_takeoff=(0.5, 2.0)) as drone:
        result, run = fly(tmp_path, drone, duration_s=10.0)
        assert result.exit_code == 1
        assert result.stderr.startswith("error: take-off failed: navdata lost (none for ")
        takeoff = next(t for t, a in refs(drone) if a & REF_TAKEOFF)
        first_land = next(t for t, a in refs(drone) if t > takeoff and not a & REF_TAKEOFF)
        assert first_land - takeoff < 1.5                  # 0.5 s flowing + 0.5 s lost
        assert wait_until(lambda: drone.phase == "landed", 5.0)
        assert_ended_cleanly(result, run, drone)


def test_a_blackout_is_answered_and_the_flight_ends_landed(tmp_path):
    """A 3 s Wi-Fi blackout: the supervisor lands (navdata lost), the drone comes back in
    bootstrap, the link re-writes navdata_demo, and the landing is confirmed."""
    with SdkDrone() as drone:
        import threading

        def blackout():
            if wait_until(lambda: drone.phase == "hovering", 20.0):
                time.sleep(1.0)
                drone.blackout(3.0)
        threading.Thread(target=blackout, daemon=True).start()
        result, run = fly(tmp_path, drone, duration_s=20.0)
        assert result.exit_code == 1 and "navdata silent" in result.stderr, result.stderr
        assert drone.link_losses == 1 and drone.phase == "landed"
        after = [args for t, name, args, _ in drone.log
                 if name == "CONFIG" and t > drone.blackout_until]
        assert ["general:navdata_demo", "TRUE"] in after      # bootstrap answered
        link = next(e for e in events(run) if e["kind"] == "drone_link")
        assert link["bootstrap_answers"] >= 1
        assert next(e for e in events(run) if e["kind"] == "session_end")["landed"] is True
        assert result.took_s < 40.0
        assert_ended_cleanly(result, run, drone)


def test_a_landing_nobody_can_confirm_ends_in_bounded_time(tmp_path, short_blind_landing):
    with SdkDrone() as drone:
        import threading

        def silence():
            if wait_until(lambda: drone.phase == "hovering", 20.0):
                time.sleep(1.0)
                drone.silent_from, drone.silent_until = time.monotonic(), float("inf")
        threading.Thread(target=silence, daemon=True).start()
        result, run = fly(tmp_path, drone, duration_s=20.0)
        assert result.exit_code == 1
        lines = result.stderr.strip().splitlines()
        assert lines[0].startswith("error: navdata silent for more than 500 ms")
        assert lines[-1] == "error: landing not confirmed by navdata — check the drone"
        failed = next(e for e in events(run) if e["kind"] == "landing_failed")
        assert failed["last_mode"] == "flying" and failed["error"].startswith("no navdata for")
        assert result.took_s < 20.0                       # not the 20 s flight, no hang
        assert drone.phase == "landed"                    # the REF land still got there
        assert_ended_cleanly(result, run, drone)


def test_a_drone_last_flown_outdoors_keeps_its_outdoor_profile(tmp_path):
    with SdkDrone(last_flown_outdoors=True) as drone:
        assert drone.config["control:euler_angle_max"] == "0.3491"
        result, run = fly(tmp_path, drone, duration_s=1.0)
        assert result.exit_code == 0, result.stderr
        configs = [args[0] for _, _, args, _ in drone.commands("CONFIG")]
        assert configs.index("control:outdoor") < configs.index("control:euler_angle_max")
        assert drone.config["control:outdoor_euler_angle_max"] == "0.3491"  # untouched
        assert drone.config["control:indoor_euler_angle_max"] == "0.2094"
        assert INDOOR_PROFILE["control:indoor_euler_angle_max"] == "0.25"


# ----------------------------------------------------------------------------- two clients
def start_fly(tmp_path, drone, mocap_port, duration_s=30.0):
    import os
    import subprocess
    import sys

    env = dict(os.environ, XDG_RUNTIME_DIR=str(tmp_path / "run"))
    return subprocess.Popen(
        [sys.executable, "-m", "ardrone_nmpc.cli.app", "fly", HOVER, "--no-dashboard",
         "--drone", "127.0.0.1", "--at-port", str(drone.at_port), "--navdata-port",
         str(drone.navdata_port), "--mocap-port", str(mocap_port), "--log-dir",
         str(tmp_path / "logs"), "--duration-s", str(duration_s), "--set", "sim.settle_s=0.5",
         "--set", "mocap.bind_host=127.0.0.1", "--set",
         f"drone.control_port={drone.control_port}"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env, cwd=ROOT)


@pytest.mark.timeout(150)
def test_emergency_cuts_a_drone_a_running_fly_holds_and_that_fly_cuts_too(tmp_path):
    """A second AT client (the operator's) against a ``fly`` in full flight: the drone takes
    the operator's cut at once, the ``fly`` cuts too (SIGUSR2) instead of landing, and neither
    ever sends take-off again."""
    from ardrone_nmpc.links.udp import open_udp

    probe = open_udp("127.0.0.1", 0, timeout_s=None)
    mocap_port = probe.getsockname()[1]
    probe.close()
    with SdkDrone() as drone:
        alt = {"hovering": 1.0, "takeoff": 0.5, "landing": 0.3}
        with MocapStandIn(mocap_port, lambda: ((0.0, 0.0, alt.get(drone.phase, 0.0)),
                                               drone.true_psi_rad)):
            proc = start_fly(tmp_path, drone, mocap_port)
            try:
                assert wait_until(lambda: drone.phase == "hovering", 90.0), \
                    proc.stderr.read() if proc.poll() is not None else "not flying"
                assert wait_until(lambda: FlightLock("127.0.0.1", drone.at_port).holder()
                                  == proc.pid, 10.0)
                time.sleep(1.0)                           # in the loop, well after take-off
                t0 = time.monotonic()
                result = operator("emergency", drone)
                out, err = proc.communicate(timeout=60)
            finally:
                if proc.poll() is None:
                    proc.kill()
                    proc.communicate()
    assert result.exit_code == 0, result.stderr
    assert "told it to cut the motors too (SIGUSR2)" in result.stderr
    # one cut, from the operator's first datagram (a priming REF land, then the edge), never
    # undone by the two clients' REFs
    i_cut = next(i for i, (_, phase) in enumerate(drone.phases) if phase == "emergency")
    t_cut = drone.phases[i_cut][0]
    assert drone.phases[i_cut:] == [(t_cut, "emergency")]
    assert drone.phase == "emergency" and t_cut > t0
    assert proc.returncode == 140, err
    assert "Traceback" not in err
    run = Path([line for line in out.splitlines() if line.startswith("run: ")][-1][5:])
    kinds = [e["kind"] for e in events(run)]
    cut = next(e for e in events(run) if e["kind"] == "emergency")
    assert cut["reason"] == "the operator's `emergency` command (SIGUSR2)"
    assert next(e for e in events(run) if e["kind"] == "landing")["reason"] == "SIGUSR2"
    assert "landed" in kinds and (run / "summary.csv").exists()
    # the fly's take-off level still in flight while it handled the signal, then none
    assert all(t - t_cut < 0.1 for t, a in refs(drone) if t > t_cut and a & REF_TAKEOFF)
