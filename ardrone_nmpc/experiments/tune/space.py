"""The search space of ``tune``: which config values a trial may change, and within what.

Default space: each weight of ``controller.q`` (7) and ``controller.r`` (4), log-uniform
within ×0.1…×10 of the config's value (a zero state weight stays zero: there is nothing to
scale). For a step only the weights that shape the stepped axes' response are searched
(:data:`STEP_WEIGHTS`: the axis' position and velocity weights and the input that moves it);
the others keep the config's values — 40 trials in 3 dimensions find what 40 in 11 miss
(docs/tuning.md §4). Parameter names are dotted config paths, ``[i]`` for an element of a
vector: ``controller.q[4]``.

A space file (YAML) replaces or extends it::

    default: true                  # keep the q/r space above (default true)
    factor: 10                     # its range: ×1/factor … ×factor (default 10)
    params:
      controller.horizon_steps: {low: 8, high: 30, type: int}
      controller.dtau_s: {low: 0.05, high: 0.2, log: true}
      controller.delay_compensation_s: {low: 0.15, high: 0.35}
      estimator.kalman_q: {factor: 10}       # log-uniform ×0.1…×10 of the config's value
      controller.q_terminal: {factor: 5}     # a vector: one parameter per (non-zero) element
      controller.q[4]: {low: 10, high: 500, log: true}   # overrides the default entry

``low``/``high`` bound a parameter (``log: true`` samples log-uniformly; needs low > 0);
``factor`` centres a log range on the config's value. ``type`` is ``float`` (default) or
``int``. Every path must name a numeric config value; mistakes fail before anything flies,
one ``--space FILE: params.<path>: message`` line each. The ``safety`` section is never
searched: a trial that loosened a limit would be scored by flying past what the supervisor is
there to stop.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ardrone_nmpc.config.io import config_to_dict
from ardrone_nmpc.config.schema import ConfigError

__all__ = ["DEFAULT_FACTOR", "STEP_WEIGHTS", "Param", "apply_params", "config_with",
           "default_space", "load_space", "parse_space", "written_config"]

DEFAULT_FACTOR = 10.0
_NAME = re.compile(r"^(?P<path>[A-Za-z_][A-Za-z0-9_.]*?)(?:\[(?P<index>\d+)\])?$")
_KEYS = {"low", "high", "log", "type", "factor"}


@dataclass(frozen=True)
class Param:
    """One searched value: ``name`` (dotted path, ``[i]`` for a vector element), its range
    and scale, its type and the config's own value (``base``)."""

    name: str
    low: float
    high: float
    log: bool = True
    kind: str = "float"  # or "int"
    base: float = math.nan

    def contains(self, value: float) -> bool:
        return self.low <= value <= self.high


def _split(name: str) -> tuple[list[str], int | None]:
    m = _NAME.match(name)
    if m is None:
        raise ValueError("expected a dotted config path, optionally with [index]")
    index = m.group("index")
    return m.group("path").split("."), (None if index is None else int(index))


def _lookup(data: Mapping[str, Any], name: str) -> Any:
    keys, index = _split(name)
    node: Any = data
    for key in keys:
        if not isinstance(node, Mapping) or key not in node:
            raise ValueError("no such config value")
        node = node[key]
    if index is not None:
        if not isinstance(node, list) or index >= len(node):
            raise ValueError(f"not a vector with an element {index}")
        node = node[index]
    return node


