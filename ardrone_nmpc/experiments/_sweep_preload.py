"""Imported by the local pool's forkserver (:mod:`ardrone_nmpc.experiments.parallel`: sweep,
tune, faults): loads every numba kernel a case uses, once, so the workers forked from it start
warm.

Importing this module runs a 0.2 s lockstep simulation into a temporary directory (~2 s) and
sets the garbage collector for processes that fly one flight after another (below); nothing
else imports it.
"""

import gc
import signal

# Ctrl-C is the sweep's parent process's to handle (the forkserver ignores SIGINT itself,
# but only once its preload is done: without this a Ctrl-C now prints its traceback).
signal.signal(signal.SIGINT, signal.SIG_IGN)

from ardrone_nmpc.experiments.sweep import warm_up  # noqa: E402 - after the signal disposition

warm_up()
# The collector, in the workers forked from here (they inherit its settings): garbage is still
# collected, only less often. The warm heap (modules, numba's dispatchers and types: ~135 000
# objects) lives as long as the process: frozen (moved out of the generations, never
# collected: the warm-up flight's few cycles of garbage stay), a full collection walks only
# what the flights made since (~1 ms) instead of it all (~60–80 ms, one every few dozen
# flights). A flight frees nearly all it allocates (its rows, when it ends): at the default
# 700 net allocations a young collection ran ~3 times a flight, walking the rows kept so far
# and finding no garbage (~1 ms a flight in all); at 10 000, about once in 20 flights.
gc.freeze()
gc.set_threshold(10_000, *gc.get_threshold()[1:])
