"""What waits to be sent to Rerun: an entity (where a series goes, how it looks) and its rows
as typed columns (``Columns``), filled by the listener and the outputs beside it (the cycle lanes,
the bus health) and taken at each flush."""

from __future__ import annotations

from array import array
from typing import Any, Final

import numpy as np

NAN: Final = float("nan")  # no timestamp

SCALAR: Final = "scalar"
LANE: Final = "lane"
TEXT: Final = "text"


class Entity:
    """Where one series goes and how it looks: ``style`` is logged static with the first rows
    (then None); ``convert`` turns a column of values into what is plotted (None: as it is)."""

    __slots__ = ("convert", "kind", "path", "style")

    def __init__(self, path: str, kind: str, style: Any = None, convert: Any = None) -> None:
        self.path = path
        self.kind = kind
        self.style = style
        self.convert = convert


class Columns(Entity):
    """The rows of one entity waiting to be sent, as typed arrays (no conversion when sent):
    ``t`` in seconds (NaN: no timestamp), ``seq`` (None for entities that live on
    ``capture_time`` only: health rates, source events), ``values`` (numbers for scalars,
    a list for text)."""

    __slots__ = ("levels", "seq", "t", "values")

    def __init__(self, path: str, kind: str, style: Any = None, *, frame: bool = True) -> None:
        super().__init__(path, kind, style)
        self.t = array("d")
        self.seq: array[int] | None = array("q") if frame else None
        self.values: Any = array("d") if kind == SCALAR else []
        self.levels: list[str] = []

    def add(self, t: float | None, seq: int | None, value: Any, level: str = "") -> None:
        self.t.append(NAN if t is None else t)
        if self.seq is not None:
            self.seq.append(-1 if seq is None else seq)
        self.values.append(value)
        if self.kind == TEXT:
            self.levels.append(level)

    def extend(self, t: list[float], seq: list[int], values: list[Any], levels: list[str]) -> None:
        """Rows of a text log (``t`` NaN: no timestamp)."""
        self.t.fromlist(t)
        if self.seq is not None:
            self.seq.fromlist(seq)
        self.values += values
        self.levels += levels

    def take(self) -> tuple[np.ndarray, np.ndarray | None, Any, list[str]]:
        """The rows so far (t, seq, values, levels), copied; the columns start empty."""
        t = np.frombuffer(self.t, dtype=np.float64).copy()
        seq = None if self.seq is None else np.frombuffer(self.seq, dtype=np.int64).copy()
        values: Any = self.values[:]
        if self.kind == SCALAR:
            values = np.frombuffer(self.values, dtype=np.float64).copy()
        rows = (t, seq, values, self.levels[:])
        for buffer in (self.t, self.seq, self.values, self.levels):
            if buffer is not None:
                del buffer[:]
        return rows
