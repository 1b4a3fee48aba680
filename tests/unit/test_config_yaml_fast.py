"""config.io's libyaml paths against the pure-Python ones they stand in for: the same data
read, the same config.yaml text written, the same error for a document either refuses."""

from __future__ import annotations

import random
from pathlib import Path

import pytest
import yaml

from ardrone_nmpc.config import io
from ardrone_nmpc.config.io import ConfigError, config_to_dict, dump_config, load_config

ROOT = Path(__file__).resolve().parents[2]
CONFIGS = sorted((ROOT / "configs").glob("*.yaml"))
pytestmark = pytest.mark.skipif(io._CDumper is None, reason="PyYAML without libyaml")


def _pure_dump(data) -> str:
    return yaml.dump(data, Dumper=io._Dumper, sort_keys=False, default_flow_style=False,
                     allow_unicode=True, width=100)


@pytest.mark.parametrize("path", CONFIGS, ids=lambda p: p.name)
def test_every_config_reads_and_dumps_as_the_pure_loader_does(path):
    text = path.read_text(encoding="utf-8")
    pure = yaml.load(text, Loader=io._UniqueKeyLoader)  # noqa: S506
    assert repr(io._load_yaml(text, fast=True)) == repr(pure)
    try:
        cfg = load_config(path)
    except ConfigError:
        return  # a config that needs a file beside it: the reading is what counts here
    data = config_to_dict(cfg)
    assert io._plain_strings(data)
    written = dump_config(cfg, header="ardrone-nmpc 0.1.0\nseed: 3\ncreated: 2026-12-02T13:00:00+00:00")
    assert written == "".join(f"# {h}\n" for h in ("ardrone-nmpc 0.1.0", "seed: 3",
                                                     "created: 2026-12-02T13:00:00+00:00")) \
        + _pure_dump(data)
    assert io._NOT_FAST.search(written) is None  # a run's config.yaml takes libyaml's scanner
    assert repr(io._load_yaml(written, fast=True)) == repr(
        yaml.load(written, Loader=io._UniqueKeyLoader))  # noqa: S506


def test_plain_strings_and_lists_dump_as_the_pure_emitter_does():
    rng = random.Random(5)
    base = config_to_dict(load_config(ROOT / "configs" / "square.yaml"))
    chars = "abcXYZ019_./-:+= "
    for _ in range(300):
        name = "".join(rng.choice(chars) for _ in range(rng.randint(0, 200)))
        values = [rng.choice([rng.gauss(0, 1), float(rng.randint(-9, 9)), float("nan"),
                              float("inf"), rng.randint(-10 ** 9, 10 ** 9), None, True])
                  for _ in range(rng.randint(0, 60))]
        data = dict(base, name=name, controller=dict(base["controller"], q=values))
        assert io._plain_strings(data)
        dumper = io._CDumper
        fast = yaml.dump(data, Dumper=dumper, sort_keys=False, default_flow_style=False,
                         allow_unicode=True, width=100)
        assert fast == _pure_dump(data)


@pytest.mark.parametrize("name", ["a#b", "é", "x'y", 'q"', "line\nbreak", "t\tab", "{a}",
                                  "a, b", "*star", "&amp", "!bang", "@at", "`tick`", "%p"])
def test_other_strings_take_the_pure_emitter(name):
    assert not io._plain_strings({"name": name})
    assert not io._plain_strings({"reference": {"path_file": [f"/data/{name}"]}})


@pytest.mark.parametrize("text", ["a: 1\na: 2\n", "a: [1, 2\n", "a:\n\t- 1\n", "- a\nb: 1\n",
                                  "a: &x 1\nb: *y\n", "{a: 1, a: 1}", "a: 'open\n",
                                  "a: [1, ?2]\n", "a: 1\tb\n", "a: b\\\n"])
def test_a_refused_document_gets_the_pure_loaders_error(text):
    """(tabs and ``?`` in a flow sequence: libyaml would take what the pure parser refuses —
    such texts are not given to it)"""
    try:
        yaml.load(text, Loader=io._UniqueKeyLoader)  # noqa: S506
    except yaml.YAMLError as err:
        with pytest.raises(type(err)) as got:
            io._load_yaml(text, fast=True)
        assert str(got.value) == str(err)
    else:
        assert repr(io._load_yaml(text, fast=True)) == repr(
            yaml.load(text, Loader=io._UniqueKeyLoader))  # noqa: S506


def test_a_users_config_is_read_by_the_pure_loader(tmp_path, monkeypatch):
    path = tmp_path / "c.yaml"
    path.write_text("name: x\n", encoding="utf-8")

    class Used(Exception):
        pass

    class Spy(io._UniqueKeyLoader):
        def __init__(self, stream):
            raise Used

    monkeypatch.setattr(io, "_FastUniqueKeyLoader", Spy)
    assert load_config(path).name == "x"  # never on libyaml's scanner
    with pytest.raises(Used):
        io.load_run_config(path)  # a run's config.yaml is


def _whole(data) -> str:
    """The document in one emitter call (config.yaml before the section cache)."""
    dumper = io._CDumper if io._plain_strings(data) else io._Dumper
    return yaml.dump(data, Dumper=dumper, sort_keys=False, default_flow_style=False,
                     allow_unicode=True, width=100)


def test_sections_from_the_cache_make_the_whole_documents_text():
    rng = random.Random(9)
    io._SECTION_TEXT.clear()
    for _ in range(3):  # the second and third rounds come from the cache
        for path in CONFIGS:
            sets = [f"sim.seed={rng.randint(0, 5)}", f"duration_s={rng.choice([1, 2.5, 60])}",
                    f"controller.dtau_s={rng.choice([0.05, 0.1])}"]
            cfg = load_config(path, sets)
            assert dump_config(cfg) == _whole(config_to_dict(cfg))


@pytest.mark.parametrize("a, b", [(1, 1.0), (1.0, True), (float("nan"), float("inf")),
                                  (0.0, -0.0), ("1", 1), (None, "null"), ([1, 2], (1, 2))])
def test_a_section_cached_for_one_value_is_not_taken_for_another_like_it(a, b):
    io._SECTION_TEXT.clear()
    for value in (a, b, a):
        data = {"name": "x", "section": {"k": value, "v": [value, 2.5]}}
        assert io._body(data) == _whole(data)


def test_shared_objects_are_written_whole():
    shared = [1.5, 2.5]
    data = {"a": {"v": shared}, "b": {"w": shared}}
    assert io._body(data) == _whole(data) and "&id" in _whole(data)


def test_cached_sections_beside_a_quoted_string_or_a_shared_object_are_written_whole():
    # a section from the cache skips the plain-strings walk: the others still decide
    io._SECTION_TEXT.clear()
    plain = {"name": "x", "sim": {"seed": 1, "rates": [1.5, 2.5]}}
    assert io._body(plain) == _whole(plain)  # both sections cached now
    quoted = {**plain, "note": "a: colon, 'quote' and ünïcode"}
    assert not io._plain_strings(quoted)
    assert io._body(quoted) == _whole(quoted)
    shared = [3.5]
    twice = {**plain, "a": {"v": shared}, "b": {"w": shared}}
    assert io._body(twice) == _whole(twice) and "&id" in io._body(twice)
    assert io._body(plain) == _whole(plain)
