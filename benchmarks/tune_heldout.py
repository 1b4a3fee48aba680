"""Configs flown on held-out seeds: the numbers docs/tuning.md §4 compares.

``python benchmarks/tune_heldout.py CONFIG... [--seeds 100,101,102,103,104] [--set path=value]
[--plant-profile P]``
flies each config in lockstep on each seed (seeds a ``tune`` run did not fly: it flies
``sim.seed`` … ``sim.seed + 2`` by default) and prints one Markdown row per config: for a step
the stepped axis' settling time (2 % band) and overshoot, mean and worst over the seeds; for a
path experiment the mean path deviation and the 3-D RMSE. Flights are recorded in memory.
``--plant-profile P`` replaces each config's ``sim.plant`` section by ``{profile: P}``: a
``best.yaml`` (or any resolved config) states every plant value of the profile it was tuned
on, which would otherwise win over P's defaults.
"""

from __future__ import annotations

import argparse
import math

import numpy as np


def _flight(cfg, seed: int) -> dict[tuple[str, str], float]:
    from ardrone_nmpc.runs.memory import MemoryRecorder
    from ardrone_nmpc.runs.summary import summarise
    from ardrone_nmpc.runtime.lockstep import run_lockstep

    cfg = cfg.model_copy(update={"sim": cfg.sim.model_copy(update={"seed": seed})})
    recorder = MemoryRecorder()
    result = run_lockstep(cfg, recorder=recorder)
    rows = summarise(recorder.run_data(cfg, seed=seed))
    values = {(r.axis, r.metric): r.value for r in rows}
    values[("run", "completed")] = float(result.ending == "completed")
    return values


def _stat(values: list[float], unit: str, digits: int = 2) -> str:
    if any(math.isnan(v) for v in values):
        return "never (some seed)"
    return f"{np.mean(values):.{digits}f} {unit} (worst {max(values):.{digits}f})"


def _load(path: str, overrides: list[str], profile: str | None):
    """``path`` loaded as ``load_config`` loads a run's config (retired keys dropped), its
    ``sim.plant`` replaced by ``{profile: P}`` when a profile is given."""
    from pathlib import Path

    from ardrone_nmpc.config.io import (_path_file, _read_yaml, _retire, apply_overrides,
                                        load_config)
    from ardrone_nmpc.config.schema import config_from_dict

    if profile is None:
        return load_config(path, overrides, allow_retired=True)
    data = _read_yaml(Path(path))
    _path_file(data, Path(path).parent)
    _retire(data, drop=True)
    data.setdefault("sim", {})["plant"] = {"profile": profile}
    return config_from_dict(apply_overrides(data, overrides))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("configs", nargs="+")
    parser.add_argument("--seeds", default="100,101,102,103,104")
    parser.add_argument("--set", dest="overrides", action="append", default=[])
    parser.add_argument("--plant-profile", default=None)
    args = parser.parse_args()
    seeds = [int(s) for s in args.seeds.split(",")]
    print(f"| config | seeds {seeds[0]}–{seeds[-1]} | | completed |")
    print("|:--|--:|--:|--:|")
    for path in args.configs:
        cfg = _load(path, args.overrides, args.plant_profile)
        flights = [_flight(cfg, s) for s in seeds]
        done = sum(int(f[("run", "completed")]) for f in flights)
        ref = cfg.reference
        if ref.kind == "step":
            cells = []
            for axis in ref.stepped_axes:
                settle = [f[(axis, "settling_time")] for f in flights]
                over = [f[(axis, "overshoot")] for f in flights]
                cells.append(f"{axis} settling {_stat(settle, 's')}; overshoot {_stat(over, '%', 1)}")
            print(f"| `{path}` | {' / '.join(cells)} | | {done}/{len(seeds)} |")
        else:
            dev = [f[("path", "mean_deviation")] for f in flights]
            rmse = [f[("xyz", "rmse")] for f in flights]
            print(f"| `{path}` | path deviation {_stat(dev, 'm', 3)} | 3-D RMSE "
                  f"{_stat(rmse, 'm', 3)} | {done}/{len(seeds)} |")


if __name__ == "__main__":
    main()
