"""``land``, ``emergency``, ``status`` and ``reset`` against the SDK stand-in
(tests/standins/sdk_drone.py: written from ARDroneLib's documented behaviour, importing nothing of
this project), over UDP/TCP on 127.0.0.1, through the command line in-process (typer's
CliRunner): ``land`` / ``emergency`` act first — REF in the first datagram, taken by a drone in
another multiconfig session, by a drone whose sequence counter another client drove high, by a
drone that sends no navdata at all; ``--config-ids`` on every operator command; ``status``
names the fault bits. Every wait has a timeout; tests wait for states, not wall time.
"""

from __future__ import annotations

import re
import socket
import time

import pytest
from typer.testing import CliRunner

import ardrone_nmpc.links.drone_link as drone_link_module
import ardrone_nmpc.links.operator_link as operator_link_module
from ardrone_nmpc.cli.app import app
from tests.integration.test_session_standin import wait_until
from tests.standins.sdk_drone import ULTRASOUND, SdkDrone

IDS = ("d2e081a3", "be27e2e4", "d87f7e0c")
SESSION = {"custom:session_id": IDS[0], "custom:profile_id": IDS[1],
           "custom:application_id": IDS[2]}
LAND, EMERGENCY = 290717696, 290717952
pytestmark = pytest.mark.timeout(90)


@pytest.fixture(autouse=True)
def loopback_only(monkeypatch, tmp_path):
    """The links' lab defaults (all interfaces, local port 5556) become loopback/ephemeral,
    and the flight locks live in this test's directory."""
    for module, name in ((drone_link_module, "DroneLink"), (operator_link_module,
                                                             "OperatorLink")):
        base = getattr(module, name)

        def init(self, *args, _base=base, **kwargs):
            kwargs.setdefault("bind_host", "127.0.0.1")
            kwargs["at_local_port"] = 0
            _base.__init__(self, *args, **kwargs)
        monkeypatch.setattr(module, name, type(name, (base,), {"__init__": init}))
    monkeypatch.setenv("XDG_RUNTIME_DIR", str(tmp_path / "run"))
    (tmp_path / "run").mkdir()


@pytest.fixture
def short_blind_landing(monkeypatch):
    """A landing with no navdata at all gives up after 1 s instead of 10, an emergency after
    1 s instead of 3."""
    import ardrone_nmpc.cli.operator as operator_module
    import ardrone_nmpc.runtime.session as session_module

    monkeypatch.setattr(session_module, "BLIND_LANDING_S", 1.0)
    monkeypatch.setattr(operator_module, "EMERGENCY_CONFIRM_S", 1.0)


def dead_port() -> int:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


def operator(command, drone, *extra, navdata_port=None):
    args = [command, "--drone", "127.0.0.1", "--at-port", str(drone.at_port),
            "--navdata-port", str(navdata_port or drone.navdata_port), *extra]
    return CliRunner().invoke(app, args)


def refs(drone):
    return [(t, args[0]) for t, _, args, _ in drone.commands("REF")]


# ----------------------------------------------------------------------------- operator
def test_land_reaches_a_drone_in_another_session_with_its_first_datagram():
    with SdkDrone(airborne_at_start=True, held=SESSION) as drone:
        result = operator("land", drone)
        assert result.exit_code == 0, result.stderr
        assert result.stdout.strip().endswith("landed (landed)")
        first_t, first = refs(drone)[0]
        assert drone.log[0][1] == "REF" and first == LAND
        assert first_t <= drone.wakeups[0]             # acted before it asked
        assert drone.phase == "landed"
        # the session ignored the plain navdata_demo of the bootstrap answer: the landing was
        # confirmed from bootstrap packets alone (state bit 0)
        assert drone.bootstrap and not drone.ack


def test_land_and_emergency_reach_a_drone_that_sends_no_navdata(short_blind_landing):
    with SdkDrone(airborne_at_start=True, held=SESSION) as drone:
        result = operator("land", drone, navdata_port=dead_port())
        assert drone.phase == "landed"                 # the drone is down …
        assert result.exit_code == 1                   # … but nobody could confirm it
        assert re.fullmatch(rf"error: REF land sent to 127\.0\.0\.1:{drone.at_port} \(\d+ "
                            r"datagrams\) but no navdata from 127\.0\.0\.1:\d+ confirmed it "
                            r"— look at the drone", result.stderr.strip())
    with SdkDrone(airborne_at_start=True) as drone:
        result = operator("emergency", drone, navdata_port=dead_port())
        assert drone.phase == "emergency" and result.exit_code == 1
        assert "REF emergency sent to" in result.stderr and "no navdata from" in result.stderr
        assert refs(drone)[0][1] == LAND and refs(drone)[1][1] == EMERGENCY   # the edge


