"""What ``eg2scope plot``'s logs show of decoded records (docs/rerun.md), gathered per bus and
per gripper in one pass: a bus's error log (every record with errors or warnings, in words,
``ERROR`` or ``WARN``; a record whose only flags say nothing is wrong is left out) and the times
its health rates count, a gripper's commands (requests that are not polls: ``WARN`` when
flagged) and its fault marks (records with errors or fault flags).

``log_rows`` asks the records' sequence (``rerun_log_rows``): a ``RecordSequence`` runs this
module's loop (``records_log_rows``, the reference), a native ``RecordBatch`` reads its records
without making a Record per record (native/src/bindings/python_rerun.rs; tests/rerun require the
same rows). A
warning-heavy capture shows most of its records in the logs.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any, Final, Protocol

from decoders.eg2_can import OP_READ
from decoders.eg2_serial import Cmd
from decoders.flags import DEVICE_FAULT, ESTIMATED_TIME, FOREIGN, UNANSWERED
from decoders.modbus_pdu import READ_HOLDING
from decoders.model import EG2_CAN, EG2_SERIAL, FRAME, MODBUS_RTU, REQUEST, Record

# requests that only read (polls), by (protocol, code): the readings are plotted, the polls
# are not listed as commands
POLLS: Final = frozenset(
    {(EG2_SERIAL, c.value) for c in Cmd if c.name.startswith("READ_")}
    | {(MODBUS_RTU, READ_HOLDING), (EG2_CAN, OP_READ)}
)
# flags that say nothing is wrong: not logged as problems
QUIET_FLAGS: Final = frozenset({FOREIGN, ESTIMATED_TIME})

_POLL_LIST: Final = sorted(POLLS)
_QUIET_LIST: Final = sorted(QUIET_FLAGS)

#: a log's rows: times (NaN: none), seqs, texts, levels
TextRows = tuple[list[float], list[int], list[str | None], list[str]]
#: a bus's error log (TextRows), then the times of its records that are no frames, that
#: have errors, and of its unanswered requests
BusRows = tuple[
    list[float], list[int], list[str | None], list[str], list[float], list[float], list[float]
]
#: a gripper's commands (TextRows), then its fault marks' times (NaN: none) and seqs
GripperRows = tuple[list[float], list[int], list[str | None], list[str], list[float], list[int]]


LogRows = tuple[dict[str, BusRows], dict[tuple[str, int], GripperRows]]


class LoggedRecords(Protocol):
    """What ``log_rows`` asks of a record sequence (``RecordSequence``, the native
    ``RecordBatch``); said here, not imported, as the session's sequences call this module."""

    def rerun_log_rows(self, polls: Sequence[Any], quiet: Sequence[str]) -> LogRows: ...


def log_rows(records: LoggedRecords) -> LogRows:
    """``(buses, grippers)``: each bus's and each gripper's rows, in the order first met
    (``records.rerun_log_rows``: a native batch makes no Record per record)."""
    rows: LogRows = records.rerun_log_rows(_POLL_LIST, _QUIET_LIST)
    return rows


def records_log_rows(
    records: Sequence[Record], polls: frozenset[tuple[str, int]], quiet: frozenset[str]
) -> LogRows:
    """``log_rows`` of Python Records (the reference the native ``rerun_log_rows`` follows);
    ``polls`` and ``quiet``: ``POLLS`` and ``QUIET_FLAGS``."""
    buses: dict[str, BusRows] = {}
    grippers: dict[tuple[str, int], GripperRows] = {}
    for rec in records:
        problem = bool(rec.errors or rec.warnings)
        command = rec.direction == REQUEST and (rec.protocol, rec.code) not in polls
        if not (problem or command):
            continue
        level = "INFO"
        if problem:
            level = _problem(rec, buses, grippers, command, quiet)
        if level and rec.device is not None and rec.kind == FRAME:
            g = grippers.get((rec.bus, rec.device)) or _new(grippers, (rec.bus, rec.device))
            _add(g, rec, rec.summary or rec.name, level)
    return buses, grippers


def _problem(
    rec: Record,
    buses: dict[str, BusRows],
    grippers: dict[tuple[str, int], GripperRows],
    command: bool,
    quiet_flags: frozenset[str],
) -> str:
    """A record with errors or warnings into its bus's rows (and a fault mark); the level of
    its command, "" for none."""
    bus = buses.get(rec.bus) or _new(buses, rec.bus, 7)
    quiet = bool(rec.flags) and quiet_flags.issuperset(rec.flags)  # nothing wrong
    if rec.errors:
        _add(bus, rec, problem_text(rec), "ERROR")
    elif not quiet:
        _add(bus, rec, problem_text(rec), "WARN")
    t = rec.t
    if t is not None:
        if rec.kind != FRAME:
            bus[4].append(t)
        if rec.errors:
            bus[5].append(t)
        if UNANSWERED in rec.flags:
            bus[6].append(t)
    if rec.device is not None and (rec.errors or DEVICE_FAULT in rec.flags):
        g = grippers.get((rec.bus, rec.device)) or _new(grippers, (rec.bus, rec.device))
        g[4].append(math.nan if t is None else t)
        g[5].append(rec.seq)
        return ""
    return ("INFO" if quiet else "WARN") if command else ""


def _new(rows: dict[Any, Any], key: Any, n: int = 6) -> Any:
    new = rows[key] = tuple([] for _ in range(n))
    return new


def _add(rows: Any, rec: Record, text: str | None, level: str) -> None:
    rows[0].append(math.nan if rec.t is None else rec.t)
    rows[1].append(rec.seq)
    rows[2].append(text)
    rows[3].append(level)


def problem_text(rec: Record) -> str:
    who = f"ID {rec.device} " if rec.device is not None else ""
    what = rec.summary or rec.name or rec.kind
    return f"{who}{what}: {'; '.join([*rec.errors, *rec.warnings])}"
