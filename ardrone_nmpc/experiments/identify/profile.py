"""An identification as a whole: every channel fitted, its report lines, and the plant
profile file (``sim.plant.profile: PLANT.yaml``; docs/plant-profiles.md §5) it becomes."""

from __future__ import annotations

import datetime as _dt
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import yaml

from ardrone_nmpc.core.types import GRAVITY_MPS2
from ardrone_nmpc.experiments.identify.channels import (fit_attitude, fit_velocity, fit_vertical,
                                                        fit_yaw)
from ardrone_nmpc.experiments.identify.data import Flight
from ardrone_nmpc.experiments.identify.fit import FitResult

__all__ = ["Identification", "identify", "profile_data", "write_profile"]

#: The plant's integration step bounds its time constants from below (sim.plant).
_MIN_TAU_S = 0.005


@dataclass
class Identification:
    """The fitted channels of some flights (their names)."""

    runs: list[str]
    attitude: FitResult
    velocity: FitResult
    vertical: FitResult
    yaw: FitResult

    def lines(self) -> list[str]:
        """One line per parameter, then the held-out fit per channel."""
        out = [p.line() for c in (self.attitude, self.velocity, self.vertical, self.yaw)
               for p in c.params.values()]
        out += self.attitude.notes
        for name, c in (("attitude", self.attitude), ("velocity", self.velocity),
                        ("vertical", self.vertical), ("yaw", self.yaw)):
            out.append(f"held-out fit, {name}: "
                       + " / ".join(f"{v:.1f} %" for v in c.held_out_fit_pct))
        return out

    @property
    def drag_per_s(self) -> tuple[float, float]:
        """The two axes' drag poles, weighted by their precision, and its σ."""
        f, l = self.velocity.params["drag_forward"], self.velocity.params["drag_left"]
        w = [1.0 / max(p.std, 1e-9) ** 2 for p in (f, l)]
        return (w[0] * f.value + w[1] * l.value) / sum(w), 1.0 / math.sqrt(sum(w))


def identify(flights: Sequence[Flight]) -> Identification:
    """Fit every channel of ``flights`` (the attitude first: its delay serves the others)."""
    attitude = fit_attitude(flights)
    delay = attitude.params["delay"].value
    return Identification([f.name for f in flights], attitude, fit_velocity(flights),
                          fit_vertical(flights, delay), fit_yaw(flights, delay))


def profile_data(ident: Identification) -> dict:
    """The profile file's mapping (``plant:`` keys of sim.plant, ``vz_gain``)."""
    a = ident.attitude.params
    plant = {"command_delay_s": round(a["delay"].value, 4),
             "attitude_gain": [round(a["roll_gain"].value, 4), round(a["pitch_gain"].value, 4)],
             "attitude_model": ident.attitude.model}
    if ident.attitude.model == "second_order":
        plant.update(attitude_wn_radps=round(a["wn"].value, 4),
                     attitude_damping=round(a["zeta"].value, 4),
                     attitude_zero_s=round(a["zero"].value, 4))
    else:
        plant["tau_tilt_s"] = round(max(a["lag"].value, _MIN_TAU_S), 4)
    plant["drag_per_s"] = round(ident.drag_per_s[0], 4)
    plant["tau_vz_s"] = round(max(ident.vertical.params["tau"].value, _MIN_TAU_S), 4)
    plant["yaw_gain"] = round(ident.yaw.params["gain"].value, 4)
    plant["tau_yaw_s"] = round(max(ident.yaw.params["tau"].value, _MIN_TAU_S), 4)
    return {"plant": plant, "vz_gain": round(ident.vertical.params["gain"].value, 4)}


def write_profile(ident: Identification, path: str | Path, *, command: str = "") -> Path:
    """Write the profile file: the fit's report as comments, then its values."""
    path = Path(path)
    when = _dt.datetime.now().astimezone().isoformat(timespec="seconds")
    notes = [f"plant profile identified {when} from {', '.join(ident.runs)}"]
    if command:
        notes.append(command)
    notes.append("(use it as --set sim.plant.profile=<this file>; docs/identification.md)")
    g_f = ident.velocity.params["accel_forward"].value / GRAVITY_MPS2
    notes.append(f"the acceleration per unit tan(tilt) is {g_f:.2f} g forward; the simulator "
                 "takes g")
    body = yaml.safe_dump(profile_data(ident), sort_keys=False, default_flow_style=None)
    text = "".join(f"# {line}\n" for line in [*notes, "", *ident.lines()]) + body
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text, encoding="utf-8")
    return path
