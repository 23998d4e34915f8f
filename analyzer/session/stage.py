"""The one decode path shared by live taps and capture replay.

Source items in (byte chunks per stream, or CAN frames), ordered Records out: per-stream framers
and decoders, then the timing linter, then request/response pairing. Pure and single-threaded:
the same input gives the same records whether it comes live or from a file.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator

from decoders.eg2_can import Eg2CanDecoder
from decoders.framing import ByteStreamDecoder
from decoders.lint import TimingLinter
from decoders.model import EG2_SERIAL, CanFrame, Chunk, Record
from decoders.pairing import Pairer
from decoders.registry import STREAM_DECODERS, detect_protocol

from ..model import Item, SourceEvent

DETECT_BYTES = 4096  # bytes of a stream looked at before choosing its protocol


class Decoding:
    """Items in, Records out, in stream order. ``protocol`` None: detect per byte stream;
    ``per_bus`` fixes the protocol of named buses (the demo knows what each line speaks)."""

    def __init__(
        self,
        protocol: str | None = None,
        per_bus: dict[str, str] | None = None,
        positional_seq: bool = False,
        start_offset: int = 0,
        can_index: int = 0,
        byte_time_s: dict[str, float] | None = None,
    ) -> None:
        """``positional_seq``: seq is each record's offset or CAN index (single-stream
        captures); ``start_offset``/``can_index``: where the input starts in a larger capture
        (the parallel decoder's parts); ``byte_time_s``: seconds per byte of live serial buses,
        so frames that arrive in one read get their own times."""
        self.protocol = protocol
        self.per_bus = dict(per_bus or {})
        self.byte_time_s = byte_time_s or {}
        self.linter = TimingLinter()
        self.pairer = Pairer(positional=positional_seq)
        self.start_offset = start_offset
        self.can_index = can_index  # frame number in the input, across all CAN channels
        self._streams: dict[tuple[str, str], ByteStreamDecoder] = {}
        self._undetected: dict[tuple[str, str], list[Chunk]] = {}
        self._can: dict[str, Eg2CanDecoder] = {}
        self.detected: dict[str, str] = {}  # bus -> protocol chosen by detection

    def feed(self, item: Item) -> list[Record]:
        payload = item.payload
        if isinstance(payload, CanFrame):
            return self.feed_can(item.bus, payload)
        key = (item.bus, item.stream)
        dec = self._streams.get(key)
        if dec is None:
            dec = self._start_stream(key, payload)
            if dec is None:
                return []
            return self._post(self._replay(key, dec))
        return self._post(dec.feed(payload))

    def feed_items(self, items: list[Item]) -> list[Record]:
        """The records of a run of items (``feed`` for each, concatenated): the session's call,
        which the native core's ``CanStage.feed`` answers for CAN input."""
        feed = self.feed
        records: list[Record] = []
        for item in items:
            records += feed(item)
        return records

    def feed_can(self, bus: str, frame: CanFrame) -> list[Record]:
        """One CAN frame (``feed`` without the Item, for tight loops over CAN captures)."""
        rec = self._decode_can(bus, frame)
        self.linter.check(rec)
        return self.pairer.push(rec)

    def feed_many(self, items: Iterable[Item | SourceEvent]) -> Iterator[Record]:
        """Every record of ``items`` (source events among them are passed over)."""
        for item in items:
            if type(item) is Item:
                yield from self.feed(item)
        yield from self.finish()

    def tick(self, now: float) -> list[Record]:
        """Live sources call this when idle: quiet lines decide their held bytes and requests
        that timed out are released."""
        records: list[Record] = []
        for key in list(self._undetected):
            # a live line may be slow to fill the detection sample: decide once a frame shows
            sample = b"".join(c.data for c in self._undetected[key])
            protocol = self.protocol or detect_protocol(sample)
            if protocol is not None:
                records += self._replay(key, self._new_stream_decoder(key, protocol))
        for dec in self._streams.values():
            records += dec.idle(now)
        return self._post(records) + self.pairer.tick(now)

    def finish(self) -> list[Record]:
        """The end of the input: held bytes are decided (a frame begun is ``truncated``) and
        the requests still waiting are ``unanswered``."""
        records = self._decide_undetected(None)
        for dec in self._streams.values():
            records += dec.finish()
        out = self._post(records)
        return out + self.pairer.flush()

    def stop(self) -> list[Record]:
        """The capture was stopped (a user's stop, the end of a duration) before its input
        ended: as ``finish``, but a frame begun and the requests still waiting are ``cut_off``
        by the stop, not errors of the bus."""
        return self._cut_off(None)

    def cut_off(self, bus: str) -> list[Record]:
        """The capture of ``bus`` was stopped (its tap closed at the session's end): what it
        holds is decided as by ``stop``, for that bus only."""
        return self._cut_off(bus)

    def set_protocol(self, bus: str, protocol: str) -> None:
        """Fix the protocol of ``bus`` (its source named it after the protocol it detected),
        before its first bytes are fed."""
        self.per_bus[bus] = protocol

    def gap(self, bus: str) -> list[Record]:
        """The bus's source went away (a port lost): the bytes held for a frame that had begun
        will not be completed, so decide them now, before the gap is shown."""
        records: list[Record] = []
        for (name, _), dec in self._streams.items():
            if name == bus:
                records += dec.finish()
        return self._post(records) + self.pairer.gap(bus)

    def undecided_before(self, position: int) -> str:
        """What the decoding still holds undecided from before ``position`` (a byte offset, or a
        CAN frame index): '' when everything before it is decided. The parallel decoder's check
        that a part ended in the same state as a one-piece decode would be in."""
        for dec in self._streams.values():
            held = dec.held_from()
            if held is not None and held < position:
                return f"bytes from offset {held} still undecided"
        if self.pairer.waiting_before(position):
            return "a request still waiting for its answer"
        return ""

    # -- internals -------------------------------------------------------------------------

    def _cut_off(self, bus: str | None) -> list[Record]:
        records = self._decide_undetected(bus)
        for (name, _), dec in self._streams.items():
            if bus is None or name == bus:
                records += dec.stop()
        return self._post(records) + self.pairer.cut_off(bus)

    def _decide_undetected(self, bus: str | None) -> list[Record]:
        """The end of the streams of ``bus`` (None: of every bus) whose protocol was not
        detected yet: decided from what they hold, their bytes decoded."""
        records: list[Record] = []
        for key in [k for k in self._undetected if bus is None or k[0] == bus]:
            dec = self._new_stream_decoder(key, self.protocol or self._choose(key))
            records += self._replay(key, dec)
        return records

    def _decode_can(self, bus: str, frame: CanFrame) -> Record:
        dec = self._can.get(bus)
        if dec is None:
            dec = self._can[bus] = Eg2CanDecoder(bus)
        index = self.can_index
        self.can_index = index + 1
        return dec.decode(frame, index)

    def _start_stream(self, key: tuple[str, str], chunk: Chunk) -> ByteStreamDecoder | None:
        held = self._undetected.setdefault(key, [])
        held.append(chunk)
        fixed = self.per_bus.get(key[0], self.protocol)
        if fixed is not None:
            return self._new_stream_decoder(key, fixed)
        if sum(len(c.data) for c in held) < DETECT_BYTES:
            return None
        return self._new_stream_decoder(key, self._choose(key))

    def _choose(self, key: tuple[str, str]) -> str:
        sample = b"".join(c.data for c in self._undetected.get(key, []))
        return detect_protocol(sample) or EG2_SERIAL

    def _new_stream_decoder(self, key: tuple[str, str], protocol: str) -> ByteStreamDecoder:
        byte_time = self.byte_time_s.get(key[0])
        cls = STREAM_DECODERS[protocol]
        dec = cls(key[0]) if byte_time is None else cls(key[0], byte_time_s=byte_time)
        dec.start_at(self.start_offset)
        self._streams[key] = dec
        self.detected.setdefault(key[0], protocol)
        return dec

    def _replay(self, key: tuple[str, str], dec: ByteStreamDecoder) -> list[Record]:
        records: list[Record] = []
        for chunk in self._undetected.pop(key, []):
            records += dec.feed(chunk)
        return records

    def _post(self, records: list[Record]) -> list[Record]:
        if not records:
            return records
        check = self.linter.check
        push = self.pairer.push
        out: list[Record] = []
        for rec in records:
            check(rec)
            out += push(rec)
        return out
