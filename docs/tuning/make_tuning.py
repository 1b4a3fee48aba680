"""Figures and tables of docs/tuning.md that `ardrone-nmpc plot` does not draw.

Reads the sweep directories written by the `ardrone-nmpc sweep` commands of docs/tuning.md
(all under one directory, default /tmp/tuning) and

* draws ``r_cases.png`` (x(t) and the pitch command of the three r cases, both formulations)
  and ``ndtau_horizon.png`` (rmse_m against the horizon length N·Δτ, one line per N);
* prints the Markdown tables of docs/tuning.md (from each sweep.csv, plus the run directories'
  summary.csv / log.csv where a column says so).

    python docs/tuning/make_tuning.py [SWEEPS_DIR] [--out docs/tuning] [--dpi 90]

Needs matplotlib (the tool's 'plot' extra). Deterministic: the simulations are.
"""
from __future__ import annotations

import argparse
import csv
import math
from pathlib import Path

import numpy as np

from ardrone_nmpc.runs.rundir import read_run

N_VALUES = [3, 4, 5, 6, 8, 10, 15, 20]
DTAU_VALUES = [0.05, 0.08, 0.1, 0.15, 0.2, 0.3, 0.4]
R_CASES = [("Case 1", "[10,30,30,60]"), ("Case 2", "[4,12,12,24]"), ("Case 3", "[1,3,3,6]")]
FACTORS = ["×0.25", "×0.5", "×1", "×2", "×4"]
FORMULATIONS = [("thesis", "thesis formulation (delay-free, navdata ẋ/ẏ)"),
                ("ours", "tool defaults (delay-compensated, mocap ẋ/ẏ)")]
TILT_LIMIT_RAD = 0.2094  # the drone's 12° euler_angle_max: the pitch command's effective bound


# ----------------------------------------------------------------------------- reading


def read_sweep(path: Path) -> list[dict[str, str]]:
    with open(path / "sweep.csv", newline="") as f:
        return list(csv.DictReader(f))


def num(row: dict[str, str], key: str) -> float:
    try:
        return float(row[key])
    except (KeyError, ValueError):
        return math.nan


def summary(run_dir: Path) -> dict[tuple[str, str], float]:
    with open(run_dir / "summary.csv", newline="") as f:
        return {(r["axis"], r["metric"]): float(r["value"]) for r in csv.DictReader(f)}


def track(run_dir: Path) -> dict[str, np.ndarray]:
    """The experiment window (t ≥ 0) of a run's log, plant truth where logged."""
    cols = read_run(run_dir).columns
    keep = cols["t_s"] >= 0.0
    out = {k: cols[k][keep] for k in ("t_s", "x_ref_m", "y_ref_m", "z_ref_m", "u_theta_rad",
                                      "u_zacc_mps2")}
    for axis in "xyz":
        truth = cols[f"{axis}_true_m"][keep]
        out[axis] = np.where(np.isfinite(truth), truth, cols[f"{axis}_m"][keep])
    return out


def tail_peaks(run_dir: Path) -> tuple[float, float]:
    """Largest |x − x_ref| and |z − z_ref| (m) over the last 25 % of the experiment window
    (the window of the sweep's status rule, split by axis)."""
    tr = track(run_dir)
    t = tr["t_s"]
    tail = t >= t[-1] - 0.25 * (t[-1] - t[0])
    ex = np.abs(tr["x"] - tr["x_ref_m"])[tail]
    ez = np.abs(tr["z"] - tr["z_ref_m"])[tail]
    return float(np.nanmax(ex, initial=math.nan)), float(np.nanmax(ez, initial=math.nan))


def rise_full(tr: dict[str, np.ndarray], x0: float, x1: float) -> tuple[float, float]:
    """(10→90 % rise time over the whole window t ≥ 0, fraction of the step done at the step
    time). The NMPC sees the step N·Δτ ahead and starts before it; the summary's rise time
    only counts samples after the step time."""
    t, s = tr["t_s"], (tr["x"] - x0) / (x1 - x0)
    step_t = float(t[np.argmax(tr["x_ref_m"] != tr["x_ref_m"][0])])
    done = float(np.interp(step_t, t, s))
    k10 = int(np.argmax(s >= 0.1))
    k90 = k10 + int(np.argmax(s[k10:] >= 0.9))
    if s[k10] < 0.1 or s[k90] < 0.9:
        return math.nan, done
    return float(t[k90] - t[k10]), done


# ----------------------------------------------------------------------------- formatting


def f(value: float, digits: int = 3) -> str:
    return "—" if not math.isfinite(value) else f"{value:.{digits}g}"


def md_table(header: list[str], rows: list[list[str]], align: str = "r") -> str:
    lines = ["| " + " | ".join(header) + " |",
             "|" + "|".join([":--"] + [f"{'--:' if align == 'r' else ':-:'}"] * (len(header) - 1))
             + "|"]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(lines)


