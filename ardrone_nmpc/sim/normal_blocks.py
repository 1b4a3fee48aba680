"""Standard normal draws of one numpy ``Generator``, drawn a block at a time.

The plant draws a few normals per sensor sample and per advance (6 per mocap pose, 7 per
navdata sample, 3 for the sensor biases …); one ``standard_normal(k)`` call per draw costs
more than the arithmetic, and the compiled lockstep run
(:func:`~ardrone_nmpc.sim.sensor_step.lockstep_run`) cannot draw from a numpy ``Generator``
itself. So the draws come from a block drawn ahead: ``Generator.standard_normal(size)`` fills
its output one ``random_standard_normal`` at a time from the bit generator, so a block of
``N`` values is the concatenation of any sequence of calls drawing ``N`` in all — the same
values in the same order (tests/unit/test_normal_blocks.py holds it to that).

A new block carries the values of the last one not consumed yet and draws on from where
the generator stands (after the last block): the same sequence, each value drawn once.

The generator may have other users (the plant's per-flight biases draw uniforms from the
stream of its bias normals): :meth:`NormalBlocks.sync` first puts it where drawing only the
values consumed so far would have left it (its state before the first block since the last
sync, then the values consumed since drawn again), so every draw after is the one it was.
"""

from __future__ import annotations

import numpy as np

__all__ = ["NormalBlocks"]

#: values drawn per block: a few hundred ticks of one stream
BLOCK_SIZE = 1024


class NormalBlocks:
    """The standard normals of ``rng``, drawn ``block`` at a time (module docstring).

    :attr:`values` holds the block, :attr:`pos` the number consumed: the compiled run reads
    ``values[pos:]`` and hands back the new ``pos``.
    """

    __slots__ = ("rng", "block", "values", "pos", "_state", "_skip")

    def __init__(self, rng: np.random.Generator, block: int = BLOCK_SIZE) -> None:
        self.rng = rng
        self.block = int(block)
        self.values = np.empty(0)
        self.pos = 0
        self._state = None  # the generator's state before the blocks since the last sync …
        self._skip = 0      # … and the values drawn from it before ``values[0]``

    def take(self, n: int) -> np.ndarray:
        """The next ``n`` normals (a view: read it before the next call)."""
        pos = self.pos
        if pos + n > self.values.shape[0]:
            self.refill(n)
            pos = 0
        self.pos = pos + n
        return self.values[pos:pos + n]

    def ensure(self, n: int) -> None:
        """At least ``n`` values left in the block (for a compiled run that takes up to ``n``)."""
        if self.pos + n > self.values.shape[0]:
            self.refill(n)

    def refill(self, n: int = 0) -> None:
        """A new block (of at least ``n``) starting at the first value not consumed: those
        left carried, then ``max(block, n)`` drawn on (module docstring)."""
        fresh = max(self.block, n)
        if self._state is None:  # the generator stands where the consumed values left it
            self._state = self.rng.bit_generator.state
            self._skip = 0
            self.values = self.rng.standard_normal(fresh)
        else:  # … after the last block: its values left come first
            self._skip += self.pos
            self.values = np.concatenate((self.values[self.pos:],
                                          self.rng.standard_normal(fresh)))
        self.pos = 0

    def sync(self) -> None:
        """Leave the generator where drawing only the consumed values would have; the block
        is dropped (the next take draws a new one)."""
        if self._state is None:
            return
        self.rng.bit_generator.state = self._state
        consumed = self._skip + self.pos
        if consumed:
            self.rng.standard_normal(consumed)
        self._state = None
        self._skip = 0
        self.values = np.empty(0)
        self.pos = 0
