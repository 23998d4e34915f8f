"""The listener contract: what a session tells the parts that show, record or count its data.

As python-can's ``Listener``, grown for a decoder: a session calls each listener with batches of
decoded records, state samples, source events and the raw input they came from, in stream order,
plus a periodic ``tick`` and a final ``close``. Every method has a no-op default, so a listener
implements only what it uses. The session guards each call: a listener that raises is told
through ``on_error``, reported once as an event and detached; the session and the other
listeners (a recording among them) go on.

Listeners are found by name in ``LISTENERS`` (as python-can finds interfaces in ``BACKENDS``):
the module is imported only when the listener is made.
"""

from __future__ import annotations

import importlib
from abc import ABC, abstractmethod
from typing import TYPE_CHECKING, Any

from ..model import Item, SourceEvent

if TYPE_CHECKING:
    from .batches import RecordSequence, SampleSequence


class Listener(ABC):
    """Base of everything a session feeds: ``on_records`` is required (as python-can's
    ``on_message_received``), every other hook is optional."""

    #: the session builds state samples only when some listener reads them
    wants_states: bool = False
    #: a listener of states that reads only the fields each sample changed (``changed``,
    #: ``series``) sets this False: when none reads more, the native tracker does not copy the
    #: whole state into every sample (the other values of its samples are then left unset)
    reads_whole_states: bool = True
    #: the session keeps raw input only when some listener reads it
    wants_raw: bool = False
    #: ``on_raw`` may be handed the native core's ``FrameBatch`` (a candump log read natively:
    #: CAN frames, no Python object per frame) instead of a list of Items: set by a listener
    #: that reads raw items only through functions taking both (``health.can_load.can_seconds``),
    #: so that wanting them does not cost the native read
    reads_frame_batches: bool = False

    @abstractmethod
    def on_records(self, records: RecordSequence) -> None:
        """Decoded records, in stream order: a ``RecordSequence`` (Python engine) or the native
        core's lazy ``RecordBatch``, the same sequence with the same bulk methods (``column``,
        ``messages``, ``problems``, ``take``, ...: analyzer/session/batches.py)."""

    def on_states(self, samples: SampleSequence) -> None:
        """State samples (one per record that set a gripper's state), in stream order: a
        ``SampleSequence`` or the native ``SampleBatch`` (``column``, ``keys``, ``series``, ...)."""

    def reads_tracker(self, tracker: Any) -> bool:
        """Before the first batch, the session's tracker: a listener of states that can read
        it directly (the native core's, whose folds a native segmenter reads without a sample)
        keeps it and says True; it then gets no ``on_states``, and reads the tracker's last
        folds in ``on_records`` (the session folds each run of records just before)."""
        return False

    def on_event(self, event: SourceEvent) -> None:
        """A source event (opened, lost, reopened, drops, passive, ...), in time order with the
        records around it."""

    def on_raw(self, items: list[Item]) -> None:
        """The raw input of the records that follow: byte chunks and CAN frames (a native
        ``FrameBatch`` for a listener that ``reads_frame_batches``)."""

    def tick(self, now: float) -> None:
        """Called after every batch and when idle (``now``: wall-clock seconds), for flushing
        and redraws."""

    def close(self) -> None:
        """The session is over: flush and release. Called once."""

    def on_error(self, exc: BaseException) -> None:
        """This listener raised ``exc`` and has been detached from the session."""


# name -> "module:Class", imported on first use
LISTENERS: dict[str, str] = {
    "text": "analyzer.sinks.text:TextListener",
    "jsonl": "analyzer.sinks.jsonl:JsonlListener",
    "csv": "analyzer.sinks.csv:CsvListener",
    "parquet": "analyzer.parquet.writer:ParquetListener",
    "stats": "analyzer.sinks.stats:StatsListener",
    "health": "analyzer.health.listener:HealthListener",
    "mcap": "analyzer.recording.recorder:McapRecorder",
    "rerun": "analyzer.plot.listener:RerunListener",
    "cycles": "analyzer.cycles.listener:CyclesListener",
}


def listener_class(name: str) -> type[Listener]:
    """The listener class registered under ``name``; ValueError lists the names."""
    try:
        target = LISTENERS[name]
    except KeyError:
        raise ValueError(
            f"unknown output {name!r}; choose one of: {', '.join(sorted(LISTENERS))}"
        ) from None
    module, _, cls = target.partition(":")
    found: type[Listener] = getattr(importlib.import_module(module), cls)
    return found


def make_listener(name: str, *args: Any, **kwargs: Any) -> Listener:
    """A new listener of the kind registered under ``name``."""
    return listener_class(name)(*args, **kwargs)


def register_listener(name: str, target: str) -> None:
    """Make ``"module:Class"`` available as ``name`` (a plug-in's own output)."""
    LISTENERS[name] = target
