"""Issue 21's eight reproductions re-run through the real command line (subprocesses, 127.0.0.1
only) against the SDK stand-in (tests/standins/sdk_drone.py) and the loopback simulators: for
each, how the drone ended, the exit code, the last ``error:`` line, whether a traceback
appeared, whether the run directory is complete, and how long it took; and the time
``ardrone-nmpc emergency`` takes to cut a drone a running ``fly`` holds (process start-up
included), over ``--repeats`` flights.

    python benchmarks/drone_alarms.py [--repeats 3] [--json FILE]
"""

from __future__ import annotations

import argparse
import json
import os
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from tests.standins.sdk_drone import (CUTOUT, MOTORS, SOFTWARE_FAULT, ULTRASOUND,  # noqa: E402
                                      MocapStandIn, SdkDrone)

SESSION = {"custom:session_id": "d2e081a3", "custom:profile_id": "be27e2e4",
           "custom:application_id": "d87f7e0c"}
APP = [sys.executable, "-m", "ardrone_nmpc.cli.launch"]  # the entry point, as a user runs it


def free_port() -> int:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


class Bench:
    def __init__(self, tmp: Path):
        self.tmp = tmp
        self.env = dict(os.environ, XDG_RUNTIME_DIR=str(tmp / "run"))
        (tmp / "run").mkdir(exist_ok=True)

    def run(self, *args, timeout=120):
        t0 = time.monotonic()
        p = subprocess.run([*APP, *args], capture_output=True, text=True, env=self.env,
                           cwd=ROOT, timeout=timeout)
        return p, time.monotonic() - t0

    def drone_args(self, drone, navdata_port=None):
        return ["--drone", "127.0.0.1", "--at-port", str(drone.at_port), "--navdata-port",
                str(navdata_port or drone.navdata_port)]

    def fly_args(self, drone, mocap_port, duration_s, *sets):
        args = ["fly", "configs/hover.yaml", "--no-dashboard", *self.drone_args(drone),
                "--mocap-port", str(mocap_port), "--log-dir", str(self.tmp / "logs"),
                "--duration-s", str(duration_s), "--set", "sim.settle_s=0.5", "--set",
                "mocap.bind_host=127.0.0.1", "--set", f"drone.control_port={drone.control_port}"]
        for s in sets:
            args += ["--set", s]
        return args

    def mocap(self, drone, port):
        alt = {"hovering": 1.0, "takeoff": 0.5, "landing": 0.3}
        return MocapStandIn(port, lambda: ((0.0, 0.0, alt.get(drone.phase, 0.0)),
                                           drone.true_psi_rad))

    def fly(self, drone, duration_s=3.0, *sets, during=None):
        port = free_port()
        with self.mocap(drone, port):
            if during is not None:
                threading.Thread(target=during, daemon=True).start()
            return self.run(*self.fly_args(drone, port, duration_s, *sets))


def outcome(label, proc, took_s, drone_end, run_complete=None, **extra):
    err = [line for line in proc.stderr.splitlines() if line.startswith("error: ")]
    return {"case": label, "drone": drone_end, "exit": proc.returncode,
            "line": err[-1] if err else (proc.stdout.strip().splitlines() or [""])[-1],
            "traceback": "Traceback" in proc.stderr, "run_dir_complete": run_complete,
            "took_s": round(took_s, 2), **extra}


def run_dir(proc) -> Path | None:
    runs = [line[5:] for line in proc.stdout.splitlines() if line.startswith("run: ")]
    return Path(runs[-1]) if runs else None


def complete(proc) -> bool | None:
    path = run_dir(proc)
    if path is None:
        return None
    return all((path / f).is_file() for f in ("config.yaml", "log.csv", "events.jsonl",
                                               "summary.csv"))


def when_hovering(drone, action, after_s=1.0):
    def go():
        deadline = time.monotonic() + 60
        while drone.phase != "hovering" and time.monotonic() < deadline:
            time.sleep(0.01)
        time.sleep(after_s)
        action()
    return go