def test_emergency_wins_over_a_client_whose_sequence_is_far_ahead():
    with SdkDrone(airborne_at_start=True) as drone:
        other = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        other.bind(("127.0.0.1", 0))
        theirs = other.getsockname()
        try:   # another client at seq 40 000 holding take-off
            other.sendto(f"AT*REF=40000,{LAND + 512}\r".encode(), ("127.0.0.1", drone.at_port))
            assert wait_until(lambda: drone.last_seq == 40000, 2.0)
            result = operator("emergency", drone)
        finally:
            other.close()
        assert result.exit_code == 0, result.stderr
        assert result.stdout == ("motors cut (emergency); clear it on the ground with "
                                 "`ardrone-nmpc reset`\n") and drone.phase == "emergency"
        ours = [a for a in drone.accepted_from if a != theirs]
        assert ours and drone.ignored_from.get(ours[0], 0) == 0   # every datagram taken


def test_every_operator_command_takes_config_ids(monkeypatch):
    import ardrone_nmpc.cli.operator as operator_module

    monkeypatch.setattr(operator_module, "CONNECT_TIMEOUT_S", 1.0)
    with SdkDrone(held=SESSION, attitude_deg=(0.0, 0.0)) as drone:
        # status connects with the handshake: without the ids the session ignores it …
        result = operator("status", drone, "--control-port", str(drone.control_port))
        assert result.exit_code == 1 and "no ACK" in result.stderr
        # … with them it is answered, and says what the drone holds
        result = operator("status", drone, "--control-port", str(drone.control_port),
                          "--config-ids", ",".join(IDS))
        assert result.exit_code == 0, result.stderr
        assert f"custom:session_id            {IDS[0]}" in result.stdout
        assert "faults     none" in result.stdout
        for command in ("land", "emergency", "reset"):
            result = operator(command, drone, "--config-ids", "nothex,0,0")
            assert result.exit_code == 2 and len(result.stderr.strip().splitlines()) == 1
            assert result.stderr.startswith("error: --config-ids: ")


def test_status_names_the_fault_bits():
    with SdkDrone(battery_pct=25, vbat_low_pct=30) as drone:
        drone.fault_bits = ULTRASOUND
        result = operator("status", drone, "--control-port", str(drone.control_port))
        assert result.exit_code == 0, result.stderr
        faults = next(line for line in result.stdout.splitlines() if line.startswith("faults"))
        assert faults == ("faults     VBAT_LOW (state bit 15: battery too low for the "
                          "firmware), ULTRASOUND (state bit 21: ultrasound sensor deaf)")


# ----------------------------------------------------------------------------- a holder
HOLDER = """
import signal, sys, time
from ardrone_nmpc.links.flight_lock import FlightLock
lock = FlightLock("127.0.0.1", int(sys.argv[1]))
lock.acquire()
got = []
for sig in (signal.SIGTERM, signal.SIGUSR2):
    signal.signal(sig, signal.SIG_IGN if sys.argv[2] == "deaf" else lambda s, f: got.append(s))
print("holding", flush=True)
deadline = time.monotonic() + float(sys.argv[3])
while not got and time.monotonic() < deadline:
    time.sleep(0.01)
print(signal.Signals(got[0]).name if got else "none", flush=True)
lock.release()
"""


@pytest.mark.parametrize("command, sig", [("land", "SIGTERM"), ("emergency", "SIGUSR2")])
def test_a_flight_holding_the_drone_is_told_and_given_time_to_let_go(tmp_path, command, sig):
    import os
    import subprocess
    import sys

    with SdkDrone() as drone:
        env = dict(os.environ, XDG_RUNTIME_DIR=os.environ["XDG_RUNTIME_DIR"])
        holder = subprocess.Popen([sys.executable, "-c", HOLDER, str(drone.at_port), "ok", "20"],
                                  stdout=subprocess.PIPE, text=True, env=env)
        try:
            assert holder.stdout.readline().strip() == "holding"
            result = operator(command, drone)
            told = holder.stdout.readline().strip()
        finally:
            holder.kill() if holder.poll() is None else None
            holder.wait(timeout=10)
        assert told == sig
        what = "land (SIGTERM)" if sig == "SIGTERM" else "cut the motors too (SIGUSR2)"
        assert f"a flight (pid {holder.pid}) holds the drone: told it to {what}\n" in \
            result.stderr
        assert f"the flight (pid {holder.pid}) let go of the drone" in result.stderr
        assert result.exit_code == 0, result.stderr   # a landed drone: down, or cut
        assert drone.log[0][1] == "REF"               # its command went first


