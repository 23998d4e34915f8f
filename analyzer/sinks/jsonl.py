"""JSONL output: the contract of docs/contracts.md, one object per record, in stream order.

Source events (a port lost or reopened, drops) are records of their own ``kind`` ("event"), in
time order with the frames.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import IO

import orjson

from decoders.model import Record

from ..model import SourceEvent
from ..session.batches import records_jsonl
from ..session.listener import Listener


class JsonlListener(Listener):
    def __init__(self, out: IO[bytes]) -> None:
        self.out = out
        self.label = f"JSONL output to {getattr(out, 'name', 'a stream')}"

    def on_records(self, records: Sequence[Record]) -> None:
        self.out.write(records_jsonl(records))

    def on_event(self, event: SourceEvent) -> None:
        self.out.write(orjson.dumps(event.to_dict()) + b"\n")

    def tick(self, now: float) -> None:
        self.out.flush()

    def close(self) -> None:
        self.out.flush()
