"""Lockstep flights with the tick's stages watched after every tick: the one home of the
flights that compare the compiled calls with the Python stages (test_after_solve,
test_control_tick)."""

from __future__ import annotations

from typing import Callable

from ardrone_nmpc.runs.memory import MemoryRecorder
from ardrone_nmpc.runtime import lockstep
from ardrone_nmpc.runtime.lockstep import run_lockstep
from ardrone_nmpc.runtime.tick import Tick


def carried(tick: Tick) -> list:
    """Everything the stages carry to the next tick, as bits (and the types of numbers)."""
    s, d, sup, r, o = tick.supervision, tick.delay, tick.supervisor, tick.response, tick.offset
    c, nmpc = tick.control, tick.control.nmpc
    last = None if s._last is None else (repr(s._last[0]), s._last[1].tobytes())
    return [d.ring.tobytes(), d._next, d.first, d.count, d._pushed, d.lead_s, repr(s.zacc_mps2),
            repr(s.vz_ref_mps), repr(s.attitude_gain), last, sup._solver_failures,
            sup._solver_good, sup._solver_fallback, sup._latched, sup.label,
            tick.estimation._state.tobytes(), c._x_solve.tobytes(), c._states.tobytes(),
            None if nmpc is None else (nmpc.memory.snapshot().tobytes(), nmpc._t0_s),
            None if r is None else (r.estimator._state.tobytes(), r.estimator._estimate is None,
                                    r._next_fit_s),
            None if o is None else (o.integrator._work.tobytes(), o.integrator._flags.tobytes())]


def fly(cfg, monkeypatch, *, use: Callable[[Tick], None],
        watch: tuple[type, str, Callable] | None = None, lane=None) -> tuple[list, list, list]:
    """A lockstep flight's rows, events and the stages' state after each tick (``carried``).

    ``use(tick)`` sets each built tick on its path; ``watch = (owner, name, tally)`` passes
    every answer of ``owner.name`` to ``tally``; ``lane`` takes ``Tick._nominal_cells``' place.
    Every tick its own (``BLOCK_TICKS`` 0: no block of ticks, whose ticks no step watches).
    """
    states = []
    init, step = Tick.__init__, Tick.step

    def new_init(self, *args, **kwargs):
        init(self, *args, **kwargs)
        use(self)

    def new_step(self, *args, **kwargs):
        out = step(self, *args, **kwargs)
        states.append(carried(self))
        return out

    with monkeypatch.context() as m:
        m.setattr(lockstep, "BLOCK_TICKS", 0)
        m.setattr(Tick, "__init__", new_init)
        m.setattr(Tick, "step", new_step)
        if watch is not None:
            owner, name, tally = watch
            original = getattr(owner, name)

            def watched(self, *args):
                answer = original(self, *args)
                tally(answer)
                return answer

            m.setattr(owner, name, watched)
        if lane is not None:
            m.setattr(Tick, "_nominal_cells", lane)
        recorder = MemoryRecorder()
        run_lockstep(cfg, recorder=recorder)
    return recorder.rows, recorder.events, states