def reproductions(b: Bench) -> list[dict]:
    out = []
    # 1. land / emergency: a session that ignores plain CONFIG, navdata silent
    with SdkDrone(airborne_at_start=True, held=SESSION) as d:
        p, s = b.run("land", *b.drone_args(d))
        out.append(outcome("1 land, drone in another config session", p, s, d.phase,
                           refs_before_first_wakeup=sum(1 for t, n, *_ in d.log
                                                        if n == "REF" and t <= d.wakeups[0])))
    with SdkDrone(airborne_at_start=True) as d:
        p, s = b.run("land", *b.drone_args(d, navdata_port=free_port()))
        out.append(outcome("1 land, navdata silent", p, s, d.phase))
    with SdkDrone(airborne_at_start=True, held=SESSION) as d:
        p, s = b.run("emergency", *b.drone_args(d, navdata_port=free_port()))
        out.append(outcome("1 emergency, session + navdata silent", p, s, d.phase))
    # 3. navdata silent from 0.5 s after the take-off REF (for 3 s)
    with SdkDrone(navdata_gap_at_takeoff=(0.5, 3.0)) as d:
        p, s = b.fly(d, 10.0)
        refs = [(t, a[0]) for t, n, a, _ in d.log if n == "REF"]
        t_off = next(t for t, a in refs if a & 512)
        t_land = next(t for t, a in refs if t > t_off and not a & 512)
        out.append(outcome("3 navdata lost during take-off", p, s, d.phase, complete(p),
                           flown_unobserved_s=round(t_land - t_off - 0.5, 2)))
    # 4. fault bits 12, 14, 18, 21 before take-off; VBAT_LOW at 25 % (firmware level 30 %)
    with SdkDrone() as d:
        d.fault_bits = MOTORS | SOFTWARE_FAULT | (1 << 18) | ULTRASOUND
        p, s = b.fly(d)
        out.append(outcome("4 fault bits 12,14,18,21 at take-off", p, s, d.phase, complete(p),
                           takeoffs=d.takeoffs))
    with SdkDrone(battery_pct=25, vbat_low_pct=30) as d:
        p, s = b.fly(d)
        out.append(outcome("4 VBAT_LOW at 25 %", p, s, d.phase, complete(p),
                           takeoffs=d.takeoffs))
    for bit, name in ((SOFTWARE_FAULT, "SOFTWARE_FAULT"), (CUTOUT, "CUTOUT")):
        with SdkDrone() as d:
            p, s = b.fly(d, 20.0, during=when_hovering(d, lambda d=d, bit=bit:
                                                       setattr(d, "fault_bits", bit)))
            out.append(outcome(f"4 {name} in flight", p, s, d.phase, complete(p)))
    # 5. a 3 s Wi-Fi blackout mid-flight
    with SdkDrone() as d:
        p, s = b.fly(d, 20.0, during=when_hovering(d, lambda: d.blackout(3.0)))
        events = [json.loads(line) for line in (run_dir(p) / "events.jsonl").read_text()
                  .splitlines()]
        answers = next(e for e in events if e["kind"] == "drone_link")["bootstrap_answers"]
        out.append(outcome("5 3 s blackout", p, s, d.phase, complete(p),
                           bootstrap_answers=answers, link_losses=d.link_losses))
    with SdkDrone() as d:  # … and navdata that never comes back
        def silence():
            d.silent_from, d.silent_until = time.monotonic(), float("inf")
        p, s = b.fly(d, 20.0, during=when_hovering(d, silence))
        out.append(outcome("5 navdata never back", p, s, d.phase, complete(p)))
    # 6. last flown outdoors
    with SdkDrone(last_flown_outdoors=True) as d:
        p, s = b.fly(d)
        out.append(outcome("6 drone last flown outdoors", p, s, d.phase, complete(p),
                           outdoor_profile_kept=d.config["control:outdoor_euler_angle_max"]
                           == "0.3491"))
    # 7. unbounded safety settings, a reference outside the fence, tune over safety
    p, s = b.run("check", "configs/hover.yaml", "--set", "safety.max_tilt_rad=54.9", "--set",
                 "safety.max_speed_mps=1e9", "--set", "safety.battery_floor_pct=0")
    out.append(outcome("7 check unbounded safety", p, s, "-", errors=p.stderr.count("error:")))
    p, s = b.run("simulate", "configs/square.yaml", "--quiet", "--set", "reference.side_m=50",
                 "--log-dir", str(b.tmp / "logs7"))
    out.append(outcome("7 simulate square side 50 m", p, s, "not flown",
                       run_dir_made=(b.tmp / "logs7").exists()))
    space = b.tmp / "space.yaml"
    space.write_text("params:\n  safety.max_tilt_rad: {low: 0.1, high: 54.9}\n")
    p, s = b.run("tune", "configs/hover.yaml", "--space", str(space), "--trials", "1",
                 "--out", str(b.tmp / "tune7"))
    out.append(outcome("7 tune over a safety field", p, s, "not flown"))
    # 8. flights that never did their job
    p, s = b.run("simulate", "configs/hover.yaml", "--quiet", "--set", "duration_s=5", "--set",
                 "safety.max_speed_mps=0.001", "--log-dir", str(b.tmp / "logs8"))
    out.append(outcome("8 simulate, every tick hover-speed", p, s, "landed", complete(p)))
    p, s = b.run("simulate", "configs/follow_car.yaml", "--quiet", "--set", "duration_s=5",
                 "--set", "sim.target=null", "--log-dir", str(b.tmp / "logs8"))
    out.append(outcome("8 simulate follow, target never seen", p, s, "landed", complete(p)))
    p, s = b.run("fly", "configs/hover.yaml", "--sim", "--no-dashboard", "--duration-s", "3",
                 "--set", "safety.max_speed_mps=0.001", "--log-dir", str(b.tmp / "logs8"))
    out.append(outcome("8 fly --sim, every tick hover-speed", p, s, "landed", complete(p)))
    return out


