"""CSV output for spreadsheets: the JSONL keys as columns, fields as a JSON string."""

from __future__ import annotations

import csv
from typing import IO

import orjson

from decoders.model import Record

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
    "pair",
    "latency_ms",
)


class CsvSink:
    def __init__(self, out: IO[str], header: bool = True) -> None:
        self.out = out
        self.writer = csv.writer(out)
        if header:
            self.writer.writerow(COLUMNS)

    def write(self, records: list[Record]) -> None:
        rows = []
        for r in records:
            d = r.to_dict()
            d["fields"] = orjson.dumps(r.fields).decode()
            d["errors"] = "; ".join(r.errors)
            d["warnings"] = "; ".join(r.warnings)
            rows.append(["" if d[c] is None else d[c] for c in COLUMNS])
        self.writer.writerows(rows)

    def close(self) -> None:
        self.out.flush()
