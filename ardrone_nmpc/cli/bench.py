"""``ardrone-nmpc bench``: run :mod:`ardrone_nmpc.experiments.bench` and present it (rich table, JSON)."""

from __future__ import annotations

import json
import platform
from pathlib import Path

from rich.console import Console
from rich.table import Table

from ardrone_nmpc.cli.console import stdout_console
from ardrone_nmpc.cli.narrow import fit
from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.control.solver import make_nmpc
from ardrone_nmpc.control.ocp import OcpSpec
from ardrone_nmpc.errors import UserError
from ardrone_nmpc.experiments.bench import BenchRow, bench_ipopt, bench_nmpc

SOLVERS = ("cgmres", "newton")


class BenchUsageError(UserError):
    """A --solvers or --compare value that cannot work (exit 1)."""


def bench_command(*, config: Path | None, overrides: list[str], horizon_steps: int | None,
                  kmax: int | None, steps: int, repeats: int, solvers: str,
                  compare: str | None, json_path: Path | None) -> list[BenchRow]:
    """The ``bench`` command: check the options, load the config, run the benchmark."""
    overrides = list(overrides)
    if horizon_steps is not None:
        overrides.append(f"controller.horizon_steps={horizon_steps}")
    if kmax is not None:
        overrides.append(f"controller.solver.kmax={kmax}")
    names = [s.strip() for s in solvers.split(",") if s.strip()]
    bad = [s for s in names if s not in SOLVERS]
    if bad or not names:
        raise BenchUsageError(f"--solvers: unknown solver(s) {', '.join(bad) or '(none)'}; "
                              f"choose {', '.join(SOLVERS)}")
    if compare not in (None, "casadi"):
        raise BenchUsageError(f"--compare: unknown comparison {compare!r}; the only one is "
                              "'casadi'")
    cfg = load_config(config, overrides)
    if compare == "casadi":
        import importlib.util

        if importlib.util.find_spec("casadi") is None:
            raise BenchUsageError("--compare casadi: CasADi is not installed: "
                                  "pip install -e '.[compare]'")
        if cfg.controller.obstacles:
            raise BenchUsageError("--compare casadi: the IPOPT comparison models no "
                                  "obstacles; remove controller.obstacles")
    return run_bench_command(cfg=cfg, solvers=names, steps=steps,
                             compare_casadi=compare == "casadi", json_path=json_path,
                             repeats=repeats)


def run_bench_command(*, cfg, solvers: list[str], steps: int, compare_casadi: bool,
                      json_path: Path | None, repeats: int = 5,
                      console: Console | None = None) -> list[BenchRow]:
    """Benchmark each solver named in ``solvers`` (and IPOPT) on ``cfg``'s OCP."""
    console = console or stdout_console()
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
    console.print(fit(render_table(rows), console))
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
        json_path.parent.mkdir(parents=True, exist_ok=True)
        json_path.write_text(json.dumps(payload, indent=2) + "\n")
        console.print(f"wrote {json_path}")
    return rows


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
