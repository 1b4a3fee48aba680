"""The grid of a sweep: ``--grid`` options parsed, and the cases they make.

Syntax
------
``--grid dotted.path=v1,v2,…`` sweeps one config field over values parsed exactly like
``--set`` values (YAML: ``5`` → int, ``0.1`` → float, ``null``, ``p`` → str). Values are
separated by commas *outside brackets and quotes*, so vector-valued fields take YAML lists::

    --grid controller.r=[4,12,12,24],[1,12,12,24]     # two values of a 4-vector
    --grid estimator.kind=kalman,luenberger
    --grid 'reference.target_m=[-1.5, 0, 1],[-0.5, 0, 1]'

Several ``--grid`` options make the Cartesian product, the first one varying slowest. A grid
value is applied after the ``--set`` overrides, and every case's config is validated before any
simulation runs, so a typo fails at once with ``field.path: message``.

Case ids
--------
A case id is ``<leaf>=<value>__<leaf>=<value>__<hash8>``: the swept fields' last path
components with their values (characters outside ``A-Za-z0-9._+-`` become ``_``), then the
first 8 hex digits of a SHA-256 of the case's whole resolved config. The id is stable across
re-runs of the same sweep (resume finds the case again) and changes when anything else about
the case changes (another base config or ``--set``), so a stale result is never reused.
"""

from __future__ import annotations

import hashlib
import json
import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from itertools import product
from pathlib import Path
from typing import TYPE_CHECKING, Any

import yaml

from ardrone_nmpc.config.schema import ConfigError

from ardrone_nmpc.config.io import config_to_dict, load_config

if TYPE_CHECKING:  # pragma: no cover
    from ardrone_nmpc.config.schema import ExperimentConfig

_ID_PART_CHARS = re.compile(r"[^A-Za-z0-9._+-]+")
_MAX_ID_TEXT = 120  # readable part of a case id (a directory name is at most 255 bytes)


@dataclass(frozen=True)
class GridParam:
    """One ``--grid`` option: a dotted config path and its values (``texts`` as given, the
    YAML text of each value; ``values`` parsed)."""

    path: str
    texts: tuple[str, ...]
    values: tuple[Any, ...]


def split_values(text: str) -> list[str]:
    """Split ``text`` on commas outside ``[]``/``{}`` and quotes; items are stripped.

    Raises ``ValueError`` on unbalanced brackets or quotes.
    """
    items, depth, quote, start = [], 0, "", 0
    for i, ch in enumerate(text):
        if quote:
            quote = "" if ch == quote else quote
        elif ch in "'\"":
            quote = ch
        elif ch in "[{":
            depth += 1
        elif ch in "]}":
            depth -= 1
            if depth < 0:
                raise ValueError(f"unbalanced {ch!r} at character {i + 1}")
        elif ch == "," and depth == 0:
            items.append(text[start:i].strip())
            start = i + 1
    if quote or depth:
        raise ValueError("unclosed " + ("quote" if quote else "bracket"))
    items.append(text[start:].strip())
    return items


def _parse_one(spec: str) -> tuple[GridParam | None, list[str]]:
    path, sep, rest = spec.partition("=")
    path = path.strip()
    keys = path.split(".")
    if not sep or any(not k.strip() or k != k.strip() for k in keys):
        return None, [f"--grid {spec!r}: expected dotted.path=v1,v2,…"]
    where = f"--grid {path}"
    try:
        texts = split_values(rest)
    except ValueError as err:
        return None, [f"{where}: {err}"]
    if any(not t for t in texts):
        return None, [f"{where}: empty value in {rest!r} (values are separated by commas)"]
    values, errors = [], []
    for text in texts:
        try:
            values.append(yaml.safe_load(text))
        except yaml.YAMLError as exc:
            errors.append(f"{where}: value {text!r} is not valid YAML: "
                          f"{str(exc).splitlines()[0]}")
    for i, value in enumerate(values):
        if value in values[:i]:
            errors.append(f"{where}: value {texts[i]!r} given twice")
    return (None if errors else GridParam(path, tuple(texts), tuple(values))), errors


def parse_grid(specs: Sequence[str]) -> list[GridParam]:
    """Parse ``--grid`` options (see the module docstring for the syntax).

    Raises
    ------
    ConfigError
        One ``--grid …: message`` line per problem: no grid, a spec without ``=``, an empty
        or unbalanced value list, a value that is not YAML, a repeated value or path.
    """
    if not specs:
        raise ConfigError("--grid: give at least one dotted.path=v1,v2,…")
    params, errors = [], []
    for spec in specs:
        param, errs = _parse_one(spec)
        errors += errs
        if param is not None:
            if any(p.path == param.path for p in params):
                errors.append(f"--grid {param.path}: swept twice (give all its values in one "
                              "--grid)")
            params.append(param)
    if errors:
        raise ConfigError(errors)
    return params


# ----------------------------------------------------------------------------- cases


@dataclass(frozen=True)
class Case:
    """One point of the grid.

    ``params`` pairs each swept dotted path with its value's text (``sweep.csv`` cells);
    ``config`` is the validated, resolved configuration flown.
    """

    index: int
    case_id: str
    params: tuple[tuple[str, str], ...]
    config: ExperimentConfig = field(repr=False)


def value_text(value: Any) -> str:
    """The canonical text of a parsed grid value (``sweep.csv`` cell): strings as they are,
    everything else as compact JSON (``0.1``, ``5``, ``[4,12,12,24]``, ``true``, ``null``)."""
    return value if isinstance(value, str) else json.dumps(value, separators=(",", ":"))


def case_id(*, params: Sequence[tuple[str, str]], cfg: ExperimentConfig) -> str:
    """The case's directory name: readable swept values, then a hash of the whole config."""
    data = json.dumps(config_to_dict(cfg), sort_keys=True, separators=(",", ":"))
    digest = hashlib.sha256(data.encode("utf-8")).hexdigest()[:8]
    parts = [f"{path.rsplit('.', 1)[-1]}={_ID_PART_CHARS.sub('_', text).strip('_')}"
             for path, text in params]
    return f"{'__'.join(parts)[:_MAX_ID_TEXT]}__{digest}"


def build_cases(*, config_path: str | Path | None, overrides: Sequence[str],
                grid: Sequence[GridParam]) -> list[Case]:
    """Every case of the grid, first grid parameter varying slowest, each validated.

    Parameters
    ----------
    config_path : the experiment YAML (None: all defaults).
    overrides : ``--set`` overrides ``dotted.path=value``, applied to every case before the
        grid values.
    grid : from :func:`parse_grid`.

    Raises
    ------
    ConfigError
        Each distinct ``field.path: message`` line once, with the first case it occurred in
        appended, before anything runs.
    """
    cases, errors = [], {}
    for index, combo in enumerate(product(*(range(len(p.values)) for p in grid))):
        texts = [p.texts[i] for p, i in zip(grid, combo)]
        case_overrides = [*overrides, *(f"{p.path}={t}" for p, t in zip(grid, texts))]
        params = tuple((p.path, value_text(p.values[i])) for p, i in zip(grid, combo))
        try:
            cfg = load_config(config_path, case_overrides)
        except ConfigError as err:
            label = ", ".join(f"{path}={text}" for path, text in params)
            for message in err.messages:
                errors.setdefault(message, f"{message} (case {label})")
            continue
        cases.append(Case(index, case_id(params=params, cfg=cfg), params, cfg))
    if errors:
        raise ConfigError(list(errors.values()))
    return cases

