"""Experiment configs as files: YAML loading, ``--set`` overrides, and dumping.

:func:`load_config` reads a YAML file (duplicate keys are errors), merges ``dotted.path=value``
overrides, resolves ``reference.path_file`` to an absolute path (relative to the config file,
or to the working directory for an override), fills in the values of a plant profile file
(``sim.plant.profile: PLANT.yaml``, the same way) and validates the result with
:func:`~ardrone_nmpc.config.schema.config_from_dict`. :func:`dump_config` writes a config back
as YAML that :func:`load_config` reads. Every problem is a
:class:`~ardrone_nmpc.config.schema.ConfigError` line.
"""

from __future__ import annotations

import copy
import re
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import yaml

from ardrone_nmpc.config.schema import ConfigError, ExperimentConfig, config_from_dict

__all__ = ["PROFILE_SECTIONS", "RETIRED_KEYS", "apply_overrides", "config_to_dict",
           "dump_config", "load_config", "load_run_config", "read_option_file",
           "resolve_data"]

#: Settings that existed once and were removed, with the reason. A user's config naming one
#: is an error that says so; a run directory written before the removal still reads (the
#: key is dropped).
RETIRED_KEYS: dict[tuple[str, str], str] = {
    ("mocap", "rate_hz"): "removed: nothing read it (the pose rate is whatever the mocap "
                          "system sends; staleness is judged by safety.mocap_*_ms)",
}


class _UniqueKeys:
    """A loader mixin that rejects duplicate keys instead of keeping the last one."""

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict[Any, Any]:
        seen: set[Any] = set()
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=deep)
            try:
                duplicate = key in seen
            except TypeError:  # unhashable key: the base class reports it
                break
            if duplicate:
                raise yaml.constructor.ConstructorError(
                    "while constructing a mapping", node.start_mark,
                    f"duplicate key {key!r}", key_node.start_mark)
            seen.add(key)
        return super().construct_mapping(node, deep=deep)


class _UniqueKeyLoader(_UniqueKeys, yaml.SafeLoader):
    """``yaml.SafeLoader`` that rejects duplicate keys instead of keeping the last one."""


#: The same loader on libyaml's parser, when PyYAML has it: ~6× faster, for the config.yaml of
#: a run directory (every sweep case reads its own back). Only the scanning is libyaml's — the
#: values are built and typed by the same Python constructor and resolver. libyaml accepts a
#: few documents the pure parser refuses (tabs, ``?`` in a flow sequence): a text holding such
#: characters, or one libyaml refuses, is parsed by :class:`_UniqueKeyLoader` (its message).
_FastUniqueKeyLoader = (type("_FastUniqueKeyLoader", (_UniqueKeys, yaml.CSafeLoader), {})
                        if getattr(yaml, "__with_libyaml__", False) else None)
_NOT_FAST = re.compile(r"[^\x20-\x3e\x40-\x5b\x5d-\x7e\n]")  # beyond printable ASCII, ? and \\


def _load_yaml(text: str, *, fast: bool = False) -> Any:
    """``text`` parsed by :class:`_UniqueKeyLoader`; ``fast``: on libyaml's scanner when the
    text is of the plain characters dump_config writes (the same data)."""
    if fast and _FastUniqueKeyLoader is not None and _NOT_FAST.search(text) is None:
        try:
            return yaml.load(text, Loader=_FastUniqueKeyLoader)  # noqa: S506 - safe, as below
        except yaml.YAMLError:
            pass  # the pure-Python loader's message, line and all
    return yaml.load(text, Loader=_UniqueKeyLoader)  # noqa: S506 - a SafeLoader subclass


