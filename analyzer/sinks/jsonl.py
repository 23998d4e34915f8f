"""JSONL output: the contract of docs/contracts.md, one object per record, in stream order.

Source events (a port lost or reopened, drops) are records of their own ``kind`` ("event"), in
time order with the frames.
"""

from __future__ import annotations

from typing import IO, TYPE_CHECKING

import orjson

from ..model import SourceEvent
from ..session.listener import Listener

if TYPE_CHECKING:
    from ..session.batches import RecordSequence


class JsonlListener(Listener):
    def __init__(self, out: IO[bytes]) -> None:
        self.out = out
        self.label = f"JSONL output to {getattr(out, 'name', 'a stream')}"

    def on_records(self, records: RecordSequence) -> None:
        self.out.write(records.jsonl())

    def on_event(self, event: SourceEvent) -> None:
        self.out.write(orjson.dumps(event.to_dict()) + b"\n")

    def tick(self, now: float) -> None:
        self.out.flush()

    def close(self) -> None:
        self.out.flush()
