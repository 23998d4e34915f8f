"""What every ``--help`` shares: one formatter (prose wrapped to the terminal, examples and
key tables kept as written), the exit-status paragraphs the epilogs end with, and the words
for a capture file."""

from __future__ import annotations

import argparse
import textwrap
from typing import Final

#: every command (``eg2scope --help``)
EXIT_STATUS: Final = (
    "exit status: 0 done (a live capture stopped with Ctrl-C, SIGTERM or SIGHUP is done: "
    "its recording is finished); 1 error (a file that cannot be read or written, a live "
    "source that never opened, a device that failed); 2 usage error; 3 decoded as far as "
    "possible, but the input is damaged; 130 a file job (decode, stats, batch, plot, tui or cycles "
    "of a capture) interrupted before the end of its input"
)
#: a capture file's job: decode, stats
FILE_EXIT_STATUS: Final = (
    "exit status: 0 decoded (an empty capture is said so on stderr); 1 error (a file that "
    "cannot be read or written); 2 usage error; 3 decoded as far as possible, but the input "
    "is damaged (see the messages on stderr); 130 interrupted (Ctrl-C, SIGTERM) before the "
    "end of the input"
)
#: a command that runs until it is stopped: live, record, demo, bridge, sim
LIVE_EXIT_STATUS: Final = (
    "exit status: 0 stopped (Ctrl-C, SIGTERM or SIGHUP, or the end of --duration: the "
    "recording is finished); 1 error (a source that does not open, a device that failed, an "
    "output that cannot be written); 2 usage error"
)
#: batch
BATCH_EXIT_STATUS: Final = (
    "exit status: 0 every capture decoded; 1 a capture could not be read or written (the "
    "others are in the dataset), or the dataset folder cannot be made; 2 usage error; 3 some "
    "capture is damaged (decoded as far as possible, marked in captures/); 130 interrupted by "
    "Ctrl-C, SIGTERM or SIGHUP (run again to finish)"
)

#: a capture file, as every command that reads one takes it
CAPTURE_FILE: Final = (
    "capture to read, its format told by its content whatever its name: a candump log in any "
    "layout, a PCAN trace (.trc, 1.0-2.1), Vector .asc/.blf, python-can .csv, ASAM .mf4, an "
    "eg2scope .mcap recording (text logs also .gz), or any other file as raw serial bytes "
    "(.gz too)"
)


def epilog(*blocks: str) -> str:
    """An epilog of blocks (examples, notes, an exit-status paragraph), a blank line apart."""
    return "\n\n".join(blocks)


class HelpFormatter(argparse.HelpFormatter):
    """argparse's formatter, paragraph by paragraph: prose is wrapped to the terminal's width;
    a paragraph laid out in indented lines (examples, a key table) is kept as written."""

    def _fill_text(self, text: str, width: int, indent: str) -> str:
        return "\n\n".join(self._paragraph(p, width, indent) for p in text.split("\n\n"))

    def _paragraph(self, text: str, width: int, indent: str) -> str:
        lines = text.splitlines()
        if any(line.startswith(" ") for line in lines):  # a layout
            return "\n".join(indent + line for line in lines)
        words = " ".join(text.split())
        return textwrap.fill(words, width, initial_indent=indent, subsequent_indent=indent)
