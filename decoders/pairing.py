"""Request/response pairing: link each response to its request, with latency.

Records arrive in stream order (possibly from several buses and protocols). A request that
expects a response is held back until its fate is known (answered, superseded, timed out, or
the stream ended), so that *both* records carry the link when they leave this stage and an
unanswered request can be flagged on the request itself. Everything behind a held request waits
with it, which keeps the output in stream order; the hold is bounded in count and, where
timestamps exist, in time, so memory stays flat.

Retransmissions. A host that times out sends the same request again (same bytes) before the
first answer arrives. The copies wait together; answers go to them in arrival order (the first
answer to the first copy), and each later copy is flagged ``retransmission``. A copy left over
once an answer has come is not "unanswered": the exchange was answered. Once answered, the
next identical request is a new one. Any other request on a one-question-at-a-time bus (serial,
Modbus), or on the same CAN identifier, still means the waiting ones were not answered.

The end. A capture that ends (``flush``) or a source that is lost (``gap``) leaves the waiting
requests ``unanswered``. A capture that was stopped (``cut_off``: a user's stop, the end of a
duration) cannot tell: their answers may have come just after it. They are flagged ``cut_off``
("no response before the capture was stopped"), which is not a problem of the bus.
"""

from __future__ import annotations

import heapq
from collections import deque
from collections.abc import Iterable
from itertools import count
from typing import Any

from . import messages as M
from .model import EG2_SERIAL, FRAME, MODBUS_RTU, REQUEST, RESPONSE, Record

# Protocols on which a host has one question open at a time (RS232 question/answer, RS485
# half duplex): a new request on the bus means the previous one will not be answered.
ONE_OUTSTANDING = frozenset({EG2_SERIAL, MODBUS_RTU})

# _expire takes from the heap every request due by now plus this, then applies the exact test
# (now - t > limit): t + limit and now - t may round differently by a few ulps
_DUE_SLACK_S = 1e-3


def _flag(rec: Record, message: M.Message, **values: object) -> None:
    """A warning in the catalogue's words and its code (once per record)."""
    rec.warnings.append(message.text(**values))
    if message.code not in rec.flags:
        rec.flags.append(message.code)


