"""Request/response pairing: link each response to its request, with latency.

Records arrive in stream order (possibly from several buses and protocols). A request that
expects a response is held back until its fate is known (answered, superseded, timed out, or
the stream ended), so that *both* records carry the link when they leave this stage and an
unanswered request can be flagged on the request itself. Everything behind a held request waits
with it, which keeps the output in stream order; the hold is bounded in count and, where
timestamps exist, in time, so memory stays flat.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterable
from typing import Any

from .model import EG2_SERIAL, FRAME, MODBUS_RTU, REQUEST, RESPONSE, Record

# Protocols on which a host has one question open at a time (RS232 question/answer, RS485
# half duplex): a new request on the bus means the previous one will not be answered.
ONE_OUTSTANDING = frozenset({EG2_SERIAL, MODBUS_RTU})


class Pairer:
    """The pairing stage. ``push`` a record, get the records that are ready, in order."""

    def __init__(
        self,
        timeout_s: float = 0.5,
        save_timeout_s: float = 2.0,
        max_held: int = 10_000,
        positional: bool = False,
    ) -> None:
        self.timeout_s = timeout_s  # response time-out (clients use 20-30 ms; be generous)
        self.save_timeout_s = save_timeout_s  # a save pauses the gripper ~850 ms
        self.max_held = max_held
        # positional: seq is the record's place in its input (offset, or CAN frame index), so
        # a capture decoded in parallel parts numbers its records the same as in one piece
        self.positional = positional
        self._held: deque[Record] = deque()
        self._pending: dict[tuple[Any, ...], Record] = {}
        self._waiting: set[int] = set()  # id() of the pending requests
        self._next_expiry = float("inf")  # earliest stream time a pending request times out
        self._seq = 0

    def push(self, rec: Record) -> list[Record]:
        if self.positional:
            rec.seq = rec.offset if rec.offset is not None else (rec.index or 0)
        else:
            rec.seq = self._seq
            self._seq += 1
        t = rec.t
        if t is not None and t > self._next_expiry:
            self._expire(t)
        # a frame that fails its checksum cannot be trusted to say who it is for
        if rec.pair_key is not None and rec.kind == FRAME and not rec.errors:
            if rec.direction == REQUEST:
                self._request(rec)
            elif rec.direction == RESPONSE:
                self._response(rec)
        held = self._held
        if not self._pending:
            if not held:
                return [rec]
            held.append(rec)
            out = list(held)
            held.clear()
            return out
        held.append(rec)
        if id(held[0]) in self._waiting:
            return [] if len(held) <= self.max_held else self._release()
        return self._release()

    def push_many(self, records: Iterable[Record]) -> list[Record]:
        out: list[Record] = []
        for rec in records:
            out += self.push(rec)
        return out

    def tick(self, now: float) -> list[Record]:
        """Live streams: time passes with no record (a quiet bus); expire and release."""
        if not self._pending:
            return []
        self._expire(now)
        return self._release()

    def flush(self) -> list[Record]:
        """End of stream: every request still waiting was never answered."""
        for key, req in list(self._pending.items()):
            self._drop(key, req, "no response before the end of the capture")
        out = list(self._held)
        self._held.clear()
        return out

    # -- internals -------------------------------------------------------------------------

    def _key(self, rec: Record) -> tuple[Any, ...]:
        assert rec.pair_key is not None
        return (rec.bus, rec.protocol, *rec.pair_key)

    def _request(self, rec: Record) -> None:
        if rec.protocol in ONE_OUTSTANDING:
            for key, old in list(self._pending.items()):
                if key[0] == rec.bus and key[1] == rec.protocol:
                    self._drop(key, old, "no response before the next request")
        else:
            key = self._key(rec)
            same = self._pending.get(key)
            if same is not None:
                self._drop(key, same, "no response before the next request with the same ID")
        if rec.expects_response:
            self._pending[self._key(rec)] = rec
            self._waiting.add(id(rec))
            if rec.t is not None:
                limit = self.save_timeout_s if rec.is_save else self.timeout_s
                self._next_expiry = min(self._next_expiry, rec.t + limit)

    def _response(self, rec: Record) -> None:
        req = self._pending.pop(self._key(rec), None)
        if req is None:
            rec.warnings.append("response without a request")
            return
        self._waiting.discard(id(req))
        req.pair = rec.seq
        rec.pair = req.seq
        if req.t is not None and rec.t is not None:
            latency = round((rec.t - req.t) * 1000.0, 3)
            req.latency_ms = rec.latency_ms = latency

    def _expire(self, now: float) -> None:
        nxt = float("inf")
        for key, req in list(self._pending.items()):
            if req.t is None:
                continue
            limit = self.save_timeout_s if req.is_save else self.timeout_s
            if now - req.t > limit:
                self._drop(key, req, f"no response within {limit * 1000:.0f} ms")
            else:
                nxt = min(nxt, req.t + limit)
        self._next_expiry = nxt

    def _drop(self, key: tuple[Any, ...], req: Record, why: str) -> None:
        """A pending request will not be answered: say so on it and stop waiting."""
        req.warnings.append(why)
        del self._pending[key]
        self._waiting.discard(id(req))

    def _release(self) -> list[Record]:
        held = self._held
        waiting = self._waiting
        out: list[Record] = []
        while held and id(held[0]) not in waiting:
            out.append(held.popleft())
        if len(held) > self.max_held:
            # bound memory: give up on the oldest request rather than hold the stream
            head = held[0]
            for key, req in list(self._pending.items()):
                if req is head:
                    self._drop(key, req, "no response within the pairing window")
            out += self._release()
        return out
