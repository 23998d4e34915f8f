"""The errors the command line turns into exit codes (docs/contracts.md, "Exit codes").

- ``UsageError``: the command asks for something impossible (a negative count, an unknown
  interface, an output that is the input); nothing was read or written. Exit 2.
- ``DamagedInput``: the input was decoded as far as it goes, but it is damaged. Exit 3.
Any other ``OSError``/``ValueError`` is exit 1.
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


class DamagedInput(Exception):
    """The input was decoded as far as possible but is damaged (exit 3)."""