def test_a_flight_that_does_not_let_go_is_waited_for_only_so_long(monkeypatch):
    import os
    import subprocess
    import sys

    import ardrone_nmpc.cli.operator as operator_module

    monkeypatch.setattr(operator_module, "HANDOVER_S", 0.5)
    with SdkDrone(airborne_at_start=True) as drone:
        holder = subprocess.Popen([sys.executable, "-c", HOLDER, str(drone.at_port), "deaf",
                                   "5"], stdout=subprocess.PIPE, text=True, env=dict(os.environ))
        try:
            assert holder.stdout.readline().strip() == "holding"
            result = operator("land", drone)
        finally:
            holder.kill()
            holder.wait(timeout=10)
        assert f"pid {holder.pid} still holds the drone after 0.5 s: confirming from here" in \
            result.stderr
        assert result.exit_code == 0 and drone.phase == "landed", result.stderr


def test_a_holder_that_cannot_be_signalled_is_said_and_not_waited_for(tmp_path):
    """The lock file names a pid that no longer exists (held through another descriptor)."""
    import fcntl
    import os

    from ardrone_nmpc.links.flight_lock import FlightLock

    with SdkDrone(airborne_at_start=True) as drone:
        lock = FlightLock("127.0.0.1", drone.at_port)
        fd = os.open(lock.path, os.O_RDWR | os.O_CREAT, 0o600)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            os.write(fd, b"4194999\nghost\n")          # above any pid_max: no such process
            result = operator("land", drone)
        finally:
            os.close(fd)
        assert result.stderr.startswith("warning: cannot signal the flight (pid 4194999): ")
        assert "let go" not in result.stderr and "still holds" not in result.stderr
        assert result.exit_code == 0 and drone.phase == "landed"


def test_emergency_on_a_drone_already_cut_cuts_it_again_once_navdata_shows_the_clear():
    """On the ground in emergency the first edge clears it (the stand-in's model, and the
    documented one); the packet that shows it brings one more edge."""
    with SdkDrone() as drone:
        with drone.lock:
            drone._set("emergency", drone.phase_t)
        result = operator("emergency", drone)
        assert result.exit_code == 0, result.stderr
        assert result.stderr == "navdata shows the drone landed, not cut: cutting again\n"
        assert [p for _, p in drone.phases] == ["emergency", "landed", "emergency"]


def test_emergency_gives_up_after_its_one_extra_edge():
    """A drone whose REF is taken by nobody (its AT port is ours): the packets never show
    the cut; one more edge, then one error line."""
    with SdkDrone() as drone:
        black_hole = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        black_hole.bind(("127.0.0.1", 0))
        try:
            result = CliRunner().invoke(app, [
                "emergency", "--drone", "127.0.0.1", "--at-port",
                str(black_hole.getsockname()[1]), "--navdata-port", str(drone.navdata_port)])
        finally:
            black_hole.close()
        assert result.exit_code == 1
        lines = result.stderr.strip().splitlines()
        assert lines == ["navdata shows the drone landed, not cut: cutting again",
                         "error: emergency not confirmed by navdata within 3 s (mode landed) — "
                         "check the drone"]


def test_emergency_and_land_answer_bootstrap_with_the_config_ids():
    with SdkDrone(held=SESSION) as drone:
        result = operator("emergency", drone, "--config-ids", ",".join(IDS))
        assert result.exit_code == 0, result.stderr
        assert not drone.bootstrap                   # navdata_demo taken, with the session ids
    with SdkDrone(held=SESSION, airborne_at_start=True) as drone:
        result = operator("land", drone, "--config-ids", ",".join(IDS))
        assert result.exit_code == 0 and not drone.bootstrap, result.stderr


class SlowLanding(SdkDrone):
    LANDING_S = 1.5       # long enough for two Ctrl-C, or the landing's first notice


def interrupt_after(*delays_s):
    """SIGINT to this process (the command line runs in its main thread) at each delay."""
    import os
    import signal
    import threading

    def fire():
        for delay in delays_s:
            time.sleep(delay)
            os.kill(os.getpid(), signal.SIGINT)
    threading.Thread(target=fire, daemon=True).start()


