"""Imported by the local pool's forkserver (:mod:`ardrone_nmpc.experiments.parallel`: sweep,
tune, faults): loads every numba kernel a case uses, once, so the workers forked from it start
warm.

Importing this module runs a 0.2 s lockstep simulation into a temporary directory (~2 s);
nothing else imports it.
"""

import gc
import signal

# Ctrl-C is the sweep's parent process's to handle (the forkserver ignores SIGINT itself,
# but only once its preload is done: without this a Ctrl-C now prints its traceback).
signal.signal(signal.SIGINT, signal.SIG_IGN)

from ardrone_nmpc.experiments.sweep import warm_up  # noqa: E402 - after the signal disposition

warm_up()
# The warm heap (modules, numba's dispatchers and types: ~135 000 objects) lives as long as the
# process: moved out of the collector's generations, each full collection in a worker walks
# only what the flights made since (~1 ms) instead of it all (~60–80 ms, one every few dozen
# flights). Inherited by the workers forked from here; what is frozen is never collected
# (the warm-up flight's few cycles of garbage stay).
gc.freeze()
