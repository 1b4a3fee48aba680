"""cli/raw_options.raw_options: the raw command line's options as the entry point reads them
before anything loads (cli/launch.pool_wanted, cli/first_datagram.target)."""

from __future__ import annotations

import pytest

from ardrone_nmpc.cli.raw_options import raw_options

NAMES = ("--jobs", "--engine")


@pytest.mark.parametrize("args, found", [
    ([], []),
    (["c.yaml"], []),
    (["c.yaml", "--jobs", "2", "--engine=dask"], [("--jobs", "2"), ("--engine", "dask")]),
    (["--jobs=2", "--jobs", "3"], [("--jobs", "2"), ("--jobs", "3")]),  # each, in order
    (["--jobs="], [("--jobs", "")]),                 # an empty value is a value
    (["--trials", "8", "--jobs", "x"], [("--jobs", "x")]),  # values unchecked, others skipped
    (["--engine", "--help"], [("--engine", "--help")]),  # a value is not read as an option
    (["--jobs", "2", "--help"], None),               # help asked
    (["-h"], None), (["-h=1"], None), (["--help=x"], None),
    (["--jobs"], None),                              # a value missing
    (["--engine", "local", "--jobs"], None),
])
def test_raw_options_reads_the_named_options_or_gives_up(args, found):
    for stop in (True, False):  # no "--" in these: the same either way
        assert raw_options(args, NAMES, stop_at_separator=stop) == found


def test_a_separator_ends_the_options_only_when_asked():
    args = ["--jobs", "2", "--", "--jobs", "1", "--help", "--engine"]
    assert raw_options(args, NAMES, stop_at_separator=True) == [("--jobs", "2")]
    assert raw_options(args, NAMES, stop_at_separator=False) is None  # help, then no value
    assert raw_options(["--", "--jobs", "1"], NAMES, stop_at_separator=False) == [
        ("--jobs", "1")]