def test_land_says_what_it_waits_for(monkeypatch):
    import ardrone_nmpc.runtime.session as session_module

    monkeypatch.setattr(session_module, "NOTICE_EVERY_S", 1.0)
    with SlowLanding(airborne_at_start=True) as drone:
        result = operator("land", drone)
        assert result.exit_code == 0, result.stderr
        assert result.stderr == ("landing: waiting for the drone to touch down (mode landing, "
                                 "ctrl_state 0x00080000)\n")
        assert result.stdout == "landed (landed)\n"


def test_a_ctrl_c_during_land_lands_first_two_cut():
    with SlowLanding(airborne_at_start=True) as drone:
        interrupt_after(0.5)
        result = operator("land", drone)
        assert result.exit_code == 130 and drone.phase == "landed"
        assert result.stderr.splitlines() == [
            "landing — press Ctrl-C again within 2 s to cut the motors (emergency)",
            "error: interrupted: landed (landed)"]
    with SlowLanding(airborne_at_start=True) as drone:
        interrupt_after(0.5, 0.3)
        result = operator("land", drone)
        assert result.exit_code == 130 and drone.phase == "emergency"
        assert result.stderr.splitlines()[-1] == "error: interrupted: motors cut (emergency)"
        assert "cutting the motors (emergency): a second Ctrl-C" in result.stderr


def test_a_landing_whose_navdata_stops_says_the_last_mode_it_saw(short_blind_landing):
    import threading

    with SdkDrone(airborne_at_start=True) as drone:
        drone.LANDING_S = 5.0                         # it is still coming down, unseen

        def silence():                                # once the operator hears it, no more
            if wait_until(lambda: getattr(drone, "last_navdata_t", None) is not None, 10.0):
                with drone.lock:
                    drone.silent_from, drone.silent_until = time.monotonic(), float("inf")
        threading.Thread(target=silence, daemon=True).start()
        result = operator("land", drone)
        assert result.exit_code == 1
        assert re.fullmatch(r"error: landing not confirmed by navdata \(the drone's last mode "
                            r"(flying|landing), \d s ago\) — look at the drone",
                            result.stderr.strip().splitlines()[-1]), result.stderr


@pytest.mark.parametrize("sig, code", [("SIGINT", 130), ("SIGTERM", 143)])
def test_an_interrupted_blind_landing_says_it_was_not_confirmed(short_blind_landing, sig, code):
    import os
    import signal
    import threading

    with SdkDrone(airborne_at_start=True) as drone:
        drone.silent_until = float("inf")            # it hears, it never answers

        def interrupt():                             # once the landing waits for navdata
            if wait_until(lambda: drone.wakeups, 10.0):
                time.sleep(0.2)
                os.kill(os.getpid(), getattr(signal, sig))
        threading.Thread(target=interrupt, daemon=True).start()
        result = operator("land", drone)
        assert result.exit_code == code, result.stderr
        assert result.stderr.strip().splitlines()[-1] == (
            "error: interrupted: landing not confirmed by navdata — check the drone")


def test_status_prints_the_snapshot_and_every_held_limit_line_by_line():
    """What the stand-in sends, as docs/first-flight.md lists it: a drone on the ground
    (ctrl_state major 2, LANDED), navdata_demo after the handshake (state bit 10), its
    battery, altitude and attitude, then the ten keys it holds (config_keys.h defaults) —
    one missing from its store said so, a control port that does not answer one line."""
    from tests.standins.sdk_drone import DEFAULT_CONFIG

    with SdkDrone(attitude_deg=(0.3, -0.2), battery_pct=80) as drone:
        del drone.config["control:flying_mode"]
        result = operator("status", drone, "--control-port", str(drone.control_port))
        at, nav = drone.at_port, drone.navdata_port
    assert result.exit_code == 0, result.stderr
    keys = ("control:euler_angle_max", "control:control_vz_max", "control:control_yaw",
            "control:altitude_max", "control:outdoor", "control:flight_without_shell",
            "control:flying_mode", "custom:session_id", "custom:profile_id",
            "custom:application_id")
    held = dict(DEFAULT_CONFIG, **{"control:flying_mode": "(missing)"})
    assert result.stdout.splitlines() == [
        f"drone      127.0.0.1:{at}/{nav}", "mode       landed",
        "state      0x00000400 NAVDATA_DEMO", "faults     none",
        "ctrl_state 0x00020000 (major 2 LANDED, minor 0)", "battery    80 %",
        "altitude   0.000 m", "attitude   roll +0.3° pitch -0.2° yaw +10.0°",
        *(f"{key:<29}{held[key]}" for key in keys)]
    with SdkDrone(serve_control_port=False) as drone:
        result = operator("status", drone, "--control-port", str(dead_port()))
    assert result.exit_code == 0, result.stderr
    assert result.stdout.splitlines()[-1].startswith("limits     not read: ")


