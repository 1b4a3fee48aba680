"""Live view cost: loop jitter of `fly --sim` with and without `--foxglove`, and what a client
receives (docs/live-view.md).

Flies `configs/hover.yaml --sim` for `--seconds` (10) of experiment, alternating runs without
and with `--foxglove` (`--repeats` pairs); with it, a Foxglove WebSocket client in this process
(tests/integration/foxglove_client.py) subscribes to every channel and counts the `/log`
messages. Reports, per run, the rows logged, the rows received, and the wake-up lateness of the
65 ms loop (the `loop_timing` event: p50 / p99 / max), then the medians per mode and the p99
difference. Also times `LiveView.row` — all the control thread pays per tick.

    python benchmarks/live_view_jitter.py [--seconds 10] [--repeats 3] [--json FILE]

Only 127.0.0.1 is used. Needs the 'foxglove' extra and tornado (both in 'test').
"""

from __future__ import annotations

import argparse
import json
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "integration"))

from foxglove_client import FoxgloveClient  # noqa: E402


def _free_tcp_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def fly(seconds: float, log_dir: Path, foxglove: bool) -> dict:
    cmd = [sys.executable, "-m", "ardrone_nmpc.cli.app", "fly", "configs/hover.yaml", "--sim",
           "--no-dashboard", "--duration-s", str(seconds), "--log-dir", str(log_dir)]
    client = None
    if foxglove:
        port = _free_tcp_port()
        cmd += ["--foxglove", "--foxglove-port", str(port)]
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    try:
        if foxglove:
            client = FoxgloveClient(port, connect_timeout_s=30.0).start()
        out, err = proc.communicate(timeout=seconds + 120)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    if proc.returncode != 0:
        raise SystemExit(f"fly failed ({proc.returncode}): {err.strip()}")
    run_dir = Path([ln for ln in out.splitlines() if ln.startswith("run: ")][-1][5:])
    rows = len((run_dir / "log.csv").read_text().splitlines()) - 1
    events = [json.loads(ln) for ln in (run_dir / "events.jsonl").read_text().splitlines()]
    timing = next(e for e in events if e["kind"] == "loop_timing")
    received = None
    if client is not None:
        time.sleep(0.5)   # the last messages in flight
        client.close()
        received = len(client.topic_messages("/log"))
    return {"foxglove": foxglove, "rows": rows, "received": received,
            "p50_ms": timing["jitter_p50_ms"], "p99_ms": timing["jitter_p99_ms"],
            "max_ms": timing["jitter_max_ms"], "overruns": timing["overruns"]}


def row_cost_us(n: int = 20000) -> float:
    """Median cost of LiveView.row (the control thread's share), µs, server running."""
    sys.path.insert(0, str(ROOT))
    from ardrone_nmpc.runs.log_columns import LOG_COLUMNS, STRING_COLUMNS
    from ardrone_nmpc.viz.live import LiveView

    row = {c: ("track" if c in STRING_COLUMNS else 0.123456789) for c in LOG_COLUMNS}
    samples = []
    with LiveView(0, queue_size=1 << 20) as view:
        for k in range(n):
            row["t_s"] = k * 0.065
            t0 = time.perf_counter_ns()
            view.row(row)
            samples.append(time.perf_counter_ns() - t0)
    return statistics.median(samples) / 1e3


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--json", type=Path)
    args = ap.parse_args()
    results = []
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(args.repeats):
            for foxglove in (False, True):
                res = fly(args.seconds, Path(tmp), foxglove)
                results.append(res)
                got = "" if res["received"] is None else \
                    f"received {res['received']}/{res['rows']} ({100 * res['received'] / res['rows']:.1f} %)"
                print(f"pair {r + 1} {'--foxglove' if foxglove else 'plain     '}: rows {res['rows']}, "
                      f"jitter p50 {res['p50_ms']:.3f} p99 {res['p99_ms']:.3f} max "
                      f"{res['max_ms']:.3f} ms, overruns {res['overruns']}  {got}", flush=True)
    med = {fg: statistics.median(r["p99_ms"] for r in results if r["foxglove"] is fg)
           for fg in (False, True)}
    worst_share = min(r["received"] / r["rows"] for r in results if r["foxglove"])
    cost = row_cost_us()
    print(f"median p99: plain {med[False]:.3f} ms, --foxglove {med[True]:.3f} ms "
          f"(difference {med[True] - med[False]:+.3f} ms); lowest share of ticks received "
          f"{100 * worst_share:.1f} %; LiveView.row {cost:.1f} µs per tick (median)")
    if args.json:
        args.json.write_text(json.dumps({"runs": results, "median_p99_ms": {
            "plain": med[False], "foxglove": med[True]}, "row_cost_us": cost}, indent=2))


if __name__ == "__main__":
    main()
