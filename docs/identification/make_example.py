"""The worked example of docs/identification.md, regenerated: ``python docs/identification/make_example.py``.

Flies configs/identify.yaml against the test emulator (tests/standins/airframe_emulator.py,
a drone of the Simulink kit's form: 0.15 s delay, tilt gains 1.3 / 1.8, drag 0.5 1/s,
vertical gain 0.8), identifies it, and flies a 1 m x step on the same drone, in simulation
with the identified profile and with the default one. Writes the figures next to this file
and prints the numbers the page quotes.
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
sys.path.insert(0, str(ROOT))

from ardrone_nmpc.config.io import load_config  # noqa: E402
from ardrone_nmpc.experiments.identify.data import read_flight  # noqa: E402
from ardrone_nmpc.experiments.identify.fit import simulate  # noqa: E402
from ardrone_nmpc.experiments.identify.profile import identify, write_profile  # noqa: E402
from ardrone_nmpc.experiments.record import record_lockstep  # noqa: E402
from ardrone_nmpc.runs.memory import MemoryRecorder  # noqa: E402
from ardrone_nmpc.runtime.lockstep import run_lockstep  # noqa: E402
from ardrone_nmpc.viz.figure import new_figure, save_figure  # noqa: E402
from tests.standins.airframe_emulator import AirframeEmulator  # noqa: E402

DRONE = dict(command_delay_s=0.15, attitude_gain=(1.3, 1.8), attitude_lag_s=None,
             vz_gain=0.8, drag_per_s=0.5)


def _step(plant=None, *overrides):
    cfg = load_config(ROOT / "configs" / "step_x.yaml",
                      ["reference.target_m=[-1.0, 0.0, 1.0]", *overrides])
    rec = MemoryRecorder()
    run_lockstep(cfg, recorder=rec, plant=plant)
    c = rec.run_data(cfg, seed=0).columns
    keep = c["t_s"] >= 0
    return c["t_s"][keep], c["x_true_m"][keep]


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        rec = record_lockstep(load_config(ROOT / "configs" / "identify.yaml"), tmp,
                              plant=AirframeEmulator(**DRONE, seed=3))
        flight = read_flight(rec.path)
        ident = identify([flight])
        profile = write_profile(ident, Path(tmp) / "drone.yaml",
                                command="ardrone-nmpc identify <run> -o drone.yaml")
        print("\n".join(ident.lines()))
        # the attitude fit against the navdata
        p = ident.attitude.params
        num, den = (([p["wn"].value ** 2 * p["zero"].value, p["wn"].value ** 2],
                     [1.0, 2 * p["zeta"].value * p["wn"].value, p["wn"].value ** 2])
                    if ident.attitude.model == "second_order" else ([1.0], [p["lag"].value, 1.0]))
        fig = new_figure(9.0, 4.5)
        axes = fig.subplots(2, 1, sharex=True)
        e = flight.euler_angle_max_rad
        for ax, a, name in ((axes[0], 1, "pitch"), (axes[1], 0, "roll")):
            model = p[f"{name}_gain"].value * simulate(num, den, flight.t_cmd,
                                                       flight.cmd[:, a] * e, flight.t_nav,
                                                       p["delay"].value)
            offset = np.mean(flight.nav_tilt_rad[:, a] - model)
            ax.plot(flight.t_nav, np.degrees(flight.nav_tilt_rad[:, a]), ".", ms=2,
                    color="0.4", label="navdata")
            ax.plot(flight.t_nav, np.degrees(model + offset), lw=1, label="identified model")
            ax.set_ylabel(f"{name} (°)")
            ax.legend(loc="upper right", fontsize=8)
        axes[1].set_xlabel("t (s)")
        axes[0].set_title("identification flight: the attitude the drone reported and the fit")
        save_figure(fig, HERE / "attitude-fit.png", dpi=80)
        # the prediction of another flight
        t, x_real = _step(AirframeEmulator(**DRONE, seed=11))
        fig = new_figure(9.0, 3.5)
        ax = fig.subplots()
        ax.plot(t, x_real, "k", lw=2, label="the drone (emulator)")
        for label, ov in (("simulate, identified profile", [f"sim.plant.profile={profile}"]),
                          ("simulate, default profile", [])):
            ts, xs = _step(None, *ov)
            xs = np.interp(t, ts, xs)
            gap = float(np.sqrt(np.mean((xs - x_real) ** 2)))
            ax.plot(t, xs, lw=1, label=f"{label} (RMS gap {gap * 100:.1f} cm)")
            print(f"{label}: x RMS gap {gap * 100:.2f} cm")
        ax.set_xlabel("t (s)")
        ax.set_ylabel("x (m)")
        ax.set_title("a 1 m x step on the same drone, and what simulate predicts")
        ax.legend(fontsize=8)
        save_figure(fig, HERE / "prediction.png", dpi=80)
        print(profile.read_text(encoding="utf-8").split("plant:")[1].strip())


if __name__ == "__main__":
    main()