@pytest.mark.parametrize("value", ["d2e081a3,be27e2e4", "d2e081a3,be27e2e4,d87f7e0c,00000000",
                                   "d2e081a3,be27e2e4,d87f7e0", "d2e081a3,be27e2e4,d87f7e0g"])
def test_config_ids_are_exactly_three_of_8_hex_digits(value):
    """docs/first-flight.md: --config-ids SESSION,PROFILE,APPLICATION, 8 hex digits each;
    anything else is one usage line (exit 2) before a datagram goes out."""
    result = CliRunner().invoke(app, ["reset", "--drone", "127.0.0.1", "--at-port",
                                      str(dead_port()), "--config-ids", value])
    assert result.exit_code == 2
    assert result.stderr == (f"error: --config-ids: {value!r}: three ids of 8 hex digits, "
                             "session,profile,application (e.g. d2e081a3,be27e2e4,d87f7e0c)\n")


def test_config_ids_may_be_spaced_and_of_either_case():
    with SdkDrone(held=SESSION) as drone:
        spaced = " D2E081A3 , be27e2e4,d87f7e0c "
        result = operator("status", drone, "--control-port", str(drone.control_port),
                          "--config-ids", spaced)
        assert result.exit_code == 0, result.stderr


def test_status_reads_a_drone_in_the_air():
    """status works against any drone, flying too (docs/first-flight.md): it must not refuse
    an airborne one as fly's connect does."""
    with SdkDrone(airborne_at_start=True) as drone:
        result = operator("status", drone, "--control-port", str(drone.control_port))
        assert drone.phase == "hovering"                # and it did not land it
    assert result.exit_code == 0, result.stderr
    lines = result.stdout.splitlines()
    assert lines[2] == "state      0x00000401 FLY NAVDATA_DEMO"      # bits 0 and 10
    assert lines[4] == "ctrl_state 0x00040000 (major 4 HOVERING, minor 0)"
    assert lines[6] == "altitude   1.000 m"                         # the stand-in's hover


class NewMajor(SdkDrone):
    """A firmware reporting a major ctrl_state control_states.h does not list."""

    def _state_and_ctrl(self, now):
        state, _ = super()._state_and_ctrl(now)
        return state, 99 << 16 | 3


def test_status_of_a_cut_drone_and_of_an_unknown_ctrl_state():
    with SdkDrone() as drone:
        _cut(drone)
        result = operator("status", drone, "--control-port", str(drone.control_port))
    assert result.exit_code == 0, result.stderr
    lines = result.stdout.splitlines()
    assert lines[1:5] == ["mode       emergency",
                          "state      0x80000400 NAVDATA_DEMO EMERGENCY",     # bits 10, 31
                          "faults     none",
                          "ctrl_state 0x00000000 (major 0 DEFAULT, minor 0)"]
    with NewMajor() as drone:
        result = operator("status", drone, "--control-port", str(drone.control_port))
    assert result.exit_code == 0, result.stderr
    assert result.stdout.splitlines()[4] == "ctrl_state 0x00630003 (major 99 unknown, minor 3)"


class StuckCut(SdkDrone):
    """A drone whose emergency does not clear on the edge (a cut the firmware holds)."""

    def _at_ref(self, args, now):
        if self.phase != "emergency":
            super()._at_ref(args, now)


def _cut(drone) -> None:
    with drone.lock:
        drone._set("emergency", drone.phase_t)


def test_reset_in_a_multiconfig_session_takes_the_ids_and_clears_the_cut():
    with SdkDrone(held=SESSION) as drone:
        _cut(drone)
        result = operator("reset", drone, "--config-ids", ",".join(IDS))
        assert result.exit_code == 0, result.stderr
        assert result.stdout == "emergency cleared\n" and drone.phase == "landed"


def test_a_cut_that_does_not_clear_is_one_error_line():
    with StuckCut() as drone:
        _cut(drone)
        result = operator("reset", drone)
        assert drone.phase == "emergency"
    assert result.exit_code == 1
    assert result.stderr == ("error: emergency not cleared (state bit 31 still set after "
                             "3.00 s)\n")


