"""The host's side of a bus: one transaction at a time. Send a request, wait for the answer
that matches it (resending on silence, a failure status or a bad checksum), and count what
happened in a ``HostResult``.

``ByteLink`` talks over a serial port (the regular protocol and Modbus RTU share it); ``CanLink``
over a python-can bus. Answers are parsed with the project's decoders: the link feeds its own
requests and the answers into one decoder, exactly as a tap would see the line.
"""

from __future__ import annotations

import contextlib
import os
import select
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import can
import serial

from decoders.eg2_can import Eg2CanDecoder
from decoders.model import REQUEST, RESPONSE, CanFrame, Chunk, Record

from ..sources.can_message import frame_to_message, message_to_frame
from .endpoints import BAUDRATE

SILENCE_S = 0.002  # a pause this long ends a frame (3.5 characters are 0.3 ms at 115200)
# a host's pace: the answer awaited this long, resent this many times, frames this far apart
TIMEOUT_S = 0.03
RETRIES = 2
MIN_GAP_S = 0.005


@dataclass(slots=True)
class GripperReading:
    """One poll's answer (None: not in it)."""

    state: int | None = None
    position: int | None = None
    fault: int | None = None
    force: int | None = None


@dataclass(slots=True)
class HostResult:
    """What happened, for tests and the demo."""

    cycles: int = 0  # complete pick-and-place cycles
    commands: int = 0  # frames sent (retries included)
    responses: int = 0  # valid answers received
    timeouts: int = 0  # commands with no answer in time
    retries: int = 0
    failures: int = 0  # failure status 0x55, Modbus exceptions, bad checksums
    grips: dict[int, int] = field(default_factory=dict)  # ID -> catches that hit the object
    found: list[int] = field(default_factory=list)  # IDs that answered the scan
    last: dict[int, GripperReading] = field(default_factory=dict)
    states_seen: dict[int, set[int]] = field(default_factory=dict)  # ID -> states polled


class Stopped(Exception):
    """The stop event was set: the host program ends."""


class Link:
    """One transaction at a time on one bus: send, wait for the matching answer."""

    def __init__(
        self,
        result: HostResult,
        stop: threading.Event,
        timeout_s: float,
        min_gap_s: float,
        retries: int,
    ) -> None:
        self.result = result
        self.stop = stop
        self.timeout_s = timeout_s
        self.min_gap_s = min_gap_s
        self.retries = retries
        self._last_send = -1e9
        self._last_heard = -1e9  # when the last wait for an answer ended

    def close(self) -> None:
        pass

    def _pace(self) -> None:
        # frames this far apart, and never sooner after an answer than the line's silence
        # (Modbus RTU's t3.5: a host that speaks sooner is one ``stats`` rightly flags)
        due = max(self._last_send + self.min_gap_s, self._last_heard + SILENCE_S)
        wait = due - time.monotonic()
        if wait > 0 and self.stop.wait(wait):
            raise Stopped
        if self.stop.is_set():
            raise Stopped

    def transact(
        self,
        request: Any,
        match: Callable[[Record], bool],
        *,
        timeout_s: float | None = None,
        retries: int | None = None,
        broadcast: bool = False,
    ) -> Record | None:
        """Send request (resending on silence or a bad answer); the answer's record or None.
        A valid answer with a failure status or an exception is returned as it is after the
        retries are spent."""
        tries = 1 + (self.retries if retries is None else retries)
        answer: Record | None = None
        for attempt in range(tries):
            if attempt:
                self.result.retries += 1
            self._pace()
            self._send(request)
            self._last_send = time.monotonic()
            self.result.commands += 1
            if broadcast:
                return None
            answer = self._wait(match, self.timeout_s if timeout_s is None else timeout_s)
            self._last_heard = time.monotonic()
            if answer is None:
                self.result.timeouts += 1
                continue
            if answer.errors or _failed(answer):
                self.result.failures += 1
                if answer.errors:
                    answer = None
                continue
            self.result.responses += 1
            return answer
        return answer

    def _send(self, request: Any) -> None:
        raise NotImplementedError

    def _wait(self, match: Callable[[Record], bool], timeout_s: float) -> Record | None:
        raise NotImplementedError


def _failed(rec: Record) -> bool:
    return rec.fields.get("status") == "failure" or "exception_code" in rec.fields


class ByteLink(Link):
    def __init__(self, port: str | serial.Serial, decoder: Any, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        if isinstance(port, str):
            self.ser = serial.Serial(port, BAUDRATE, timeout=0)
            self._own = True
        else:
            self.ser = port
            self._own = False
        self.ser.reset_input_buffer()
        self.dec = decoder

    def close(self) -> None:
        if self._own:
            with contextlib.suppress(Exception):
                self.ser.close()

    def _send(self, request: Any) -> None:
        # drop what arrived unasked (late answers, noise): it answers nothing we wait for
        fd = self.ser.fileno()
        while select.select([fd], [], [], 0)[0]:
            stale = os.read(fd, 4096)
            if not stale:
                break
            self.dec.feed(Chunk(stale, time.monotonic(), RESPONSE))
        self.ser.write(request)
        self.dec.feed(Chunk(request, time.monotonic(), REQUEST))

    def _wait(self, match: Callable[[Record], bool], timeout_s: float) -> Record | None:
        fd = self.ser.fileno()
        deadline = time.monotonic() + timeout_s
        held = False  # the decoder holds bytes it could not decide yet
        while True:
            left = deadline - time.monotonic()
            if left <= 0 or self.stop.is_set():
                return None
            ready, _, _ = select.select([fd], [], [], min(left, SILENCE_S if held else 0.05))
            if ready:
                data = os.read(fd, 4096)
                if not data:
                    raise OSError("the serial port hung up")
                records = self.dec.feed(Chunk(data, time.monotonic(), RESPONSE))
                held = True
            elif held:
                # silence after bytes ends a frame (the RTU rule): decide what is held
                records = self.dec.finish()
                held = False
            else:
                continue
            for rec in records:
                if rec.direction == RESPONSE and match(rec):
                    return rec


class CanLink(Link):
    def __init__(self, bus: can.BusABC | str, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        if isinstance(bus, str):
            self.bus: can.BusABC = can.Bus(
                interface="virtual", channel=bus, receive_own_messages=False
            )
            self._own = True
        else:
            self.bus = bus
            self._own = False
        self.dec = Eg2CanDecoder("host")
        self._index = 0

    def close(self) -> None:
        if self._own:
            self.bus.shutdown()

    def _decode(self, frame: CanFrame) -> Record:
        rec = self.dec.decode(frame, self._index)
        self._index += 1
        return rec

    def _send(self, request: Any) -> None:
        while (stale := self.bus.recv(0)) is not None:
            self._decode(message_to_frame(stale))
        frame: CanFrame = request
        self.bus.send(frame_to_message(frame))
        frame.t = time.time()
        self._decode(frame)

    def _wait(self, match: Callable[[Record], bool], timeout_s: float) -> Record | None:
        deadline = time.monotonic() + timeout_s
        while True:
            left = deadline - time.monotonic()
            if left <= 0 or self.stop.is_set():
                return None
            msg = self.bus.recv(min(left, 0.05))
            if msg is None:
                continue
            rec = self._decode(message_to_frame(msg))
            if rec.direction == RESPONSE and match(rec):
                return rec
