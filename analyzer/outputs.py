"""Live-session outputs: decoded text on a stream, and the MCAP recording."""

from __future__ import annotations

import sys
import time
from typing import IO, Any

from decoders.model import Record

from .live import OutputBase
from .pipeline import Item
from .sinks.jsonl import JsonlSink
from .sinks.text import TextSink, format_event
from .sources.live import SourceEvent
from .tracker import DeviceState


class TextOutput(OutputBase):
    """Decoded lines and source events, flushed after every batch so a terminal stays live."""

    def __init__(self, out: IO[str] | None = None, colour: bool | None = None) -> None:
        self.out = out or sys.stdout
        # live: time counts from the session's start (buses interleave around any first record)
        self.sink = TextSink(self.out, colour=colour, t0=time.time())

    def records(self, records: list[Record]) -> None:
        self.sink.write(records)

    def event(self, event: SourceEvent) -> None:
        colour = self.sink.formatter.colour
        self.out.write(format_event(event.message, event.bus, event.level, colour) + "\n")

    def tick(self) -> None:
        self.out.flush()


class JsonlOutput(OutputBase):
    def __init__(self, out: IO[bytes] | None = None) -> None:
        self.sink = JsonlSink(out or sys.stdout.buffer)

    def records(self, records: list[Record]) -> None:
        self.sink.write(records)

    def tick(self) -> None:
        self.sink.out.flush()


class McapOutput(OutputBase):
    """Raw input, decoded records, device states and events into an MCAP recording."""

    def __init__(self, recorder: Any) -> None:
        self.recorder = recorder

    def items(self, items: list[Item]) -> None:
        for item in items:
            self.recorder.write_item(item)

    def records(self, records: list[Record]) -> None:
        for rec in records:
            self.recorder.write_record(rec)

    def states(self, states: list[DeviceState]) -> None:
        for st in states:
            self.recorder.write_state(st.to_dict())

    def event(self, event: SourceEvent) -> None:
        self.recorder.write_event(event)

    def tick(self) -> None:
        self.recorder.tick()

    def close(self) -> None:
        self.recorder.close()
