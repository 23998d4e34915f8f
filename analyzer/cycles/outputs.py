"""Where cycles go: text for people, JSONL, CSV and Parquet (docs/contracts.md, "Grip cycles").

Each output takes the cycles as they end (``write``), and is flushed on the session's ticks and
closed at its end. Parquet's is in ``parquet.py`` (pyarrow is imported only there); the run
chooses one by its format (``run.make_output``).
"""

from __future__ import annotations

import csv
from typing import IO, Any, Final

import orjson

from .model import KEYS, Cycle, CycleCounts

FORMATS: Final = ("text", "jsonl", "csv", "parquet")
BINARY: Final = frozenset({"jsonl", "parquet"})
_LISTS: Final = ("faults", "warnings", "unknown", "evidence")


class CycleOutput:
    """An output of cycles. ``t0``: the capture's first time (the text shows times from it);
    set by the listener from the first record."""

    label = "cycles output"
    t0: float | None = None
    #: it counts cycles, no more: the listener may call ``write_counts`` instead of ``write``
    #: (the native segmenter then makes no ``Cycle`` for it)
    counts_only = False

    def write(self, cycles: list[Cycle]) -> None:
        raise NotImplementedError

    def write_counts(self, counts: list[CycleCounts]) -> None:
        """``write``'s cycles as ``counts_of`` counts them (for a ``counts_only`` output)."""
        raise NotImplementedError

    def flush(self) -> None:
        """Called on the session's ticks."""

    def close(self) -> None:
        """The session is over."""


class StreamOutput(CycleOutput):
    """An output on an open stream."""

    def __init__(self, out: IO[Any]) -> None:
        self.out = out
        self.label = f"cycles output to {getattr(out, 'name', 'a stream')}"

    def write(self, cycles: list[Cycle]) -> None:
        raise NotImplementedError

    def flush(self) -> None:
        self.out.flush()

    def close(self) -> None:
        self.out.flush()


class JsonlCycles(StreamOutput):
    """One JSON object per cycle (``Cycle.to_dict``)."""

    def write(self, cycles: list[Cycle]) -> None:
        dumps = orjson.dumps
        self.out.write(b"".join([dumps(c.to_dict()) + b"\n" for c in cycles]))


class CsvCycles(StreamOutput):
    """The JSONL keys as columns; lists joined with "; "; an empty cell is a null."""

    def __init__(self, out: IO[str]) -> None:
        super().__init__(out)
        self.writer = csv.writer(out)
        self.writer.writerow(KEYS)

    def write(self, cycles: list[Cycle]) -> None:
        rows = []
        for cycle in cycles:
            d = cycle.to_dict()
            for key in _LISTS:
                d[key] = "; ".join(map(str, d[key]))
            rows.append(["" if d[k] is None else d[k] for k in KEYS])
        self.writer.writerows(rows)


class TextCycles(StreamOutput):
    """One line per cycle: when it began (seconds from the capture's first record, or ``@seq``
    without times), bus, gripper, outcome, the command in words, then what was measured."""

    def write(self, cycles: list[Cycle]) -> None:
        self.out.write("".join([self.line(c) + "\n" for c in cycles]))

    def line(self, c: Cycle) -> str:
        if c.start_t is None:
            when = f"@{c.start_seq}".rjust(11)
        else:
            when = f"{c.start_t - (self.t0 if self.t0 is not None else c.start_t):11.6f}"
        head = f"{when} {c.bus:6} ID {c.device:<5} {c.outcome:12} {c.command}"
        return f"{head}  [{', '.join(details(c))}]"


def details(c: Cycle) -> list[str]:
    """What a cycle measured, in words."""
    words = []
    if c.width_mm is not None:
        words.append(f"width {c.width_mm} mm")
    if c.force_peak is not None:
        words.append(f"force peak {c.force_peak}")
    if c.time_to_contact_ms is not None:
        words.append(f"contact {c.time_to_contact_ms:.1f} ms")
    if c.settle_ms is not None:
        words.append(f"settled {c.settle_ms:.1f} ms")
    if c.retries:
        words.append(f"{c.retries} retr{'y' if c.retries == 1 else 'ies'}")
    if c.faults:
        words.append("faults: " + ", ".join(c.faults))
    words += [f"warning: {w}" for w in c.warnings]
    if c.unknown:
        words.append("not read: " + ", ".join(c.unknown))
    words.append(f"frames {c.start_seq}-{c.end_seq}")
    return words
