"""Where a cold start's seconds go: numba's compile events of one ``simulate``, per kernel.

    NUMBA_CACHE_DIR=$(mktemp -d) python benchmarks/compile_events.py [CONFIG] [--top 20]

Runs ``simulate CONFIG`` (default ``configs/hover.yaml``) in this process with a listener on
``numba:compile`` and prints, per compiled kernel, the CPU seconds from its compile's start to
its end (inclusive: a kernel's compile includes those of the kernels it calls the first time)
and the process's CPU seconds in all. Run it on an empty ``NUMBA_CACHE_DIR`` (a filled cache
compiles nothing).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("config", nargs="?", default=str(ROOT / "configs" / "hover.yaml"))
    ap.add_argument("--top", type=int, default=20)
    args = ap.parse_args()
    cpu0 = time.process_time()
    from numba.core import event

    started: dict[int, float] = {}
    spent: dict[str, float] = {}

    class _CpuListener(event.Listener):
        def on_start(self, ev):
            started[id(ev.data["dispatcher"]), str(ev.data["args"])] = time.process_time()

        def on_end(self, ev):
            key = id(ev.data["dispatcher"]), str(ev.data["args"])
            name = ev.data["dispatcher"].py_func.__qualname__
            spent[name] = spent.get(name, 0.0) + time.process_time() - started.pop(key)

    from ardrone_nmpc.cli.app import app

    with event.install_listener("numba:compile", _CpuListener()), \
            tempfile.TemporaryDirectory() as logs:
        try:
            app(["simulate", args.config, "--quiet", "--log-dir", logs], standalone_mode=False)
        except SystemExit as done:
            if done.code:
                raise
    total = time.process_time() - cpu0
    for name, cpu in sorted(spent.items(), key=lambda kv: -kv[1])[:args.top]:
        print(f"{cpu:7.2f} s  {name}")
    print(f"{total:7.2f} s  CPU in all (imports, compiles, the flight)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
