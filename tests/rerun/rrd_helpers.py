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
    kind: str = ""  # which of VALUE_COLUMNS its rows hold

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
        e.kind = value_name
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


# -- the blueprint's views, resolved against the data ------------------------------------------

# the archetype each kind of view draws, by its data column (VALUE_COLUMNS)
VIEW_DRAWS = {
    "TimeSeries": "Scalars:scalars",
    "StateTimeline": "StateChange:state",
    "TextLog": "TextLog:text",
}
# the viewer's shared time axis of linked plots (analyzer.plot.blueprint.SHARED_AXIS_VIEW)
SHARED_AXIS = "/view/5c0dca6a-e63f-9cf7-f657-2602590474cc/TimeAxis"


@dataclass
class View:
    """One view of a blueprint: its kind, title, origin, content query and properties, and
    the entities of the recording it shows."""

    kind: str
    name: str
    origin: str
    query: list[str]
    properties: dict[str, Any]
    entities: list[str] = field(default_factory=list)
    containers: list[str] = field(default_factory=list)  # the names around it, outermost first


def newest_blueprint(rrd: Rrd) -> dict[str, dict[str, Any]]:
    """The blueprint sent last (the one the viewer makes active): each blueprint entity's
    components, the last value of each."""
    if not rrd.blueprints:
        return {}

    def sent(store: list[dict[str, Any]]) -> int:
        return max(max(c.get("log_time") or [0]) for c in store)

    out: dict[str, dict[str, Any]] = {}
    for chunk in max(rrd.blueprints, key=sent):
        components = out.setdefault(chunk["entity"], {})
        for name, values in chunk.items():
            if ":" in name and values:
                components[name] = values[-1]
    return out


def _matches(rule: str, path: str) -> bool:
    if rule.endswith("/**"):
        base = rule[:-3]
        return path == base or path.startswith(base.rstrip("/") + "/")
    return path == rule


def resolve(query: list[str], origin: str, paths: list[str]) -> list[str]:
    """The entity paths a view's content query selects (``+ rule``, ``- rule``, ``$origin``,
    a trailing ``/**`` for a subtree): included by a rule and excluded by none."""
    include, exclude = [], []
    for expr in query:
        expr = expr.strip().replace("$origin", origin.rstrip("/") or "")
        if expr.startswith("- "):
            exclude.append(expr[2:].strip())
        else:
            include.append(expr.removeprefix("+ ").strip())
    return [
        p
        for p in paths
        if any(_matches(r, p) for r in include) and not any(_matches(r, p) for r in exclude)
    ]


def views(rrd: Rrd) -> list[View]:
    """Every view of the newest blueprint that a container shows, with the entities that have
    rows of what the view draws."""
    bp = newest_blueprint(rrd)
    root = (bp.get("/viewport") or {}).get("ViewportBlueprint:root_container")
    out: list[View] = []
    if root is None:
        return out
    import uuid

    stack: list[tuple[str, list[str]]] = [(f"container/{uuid.UUID(bytes=bytes(root[0]))}", [])]
    while stack:
        path, around = stack.pop(0)
        item = bp.get(f"/{path}", {})
        if path.startswith("container/"):
            name = (item.get("ContainerBlueprint:display_name") or [""])[0]
            stack += [(c, [*around, name]) for c in item.get("ContainerBlueprint:contents") or []]
            continue
        properties = {
            name: value
            for entity, components in bp.items()
            if entity.startswith(f"/{path}/")
            for name, value in components.items()
        }
        kind = item["ViewBlueprint:class_identifier"][0]
        origin = item["ViewBlueprint:space_origin"][0]
        query = properties.get("ViewContents:query") or ["$origin/**"]
        drawn = VIEW_DRAWS[kind]
        with_rows = [p for p, e in rrd.entities.items() if e.values and e.kind == drawn]
        out.append(
            View(
                kind,
                item["ViewBlueprint:display_name"][0],
                origin,
                query,
                properties,
                resolve(query, origin, with_rows),
                around,
            )
        )
    return out


def shared_time_range(rrd: Rrd) -> dict[str, Any] | None:
    """The x range every linked plot shows (``TimeAxis:view_range`` of the shared axis)."""
    axis = newest_blueprint(rrd).get(SHARED_AXIS) or {}
    ranges = axis.get("TimeAxis:view_range")
    return ranges[0] if ranges else None