def apply_overrides(data: Mapping[str, Any], overrides: Sequence[str]) -> dict[str, Any]:
    """Return a copy of ``data`` with each ``dotted.path=value`` override set.

    The value is parsed as YAML (``5`` → int, ``0.1`` → float, ``[1, 2]`` → list, ``null`` →
    None, ``p`` → str); missing intermediate mappings are created. Raises :class:`ConfigError`
    listing every malformed override.
    """
    result = copy.deepcopy(dict(data))
    errors = []
    for override in overrides:
        path, sep, text = override.partition("=")
        keys = path.strip().split(".")
        if not sep or any(not key.strip() for key in keys):
            errors.append(f"override {override!r}: expected dotted.path=value")
            continue
        keys = [key.strip() for key in keys]
        try:
            value = yaml.safe_load(text)
        except yaml.YAMLError as exc:
            errors.append(f"override {override!r}: invalid YAML value: {exc}".replace("\n", " "))
            continue
        node = result
        for depth, key in enumerate(keys[:-1]):
            child = node.setdefault(key, {})
            if not isinstance(child, dict):
                errors.append(f"override {override!r}: "
                              f"{'.'.join(keys[:depth + 1])} is not a mapping")
                break
            node = child
        else:
            node[keys[-1]] = value
    if errors:
        raise ConfigError(errors)
    return result


def _read_yaml(path: Path, *, fast: bool = False) -> dict[str, Any]:
    if not path.exists():
        raise ConfigError(f"{path}: no such file")
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{path}: cannot read: {exc}") from None
    try:
        data = _load_yaml(text, fast=fast)
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        line = f" (line {mark.line + 1})" if mark is not None else ""
        problem = exc.problem or exc.context or "syntax error"
        raise ConfigError(f"{path}: invalid YAML{line}: {problem}") from None
    except yaml.YAMLError as exc:
        raise ConfigError(f"{path}: invalid YAML: {exc}".replace("\n", " ")) from None
    if data is None:
        # Most likely a truncated or wrong file; flying the default experiment instead would
        # be a surprise. `{}` (or no config at all) asks for the defaults explicitly.
        raise ConfigError(f"{path}: empty file (no settings); write {{}} in it for an "
                          "experiment with every default")
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: the top level must be a mapping of section names to "
                          f"values, not a {type(data).__name__}")
    return data


def read_option_file(path: str | Path, option: str) -> Any:
    """The YAML of a file a command-line option names (``--space``, ``--grid-file``): its
    parsed contents, or one ``option path: …`` ConfigError line."""
    path = Path(path)
    try:
        return yaml.safe_load(path.read_text(encoding="utf-8"))
    except OSError as err:
        raise ConfigError(f"{option} {path}: cannot read: {err.strerror or err}") from None
    except UnicodeDecodeError as err:
        raise ConfigError(f"{option} {path}: not UTF-8 text (byte {err.start})") from None
    except yaml.YAMLError as err:
        raise ConfigError(f"{option} {path}: invalid YAML: {str(err).splitlines()[0]}") from None


def _retire(data: dict[str, Any], *, drop: bool) -> list[str]:
    """Remove retired keys from ``data`` (``drop``) or return one error line per key found."""
    errors = []
    for (section, key), why in RETIRED_KEYS.items():
        node = data.get(section)
        if isinstance(node, dict) and key in node:
            if drop:
                del node[key]
            else:
                errors.append(f"{section}.{key}: no longer a setting ({why}); delete it")
    return errors


def _path_file(data: dict[str, Any], base: Path) -> None:
    """Make a relative ``reference.path_file`` absolute against ``base`` (in place)."""
    reference = data.get("reference")
    if isinstance(reference, dict) and isinstance(reference.get("path_file"), str) \
            and reference["path_file"]:
        reference["path_file"] = str((base / Path(reference["path_file"]).expanduser())
                                     .resolve())


#: The keys of a plant profile file: ``plant:`` holds ``sim.plant`` keys, ``vz_gain`` is
#: ``sim.vz_gain`` (docs/plant-profiles.md §5).
PROFILE_SECTIONS = ("plant", "vz_gain")


def _profile_node(data: dict[str, Any]) -> dict[str, Any] | None:
    """The ``sim.plant`` mapping of ``data`` if its profile names a file."""
    from ardrone_nmpc.config.sim import is_profile_file

    sim = data.get("sim")
    plant = sim.get("plant") if isinstance(sim, dict) else None
    profile = plant.get("profile") if isinstance(plant, dict) else None
    return plant if isinstance(profile, str) and is_profile_file(profile) else None