def grid(rows: list[dict[str, str]], kx: str, ky: str) -> dict[tuple[str, str], dict[str, str]]:
    return {(r[ky], r[kx]): r for r in rows}


# ----------------------------------------------------------------------------- studies


def table_ndtau(root: Path, form: str) -> str:
    rows = read_sweep(root / f"ndtau_{form}")
    g = {(int(r["controller.horizon_steps"]), float(r["controller.dtau_s"])): r for r in rows}
    out = []
    for n in N_VALUES:
        cells = [f"**{n}**"]
        for d in DTAU_VALUES:
            r = g[(n, d)]
            cell = f"{f(num(r, 'rmse_m'), 2)} / {f(num(r, 'settling_s'), 2)}"
            if r["status"] != "ok":
                cell += " ✘"
            cells.append(cell)
        out.append(cells)
    return md_table(["N \\ Δτ (s)"] + [f"{d:g}" for d in DTAU_VALUES], out)


def table_ndtau_tails(root: Path, form: str) -> str:
    rows = read_sweep(root / f"ndtau_{form}")
    g = {(int(r["controller.horizon_steps"]), float(r["controller.dtau_s"])): r for r in rows}
    out = []
    for n in N_VALUES:
        cells = [f"**{n}**"]
        for d in DTAU_VALUES:
            r = g[(n, d)]
            if "aborted" in r["message"]:  # landed by the supervisor: no reference after it
                cells.append("aborted")
                continue
            ex, ez = tail_peaks(root / f"ndtau_{form}" / r["run_dir"])
            cells.append(f"{ex:.2f} / {ez:.2f}")
        out.append(cells)
    return md_table(["N \\ Δτ (s)"] + [f"{d:g}" for d in DTAU_VALUES], out)


def table_r_cases(root: Path) -> str:
    out = []
    for form, _ in FORMULATIONS:
        rows = {r["controller.r"]: r for r in read_sweep(root / f"rcases_{form}")}
        for name, r_vec in R_CASES:
            r = rows[r_vec]
            run = root / f"rcases_{form}" / r["run_dir"]
            s = summary(run)
            tr = track(run)
            rise, done = rise_full(tr, 0.0, -1.5)
            at_limit = float(np.mean(np.abs(tr["u_theta_rad"]) >= 0.995 * TILT_LIMIT_RAD)) * 100
            out.append([form, f"{name} r={r_vec}", f(rise, 2), f(s[("x", "rise_time")], 2),
                        f"{done * 100:.0f} %",
                        f(num(r, "settling_s"), 3), f(num(r, "overshoot_pct"), 3),
                        f(s[("x", "rmse")], 3), f(s[("u_theta", "peak_abs")], 3),
                        f"{at_limit:.1f} %", f(s[("u_zacc", "peak_abs")], 2),
                        r["status"]])
    return md_table(["formulation", "case", "rise 10–90 % (s)", "summary rise (s)",
                     "done at step time", "settling (s)", "overshoot (%)", "x RMSE (m)",
                     "peak abs(θ) (rad)", "ticks at tilt limit", "peak abs(z̈) (m/s²)",
                     "status"], out)


def table_qr(root: Path, form: str) -> str:
    rows = read_sweep(root / f"qr_{form}")
    qs = list(dict.fromkeys(r["controller.q"] for r in rows))
    rs = list(dict.fromkeys(r["controller.r"] for r in rows))
    g = grid(rows, "controller.r", "controller.q")
    out = []
    for fq, q in zip(FACTORS, qs):
        cells = [f"**q_pos {fq}** {q}"]
        for r_vec in rs:
            r = g[(q, r_vec)]
            cell = (f"{f(num(r, 'rmse_m'), 3)} / {f(num(r, 'overshoot_pct'), 2)} / "
                    f"{f(num(r, 'settling_s'), 2)}")
            if r["status"] != "ok":
                cell += " ✘"
            cells.append(cell)
        out.append(cells)
    return md_table(["q \\ r"] + [f"**r {fr}** {r_vec}" for fr, r_vec in zip(FACTORS, rs)], out)


# ----------------------------------------------------------------------------- figures


