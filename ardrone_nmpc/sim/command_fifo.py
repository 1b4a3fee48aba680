"""The plant's command transport delay: the PCMDs sent and not yet acting, oldest first.

A ring of rows ``(roll, pitch, gaz, yaw, position_hold as 0/1)`` in one array, so the compiled
flying steps (:func:`~ardrone_nmpc.sim.airframe.flying_steps`) shift it in place, and the
step-by-step path one command at a time (:meth:`CommandFifo.shift`): both see the same queue.
"""

from __future__ import annotations

import numpy as np

__all__ = ["CommandFifo"]


def _command(row: list) -> tuple:
    return (row[0], row[1], row[2], row[3], row[4] != 0.0)


class CommandFifo:
    """``commands`` (oldest first, each a 5-tuple as the plant holds its command) in a ring:
    :attr:`rows` (n, 5) with the oldest at :attr:`head`."""

    def __init__(self, commands: list) -> None:
        self.rows = np.array(commands, dtype=np.float64).reshape(len(commands), 5)
        self.head = 0

    def __len__(self) -> int:
        return self.rows.shape[0]

    def shift(self, current: tuple) -> tuple:
        """Queue ``current`` and return the oldest command (``current`` itself when the queue
        is empty: no delay)."""
        n = self.rows.shape[0]
        if n == 0:
            return current
        head = self.head
        delayed = _command(self.rows[head].tolist())
        self.rows[head] = current
        self.head = head + 1 if head + 1 < n else 0
        return delayed

    def commands(self) -> list[tuple]:
        """The queue, oldest first."""
        rows = self.rows.tolist()
        return [_command(row) for row in rows[self.head:] + rows[:self.head]]

    def resized(self, n: int, current: tuple) -> CommandFifo:
        """The queue of length ``n``: a longer one repeats the oldest command (``current`` if
        there is none), a shorter one drops the oldest."""
        commands = self.commands()
        oldest = commands[0] if commands else current
        if n > len(commands):
            commands = [oldest] * (n - len(commands)) + commands
        return CommandFifo(commands[len(commands) - n:])