class Pairer:
    """The pairing stage. ``push`` a record, get the records that are ready, in order."""

    def __init__(
        self,
        timeout_s: float = 0.5,
        save_timeout_s: float = 2.0,
        max_held: int = 10_000,
        positional: bool = False,
        max_held_bytes: int = 64 << 10,
    ) -> None:
        self.timeout_s = timeout_s  # response time-out (clients use 20-30 ms; be generous)
        self.save_timeout_s = save_timeout_s  # a save pauses the gripper ~850 ms
        self.max_held = max_held
        # and in input bytes: a request never answered in a long run of garbage must not hold
        # megabytes of records (64 KiB is seconds of a saturated serial line)
        self.max_held_bytes = max_held_bytes
        self._held_bytes = 0
        # positional: seq is the record's place in its input (offset, or CAN frame index), so
        # a capture decoded in parallel parts numbers its records the same as in one piece
        self.positional = positional
        self._held: deque[Record] = deque()
        # pairing key -> the requests waiting for an answer there: one, or a request and its
        # retransmissions, oldest first
        self._pending: dict[tuple[Any, ...], list[Record]] = {}
        self._answered: set[tuple[Any, ...]] = set()  # keys whose first copy got its answer
        self._waiting: set[int] = set()  # id() of the pending requests
        self._next_expiry = float("inf")  # earliest stream time a pending request times out
        # (t + limit, arrival, t, limit, key, request) of every pending request with a time, in
        # time-out order: expiring looks at the requests that are due, not at every one waiting
        # (thousands wait on a CAN bus whose gripper is gone). Entries of requests answered or
        # dropped meanwhile stay until they reach the top.
        self._due: list[tuple[float, int, float, float, tuple[Any, ...], Record]] = []
        self._arrival = count()
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
            self._held_bytes = 0
            return out
        held.append(rec)
        self._held_bytes += rec.length
        if id(held[0]) in self._waiting and not self._over_limit():
            return []
        return self._release()

    def _over_limit(self) -> bool:
        return len(self._held) > self.max_held or self._held_bytes > self.max_held_bytes

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
        for key in list(self._pending):
            self._close(key, M.PAIRING_END)
        out = list(self._held)
        self._held.clear()
        self._held_bytes = 0
        return out

    def gap(self, bus: str) -> list[Record]:
        """The source of ``bus`` went away (a port lost): answers to the requests waiting on it
        cannot be seen any more. They are flagged and released, so the records before a gap
        come out before it."""
        for key in [k for k in self._pending if k[0] == bus]:
            self._close(key, M.PAIRING_SOURCE_LOST)
        return self._release()

    def cut_off(self, bus: str | None = None) -> list[Record]:
        """The capture of ``bus`` (None: of every bus) was stopped: the requests waiting there
        are flagged ``cut_off``, not ``unanswered`` (their answers may have come after the
        stop), and released. With ``bus`` None nothing is held afterwards."""
        for key in [k for k in self._pending if bus is None or k[0] == bus]:
            self._close(key, M.PAIRING_STOPPED)
        return self._release()

    def waiting_before(self, position: int) -> bool:
        """A request from before ``position`` (a byte offset, or a CAN frame index) still waits
        for its answer: the parallel decoder's check that a part ends decided."""
        for requests in self._pending.values():
            for req in requests:
                where = req.offset if req.offset is not None else req.index
                if where is not None and where < position:
                    return True
        return False

    # -- internals -------------------------------------------------------------------------

    def _key(self, rec: Record) -> tuple[Any, ...]:
        assert rec.pair_key is not None
        return (rec.bus, rec.protocol, *rec.pair_key)

    def _request(self, rec: Record) -> None:
        key = self._key(rec)
        same = self._pending.get(key)
        if same is not None and key not in self._answered and rec.raw == same[0].raw:
            _flag(rec, M.PAIRING_RETRANSMISSION)
            same.append(rec)
        else:
            if rec.protocol in ONE_OUTSTANDING:
                for other in [k for k in self._pending if k[0] == rec.bus and k[1] == rec.protocol]:
                    self._close(other, M.PAIRING_NEXT_REQUEST)
            elif same is not None:
                self._close(key, M.PAIRING_NEXT_SAME_ID)
            if not rec.expects_response:
                return
            self._pending[key] = [rec]
        self._waiting.add(id(rec))
        if rec.t is not None and rec.t == rec.t:  # a NaN time never times out (nor orders a heap)
            limit = self.save_timeout_s if rec.is_save else self.timeout_s
            due = rec.t + limit
            heapq.heappush(self._due, (due, next(self._arrival), rec.t, limit, key, rec))
            self._next_expiry = min(self._next_expiry, due)

    def _response(self, rec: Record) -> None:
        key = self._key(rec)
        requests = self._pending.get(key)
        if requests is None:
            _flag(rec, M.PAIRING_NO_REQUEST)
            return
        req = requests[0]  # answers come in the order the copies were sent
        if len(requests) == 1:
            del self._pending[key]
            if self._answered:
                self._answered.discard(key)
        else:
            del requests[0]
            self._answered.add(key)
        self._waiting.discard(id(req))
        req.pair = rec.seq
        rec.pair = req.seq
        if req.t is not None and rec.t is not None:
            latency = round((rec.t - req.t) * 1000.0, 3)
            req.latency_ms = rec.latency_ms = latency

    def _expire(self, now: float) -> None:
        due, waiting = self._due, self._waiting
        later = []
        while due and due[0][0] <= now + _DUE_SLACK_S:
            entry = heapq.heappop(due)
            _, _, t, limit, key, req = entry
            if id(req) not in waiting:
                continue  # answered or dropped since
            if now - t > limit:
                self._drop(key, req, M.PAIRING_TIMEOUT, ms=limit * 1000)
            else:
                later.append(entry)
        for entry in later:
            heapq.heappush(due, entry)
        while due and id(due[0][5]) not in waiting:
            heapq.heappop(due)
        self._next_expiry = due[0][0] if due else float("inf")

    def _close(self, key: tuple[Any, ...], why: M.Message) -> None:
        """No more answers will come for the requests waiting on key."""
        for req in list(self._pending[key]):
            self._drop(key, req, why)

    def _drop(self, key: tuple[Any, ...], req: Record, why: M.Message, **values: object) -> None:
        """A waiting request will not be answered (``why``, with its flag): say so on it
        (unless an earlier copy of it was answered) and stop waiting."""
        if key not in self._answered:
            _flag(req, why, **values)
        requests = self._pending[key]
        # by identity, not ==: the copies of a request are equal records
        del requests[next(i for i, r in enumerate(requests) if r is req)]
        if not requests:
            del self._pending[key]
            self._answered.discard(key)
        self._waiting.discard(id(req))

    def _release(self) -> list[Record]:
        held = self._held
        waiting = self._waiting
        out: list[Record] = []
        while held and id(held[0]) not in waiting:
            rec = held.popleft()
            self._held_bytes -= rec.length
            out.append(rec)
        if not held:
            self._held_bytes = 0
        elif self._over_limit():
            # bound memory: give up on the oldest request rather than hold the stream
            head = held[0]
            self._drop(self._key(head), head, M.PAIRING_WINDOW)
            out += self._release()
        return out
