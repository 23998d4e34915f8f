"""Export records from the store: JSONL and CSV (the ``decode`` contract and columns) and MCAP
(the recording layout: raw input rebuilt from each record's bytes, so ``eg2scope decode`` reads
the file back, plus the decoded records as they are)."""

from __future__ import annotations

import os
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Final

from decoders.model import EG2_CAN, FOREIGN_CAN, CanFrame, Chunk, Record

from ..model import Item
from ..recording.recorder import McapRecorder
from ..session.batches import RecordSequence
from ..sinks.csv import CsvListener
from ..sinks.jsonl import JsonlListener
from .store import RecordStore

FORMATS: Final = {".jsonl": "jsonl", ".json": "jsonl", ".csv": "csv", ".mcap": "mcap"}
BATCH: Final = 4096


def export_format(path: str) -> str:
    """The format a file name asks for; ValueError names the suffixes."""
    fmt = FORMATS.get(Path(path).suffix.lower())
    if fmt is None:
        raise ValueError(f"export to .jsonl, .csv or .mcap, not {Path(path).name!r}")
    return fmt


def _batches(records: Iterable[Record]) -> Iterator[RecordSequence]:
    batch = RecordSequence()
    for rec in records:
        batch.append(rec)
        if len(batch) >= BATCH:
            yield batch
            batch = RecordSequence()
    if batch:
        yield batch


def raw_item(rec: Record) -> Item:
    """The input a record was decoded from, rebuilt from its bytes."""
    if rec.protocol in (EG2_CAN, FOREIGN_CAN):
        ident = rec.fields.get("id")
        aid = int(ident, 16) if isinstance(ident, str) else 0
        frame = CanFrame(
            rec.t,
            aid,
            rec.raw,
            is_extended=bool(rec.fields.get("extended", True)),
            dlc=None if rec.length == len(rec.raw) else rec.length,
        )
        return Item(rec.bus, frame)
    return Item(rec.bus, Chunk(rec.raw, rec.t, None))


def export(store: RecordStore, indices: Iterable[int], path: str) -> int:
    """Write the records at ``indices`` to ``path`` (format by suffix); returns how many."""
    fmt = export_format(path)
    records = store.records(indices)
    n = 0
    tmp = f"{path}.part"
    try:
        if fmt == "mcap":
            recorder = McapRecorder(tmp, metadata={"exported_from": "eg2scope tui"})
            try:
                for batch in _batches(records):
                    recorder.on_raw([raw_item(r) for r in batch])
                    recorder.on_records(batch)
                    recorder.tick()
                    n += len(batch)
            finally:
                recorder.close()
        else:
            binary = fmt == "jsonl"
            with open(tmp, "wb" if binary else "w", newline=None if binary else "") as out:
                sink = JsonlListener(out) if binary else CsvListener(out)
                for batch in _batches(records):
                    sink.on_records(batch)
                    n += len(batch)
                sink.close()
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return n
