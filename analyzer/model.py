"""What flows between the session's parts: source input (Item), source events, state samples.

Decoded records (``decoders.model.Record``) are the decoders' own; everything here is what the
application adds around them. Plain data, no I/O.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Final

from decoders.model import CanFrame, Chunk
from decoders.registers import fault_text, opening_mm, state_text

# foxglove.Log levels, used for source events
DEBUG: Final = 1
INFO: Final = 2
WARNING: Final = 3
ERROR: Final = 4
LEVEL_NAMES: Final = {DEBUG: "debug", INFO: "info", WARNING: "warning", ERROR: "error"}

EVENT: Final = "event"  # the JSONL ``kind`` of a source event


@dataclass(slots=True)
class Item:
    """One unit of source input: a chunk of one byte stream, or one CAN frame.

    ``stream`` separates byte streams on one bus that must be framed apart (the two wires of
    an RS232 line tapped with two adapters); records still carry ``bus``, so pairing joins them.
    """

    bus: str
    payload: Chunk | CanFrame
    stream: str = ""


@dataclass(slots=True)
class SourceEvent:
    """Something that happened to a source rather than on the bus: a port opened, lost or
    reopened, drops, whether a tap is passive. ``count`` > 1: the same event repeated (a
    flapping adapter), collapsed into one."""

    t: float
    bus: str
    level: int
    message: str
    kind: str = "info"  # "open", "passive", "lost", "reopened", "drops", "closed", "info", ...
    count: int = 1

    def to_dict(self) -> dict[str, Any]:
        """The JSONL form: a record of its own ``kind`` ("event"), in time order with frames."""
        return {
            "t": self.t,
            "bus": self.bus,
            "kind": EVENT,
            "event": self.kind,
            "level": LEVEL_NAMES.get(self.level, "info"),
            "message": self.message,
            "count": self.count,
        }


@dataclass(slots=True)
class StateSample:
    """One reading or setting of one gripper: what a record changed, at the record's time.

    ``changed`` holds the state fields this record set (a reading that repeats the last value
    is still a reading: plots get every sample). ``values`` is the gripper's whole state after
    this record (a snapshot: later records do not change it). ``seq`` is the record's.
    """

    t: float | None
    bus: str
    device: int
    protocol: str
    seq: int
    changed: dict[str, Any]
    values: dict[str, Any]

    def to_dict(self) -> dict[str, Any]:
        """The whole state, flat (MCAP ``/state/<bus>/<device>``), with ``changed`` naming the
        fields this sample set. Hand-written: this runs once per reading."""
        d: dict[str, Any] = {
            "t": self.t,
            "bus": self.bus,
            "device": self.device,
            "protocol": self.protocol,
            "seq": self.seq,
        }
        d.update(self.values)
        derived(d)
        d["changed"] = list(self.changed)
        return d


# derived() runs once per state sample a recording writes: look the common values up
_MM: Final = [opening_mm(v) for v in range(1001)]
_STATE_WORDS: Final = [state_text(v) for v in range(256)]


def _mm(value: Any) -> float | None:
    if value is None:
        return None
    return _MM[value] if 0 <= value <= 1000 else opening_mm(value)


def json_default(obj: Any) -> Any:
    """orjson's fallback for values a decoder may put in ``fields`` (bytes, sets, tuples)."""
    if isinstance(obj, bytes | bytearray | memoryview):
        return bytes(obj).hex(" ").upper()
    if isinstance(obj, set | frozenset | tuple):
        return list(obj)
    return str(obj)


def derived(d: dict[str, Any]) -> dict[str, Any]:
    """Add the fields a person reads to a state's values: millimetres and words."""
    state, fault = d.get("state"), d.get("fault")
    d["opening_mm"] = _mm(d.get("opening"))
    d["target_mm"] = _mm(d.get("target_opening"))
    if state is None:
        d["state_text"] = None
    else:
        d["state_text"] = _STATE_WORDS[state] if 0 <= state < 256 else state_text(state)
    d["fault_text"] = fault_text(fault) if fault else []
    return d
