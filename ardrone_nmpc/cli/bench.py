"""``ardrone-nmpc bench``: run :mod:`ardrone_nmpc.experiments.bench` and present it (rich table, JSON)."""

from __future__ import annotations

import json
import platform
from pathlib import Path

from rich.console import Console
from rich.table import Table

from ardrone_nmpc.experiments.bench import BenchRow, bench_ipopt, bench_nmpc
from ardrone_nmpc.control.solver import make_nmpc
from ardrone_nmpc.control.ocp import OcpSpec


def run_bench_command(*, cfg, solvers: list[str], steps: int, compare_casadi: bool,
                      json_path: Path | None, repeats: int = 5,
                      console: Console | None = None) -> list[BenchRow]:
    """Benchmark each solver named in ``solvers`` (and IPOPT) on ``cfg``'s OCP."""
    console = console or Console(width=None if _is_tty() else 150)
    period_s = cfg.loop.period_s
    rows: list[BenchRow] = []
    with console.status("benchmarking…") as status:
        for name in solvers:
            status.update(f"{name}: JIT warm-up and {repeats}× {steps} closed-loop ticks…")
            controller = cfg.controller.model_copy(
                update={"solver": cfg.controller.solver.model_copy(update={"method": name})})
            rows.append(bench_nmpc(lambda: make_nmpc(controller, period_s=period_s),
                                   steps=steps, repeats=repeats))
        if compare_casadi:
            status.update(f"ipopt: {steps} closed-loop ticks (slow)…")
            rows.append(bench_ipopt(OcpSpec.from_config(cfg.controller), steps=steps,
                                    period_s=period_s))
    console.print(render_table(rows))
    ipopt = next((r for r in rows if r.solver == "ipopt"), None)
    if ipopt is not None:
        for row in rows:
            if row is not ipopt:
                console.print(f"{row.solver}: {ipopt.mean_us / row.mean_us:,.0f}× faster than "
                              f"IPOPT (mean); closed-loop cost {row.closed_loop_cost / ipopt.closed_loop_cost:.4f}× IPOPT's")
    if json_path is not None:
        payload = {"machine": platform.machine(), "python": platform.python_version(),
                   "repeats": repeats, "timing": "per-tick minimum over identical repeats",
                   "rows": [r.to_json() for r in rows]}
        if ipopt is not None:
            payload["vs_ipopt"] = {r.solver: {"time_ratio": ipopt.mean_us / r.mean_us,
                                              "cost_ratio": r.closed_loop_cost / ipopt.closed_loop_cost}
                                   for r in rows if r is not ipopt}
        json_path.write_text(json.dumps(payload, indent=2) + "\n")
        console.print(f"wrote {json_path}")
    return rows


def _is_tty() -> bool:
    import sys

    return sys.stdout.isatty()


def render_table(rows: list[BenchRow]) -> Table:
    table = Table(title="closed-loop NMPC timing (µs per tick; each tick's best of the repeats)",
                  caption="update: the solver's own solve (kernel + dispatch), as SolveResult."
                  "solve_time_us reports it; call: the whole solve() call the tick pays")
    for col in ("solver", "N", "kmax", "ticks", "update mean", "p50", "p99", "max",
                "call mean", "call p99", "‖F‖ mean", "‖F‖ max", "cost", "failures"):
        table.add_column(col, justify="left" if col == "solver" else "right")
    for r in rows:
        res = "–" if r.residual_mean != r.residual_mean else f"{r.residual_mean:.3g}"
        resmax = "–" if r.residual_max != r.residual_max else f"{r.residual_max:.3g}"
        table.add_row(r.solver, str(r.horizon_steps), str(r.kmax or "–"), str(r.steps),
                      f"{r.mean_us:.1f}", f"{r.p50_us:.1f}", f"{r.p99_us:.1f}", f"{r.max_us:.0f}",
                      f"{r.call_mean_us:.1f}", f"{r.call_p99_us:.1f}",
                      res, resmax, f"{r.closed_loop_cost:.4f}", str(r.failures))
    return table