def emergency_during_fly(b: Bench) -> dict:
    """2. ``emergency`` while a ``fly`` holds the drone: seconds from launching the command
    to the drone's cut, and what both processes and the drone show after."""
    port = free_port()
    with SdkDrone() as d, b.mocap(d, port):
        fly = subprocess.Popen([*APP, *b.fly_args(d, port, 60.0)], stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True, env=b.env, cwd=ROOT)
        try:
            deadline = time.monotonic() + 90
            while d.phase != "hovering" and time.monotonic() < deadline:
                time.sleep(0.01)
            time.sleep(2.0)
            t0 = time.monotonic()
            p = subprocess.run([*APP, "emergency", *b.drone_args(d)], capture_output=True,
                               text=True, env=b.env, cwd=ROOT, timeout=60)
            out, err = fly.communicate(timeout=60)
        finally:
            if fly.poll() is None:
                fly.kill()
                fly.communicate()
        i = next(i for i, (_, phase) in enumerate(d.phases) if phase == "emergency")
        first_ref = min(t for t, n, a, _ in d.log if n == "REF" and t > t0 and a[0] & 256)
        return {"cut_s": round(d.phases[i][0] - t0, 3),
                "first_emergency_ref_s": round(first_ref - t0, 3),
                "phases_after_cut": [p_ for _, p_ in d.phases[i:]],
                "emergency_exit": p.returncode, "fly_exit": fly.returncode,
                "fly_traceback": "Traceback" in err, "drone": d.phase}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--json", type=Path)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="drone-alarms-") as tmp:
        b = Bench(Path(tmp))
        cuts = [emergency_during_fly(b) for _ in range(args.repeats)]
        rows = reproductions(b)
    for r in rows:
        print(json.dumps(r, ensure_ascii=False))
    for c in cuts:
        print(json.dumps({"case": "2 emergency during fly", **c}))
    times = sorted(c["cut_s"] for c in cuts)
    print(f"emergency during fly: cut after {times[0]:.3f} … {times[-1]:.3f} s "
          f"(median {times[len(times) // 2]:.3f} s) over {len(times)} flights")
    if args.json:
        args.json.write_text(json.dumps({"reproductions": rows, "emergency": cuts}, indent=1,
                                        ensure_ascii=False) + "\n")


if __name__ == "__main__":
    main()
