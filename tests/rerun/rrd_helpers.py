"""Reading an .rrd file back with the installed rerun-sdk's reader (``rerun.chunk.RrdReader``):
every entity's rows (capture_time, frame, value), its static components and the blueprints."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pyarrow as pa
from rerun.chunk import RrdReader

# the one data column of each archetype the listener sends
VALUE_COLUMNS = ("Scalars:scalars", "StateChange:state", "TextLog:text")


@dataclass
class Entity:
    """One entity of a recording: its rows in file order and its static components."""

    path: str
    capture_time: list[int | None] = field(default_factory=list)  # ns, None: not on it
    frame: list[int | None] = field(default_factory=list)
    values: list[Any] = field(default_factory=list)
    levels: list[str | None] = field(default_factory=list)
    static: dict[str, Any] = field(default_factory=dict)
    timelines: set[str] = field(default_factory=set)

    def rows(self) -> list[tuple[int | None, int | None, Any]]:
        """(capture_time ns, frame, value), sorted."""
        return sorted(
            zip(self.capture_time, self.frame, self.values, strict=True),
            key=lambda r: (r[1] if r[1] is not None else -1, r[0] or 0),
        )


@dataclass
class Rrd:
    entities: dict[str, Entity]
    blueprints: list[list[dict[str, Any]]]  # per blueprint store: each chunk as a dict
    recordings: int

    def __getitem__(self, path: str) -> Entity:
        return self.entities[path]

    def timelines(self) -> set[str]:
        return set().union(*(e.timelines for e in self.entities.values()))


def _column(batch: pa.RecordBatch, name: str) -> list[Any] | None:
    if name not in batch.schema.names:
        return None
    col = batch.column(name)
    if pa.types.is_timestamp(col.type):
        col = col.cast(pa.int64())
    return col.to_pylist()


def _first(cell: Any) -> Any:
    """Each row of a component column is a list (one instance here)."""
    return cell[0] if isinstance(cell, list) and len(cell) == 1 else cell


def _as_dict(path: str, batch: pa.RecordBatch) -> dict[str, Any]:
    out: dict[str, Any] = {"entity": path}
    for name in batch.schema.names:
        out[name] = _column(batch, name)
    return out


def read_rrd(path: Path | str) -> Rrd:
    reader = RrdReader(path)
    entities: dict[str, Entity] = {}
    for chunk in reader.stream():  # works with or without the file's footer
        e = entities.setdefault(chunk.entity_path, Entity(chunk.entity_path))
        batch = chunk.to_record_batch()
        data = [n for n in batch.schema.names if ":" in n]
        if chunk.is_static:
            for name in data:
                e.static[name] = _column(batch, name)
            continue
        e.timelines.update(chunk.timeline_names)
        n = batch.num_rows
        value_name = next(c for c in VALUE_COLUMNS if c in data)
        e.values += [_first(v) for v in _column(batch, value_name) or []]
        e.capture_time += _column(batch, "capture_time") or [None] * n
        e.frame += _column(batch, "frame") or [None] * n
        e.levels += [_first(v) for v in _column(batch, "TextLog:level") or [None] * n]
    blueprints = [
        [_as_dict(c.entity_path, c.to_record_batch()) for c in reader.stream(store=b)]
        for b in reader.blueprints()
    ]
    return Rrd(entities, blueprints, len(reader.recordings()))


def blueprint_text(rrd: Rrd) -> str:
    """The newest blueprint's contents as one string (view origins, names, container kinds):
    the one sent last, which the viewer makes active."""
    if not rrd.blueprints:
        return ""

    def sent(store: list[dict[str, Any]]) -> int:
        return max(max(c.get("log_time") or [0]) for c in store)

    return repr(max(rrd.blueprints, key=sent))
