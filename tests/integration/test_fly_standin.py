"""``fly`` and the operator commands end to end against the SDK stand-in (not our sim-drone):
the targets of issue 17 measured through the CLI, in-process (typer's CliRunner), on
127.0.0.1 only.

* a drone that ignores config writes: no take-off REF ever, exit ≠ 0, the key named;
* a drone that lands itself 4 s after take-off: zero take-off REFs accepted after touch-down,
  exit ≠ 0, the summary written;
* a second ``fly`` at a drone already flown from here: refused before a datagram;
* ``land`` lands a drone left hovering by a dead client within 10 s; ``emergency`` cuts one;
  ``reset`` clears it; ``status`` shows the limits the firmware holds.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import pytest
from typer.testing import CliRunner

from ardrone_nmpc.cli.app import app
from ardrone_nmpc.links.flight_lock import FlightLock
from tests.standins.sdk_drone import OUTDOOR_HELD, REF_TAKEOFF, MocapStandIn, SdkDrone

ROOT = Path(__file__).parents[2]
HOVER = str(ROOT / "configs" / "hover.yaml")
pytestmark = [pytest.mark.timeout(90), pytest.mark.usefixtures("loopback_only")]


def fly(tmp_path, drone: SdkDrone, *sets, duration_s=3.0):
    from ardrone_nmpc.links.udp import open_udp

    probe = open_udp("127.0.0.1", 0, timeout_s=None)
    mocap_port = probe.getsockname()[1]
    probe.close()
    alt = {"hovering": 1.0, "takeoff": 0.5, "landing": 0.3}
    stream = MocapStandIn(mocap_port, lambda: ((0.0, 0.0, alt.get(drone.phase, 0.0)),
                                               drone.true_psi_rad))
    args = ["fly", HOVER, "--no-dashboard", "--drone", "127.0.0.1", "--at-port",
            str(drone.at_port), "--navdata-port", str(drone.navdata_port), "--mocap-port",
            str(mocap_port), "--log-dir", str(tmp_path / "logs"), "--duration-s",
            str(duration_s), "--set", "sim.settle_s=0.5", "--set", "mocap.bind_host=127.0.0.1",
            "--set", f"drone.control_port={drone.control_port}"]
    for s in sets:
        args += ["--set", s]
    with stream:
        result = CliRunner().invoke(app, args)
    runs = [l[len("run: "):] for l in result.stdout.splitlines() if l.startswith("run: ")]
    return result, (Path(runs[-1]) if runs else None)


def events(run: Path) -> list[dict]:
    return [json.loads(l) for l in (run / "events.jsonl").read_text().splitlines()]


def test_fly_refuses_a_drone_that_ignores_config_writes(tmp_path):
    with SdkDrone(ignore_config_writes=True, held=OUTDOOR_HELD) as drone:
        result, run = fly(tmp_path, drone)
        assert result.exit_code == 1
        assert "control:euler_angle_max" in result.stderr and "'0.52'" in result.stderr
        assert drone.commands("REF") == [] and drone.takeoffs == 0
    assert "Traceback" not in result.stderr
    assert (run / "summary.csv").exists()


def test_fly_against_a_drone_that_lands_itself_4_s_after_take_off(tmp_path):
    with SdkDrone(land_by_itself_after_s=4.0, ctrl_codes="fw24") as drone:
        t0 = time.monotonic()
        result, run = fly(tmp_path, drone, duration_s=20.0)
        assert time.monotonic() - t0 < 30.0  # it did not fly the 20 s
        assert result.exit_code == 1, result.stderr
        assert "error: the drone landed by itself" in result.stderr
        assert "take-off bit was dropped" in result.stderr
        assert drone.self_landed_t is not None and drone.takeoffs == 1
        assert drone.takeoff_refs_after_touchdown() == []
        # dropped within one navdata period (67 ms) plus one keepalive (30 ms) of the start
        refs_after = drone.commands("REF", drone.self_landing_start_t + 0.1)
        assert len(refs_after) >= 5
        assert all(not args[0] & REF_TAKEOFF for _, _, args, _ in refs_after)
    kinds = [e["kind"] for e in events(run)]
    assert "drone_landed_itself" in kinds and kinds[-2:] == ["session_end", "exception"]
    assert (run / "summary.csv").read_text().startswith("axis,metric,value,unit")
    log = (run / "log.csv").read_text().splitlines()
    col = log[0].split(",").index("nav_ctrl_state")
    states = {row.split(",")[col] for row in log[1:]}
    assert str(4 << 16) in states  # hovering, logged raw each tick


def test_fly_refuses_a_faults_section_on_a_drone_that_is_not_simulated(tmp_path):
    """Faults are injected only in simulation: a real drone with a faults section is refused
    with one line naming it, before any datagram (no take-off REF, no run directory)."""
    with SdkDrone() as drone:
        result, run = fly(tmp_path, drone, "faults.solver_diverge.start_s=5")
        assert result.exit_code == 1 and run is None
        assert drone.commands("REF") == [] and drone.takeoffs == 0
        assert drone.commands("CONFIG") == []
    errors = [line for line in result.stderr.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and "faults: solver_diverge" in errors[0]
    assert "only in simulation" in errors[0] and "udp://127.0.0.1" in errors[0]
    assert "Traceback" not in result.stderr


def test_a_second_fly_at_a_held_drone_is_refused_before_any_datagram(tmp_path):
    with SdkDrone() as drone:
        with FlightLock("127.0.0.1", drone.at_port):
            result, run = fly(tmp_path, drone)
        assert result.exit_code == 1 and run is None
        assert "is being flown from this machine" in result.stderr
        assert drone.wakeups == [] and drone.log == []
    assert not (tmp_path / "logs").exists() or not any((tmp_path / "logs").iterdir())


@pytest.mark.parametrize("option, value, code, message", [
    # the command line's own checks (exit 2), before the config is even read
    ("--navdata-port", "-1", 2, "--navdata-port: -1 is not a port (1 … 65535)"),
    ("--navdata-port", "0", 2, "--navdata-port: 0 is not a port (1 … 65535)"),
    ("--at-port", "70000", 2, "--at-port: 70000 is not a port (1 … 65535)"),
    ("--drone", "", 2, "--drone: must not be empty"),
    ("--duration-s", "1e308", 1, "duration_s"),  # the schema or the tick count refuses it
])
def test_what_can_fail_is_checked_before_anything_is_sent(tmp_path, option, value, code,
                                                          message):
    result = CliRunner().invoke(app, ["fly", HOVER, "--no-dashboard", "--log-dir",
                                      str(tmp_path / "logs"), option, value])
    assert result.exit_code == code and message in result.stderr, result.stderr
    assert "Traceback" not in result.stderr and "Wi-Fi" not in result.stderr
    assert not (tmp_path / "logs").exists()


def ports(drone):
    return ["--drone", "127.0.0.1", "--at-port", str(drone.at_port), "--navdata-port",
            str(drone.navdata_port)]


def test_land_brings_down_a_drone_left_hovering_within_10_s():
    with SdkDrone(airborne_at_start=True) as drone:
        t0 = time.monotonic()
        result = CliRunner().invoke(app, ["land", *ports(drone)])
        took = time.monotonic() - t0
        assert result.exit_code == 0, result.stderr
        assert drone.phase == "landed" and took < 10.0
        assert result.stdout.strip().endswith("landed (landed)")


def test_emergency_cuts_then_reset_clears_then_status_reads(tmp_path):
    with SdkDrone(airborne_at_start=True, held={"control:euler_angle_max": "0.35"}) as drone:
        result = CliRunner().invoke(app, ["emergency", *ports(drone)])
        assert result.exit_code == 0, result.stderr
        assert drone.phase == "emergency" and "motors cut" in result.stdout
        result = CliRunner().invoke(app, ["reset", *ports(drone)])
        assert result.exit_code == 0 and drone.phase == "landed", result.stderr
        result = CliRunner().invoke(app, ["reset", *ports(drone)])
        assert result.exit_code == 1 and "not in emergency" in result.stderr
        result = CliRunner().invoke(app, ["status", *ports(drone), "--control-port",
                                          str(drone.control_port)])
        assert result.exit_code == 0, result.stderr
        assert "mode       landed" in result.stdout
        assert "control:euler_angle_max      0.35" in result.stdout
        assert "ctrl_state 0x00020000 (major 2 LANDED" in result.stdout


def test_status_and_reset_refuse_while_a_flight_holds_the_drone_land_goes_through():
    with SdkDrone(airborne_at_start=True) as drone:
        with FlightLock("127.0.0.1", drone.at_port):
            for command in ("status", "reset"):
                result = CliRunner().invoke(app, [command, *ports(drone)])
                assert result.exit_code == 1 and "being flown" in result.stderr
            assert drone.log == []
        result = CliRunner().invoke(app, ["land", *ports(drone)])
        assert result.exit_code == 0 and drone.phase == "landed"


def test_operator_commands_reject_bad_ports_in_one_line():
    for args in (["land", "--navdata-port", "0"], ["status", "--drone", ""],
                 ["emergency", "--at-port", "-5"]):
        result = CliRunner().invoke(app, args)
        assert result.exit_code == 2 and result.stderr.startswith("error: ")
        assert len(result.stderr.strip().splitlines()) == 1