def _profile_path(data: dict[str, Any], base: Path) -> None:
    """Make a relative profile file absolute against ``base`` (in place)."""
    plant = _profile_node(data)
    if plant is not None:
        plant["profile"] = str((base / Path(plant["profile"]).expanduser()).resolve())


def _plant_profile(data: dict[str, Any], *, missing_ok: bool = False) -> None:
    """A ``sim.plant.profile`` naming a file (absolute by now) fills the ``sim.plant`` keys
    (and ``sim.vz_gain``) the config leaves out with the file's values (in place).
    ``missing_ok``: a file that is gone fills nothing (a run directory's config holds every
    value)."""
    from ardrone_nmpc.config.sim import PlantConfig

    plant = _profile_node(data)
    if plant is None:
        return
    sim = data["sim"]
    path = Path(plant["profile"])
    if missing_ok and not path.is_file():
        return
    where = f"sim.plant.profile {path}"
    try:
        values = _read_yaml(path)
    except ConfigError as err:
        raise ConfigError([f"sim.plant.profile: {m}" for m in err.messages]) from None
    errors = [f"{where}: unknown key {k!r} (expected {', '.join(PROFILE_SECTIONS)})"
              for k in values if k not in PROFILE_SECTIONS]
    own = values.get("plant") or {}
    if not isinstance(own, dict):
        errors.append(f"{where}: plant: expected a mapping of sim.plant keys")
        own = {}
    for key in own:
        if key == "profile" or key not in PlantConfig.model_fields:
            errors.append(f"{where}: plant.{key}: not a sim.plant key")
    if errors:
        raise ConfigError(errors)
    for key, value in own.items():
        plant.setdefault(key, value)
    if "vz_gain" in values:
        sim.setdefault("vz_gain", values["vz_gain"])


def resolve_data(data: Mapping[str, Any], base: Path | None = None) -> ExperimentConfig:
    """Validate a config mapping (a config as written, overrides applied) the way
    :func:`load_config` does: a profile file fills its values first (relative to ``base``,
    default the working directory)."""
    data = copy.deepcopy(dict(data))
    _profile_path(data, base or Path.cwd())
    _plant_profile(data)
    return config_from_dict(data)


def load_run_config(path: str | Path) -> ExperimentConfig:
    """The configuration a run directory's ``config.yaml`` holds (:func:`load_config` with
    ``allow_retired``; a text of the plain characters :func:`dump_config` writes is scanned
    by libyaml — the same data, ~6× faster)."""
    return load_config(path, allow_retired=True, _fast=True)


def load_config(path: str | Path | None = None, overrides: Sequence[str] = (), *,
                allow_retired: bool = False, _fast: bool = False) -> ExperimentConfig:
    """Load and validate an experiment.

    ``path`` None means all defaults. ``overrides`` (``dotted.path=value``) are merged before
    validation. A relative ``reference.path_file`` written in the file is resolved against the
    file's directory; one given by an override, against the working directory. The file is
    not read here (see :func:`ardrone_nmpc.reference.trajectories.make_trajectory`).
    ``allow_retired`` drops :data:`RETIRED_KEYS` silently (run directories of older versions)
    instead of reporting them. Raises :class:`ConfigError` with every problem found.
    """
    data: dict[str, Any] = {}
    if path is not None:
        path = Path(path)
        data = _read_yaml(path, fast=_fast)
        _path_file(data, path.parent)
        _profile_path(data, path.parent)
    data = apply_overrides(data, overrides)
    _path_file(data, Path.cwd())
    _profile_path(data, Path.cwd())
    _plant_profile(data, missing_ok=allow_retired)
    errors = _retire(data, drop=allow_retired)
    if errors:
        raise ConfigError(errors)
    return config_from_dict(data)


class _Dumper(yaml.SafeDumper):
    """Block-style mappings, vectors on one line (``q: [12.0, 2.0, …]``)."""


def _flow_lists(dumper_class: type) -> type:
    dumper_class.add_representer(
        list, lambda dumper, data: dumper.represent_sequence(
            "tag:yaml.org,2002:seq", data, flow_style=True))
    return dumper_class


