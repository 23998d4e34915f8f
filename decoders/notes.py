"""The errors and warnings found while decoding one frame, each with its flag code.

A decoder says what is wrong in words for people and in a code (``decoders/flags.py``) for
programs; collecting both in one call keeps every text with its code.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from .messages import Message


class Notes:
    """Errors, warnings and their flag codes, in the order they were found (codes once)."""

    __slots__ = ("errors", "flags", "warnings")

    def __init__(self) -> None:
        self.errors: list[str] = []
        self.warnings: list[str] = []
        self.flags: list[str] = []

    def error(self, code: str, text: str) -> None:
        self.errors.append(text)
        if code not in self.flags:
            self.flags.append(code)

    def warn(self, code: str, text: str) -> None:
        self.warnings.append(text)
        if code not in self.flags:
            self.flags.append(code)

    def error_of(self, message: Message, **values: object) -> None:
        """An error in a catalogue's words (``decoders/messages.py``), with its code."""
        self.error(message.code, message.text(**values))

    def warn_of(self, message: Message, **values: object) -> None:
        """A warning in a catalogue's words (``decoders/messages.py``), with its code."""
        self.warn(message.code, message.text(**values))

    def flag(self, code: str) -> None:
        """A code without words (the record says it otherwise, as an exception response
        does in its summary)."""
        if code not in self.flags:
            self.flags.append(code)
