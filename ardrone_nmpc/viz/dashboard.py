"""Live flight dashboard (rich): rendered by rich's own refresh thread at ~4 Hz, so the
control loop only hands over a dict of the latest figures."""

from __future__ import annotations

import math

from rich.table import Table


class LiveStatus:
    """``update(figures)`` from the control loop; rich calls ``__rich__`` to draw."""

    def __init__(self, title: str):
        self.title = title
        self._figures: dict = {}

    def update(self, figures: dict) -> None:
        self._figures = figures  # one reference swap: safe to read from the render thread

    def __rich__(self) -> Table:
        f = self._figures
        table = Table(title=self.title, show_header=False, min_width=60)
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
        table.add_row("progress", f"{100 * f.get('progress', 0):.0f} %")
        return table