_flow_lists(_Dumper)
#: :class:`_Dumper` on libyaml's emitter (~4× faster; every run directory writes its
#: config.yaml). Its text equals the pure-Python emitter's for strings of :data:`_PLAIN_TEXT`
#: (checked: every config of configs/, fuzzed names, paths and lists); other strings — the
#: emitters quote and fold some characters differently — take :class:`_Dumper`.
_CDumper = (_flow_lists(type("_CDumper", (yaml.CSafeDumper,), {}))
            if getattr(yaml, "__with_libyaml__", False) else None)
_PLAIN_TEXT = re.compile(r"[A-Za-z0-9 _./:+=-]*")


def _plain_strings(data: Any) -> bool:
    """Whether every str in ``data`` (keys and values, nested) is of :data:`_PLAIN_TEXT`."""
    if isinstance(data, str):
        return _PLAIN_TEXT.fullmatch(data) is not None
    if isinstance(data, dict):
        return all(_plain_strings(k) and _plain_strings(v) for k, v in data.items())
    if isinstance(data, (list, tuple)):
        return all(_plain_strings(v) for v in data)
    return True


def config_to_dict(cfg: ExperimentConfig) -> dict[str, Any]:
    """The configuration as plain JSON/YAML-safe data (tuples become lists), declared order."""
    return cfg.model_dump(mode="json")


def _dump(data: Any, dumper: type) -> str:
    return yaml.dump(data, Dumper=dumper, sort_keys=False, default_flow_style=False,
                     allow_unicode=True, width=100)


def _unshared(data: Any, seen: set[int]) -> bool:
    """Whether no dict or list of ``data`` appears twice (the emitter would write an anchor
    and an alias for it: text that spans sections)."""
    if isinstance(data, (dict, list)):
        if id(data) in seen:
            return False
        seen.add(id(data))
        values = data.values() if isinstance(data, dict) else data
        # scalars (most values) need no call: only a container can be shared
        return all(_unshared(v, seen) for v in values if isinstance(v, (dict, list)))
    return True


#: The text of a top-level section, by ``(key, repr(value))``: a sweep's configs differ in a
#: section or two (the seed, a gain), and each run directory writes its config.yaml.
_SECTION_TEXT: dict[tuple[str, str], str] = {}
_SECTIONS_KEPT = 512


def _body(data: dict[str, Any]) -> str:
    """``data`` as YAML. Plain text (:func:`_plain_strings`) on libyaml, a section at a time
    from :data:`_SECTION_TEXT`: a block mapping's sections are written one after the other,
    each the text it has alone, when no object is shared (no anchor). The rest on
    :class:`_Dumper`, whole."""
    if _CDumper is None:
        return _dump(data, _Dumper)
    # A section found in the cache is plain text: its key is its repr, which spells out every
    # string of it, and only plain sections are cached; the others are walked (a sweep's
    # configs differ in a section or two: the walk over the rest was ~0.1 ms a run).
    parts: list = []
    for key, value in data.items():
        at = (key, repr(value))  # repr tells 1 from 1.0 and True, nan from inf, -0.0 from 0.0
        text = _SECTION_TEXT.get(at)
        if text is None:
            if not (_plain_strings(key) and _plain_strings(value)):
                return _dump(data, _Dumper)
            text = at  # dumped below, once the whole is known to share nothing
        parts.append(text)
    if not _unshared(data, set()):
        return _dump(data, _CDumper)
    for i, at in enumerate(parts):
        if at.__class__ is tuple:  # a section not in the cache: (key, repr)
            text = parts[i] = _dump({at[0]: data[at[0]]}, _CDumper)
            if len(_SECTION_TEXT) >= _SECTIONS_KEPT:
                _SECTION_TEXT.clear()
            _SECTION_TEXT[at] = text
    return "".join(parts)


def dump_config(cfg: ExperimentConfig, header: str | None = None) -> str:
    """The configuration as YAML, keys in declared order, loadable by :func:`load_config`.

    ``header`` (e.g. the tool version) is written as leading ``#`` comment lines.
    """
    body = _body(config_to_dict(cfg))
    if not header:
        return body
    comments = "".join(f"# {line}".rstrip() + "\n" for line in header.splitlines())
    return comments + body
