"""What the Rerun view's logs show of a batch of records, as columns: the records with errors or
warnings (the bus's error log, its health counts, the red marks on the force plot) and the
controller's commands (its grippers' command logs).

A capture in which every command draws a warning shows most of its records here, so they are
read as columns (``batches.column``: a native batch makes no record, which costs less than
making the records shown) and sorted into the logs with boolean arrays; only the text of a
logged row is made one at a time.
"""

from __future__ import annotations

from collections.abc import Sequence
from itertools import compress, repeat
from operator import attrgetter, contains, eq, itemgetter
from typing import Any, Final

import numpy as np

from decoders.eg2_can import OP_READ
from decoders.eg2_serial import Cmd
from decoders.flags import DEVICE_FAULT, ESTIMATED_TIME, FOREIGN, UNANSWERED
from decoders.modbus_pdu import READ_HOLDING
from decoders.model import EG2_CAN, EG2_SERIAL, FRAME, MODBUS_RTU, REQUEST, Record

from ..batches import RecordBatch, column, problem_indexes

# requests that only read (polls), by (protocol, code): the readings are plotted, the polls
# are not listed as commands
POLLS: Final = frozenset(
    {(EG2_SERIAL, c.value) for c in Cmd if c.name.startswith("READ_")}
    | {(MODBUS_RTU, READ_HOLDING), (EG2_CAN, OP_READ)}
)
# flags that say nothing is wrong: not logged as problems
QUIET_FLAGS: Final = frozenset({FOREIGN, ESTIMATED_TIME})
ERROR: Final = "ERROR"
WARN: Final = "WARN"
INFO: Final = "INFO"


def _flags(flags: list[list[str]], test: Any) -> np.ndarray:
    return np.fromiter(map(test, flags), bool, len(flags))


class ShownRecords:
    """The records of one batch that the logs show, in order, a column per attribute
    (``index``: their places in the batch), and what each is shown as:

    - ``logged``: a row of the error log, at ``levels`` ERROR (errors) or WARN (warnings that
      say something is wrong);
    - ``marked``: a red mark on its gripper's force plot (errors, or the gripper's fault bits);
    - ``command``: a row of its gripper's command log (a request that is not a poll, unless it
      is marked), at ``command_levels`` INFO or WARN (flagged);
    - ``nonframe``, ``error``, ``unanswered``: counted in the bus's health (timed rows only).
    """

    def __init__(self, records: Sequence[Record], stamps: np.ndarray, seqs: np.ndarray) -> None:
        problems = problem_indexes(records)
        directions = column(records, "direction")
        asks = list(compress(range(len(directions)), map(eq, directions, repeat(REQUEST))))
        if asks:
            protocols, codes = column(records, "protocol"), column(records, "code")
            asks = [i for i in asks if (protocols[i], codes[i]) not in POLLS]
        index = sorted(set(problems).union(asks)) if asks else problems
        self.index = np.array(index, dtype=np.int64)
        n = len(index)
        self.t = stamps[self.index]
        self.seq = seqs[self.index]
        picked = _columns_of(records, index)
        self.device, self.kind, errors, warnings, flags, self.summary, self.name = picked
        self.errors, self.warnings = errors, warnings
        has_error = np.fromiter(map(bool, errors), bool, n)
        problem = has_error | np.fromiter(map(bool, warnings), bool, n)
        quiet = _flags(flags, bool) & _flags(flags, QUIET_FLAGS.issuperset)  # nothing wrong
        known = np.fromiter((d is not None for d in self.device), bool, n)
        frame = np.fromiter(map(eq, self.kind, repeat(FRAME)), bool, n)
        ask = np.zeros(len(directions), bool)
        ask[asks] = True
        ask = ask[self.index]
        timed = ~np.isnan(self.t)
        self.logged = has_error | (problem & ~quiet)
        self.levels = np.where(has_error, ERROR, WARN)
        fault = np.fromiter(map(contains, flags, repeat(DEVICE_FAULT)), bool, n)
        self.marked = problem & known & (has_error | fault)
        self.command = ask & known & frame & ~self.marked
        self.command_levels = np.where(problem & ~quiet, WARN, INFO)
        self.nonframe = problem & timed & ~frame
        self.error = has_error & timed
        unanswered = np.fromiter(map(contains, flags, repeat(UNANSWERED)), bool, n)
        self.unanswered = problem & timed & unanswered

    def __len__(self) -> int:
        return len(self.index)

    def between(self, lo: int, hi: int) -> slice:
        """The rows of the records at places ``lo`` to ``hi`` of the batch (one bus's run)."""
        a, b = np.searchsorted(self.index, (lo, hi))
        return slice(int(a), int(b))

    def texts(self, rows: np.ndarray) -> list[str]:
        """The error log's words for ``rows``: who, what, and every error and warning."""
        device, summary, name, kind = self.device, self.summary, self.name, self.kind
        errors, warnings = self.errors, self.warnings
        return [
            f"{'' if device[i] is None else f'ID {device[i]} '}"
            f"{summary[i] or name[i] or kind[i]}: {'; '.join([*errors[i], *warnings[i]])}"
            for i in rows.tolist()
        ]

    def command_texts(self, rows: np.ndarray) -> list[str]:
        summary, name = self.summary, self.name
        return [summary[i] or name[i] for i in rows.tolist()]


# the attributes read for the rows shown (in ShownRecords.__init__'s order)
_READ: Final = ("device", "kind", "errors", "warnings", "flags", "summary", "name")
# below this share of a native batch shown, making the records shown costs less than reading
# whole columns (about 6.5 us a record against 1.2 us a record of the batch for all of _READ)
_FEW: Final = 0.2


def _columns_of(records: Sequence[Record], index: list[int]) -> list[list[Any]]:
    """The attributes of _READ of the records at ``index``, a list per attribute."""
    if not index:
        return [[] for _ in _READ]
    if isinstance(records, RecordBatch) and len(index) >= _FEW * len(records):
        pick = itemgetter(*index) if len(index) > 1 else lambda c: [c[index[0]]]
        return [list(pick(column(records, name))) for name in _READ]
    shown = [records[i] for i in index]
    return [list(map(attrgetter(name), shown)) for name in _READ]
