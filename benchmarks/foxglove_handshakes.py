"""Foxglove clients of both subprotocols against a real `fly --sim --foxglove --mcap` flight
(docs/live-view.md, "Which Foxglove").

Starts the flight in a subprocess, then: `--old N` clients asking only for
`foxglove.websocket.v1` (Foxglove Studio 1.x, Lichtblick ≤ 1.21) one after the other, and one
client asking for `foxglove.sdk.v1` (tests/integration/foxglove_client.py) that stays for the
flight. Reports what each got, the flight's stderr lines about the handshake, the run's
`foxglove_*` events, and what the `--mcap` file holds.

    python benchmarks/foxglove_handshakes.py [--seconds 6] [--old 5]

Only 127.0.0.1 is used. Needs the 'foxglove' and 'mcap' extras and tornado (all in 'test').
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "integration"))
sys.path.insert(0, str(ROOT / "benchmarks"))

from foxglove_client import FoxgloveClient  # noqa: E402
from live_view_jitter import _free_tcp_port  # noqa: E402  (a script beside this one)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=6.0)
    ap.add_argument("--old", type=int, default=5, help="foxglove.websocket.v1 attempts")
    args = ap.parse_args()
    port = _free_tcp_port()
    tmp = Path(tempfile.mkdtemp(prefix="fg-handshakes-"))
    recording = tmp / "flight.mcap"
    cmd = [sys.executable, "-m", "ardrone_nmpc.cli.app", "fly", "configs/hover.yaml", "--sim",
           "--no-dashboard", "--duration-s", str(args.seconds), "--log-dir", str(tmp / "logs"),
           "--foxglove", "--foxglove-port", str(port), "--mcap", str(recording)]
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    with FoxgloveClient(port, connect_timeout_s=60) as current:
        if not current.subscribed.wait(60):
            sys.exit(f"no connection: {current.error}")
        refused = []
        for _ in range(args.old):
            old = FoxgloveClient(port, subprotocol="foxglove.websocket.v1").start()
            old._thread.join(10)
            refused.append(str(old.error))
        out, err = proc.communicate(timeout=120)
        time.sleep(0.5)
    run_dir = Path(out.strip().splitlines()[-1][len("run: "):])
    events = [json.loads(line) for line in (run_dir / "events.jsonl").read_text().splitlines()]
    fox_events = [e for e in events if e["kind"].startswith("foxglove")]
    from ardrone_nmpc.experiments.export import read_mcap

    back = read_mcap(recording)
    print(f"exit code: {proc.returncode}")
    print(f"foxglove.sdk.v1 client: {len(current.topic_messages('/log'))} /log, "
          f"{len(current.topic_messages('/tf'))} /tf messages; topics "
          f"{sorted({c['topic'] for c in current.channels.values()})}")
    print(f"foxglove.websocket.v1 clients: {len(refused)} attempts, answers "
          f"{sorted(set(refused))}")
    handshake_lines = [ln for ln in err.splitlines() if "handshake failed" in ln
                       or "Dropping client" in ln]
    print(f"stderr lines about the handshake: {len(handshake_lines)}; stderr was:")
    for line in err.splitlines():
        print(f"    {line}")
    print(f"run events foxglove_*: {len(fox_events)}")
    for e in fox_events:
        print(f"    {json.dumps(e, ensure_ascii=False)}")
    print(f"--mcap file: {len(back.rows)} rows ({sum(1 for _ in open(run_dir / 'log.csv')) - 1}"
          f" in log.csv), /tf {len(back.poses.get('/tf', []))}, /flight_path "
          f"{len(back.poses.get('/flight_path', []))} message(s), /config {back.n_configs}")


if __name__ == "__main__":
    main()
