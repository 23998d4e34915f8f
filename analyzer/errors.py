"""The errors the command line turns into exit codes (docs/contracts.md, "Exit codes").

- ``UsageError``: the command asks for something impossible (a negative count, an unknown
  interface, an output that is the input); nothing was read or written. Exit 2.
- ``SourceError``: a live source never opened (no such port, no such CAN interface, a driver
  missing); nothing was captured or written. Exit 1.
Any other ``OSError``/``ValueError`` is exit 1. An input decoded as far as it goes but damaged
is no exception: the command reports each damage where it is and returns ``EXIT_DAMAGED`` (3).

A command that runs until it is stopped (a live capture, the simulator) ends cleanly, exit 0,
on Ctrl-C, SIGTERM or SIGHUP, as candump and tcpdump do; a file job interrupted before the end
of its input exits 130 (``stop_status``).
"""

from __future__ import annotations

from typing import Final

EXIT_OK: Final = 0
EXIT_ERROR: Final = 1
EXIT_USAGE: Final = 2
EXIT_DAMAGED: Final = 3
EXIT_INTERRUPTED: Final = 130


class UsageError(ValueError):
    """The command line asks for something that cannot be done (exit 2)."""


class SourceError(OSError):
    """A live source never opened: the message names the device and says why (exit 1)."""


def stop_status(until_stopped: bool) -> int:
    """The exit status of a command ended by Ctrl-C, SIGTERM or SIGHUP: 0 for a command that
    runs until stopped (stopping it is how it ends), 130 for a file job cut short."""
    return EXIT_OK if until_stopped else EXIT_INTERRUPTED
