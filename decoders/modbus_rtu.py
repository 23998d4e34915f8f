"""Modbus RTU on the EG2-4X2's RS485 line (reference section 2), from the bytes alone.

``ModbusRtuDecoder`` joins the two halves: ``modbus_framing`` finds the frames (candidate
lengths, CRC, collisions), ``modbus_pdu`` says what they mean (functions 03/06/16, exceptions;
register names from ``modbus_registers``). What ties them is the bus state this class keeps:
the request awaiting its response, which orders the framer's candidates and names a read
response's registers.

Retransmissions. A host that times out sends the same request again (pymodbus and minimalmodbus
retry this way), and the gripper may then answer both. Identical requests sent one after another
with no answer between them are kept as outstanding together, so each answer is decoded against
its request, in arrival order. (The pairing stage flags the second request ``retransmission``.)

Speed: decoded frames are memoised by (bytes, pending request, direction hint), so a polling
loop costs a dictionary lookup and a Record per frame once values repeat; register values are
memoised per register, so a response with new values costs little more.
"""

from __future__ import annotations

from typing import Final

from . import messages as M
from .flags import SHORT_REGISTER_NUMBERS
from .modbus_framing import CRC_OK, CRC_SWAPPED_ORDER, ModbusFramer, Pending, crc16
from .modbus_pdu import Entry, decode
from .model import FRAME, MODBUS_RTU, RESPONSE, Record

# the decoder, and what other modules take from here (the CRC for decoders.build)
__all__ = ["MEMO_LIMIT", "ModbusRtuDecoder", "crc16"]

MEMO_LIMIT: Final = 50_000
_SHORT: Final = "short register number"  # how MODBUS_SHORT_NUMBER and _NUMBERS start


class ModbusRtuDecoder(ModbusFramer):
    """Modbus RTU frames of one RS485 line, in stream order (feed Chunks, then finish)."""

    def __init__(self, bus: str = "rs485", *, byte_time_s: float | None = None) -> None:
        super().__init__(bus, byte_time_s=byte_time_s)
        self._outstanding = 0  # identical requests sent and not yet answered
        self._answered = False  # an answer came since the pending request was first sent
        self._memo: dict[tuple[bytes, Pending | None, str | None], Entry] = {}
        self._short_seen: set[int] = set()  # devices already said to use short numbers

    @property
    def outstanding(self) -> int:
        """How many identical copies of ``pending`` await an answer (a host's retries)."""
        return self._outstanding

    def make_record(self, raw: bytes, offset: int, t: float | None, valid: bool) -> Record:
        hint = self.direction_hint
        key = (raw, self._pending, hint)
        memo = self._memo
        e = memo.get(key)
        if e is None:
            if len(memo) >= MEMO_LIMIT:
                memo.clear()
            crc = None
            if valid:  # frame_at checked the CRC already
                swapped = self._swapped == (offset, len(raw))
                crc = CRC_SWAPPED_ORDER if swapped else CRC_OK
            e = memo[key] = decode(raw, self._pending, hint, crc)
        direction, name, fields, summary, errors, warnings, pair_key, expects, save, nxt, flags = e
        self._follow(direction, nxt)
        if flags and SHORT_REGISTER_NUMBERS in flags:
            warnings, flags = self._short_numbering_once(raw[0], warnings, flags)
        # fresh lists: the pairing and lint stages append to them
        return Record(
            t,
            self.bus,
            MODBUS_RTU,
            FRAME,
            len(raw),
            raw,
            offset,
            None,
            direction,
            raw[0],
            raw[1],
            name,
            fields,
            list(errors) if errors else [],
            list(warnings) if warnings else [],
            summary,
            -1,
            None,
            None,
            pair_key,
            expects,
            save,
            list(flags) if flags else [],
        )

    def _follow(self, direction: str | None, request: Pending | None) -> None:
        """Keep the outstanding requests up to date after a frame."""
        if direction == RESPONSE:
            # an answer: an identical request sent again before it waits for its own
            self._answered = True
            self._outstanding -= 1
            if self._outstanding <= 0:
                self._outstanding = 0
                self._pending = None
        elif request is not None and request == self._pending and not self._answered:
            self._outstanding += 1  # the same request again before any answer: a retry
        else:
            # a new request (or a broadcast, which nobody answers): earlier ones are given up
            self._pending = request
            self._outstanding = 0 if request is None else 1
            self._answered = False

    def _short_numbering_once(
        self, slave: int, warnings: tuple[str, ...], flags: tuple[str, ...]
    ) -> tuple[tuple[str, ...], tuple[str, ...]]:
        """A host that leaves out the 1000 offset does it on every frame: say so on its first
        frame per device; later frames keep ``numbering: "short"`` without the warning."""
        if slave not in self._short_seen:
            self._short_seen.add(slave)
            return tuple(
                M.MODBUS_HOST_SHORT_NUMBERS.text(warning=w) if w.startswith(_SHORT) else w
                for w in warnings
            ), flags
        return (
            tuple(w for w in warnings if not w.startswith(_SHORT)),
            tuple(f for f in flags if f != SHORT_REGISTER_NUMBERS),
        )
