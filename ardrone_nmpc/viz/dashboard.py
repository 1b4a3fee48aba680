"""Live flight dashboard (rich): rendered by rich's own refresh thread at ~4 Hz, so the
control loop only hands over a dict of the latest figures. It also shows the operator's keys
and any foreign mocap sender (ignored, but worth a look: a stale replay, a second tracker)."""

from __future__ import annotations

import math

from rich.table import Table

from ardrone_nmpc.runtime.operator_input import KEYS_HELP


class LiveStatus:
    """``update(figures)`` from the control loop; rich calls ``__rich__`` to draw."""

    def __init__(self, title: str, keys_help: str | None = KEYS_HELP):
        self.title = title
        self.keys_help = keys_help
        self._figures: dict = {}

    def update(self, figures: dict) -> None:
        self._figures = figures  # one reference swap: safe to read from the render thread

    def __rich__(self) -> Table:
        f = self._figures
        table = Table(title=self.title, show_header=False, min_width=60,
                      caption=self.keys_help)
        table.add_column(style="bold")
        table.add_column(justify="right")
        if not f:
            table.add_row("status", "connecting…")
            return table
        num = lambda key, fmt="{:.3f}": "—" if not isinstance(f.get(key), (int, float)) or \
            not math.isfinite(f.get(key)) else fmt.format(f[key])
        table.add_row("t / mode", f"{num('t_s', '{:.1f}')} s  {f.get('mode', '')}")
        for axis, unit in (("x", "m"), ("y", "m"), ("z", "m")):
            table.add_row(f"{axis} / ref", f"{num(axis + '_m')} / {num(axis + '_ref_m')} {unit}")
        table.add_row("ψ / ref", f"{num('psi_rad')} / {num('psi_ref_rad')} rad")
        table.add_row("PCMD roll pitch gaz yaw",
                      " ".join(num(c, "{:+.2f}") for c in ("cmd_roll_frac", "cmd_pitch_frac",
                                                           "cmd_gaz_frac", "cmd_yaw_frac")))
        table.add_row("solver", f"{f.get('solver_status', '')} {num('solve_us', '{:.0f}')} µs")
        table.add_row("mocap / navdata", f"{num('mocap_rate_hz', '{:.0f}')} Hz "
                      f"({num('mocap_age_ms', '{:.0f}')} ms) / {num('navdata_rate_hz', '{:.0f}')} Hz "
                      f"({num('navdata_age_ms', '{:.0f}')} ms)")
        table.add_row("battery / overruns", f"{num('battery_pct', '{:.0f}')} % / {f.get('overruns', 0)}")
        ctrl = f.get("nav_ctrl_state")
        table.add_row("drone mode / ctrl_state", f"{f.get('nav_mode', '')} / " + (
            f"0x{int(ctrl):08x}" if isinstance(ctrl, (int, float)) and math.isfinite(ctrl)
            else "—"))
        table.add_row("mocap sender", str(f.get("mocap_sender") or "—"))
        foreign = f.get("mocap_foreign") or {}
        if foreign:
            table.add_row("[bold red]IGNORED mocap senders[/]", ", ".join(
                f"{name} ({count})" for name, count in foreign.items()))
        table.add_row("progress", f"{100 * f.get('progress', 0):.0f} %")
        return table
