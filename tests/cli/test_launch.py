"""The entry point's early start of a local pool's forkserver (cli/launch.py): which command
lines ask for one, and that a forkserver started for nothing ends with its process."""

from __future__ import annotations

import os
import subprocess
import sys
import time

import pytest

from ardrone_nmpc.cli.launch import POOL_COMMANDS, pool_wanted

CPUS = os.cpu_count() or 1


@pytest.mark.parametrize("args, wanted", [
    (["sweep", "c.yaml", "--jobs", "2"], True),
    (["sweep", "c.yaml", "--jobs=3", "--engine", "local"], True),
    (["tune", "c.yaml", "--jobs", "2", "--trials", "8"], True),
    (["robustness", "c.yaml", "--jobs", "4"], True),
    (["faults", "--jobs", "2"], True),
    (["faults"], False),                                  # its default: one job, in-process
    (["sweep", "c.yaml", "--jobs", "1"], False),
    (["sweep", "c.yaml", "--jobs", "2", "--engine", "dask"], False),
    (["sweep", "c.yaml", "--engine=dask", "--jobs", "2"], False),
    (["sweep", "c.yaml", "--jobs", "2", "--help"], False),
    (["sweep", "c.yaml", "--jobs"], False),               # a value missing
    (["sweep", "c.yaml", "--jobs", "two"], False),        # malformed
    (["sweep", "c.yaml", "--jobs", "\u00b2"], False),     # a digit int() refuses: typer's error
    (["sweep", "c.yaml", "--jobs", "2", "--", "--jobs", "1"], True),  # after --: arguments
    (["simulate", "c.yaml", "--jobs", "2"], False),       # not a pool command
    (["sweep", "c.yaml"], CPUS > 1),                      # the default: the CPU count
    ([], False),
])
def test_pool_wanted_reads_the_command_jobs_and_engine(args, wanted):
    assert pool_wanted(args) is wanted


def test_the_pool_commands_are_the_commands_with_jobs_and_their_defaults():
    """POOL_COMMANDS restates the ``--jobs`` defaults of cli/: held to them here."""
    from typer.main import get_command

    from ardrone_nmpc.cli.app import app

    group = get_command(app)
    with_jobs = {}
    for name, command in group.commands.items():
        for param in command.params:
            if param.name == "jobs":
                with_jobs[name] = param.default
    assert with_jobs == POOL_COMMANDS


@pytest.mark.timeout(120)
def test_a_forkserver_started_for_no_pool_ends_with_its_process():
    """A command that started the forkserver and then opened no pool (a config error, nothing
    left to fly): the forkserver must not outlive it — also while still in its preload."""
    code = ("from multiprocessing import forkserver\n"
            "from ardrone_nmpc.experiments.parallel import start_forkserver\n"
            "start_forkserver()\n"
            "print(forkserver._forkserver._forkserver_pid, flush=True)\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=60, check=True)
    pid = int(done.stdout.strip())
    deadline = time.monotonic() + 90  # its preload first: seconds on a cold numba cache
    while _running(pid):
        assert time.monotonic() < deadline, f"forkserver {pid} still running"
        time.sleep(0.05)


def _running(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as stat:
            text = stat.read()
    except OSError:
        return False
    return text[text.rindex(")") + 2] != "Z"


_AT_EXIT = """
import atexit, os, sys
from multiprocessing import forkserver
from ardrone_nmpc.experiments.parallel import open_executor, start_forkserver
start_forkserver()
pid = forkserver._forkserver._forkserver_pid
if sys.argv[1] == "pool":
    with open_executor("local", jobs=2) as pool:
        assert [d.value for d in pool.map(abs, [-1])] == [1]
atexit._run_exitfuncs()  # what this process's exit runs, with the process still here
if sys.argv[1] == "pool":
    print("running" if os.waitpid(pid, os.WNOHANG)[0] == 0 else "ended")
else:  # (without the hook this waits forever: the forkserver waits for this process to end)
    print(os.waitstatus_to_exitcode(os.waitpid(pid, 0)[1]))
"""


@pytest.mark.timeout(180)
def test_a_forkserver_no_pool_used_is_ended_as_its_process_exits(tmp_path):
    """It holds the process's stdout and stderr: left to finish its preload, a caller reading
    them through a pipe would wait it out after a command that stopped at once. Ended by a
    SIGTERM at exit (its preload's warm-up flight cleaning up its temporary directory); a
    forkserver a pool used is left to end with the process, as before."""
    env = dict(os.environ, TMPDIR=str(tmp_path))
    ended = subprocess.run([sys.executable, "-c", _AT_EXIT, "none"], capture_output=True,
                           text=True, timeout=60, check=True, env=env)
    assert int(ended.stdout) in (-15, 128 + 15)  # SIGTERM: by default, or the preload's exit
    assert not list(tmp_path.glob("ardrone-nmpc-warm-*"))
    used = subprocess.run([sys.executable, "-c", _AT_EXIT, "pool"], capture_output=True,
                          text=True, timeout=120, check=True, env=env)
    assert used.stdout.strip() == "running"
