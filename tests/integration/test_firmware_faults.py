"""A loopback drone that behaves like firmware (issue 17 item 6), against the project's link and
``fly --sim``: the configuration read-back over the control port, a drone left in another
configuration session, a control port that does not answer, another firmware's ctrl_state codes
and a drone that lands by itself — and the client's answers: refuse take-off on a mismatched
or unread configuration, never take off again after the drone landed by itself.
Only 127.0.0.1 is used; every socket is closed and every subprocess has a timeout.
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import pytest

from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.links.drone_link import DroneLink, LinkError
from ardrone_nmpc.sim.loopback import start_loopback

ROOT = Path(__file__).parents[2]
FLY = [sys.executable, "-m", "ardrone_nmpc.cli.app", "fly", "configs/hover.yaml", "--sim",
       "--no-dashboard"]
IDS = ("d2e081a3", "be27e2e4", "d87f7e0c")   # the foreign_session fault's defaults
LIMITS = dict(euler_angle_max_rad=0.2094, control_vz_max_mps=0.7, control_yaw_radps=1.745,
              altitude_max_m=3.0)
def _link(loop, **options) -> DroneLink:
    return DroneLink(loop.drone_host, at_port=loop.at_port, navdata_port=loop.navdata_port,
                     bind_host="127.0.0.1", control_port=loop.control_port, **options)


def _numbers(config: dict, keys) -> list[float]:
    return [float(config[k]) for k in keys]


# ----------------------------------------------------------------------------- the link
@pytest.mark.timeout(30)
def test_the_loopback_serves_its_configuration_to_the_link():
    with start_loopback(load_config(None), seed=1) as loop:
        assert loop.control_port is not None            # served by default (a free port)
        with _link(loop) as link:
            link.connect(timeout_s=5.0)
            written = link.configure_limits(**LIMITS)
            held = link.read_config(timeout_s=2.0)
    assert _numbers(held, written) == pytest.approx(_numbers(written, written), rel=1e-3)
    assert held["general:navdata_demo"] == "TRUE"


@pytest.mark.timeout(30)
def test_a_drone_in_another_session_acks_writes_and_keeps_its_limits():
    cfg = load_config(None, ["faults.foreign_session.session_id=d2e081a3"])
    with start_loopback(cfg, seed=1) as loop:
        with _link(loop) as link:
            link.connect(timeout_s=5.0)
            written = link.configure_limits(**LIMITS)    # every write acknowledged …
            held = link.read_config(timeout_s=2.0)
        ignored = loop.drone.counters.config_writes_ignored
        with _link(loop, config_ids=IDS) as link:         # … but only that session's obeyed
            link.connect(timeout_s=5.0)
            link.configure_limits(**LIMITS)
            obeyed = link.read_config(timeout_s=2.0)
        params = loop.plant.params
    assert float(held["control:euler_angle_max"]) == pytest.approx(0.52)
    assert float(held["control:control_vz_max"]) == pytest.approx(2000.0)
    assert float(held["control:control_yaw"]) == pytest.approx(6.11)
    assert held["custom:session_id"] == IDS[0]
    assert ignored >= 3      # the three per-session limits (altitude_max is shared)
    assert float(held["control:altitude_max"]) == float(written["control:altitude_max"])
    assert _numbers(obeyed, written) == pytest.approx(_numbers(written, written), rel=1e-3)
    assert params.euler_angle_max_rad == pytest.approx(0.2094)


@pytest.mark.timeout(30)
@pytest.mark.parametrize("mode, within_s", [("silent", 3.0), ("refused", 1.0)])
def test_a_control_port_that_does_not_answer_fails_the_read_back(mode, within_s):
    cfg = load_config(None, [f"faults.control_port_drop.mode={mode}"])
    with start_loopback(cfg, seed=1) as loop:
        with _link(loop) as link:
            link.connect(timeout_s=5.0)
            link.configure_limits(**LIMITS)
            t0 = time.monotonic()
            with pytest.raises(LinkError, match="control port|configuration dump"):
                link.read_config(timeout_s=1.0)
            assert time.monotonic() - t0 < within_s
        assert loop.drone.counters.config_dumps == 0


# ----------------------------------------------------------------------------- fly --sim
def _fly(tmp_path, *overrides, duration_s="3"):
    sets = [a for o in ("sim.settle_s=1", *overrides) for a in ("--set", o)]
    proc = subprocess.run([*FLY, "--log-dir", str(tmp_path), "--duration-s", duration_s, *sets],
                          capture_output=True, text=True, timeout=110, cwd=ROOT)
    runs = sorted(Path(tmp_path).glob("*-hover"))
    events = ([json.loads(line) for line in (runs[-1] / "events.jsonl").read_text().splitlines()]
              if runs else [])
    return proc, events


@pytest.mark.timeout(120)
def test_fly_sim_reads_back_the_limits_it_wrote(tmp_path):
    proc, events = _fly(tmp_path)
    assert proc.returncode == 0, proc.stderr
    kinds = [e["kind"] for e in events]
    assert "config_read_failed" not in kinds
    written = next(e for e in events if e["kind"] == "config_written")
    read = next(e for e in events if e["kind"] == "config_read")
    limits = ["control:euler_angle_max", "control:control_vz_max", "control:control_yaw",
              "control:altitude_max"]
    keys = [k for k in written if k.startswith("control:")]
    assert set(limits) <= set(keys)  # and the profile: outdoor, flight_without_shell, flying_mode
    assert _numbers(read, limits) == pytest.approx(_numbers(written, limits), rel=1e-3)
    for key in set(keys) - set(limits):
        assert str(read[key]).upper() == str(written[key]).upper(), key


@pytest.mark.timeout(120)
def test_fly_sim_flies_a_drone_with_firmware_2_4_codes(tmp_path):
    proc, events = _fly(tmp_path, "faults.ctrl_codes.codes=fw2.4")
    assert proc.returncode == 0, proc.stderr
    kinds = [e["kind"] for e in events]
    assert kinds.index("takeoff") < kinds.index("landed")


@pytest.mark.timeout(120)
def test_fly_sim_refuses_to_take_off_with_limits_the_drone_did_not_accept(tmp_path):
    proc, events = _fly(tmp_path, "faults.foreign_session.session_id=d2e081a3")
    assert proc.returncode != 0
    assert "euler_angle_max" in proc.stderr + proc.stdout     # the line names the key
    assert "takeoff" not in [e["kind"] for e in events]


@pytest.mark.timeout(120)
def test_fly_sim_refuses_to_take_off_without_a_read_back(tmp_path):
    proc, events = _fly(tmp_path, "faults.control_port_drop.mode=silent")
    assert proc.returncode != 0
    assert "takeoff" not in [e["kind"] for e in events]


@pytest.mark.timeout(120)
def test_fly_sim_never_relaunches_a_drone_that_landed_by_itself(tmp_path):
    from ardrone_nmpc.runs.rundir import read_run

    proc, events = _fly(tmp_path, "faults.self_land.start_s=1", duration_s="6")
    assert proc.returncode != 0                                # a clear failure, not exit 0
    landed = next(e for e in events if e.get("fault") == "self_land")
    assert landed["accepted"]
    run = read_run(sorted(Path(tmp_path).glob("*-hover"))[-1])
    t, z = run.columns["t_s"], run.columns["z_m"]
    after = z[t > landed["t_s"] + 3.0]                         # landing takes < 3 s from 1 m
    assert after.size == 0 or after.max() < 0.1                # and it stays down
