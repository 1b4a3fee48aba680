"""Run directories written on two trees, file by file: are the written bytes unchanged?

    python benchmarks/rundir_bytes.py record DIR
    python benchmarks/rundir_bytes.py compare A B

``record`` writes one run directory per case (a config, ``--set`` overrides and a seed:
square flights long and short, a step, ``follow``, a moving obstacle, hover, the P
controller, faults that hold, land and stop, wind, obstacles, excitation) the way
``simulate`` and sweeps do (``experiments.record.record_lockstep``, blocks of rows) under
``DIR`` with the tree on ``sys.path``:
``PYTHONPATH=/tmp/base python benchmarks/rundir_bytes.py record /tmp/a``.
``compare`` checks every file of every case byte for byte — but for what is the clock's:
the ``solve_us`` and ``compute_us`` cells of ``log.csv`` (a number either way), the
summary's solve-time and compute rows, the events' ``wall_s`` and ``config.yaml``'s
``created:`` line. Exit 1 on any difference. (``tick_equivalence.py`` compares the values a
flight logs; this, the text the run directory holds.)
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SHORT = ["duration_s=20"]
CASES: list[tuple[str, list[str], int]] = [
    ("square", ["duration_s=60"], 0),
    ("square", SHORT, 3),
    ("step_x", [], 1),
    ("follow_car", ["duration_s=15"], 0),
    ("moving_obstacle", ["duration_s=15"], 1),
    ("hover", ["duration_s=10"], 2),
    ("step_z", ["controller.kind=p"], 0),
    ("square", [*SHORT, "faults.mocap_dropout.start_s=5", "faults.mocap_dropout.duration_s=2"], 0),
    ("square", [*SHORT, "faults.mocap_occlusion.start_s=4",
                "faults.mocap_occlusion.duration_s=1.5"], 1),
    ("square", [*SHORT, "faults.emergency.start_s=8"], 0),
    ("square", [*SHORT, "faults.battery_floor.start_s=6"], 0),
    ("square", [*SHORT, "faults.wind.velocity_mps=[1.5,0.5,0]"], 4),
    ("obstacle", [], 0),
    ("lorenz", ["duration_s=15"], 1),
    ("identify", [], 0),
    ("square", [*SHORT, "controller.solver.method=newton"], 2),  # the thesis' Newton scheme
]
CLOCK_CELLS = ("solve_us", "compute_us")
CLOCK_SUMMARY = (b"solver,solve_time", b"loop,compute")


def record(out: Path) -> None:
    from ardrone_nmpc.config.io import load_config
    from ardrone_nmpc.experiments.record import record_lockstep
    from ardrone_nmpc.runtime import lockstep

    if hasattr(lockstep, "warm_up_blocks"):  # blocks of ticks' kernel: the flights fly them
        lockstep.warm_up_blocks()

    for i, (name, sets, seed) in enumerate(CASES):
        cfg = load_config(ROOT / "configs" / f"{name}.yaml", sets)
        rec = record_lockstep(cfg, out, seed=seed, name=f"case{i:02d}-{name}", catch=True)
        ending = rec.result.ending if rec.result is not None else rec.error
        print(f"case{i:02d} {name:12s} {ending}")


def _text(path: Path) -> list[bytes]:
    """The file's lines, what is the clock's masked."""
    lines = path.read_bytes().splitlines(keepends=True)
    if path.name == "config.yaml":
        return [line for line in lines if not line.startswith(b"# created:")]
    if path.name == "events.jsonl":
        return [json.dumps({k: v for k, v in json.loads(line).items() if k != "wall_s"})
                .encode() for line in lines]
    if path.name == "summary.csv":
        return [line for line in lines if not line.startswith(CLOCK_SUMMARY)]
    if path.name == "log.csv" and lines:
        header = lines[0].decode().rstrip("\n").split(",")
        slots = [header.index(c) for c in CLOCK_CELLS if c in header]
        out = [lines[0]]
        for line in lines[1:]:
            cells = line.split(b",")
            for i in slots:
                if cells[i] not in (b"", b"nan"):
                    cells[i] = b"<clock>"
            out.append(b",".join(cells))
        return out
    return lines


def compare(a: Path, b: Path) -> int:
    files = sorted(p.relative_to(a) for p in a.rglob("*") if p.is_file())
    others = sorted(p.relative_to(b) for p in b.rglob("*") if p.is_file())
    differ = sorted(set(files) ^ set(others))
    differ += [f for f in files if f in set(others) and _text(a / f) != _text(b / f)]
    for f in differ:
        print(f"differs: {f}")
    print(f"{len(files) - len(differ)} of {len(files)} files the same bytes")
    return 1 if differ else 0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    sub.add_parser("record").add_argument("dir", type=Path)
    cmp = sub.add_parser("compare")
    cmp.add_argument("a", type=Path)
    cmp.add_argument("b", type=Path)
    args = parser.parse_args()
    if args.command == "record":
        record(args.dir)
        return 0
    return compare(args.a, args.b)


if __name__ == "__main__":
    sys.exit(main())
