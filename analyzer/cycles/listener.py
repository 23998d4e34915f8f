"""Grip cycles as a session listener: records and state samples in, cycles to an output.

On the native engine the native segmenter does it all (``reads_tracker``): it finds the
commands and answers in each batch's records and reads the session's tracker for what the
records set, with no Python object per record or sample; only the ended cycles come back.

Elsewhere it works on the sequences' bulk methods (analyzer/session/batches.py): of the records,
one column (``code``) picks the few candidates (motion commands, stops and their answers), and
only those become ``Record`` objects (``take``); the readings come from the samples' ``series``,
a column per quantity and gripper. A batch's records come before its samples, so its commands
wait for them (or for the next batch, a tick or the end, when it set no state).

A cycle goes to the output once it has ended (the next motion command to its gripper, a stop, or
the end of the capture), so a live session shows each cycle as it ends."""

from __future__ import annotations

from itertools import compress, repeat
from typing import TYPE_CHECKING, Any, Final

from ..session.engine import _native
from ..session.listener import Listener
from .commands import CODES, answer_of, command_of
from .segmenter import COMMAND, READING, Event, Segmenter

if TYPE_CHECKING:
    from ..session.batches import RecordSequence, SampleSequence
    from .outputs import CycleOutput

#: the state fields a cycle reads, in the order of a reading event's values
FIELDS: Final = (
    "state",
    "opening",
    "force",
    "fault",
    "force_setting",
    "max_opening",
    "min_opening",
)
_CANDIDATE: Final = CODES.__contains__


class CyclesListener(Listener):
    """Cuts the session's timeline into grip cycles and writes them to ``output`` (only those
    of gripper ``device``, when given). ``count``: the cycles written."""

    wants_states = True
    reads_whole_states = False  # a reading's fields: the ones its sample changed

    def __init__(self, output: CycleOutput, device: int | None = None) -> None:
        self.output = output
        self.device = device
        self.segmenter = Segmenter()
        self.native: Any = None  # the native core's segmenter, on the native engine
        self.tracker: Any = None  # the native tracker it reads (``reads_tracker``)
        self.pending: list[tuple[str, int, Event]] = []  # this batch's commands and answers
        self.count = 0
        self.label = getattr(output, "label", "cycles output")

    def reads_tracker(self, tracker: Any) -> bool:
        """On the native engine, the native segmenter reads the session's tracker itself."""
        if _native is None or not isinstance(tracker, _native.Tracker):
            return False
        tracker.readings = True
        self.native = _native.CycleSegmenter(counts=self.output.counts_only)
        self.tracker = tracker
        return True

    def on_records(self, records: RecordSequence) -> None:
        if self.output.t0 is None and len(records):
            self.output.t0 = records[0].t
        if self.native is not None:  # this batch's commands, answers and readings at once
            self.native.feed_from(self.tracker, records)
            self._write_native(self.native.take())
            return
        self._flush()  # the last batch's commands: it set no state
        codes = records.column("code")
        picked = list(compress(range(len(codes)), map(_CANDIDATE, codes)))
        if not picked:
            return
        pending = self.pending
        for rec in records.take(picked):
            found: Any = command_of(rec) or answer_of(rec)
            if found is not None:
                pending.append((found.bus, found.device, (found.seq, COMMAND, found.t, found)))

    def on_states(self, samples: SampleSequence) -> None:
        if self.native is not None:
            return  # it read the tracker in ``on_records`` (a listener around it passes these)
        readings: dict[tuple[str, int], list[Event]] = {}
        holder = self.segmenter.holder
        for bus, device, names, times, seqs, columns in samples.series(FIELDS):
            by_name = dict(zip(names, columns, strict=True))
            values = zip(*[by_name.get(name) or repeat(None) for name in FIELDS], strict=False)
            key = (bus, device)
            events = zip(seqs, repeat(READING), times, values, repeat(holder(key, names)))
            found = readings.get(key)
            if found is None:
                readings[key] = list(events)
            else:
                found += events
        self.segmenter.feed(readings, self.pending)
        self.pending = []
        self._write(self.segmenter.take())

    def tick(self, now: float) -> None:
        self._flush()
        self.output.flush()

    def close(self) -> None:
        self._flush()
        if self.native is not None:
            self._write_native(self.native.finish())
        else:
            self._write(self.segmenter.finish())
        self.output.close()

    def _flush(self) -> None:
        if self.pending:
            self.segmenter.feed({}, self.pending)
            self._write(self.segmenter.take())
            self.pending = []

    def _write_native(self, ended: list[Any]) -> None:
        """The native segmenter's ended cycles: counted (``counts_of``) for an output that
        only counts them, ``Cycle``s otherwise."""
        if not self.output.counts_only:
            self._write(ended)
            return
        if self.device is not None:
            ended = [counts for counts in ended if counts[1] == self.device]
        if ended:
            self.count += sum(len(counts[2]) for counts in ended)
            self.output.write_counts(ended)

    def _write(self, cycles: list[Any]) -> None:
        if self.device is not None:
            cycles = [c for c in cycles if c.device == self.device]
        if cycles:
            self.count += len(cycles)
            self.output.write(cycles)
