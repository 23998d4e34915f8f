"""JSONL output: the contract of DESIGN.md, one object per record, in stream order."""

from __future__ import annotations

from typing import IO

import orjson

from decoders.model import Record


class JsonlSink:
    def __init__(self, out: IO[bytes]) -> None:
        self.out = out

    def write(self, records: list[Record]) -> None:
        dumps = orjson.dumps
        self.out.write(b"".join([dumps(r.to_dict()) + b"\n" for r in records]))

    def close(self) -> None:
        self.out.flush()
