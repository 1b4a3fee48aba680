"""Imported by the local pool's forkserver (:mod:`ardrone_nmpc.experiments.parallel`: sweep,
tune, faults): loads every numba kernel a case uses, once, so the workers forked from it start
warm.

Importing this module runs a 0.2 s lockstep simulation into a temporary directory and sets the
garbage collector for processes that fly one flight after another
(:func:`~ardrone_nmpc.experiments.sweep.cases.warm_worker`); nothing else imports it. On
cached kernels ~0.8 s on one core, measured: the imports ~0.45 s (numba and numpy ~0.2 s),
numba's one-time set-up of its compiler ~0.25 s (its registries; ``scipy.linalg`` among them,
to find a BLAS), the flight ~0.08 s — the ~22 kernels' loading ~0.05 s of it. The entry
point starts it before it parses the command line (``cli/launch.py``), to run beside that.
"""

import signal

# Ctrl-C is the sweep's parent process's to handle (the forkserver ignores SIGINT itself,
# but only once its preload is done: without this a Ctrl-C now prints its traceback).
signal.signal(signal.SIGINT, signal.SIG_IGN)


def _stop(signum, frame):
    """SIGTERM during the preload (a forkserver no pool used, parallel.py): end, cleaning up
    the warm-up flight's temporary directory."""
    raise SystemExit(128 + signum)


signal.signal(signal.SIGTERM, _stop)
try:
    from ardrone_nmpc.experiments.sweep import warm_worker

    warm_worker()
finally:  # the forkserver and the workers it forks: SIGTERM's default again
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
