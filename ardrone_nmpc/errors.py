"""The user-facing error base and the command line's exit codes.

Every error a user can cause or must act on (a bad config, an unreadable run directory, a
file that cannot be written, a flight that ended early) subclasses :class:`UserError`. The
command line prints it as ``error: <line>`` on stderr, one line per entry of
:attr:`UserError.messages`, and exits with its :attr:`UserError.exit_code` — never a
traceback. Anything else that escapes a command is a bug and keeps its traceback.

Exit codes of ``ardrone-nmpc`` (also in ``ardrone-nmpc --help``):

====  ===============================================================================
0     success
1     an error in what the command was given or had to do: a config, a file, a run
      directory, a flight that ended early or without a confirmed landing
2     the command line itself: an unknown option, a missing argument, an option value
      that is not a number or outside its range
130   interrupted (Ctrl-C, SIGINT); a sweep resumes when re-run, a tune with ``--resume``
143   terminated (SIGTERM); ``fly`` lands first; any other terminating signal (SIGHUP,
      SIGQUIT, SIGUSR1/2): 128 + its number, the same way
====  ===============================================================================

This module imports nothing, so every layer may raise these errors.
"""

from __future__ import annotations

__all__ = ["EXIT_ERROR", "EXIT_INTERRUPTED", "EXIT_OK", "EXIT_TERMINATED", "EXIT_USAGE",
           "UserError"]

EXIT_OK = 0
#: A user error (:class:`UserError`): bad input, a file that cannot be read or written.
EXIT_ERROR = 1
#: The command line cannot be parsed, or an option value is out of its range.
EXIT_USAGE = 2
#: Ctrl-C (128 + SIGINT).
EXIT_INTERRUPTED = 130
#: SIGTERM (128 + SIGTERM).
EXIT_TERMINATED = 143


class UserError(Exception):
    """An error the user can act on: printed as ``error: …`` lines, no traceback.

    ``messages`` are the lines (default: the exception's text, one entry per line);
    ``exit_code`` is the process exit code the command line ends with (default 1,
    :data:`EXIT_ERROR`).
    """

    exit_code: int = EXIT_ERROR

    @property
    def messages(self) -> list[str]:
        explicit = self.__dict__.get("_messages")
        if explicit is not None:
            return list(explicit)
        return str(self).splitlines() or [type(self).__name__]

    @messages.setter
    def messages(self, lines: list[str]) -> None:
        self._messages = list(lines)