def test_a_busy_local_at_port_is_a_warning_not_an_error(monkeypatch):
    """The lab's local AT port 5556 taken by another program: AT commands go out from an
    ephemeral port, and the command says so on stderr (docs/first-flight.md)."""
    busy = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    busy.bind(("127.0.0.1", 0))
    port = busy.getsockname()[1]
    base = drone_link_module.DroneLink

    def init(self, *args, **kwargs):
        base.__init__(self, *args, **kwargs)
        self.at_local_port = port
    monkeypatch.setattr(drone_link_module, "DroneLink", type("DroneLink", (base,),
                                                             {"__init__": init}))
    try:
        with SdkDrone() as drone:
            result = operator("status", drone, "--control-port", str(drone.control_port))
    finally:
        busy.close()
    assert result.exit_code == 0, result.stderr
    assert result.stderr.startswith(f"warning: local UDP port {port} is busy (")
    assert result.stderr.endswith("; AT commands go out from an ephemeral port\n")
    assert result.stdout.startswith("drone      127.0.0.1:")


@pytest.mark.parametrize("command", ["status", "reset"])
def test_an_address_that_is_no_host_is_one_error_line(command):
    result = CliRunner().invoke(app, [command, "--drone", "127.0.0.1 x", "--at-port",
                                      str(dead_port())])
    assert result.exit_code == 1
    assert result.stderr == ("error: drone address must be an address or host name, got "
                             "'127.0.0.1 x'\n")


class BootstrapOnly(SdkDrone):
    """A drone that acknowledges navdata_demo but keeps sending bootstrap packets (header
    and state only: no demo option, so no ctrl_state, battery or attitude)."""

    def _at_config(self, args, now):
        super()._at_config(args, now)
        self.bootstrap = True


def test_status_of_a_drone_stuck_in_bootstrap_is_one_error_line(monkeypatch):
    """Without the demo option there is no ctrl_state, battery or attitude to print: the
    connection fails, in one line (so status never prints a snapshot without a ctrl_state)."""
    import ardrone_nmpc.cli.operator as operator_module

    monkeypatch.setattr(operator_module, "CONNECT_TIMEOUT_S", 1.0)
    with BootstrapOnly() as drone:
        result = operator("status", drone, "--control-port", str(drone.control_port))
    assert result.exit_code == 1 and result.stdout == ""
    assert re.fullmatch(r"error: navdata from 127\.0\.0\.1 still in bootstrap mode \(no demo "
                        r"option\) [0-9.]+ s after connecting, although general:navdata_demo "
                        r"was acknowledged\n", result.stderr), result.stderr


def test_emergency_after_the_entry_points_edge_sends_no_second_one(monkeypatch):
    """The installed command's entry point sent the edge (REF land, then emergency) before
    typer loaded; the command's own link must then hold REF land: a second rising edge of
    bit 8 would toggle the emergency again (the SDK toggles it on every edge)."""
    from ardrone_nmpc.cli import first_datagram as launch

    monkeypatch.setattr(launch, "SENT", None)
    monkeypatch.setattr(launch, "_LOCAL_AT_PORT", dead_port())
    with SdkDrone(airborne_at_start=True) as drone:
        launch.send_first(["emergency", "--drone", "127.0.0.1", "--at-port", str(drone.at_port)])
        assert launch.SENT == ("emergency", "127.0.0.1", drone.at_port)
        assert wait_until(lambda: drone.phase == "emergency", 5.0)
        result = operator("emergency", drone)
        values = [v for _, v in refs(drone)]
        rising = sum(1 for a, b in zip(values, values[1:]) if a == LAND and b == EMERGENCY)
        assert rising == 1, values[:8]
        assert result.exit_code == 0, result.stderr
        assert drone.phase == "emergency"


@pytest.mark.parametrize("command", ["land", "emergency"])
def test_a_link_that_cannot_be_opened_is_one_error_line_naming_why(monkeypatch, command):
    from ardrone_nmpc.links.drone_config import LinkError

    def refuse(self, command, *, edge_sent=False):
        raise LinkError("cannot open a link to 127.0.0.1: [Errno 99] no such address")
    monkeypatch.setattr(operator_link_module.OperatorLink, "start", refuse)
    result = CliRunner().invoke(app, [command, "--drone", "127.0.0.1", "--at-port",
                                      str(dead_port())])
    assert result.exit_code == 1
    assert result.stderr == ("error: cannot open a link to 127.0.0.1: [Errno 99] no such "
                             "address\n")
