"""CSV output for spreadsheets: the JSONL keys as columns, fields as a JSON string, the lists
(errors, warnings, flags) joined with "; ". Source events have no row (see the JSONL output)."""

from __future__ import annotations

import csv
from collections.abc import Sequence
from typing import IO

import orjson

from decoders.model import Record

from ..session.listener import Listener

COLUMNS = (
    "seq",
    "t",
    "bus",
    "protocol",
    "kind",
    "offset",
    "index",
    "length",
    "direction",
    "device",
    "code",
    "name",
    "summary",
    "fields",
    "raw",
    "errors",
    "warnings",
    "flags",
    "pair",
    "latency_ms",
)
_JOINED = ("errors", "warnings", "flags")


class CsvListener(Listener):
    def __init__(self, out: IO[str], header: bool = True) -> None:
        self.out = out
        self.writer = csv.writer(out)
        self.label = f"CSV output to {getattr(out, 'name', 'a stream')}"
        if header:
            self.writer.writerow(COLUMNS)

    def on_records(self, records: Sequence[Record]) -> None:
        rows = []
        for r in records:
            d = r.to_dict()
            d["fields"] = orjson.dumps(r.fields).decode()
            for key in _JOINED:
                d[key] = "; ".join(d[key])
            rows.append(["" if d[c] is None else d[c] for c in COLUMNS])
        self.writer.writerows(rows)

    def tick(self, now: float) -> None:
        self.out.flush()

    def close(self) -> None:
        self.out.flush()