def _numeric(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _finite(value: Any) -> bool:
    return _numeric(value) and math.isfinite(value)


def _checked(p: Param) -> Param:
    """``p`` if the sampler can draw from it: finite bounds (an int range holding an
    integer); ValueError otherwise."""
    if not (math.isfinite(p.low) and math.isfinite(p.high)):
        raise ValueError(f"the range {p.low:g} … {p.high:g} is not finite")
    if p.kind == "int" and math.ceil(p.low) > math.floor(p.high):
        raise ValueError(f"type int: no integer lies in {p.low:g} … {p.high:g}")
    return p


#: Per axis, the weights (of ``controller``) that shape its step response: its position and
#: velocity state weights, q = [x, ẋ, y, ẏ, z, ż, ψ], and the input that moves it, r = [z̈, φ,
#: θ, ψ̇] (θ tilts towards x, φ towards y).
STEP_WEIGHTS: dict[str, tuple[str, ...]] = {
    "x": ("q[0]", "q[1]", "r[2]"), "y": ("q[2]", "q[3]", "r[1]"),
    "z": ("q[4]", "q[5]", "r[0]"), "psi": ("q[6]", "r[3]")}


def _around(name: str, base: float, factor: float, kind: str = "float") -> Param:
    return _checked(Param(name, base / factor, base * factor, True, kind, base))


def default_space(cfg, *, factor: float = DEFAULT_FACTOR) -> dict[str, Param]:
    """q (7) and r (4) log-uniform within ×1/factor…×factor of ``cfg``'s values; for a step,
    only the stepped axes' :data:`STEP_WEIGHTS`."""
    axes = cfg.reference.stepped_axes
    wanted = {w for a in axes for w in STEP_WEIGHTS[a]}
    space = {}
    for vec in ("q", "r"):
        for i, v in enumerate(getattr(cfg.controller, vec)):
            if v > 0 and (not axes or f"{vec}[{i}]" in wanted):
                name = f"controller.{vec}[{i}]"
                space[name] = _around(name, float(v), factor)
    return space


def _one(name: str, spec: Any, data: Mapping[str, Any]) -> list[Param]:
    """The parameters of one ``params`` entry (several for a whole vector)."""
    if not isinstance(spec, Mapping):
        raise ValueError("expected a mapping {low, high[, log, type]} or {factor}")
    unknown = set(spec) - _KEYS
    if unknown:
        raise ValueError(f"unknown key(s) {', '.join(sorted(unknown))}; expected "
                         f"{', '.join(sorted(_KEYS))}")
    kind = spec.get("type", "float")
    if kind not in ("float", "int"):
        raise ValueError(f"type {kind!r}: choose float or int")
    value = _lookup(data, name)
    if isinstance(value, list):  # a whole vector: one parameter per element
        if "factor" not in spec:
            raise ValueError("a vector takes {factor: F}; bound single elements with "
                             "path[i]: {low, high}")
        return [p for i, v in enumerate(value) if _numeric(v) and v > 0
                for p in _one(f"{name}[{i}]", spec, data)]
    if not _numeric(value):
        raise ValueError(f"not a number in the config ({value!r})")
    base = float(value)
    if "factor" in spec:
        if {"low", "high"} & set(spec):
            raise ValueError("give factor or low/high, not both")
        factor = spec["factor"]
        if not _finite(factor) or factor <= 1:
            raise ValueError(f"factor {factor!r}: must be a finite number > 1")
        if base <= 0:
            raise ValueError(f"factor needs a positive config value (it is {value!r})")
        return [_around(name, base, float(factor), kind)]
    low, high = spec.get("low"), spec.get("high")
    if not (_finite(low) and _finite(high)) or not low < high:
        raise ValueError("needs finite numbers low < high")
    log = bool(spec.get("log", False))
    if log and low <= 0:
        raise ValueError("log: true needs low > 0")
    return [_checked(Param(name, float(low), float(high), log, kind, base))]


def parse_space(spec: Mapping[str, Any] | None, cfg, *, where: str = "--space") -> dict[str, Param]:
    """The space of a parsed space file (None: the default) for the config ``cfg``.

    Raises :class:`ConfigError` with one ``<where>: <key>: message`` line per problem.
    """
    spec = {} if spec is None else spec
    if not isinstance(spec, Mapping):
        raise ConfigError(f"{where}: expected a mapping with default, factor, params")
    errors = [f"{where}: {k}: unknown key (expected default, factor, params)"
              for k in spec if k not in ("default", "factor", "params")]
    factor = spec.get("factor", DEFAULT_FACTOR)
    if not _finite(factor) or factor <= 1:
        errors.append(f"{where}: factor: {factor!r} must be a finite number > 1")
        factor = DEFAULT_FACTOR
    try:
        space = default_space(cfg, factor=float(factor)) if spec.get("default", True) else {}
    except ValueError as err:  # a factor that takes a weight beyond the doubles
        errors.append(f"{where}: factor: {factor!r}: {err}")
        space = {}
    params = spec.get("params") or {}
    if not isinstance(params, Mapping):
        errors.append(f"{where}: params: expected a mapping of config paths to ranges")
        params = {}
    data = config_to_dict(cfg)
    for name, entry in params.items():
        if str(name).split(".")[0] == "safety":
            errors.append(f"{where}: params.{name}: the safety limits are not searched (set "
                          "them with --set; tune the controller, not the supervisor)")
            continue
        try:
            for p in _one(str(name), entry, data):
                space[p.name] = p
        except ValueError as err:
            errors.append(f"{where}: params.{name}: {err}")
    if errors:
        raise ConfigError(errors)
    if not space:
        raise ConfigError(f"{where}: the space is empty (default: false and no params)")
    return space


def load_space(path: str | Path | None, cfg) -> dict[str, Param]:
    """:func:`parse_space` of a YAML file (None: the default space)."""
    if path is None:
        return parse_space(None, cfg)
    from ardrone_nmpc.config.io import read_option_file

    return parse_space(read_option_file(path, "--space"), cfg, where=f"--space {path}")


def apply_params(data: Mapping[str, Any], values: Mapping[str, float],
                 space: Mapping[str, Param] | None = None, *,
                 resolved: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """A copy of the config mapping ``data`` with each named value set (ints for int
    parameters). The caller validates it (:func:`config_from_dict`).

    ``data`` may be a config as written (keys left out take their defaults, and profile
    defaults such as ``sim.plant.profile``'s then still apply); a path it leaves out is
    first copied from ``resolved`` (the validated config as a mapping): a whole vector when
    one of its elements is set."""
    import copy

    out = copy.deepcopy(dict(data))
    for name, value in values.items():
        keys, index = _split(name)
        node, source = out, resolved
        for key in keys[:-1]:
            source = source[key] if source is not None else None
            if key not in node:
                node[key] = {}
            node = node[key]
        if keys[-1] not in node and source is not None:
            node[keys[-1]] = copy.deepcopy(source[keys[-1]])
        if space is not None and space[name].kind == "int":
            value = int(round(value))
        if index is None:
            node[keys[-1]] = value
        else:
            vec = list(node[keys[-1]])
            vec[index] = value
            node[keys[-1]] = vec
    return out


def written_config(path: str | Path | None, overrides: Sequence[str]) -> dict[str, Any]:
    """The config as written in ``path`` with the ``--set`` overrides, as a mapping (keys
    left out stay out, so defaults that depend on other keys — a plant profile's — still
    follow them), read as :func:`~ardrone_nmpc.config.io.load_config` reads it."""
    from ardrone_nmpc.config.io import _path_file, _profile_path, _read_yaml, apply_overrides

    data: dict[str, Any] = {}
    if path is not None:
        data = _read_yaml(Path(path))
        _path_file(data, Path(path).parent)
        _profile_path(data, Path(path).parent)
    data = apply_overrides(data, overrides)
    _path_file(data, Path.cwd())
    _profile_path(data, Path.cwd())
    return data


def config_with(cfg, values: Mapping[str, float], space: Mapping[str, Param] | None = None,
                overrides: Sequence[str] = ()):
    """``cfg`` with the parameter values (and then ``--set``-style overrides) applied,
    validated. Raises :class:`ConfigError`."""
    from ardrone_nmpc.config.io import apply_overrides, resolve_data

    data = apply_params(config_to_dict(cfg), values, space)
    return resolve_data(apply_overrides(data, overrides))