def figure_r_cases(root: Path, out: Path, dpi: int) -> Path:
    from matplotlib.figure import Figure

    fig = Figure(figsize=(9.5, 5.3), layout="constrained")
    axes = fig.subplots(2, 2, sharex=True, height_ratios=[2, 1])
    colours = ["tab:blue", "tab:orange", "tab:green"]
    for col, (form, label) in enumerate(FORMULATIONS):
        rows = {r["controller.r"]: r for r in read_sweep(root / f"rcases_{form}")}
        ax_x, ax_u = axes[0, col], axes[1, col]
        for (name, r_vec), c in zip(R_CASES, colours):
            tr = track(root / f"rcases_{form}" / rows[r_vec]["run_dir"])
            ax_x.plot(tr["t_s"], tr["x"], color=c, lw=1.4, label=f"{name} r={r_vec}")
            ax_u.plot(tr["t_s"], tr["u_theta_rad"], color=c, lw=1.0)
        ax_x.plot(tr["t_s"], tr["x_ref_m"], "k--", lw=1.0, label="reference")
        ax_x.axhspan(-1.53, -1.47, color="grey", alpha=0.15, lw=0, label="±2 % band")
        for lim in (-TILT_LIMIT_RAD, TILT_LIMIT_RAD):
            ax_u.axhline(lim, color="grey", ls=":", lw=1.0)
        ax_x.set_title(label, fontsize=10)
        ax_x.set_ylabel("x (m)")
        ax_u.set_ylabel("θ command (rad)")
        ax_u.set_xlabel("t (s), step at 1 s")
        ax_x.set_xlim(0, 15)
        ax_x.set_ylim(-2.25, 0.3)
        ax_x.grid(alpha=0.3)
        ax_u.grid(alpha=0.3)
    axes[0, 0].legend(loc="upper right", fontsize=8)
    axes[1, 0].text(0.99, 0.04, "dotted: the drone's ±12° tilt limit", fontsize=8,
                    ha="right", transform=axes[1, 0].transAxes)
    fig.suptitle("x step 0 → −1.5 m (step_x, 30 s): thesis r cases 1–3", fontsize=11)
    path = out / "r_cases.png"
    fig.savefig(path, dpi=dpi)
    return path


def figure_horizon(root: Path, out: Path, dpi: int) -> Path:
    from matplotlib import colormaps
    from matplotlib.figure import Figure
    from matplotlib.ticker import NullFormatter

    fig = Figure(figsize=(11, 4.6), layout="constrained")
    axes = fig.subplots(1, 2, sharey=True)
    cmap = colormaps["viridis"]
    for ax, (form, label) in zip(axes, FORMULATIONS):
        rows = read_sweep(root / f"ndtau_{form}")
        for i, n in enumerate(N_VALUES):
            c = cmap(i / (len(N_VALUES) - 1))
            pts = sorted((n * float(r["controller.dtau_s"]), num(r, "rmse_m"), r["status"])
                         for r in rows if int(r["controller.horizon_steps"]) == n)
            T = [p[0] for p in pts]
            ax.plot(T, [p[1] for p in pts], "-", color=c, lw=1.0, label=f"N = {n}")
            ok = [p for p in pts if p[2] == "ok"]
            bad = [p for p in pts if p[2] != "ok"]
            ax.plot([p[0] for p in ok], [p[1] for p in ok], "o", color=c, ms=4)
            ax.plot([p[0] for p in bad], [p[1] for p in bad], "x", color="red", ms=8, mew=2)
        ax.set_xscale("log")
        ax.set_xticks([0.15, 0.25, 0.4, 0.6, 1, 1.5, 2.5, 4, 8])
        ax.set_xticklabels(["0.15", "0.25", "0.4", "0.6", "1", "1.5", "2.5", "4", "8"])
        ax.xaxis.set_minor_formatter(NullFormatter())
        ax.set_xlabel("horizon length N·Δτ (s)")
        ax.set_title(label, fontsize=10)
        ax.grid(alpha=0.3, which="both")
    axes[0].set_ylabel("rmse_m (3-D, whole run)")
    axes[0].plot([], [], "x", color="red", ms=8, mew=2, label="unstable (sweep rule)")
    axes[0].legend(fontsize=8, ncol=2)
    fig.suptitle("N × Δτ on step_x: RMSE against the horizon length", fontsize=11)
    path = out / "ndtau_horizon.png"
    fig.savefig(path, dpi=dpi)
    return path


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("sweeps", nargs="?", default="/tmp/tuning", type=Path)
    ap.add_argument("--out", default=Path(__file__).resolve().parent, type=Path)
    ap.add_argument("--dpi", default=90, type=int)
    a = ap.parse_args()
    a.out.mkdir(parents=True, exist_ok=True)
    for path in (figure_r_cases(a.sweeps, a.out, a.dpi), figure_horizon(a.sweeps, a.out, a.dpi)):
        print(f"plot: {path}")
    for form, label in FORMULATIONS:
        print(f"\n### N × Δτ, {label}: rmse_m / settling_s (✘ unstable)\n")
        print(table_ndtau(a.sweeps, form))
    print("\n### N × Δτ, thesis formulation: last-25 % peak |x − x_ref| / |z − z_ref| (m)\n")
    print(table_ndtau_tails(a.sweeps, "thesis"))
    print("\n### N × Δτ, tool defaults: last-25 % peak |x − x_ref| / |z − z_ref| (m)\n")
    print(table_ndtau_tails(a.sweeps, "ours"))
    print("\n### r cases\n")
    print(table_r_cases(a.sweeps))
    for form, label in FORMULATIONS:
        print(f"\n### q/r, {label}: rmse_m / overshoot_pct / settling_s (✘ unstable)\n")
        print(table_qr(a.sweeps, form))


if __name__ == "__main__":
    main()
