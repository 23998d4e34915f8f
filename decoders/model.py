"""The data that flows through eg2scope: raw input (Chunk, CanFrame) and decoded Records.

Everything here is plain data. Decoders turn Chunks (byte streams) or CanFrames into Records;
the pairing and lint stages annotate Records; sinks serialise them (see docs/contracts.md, "JSONL
records", for the keys other programs rely on).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

# protocol names used in Record.protocol
EG2_SERIAL = "eg2-serial"
MODBUS_RTU = "modbus-rtu"
EG2_CAN = "eg2-can"
FOREIGN_CAN = "can"

# Record.kind
FRAME = "frame"
GARBAGE = "garbage"
TRUNCATED = "truncated"
CUT_OFF = "cut_off"  # the bytes of a frame begun when the capture was stopped: not damage

# Record.direction
REQUEST = "request"
RESPONSE = "response"


@dataclass(slots=True)
class Chunk:
    """Bytes as they arrived from a serial line or a capture file.

    ``t`` is when the chunk arrived (seconds, epoch or capture clock), or None when the source
    carries no timing. A live tap stamps a read when it returns, i.e. when the chunk's last
    byte arrived; a decoder told the line's byte time counts each frame's time back from it.
    ``direction`` is set only when the source knows it (one port per RS232 wire, or the two
    sides of a bridge).
    """

    data: bytes
    t: float | None = None
    direction: str | None = None


@dataclass(slots=True)
class CanFrame:
    """One CAN frame, independent of python-can (decoders must not import it)."""

    t: float | None
    arbitration_id: int
    data: bytes = b""
    is_extended: bool = True
    is_remote: bool = False
    is_error: bool = False
    is_fd: bool = False
    dlc: int | None = None  # None: len(data); remote frames carry a DLC but no data
    channel: str | None = None

    @property
    def length(self) -> int:
        return self.dlc if self.dlc is not None else len(self.data)


@dataclass(slots=True)
class Record:
    """One decoded frame, or one run of bytes that belongs to no frame.

    The first block of attributes is the JSONL contract (docs/contracts.md). ``summary`` is the
    human one-liner ("catch speed=500 force=100 g"). ``seq`` numbers records in output order;
    ``pair`` is the ``seq`` of the linked request or response, ``latency_ms`` the time between
    them. ``pair_key``, ``expects_response`` and ``is_save`` are for the pairing and lint stages
    and are not serialised.
    """

    t: float | None
    bus: str
    protocol: str
    kind: str
    length: int
    raw: bytes
    offset: int | None = None
    index: int | None = None
    direction: str | None = None
    device: int | None = None
    code: int | None = None
    name: str | None = None
    fields: dict[str, Any] = field(default_factory=dict)
    errors: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    summary: str = ""
    seq: int = -1
    pair: int | None = None
    latency_ms: float | None = None
    # internal, for pairing and lint
    pair_key: tuple[Any, ...] | None = None
    expects_response: bool = False
    is_save: bool = False
    # machine-readable codes for every error and warning (decoders/flags.py); last so the hot
    # paths that build Records positionally need not pass it
    flags: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return self.kind == FRAME and not self.errors

    def to_dict(self) -> dict[str, Any]:
        """The JSONL contract: every key docs/contracts.md names, in a fixed order."""
        return {
            "t": self.t,
            "bus": self.bus,
            "protocol": self.protocol,
            "kind": self.kind,
            "offset": self.offset,
            "index": self.index,
            "length": self.length,
            "direction": self.direction,
            "device": self.device,
            "code": self.code,
            "name": self.name,
            "fields": self.fields,
            "raw": self.raw.hex(" ").upper(),
            "errors": self.errors,
            "warnings": self.warnings,
            "flags": self.flags,
            "summary": self.summary,
            "seq": self.seq,
            "pair": self.pair,
            "latency_ms": self.latency_ms,
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Record:
        """Inverse of to_dict (used when reading decoded records back from a recording)."""
        return cls(
            t=d.get("t"),
            bus=d["bus"],
            protocol=d["protocol"],
            kind=d["kind"],
            length=d["length"],
            raw=bytes.fromhex(d.get("raw") or ""),
            offset=d.get("offset"),
            index=d.get("index"),
            direction=d.get("direction"),
            device=d.get("device"),
            code=d.get("code"),
            name=d.get("name"),
            fields=d.get("fields") or {},
            errors=list(d.get("errors") or []),
            warnings=list(d.get("warnings") or []),
            flags=list(d.get("flags") or []),
            summary=d.get("summary") or "",
            seq=d.get("seq", -1),
            pair=d.get("pair"),
            latency_ms=d.get("latency_ms"),
        )
