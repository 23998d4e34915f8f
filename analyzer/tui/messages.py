"""Every message the TUI's parts send each other, in one place."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from textual.message import Message

from ..model import SourceEvent
from .aggregates import DeviceKey, Snapshot
from .spans import Span

if TYPE_CHECKING:
    from ..cycles.model import Cycle
    from ..health.seconds import HealthSecond


@dataclass
class DeviceRow:
    """One gripper's state as the session's tracker holds it (a copy)."""

    bus: str
    device: int
    protocol: str
    t: float | None
    values: dict[str, Any]


class FeedUpdate(Message):
    """A batch from the session thread (10-20 a second, never one per record)."""

    def __init__(
        self,
        count: int,
        devices: list[DeviceRow],
        changed: set[tuple[str, int, str]],
        snapshot: Snapshot | None,
        events: list[SourceEvent],
        trigger: int | None,
        captured: int,
        dropped: int,
        done: bool = False,
    ) -> None:
        super().__init__()
        self.count = count  # records in the store
        self.devices = devices
        self.changed = changed  # (bus, device, field) set since the last update
        self.snapshot = snapshot  # panels' tables (None: unchanged)
        self.events = events
        self.trigger = trigger  # store index of the record the trigger fired on
        self.captured = captured  # chunks/frames captured so far
        self.dropped = dropped
        self.done = done  # the session has ended


class CyclesUpdate(Message):
    """Grip cycles that ended since the last update (posted in batches from the session's
    thread; the last ones before the feed's final update)."""

    def __init__(self, cycles: list[Cycle]) -> None:
        super().__init__()
        self.cycles = cycles


class HealthUpdate(Message):
    """Bus-health seconds completed since the last update (one row per bus and second);
    ``untimed``: buses whose frames have no times (no load or rate can be said); ``whole``: at
    the end of the session (the open seconds came too), every bus's figures over all of it,
    as ``stats --format json`` gives them under ``buses`` (None: not over)."""

    def __init__(
        self,
        seconds: list[HealthSecond],
        untimed: set[str],
        whole: list[dict[str, Any]] | None = None,
    ) -> None:
        super().__init__()
        self.seconds = seconds
        self.untimed = untimed
        self.whole = whole


class CycleChosen(Message):
    """Enter on a cycle in the cycles panel: show its frames."""

    def __init__(self, cycle: Cycle) -> None:
        super().__init__()
        self.cycle = cycle


class RowSelected(Message):
    """The frame list's cursor moved to store index ``index`` (None: nothing shown)."""

    def __init__(self, index: int | None) -> None:
        super().__init__()
        self.index = index


class JumpTo(Message):
    """Show and select store index ``index`` (problems panel, marks, go-to, pair)."""

    def __init__(self, index: int) -> None:
        super().__init__()
        self.index = index


class FieldSelected(Message):
    """A field of the detail tree was selected: highlight its bytes."""

    def __init__(self, span: Span | None) -> None:
        super().__init__()
        self.span = span


class ByteSelected(Message):
    """A byte of the hex pane was selected: select the field that holds it."""

    def __init__(self, offset: int) -> None:
        super().__init__()
        self.offset = offset


class DeviceChosen(Message):
    """A gripper was chosen in the device panel (the register watch follows it)."""

    def __init__(self, key: DeviceKey) -> None:
        super().__init__()
        self.key = key


class FilterCancelled(Message):
    """Esc in the display filter's box: the edit is dropped, the applied filter stays."""
