"""A scripted host program: the robot controller side of a pick-and-place cell.

``run_host_cycle`` drives one or more grippers through pick-and-place cycles on any of the three
protocols, the way real controllers do it (reference sections 1.4 and 4): set speed and force,
close on the object, poll state and opening every ``poll_s`` until the catch completes (state 6,
or 2 when there was nothing to catch), "move the arm" for a moment, open, poll until fully open.
It keeps at least ``min_gap_s`` (5 ms) between commands, waits ``timeout_s`` (30 ms) for each
answer and resends a few times (also after a failure status 0x55 or a bad checksum), and waits
more than a second after a save.

Quirks of third-party clients (section 4) are options of ``HostQuirks``: Modbus registers
without the 1000 offset (xArm style: 10 for 1010), an ID scan that probes IDs 1-N, a save at
start, continuous catch, zero-padded CAN read requests.

Responses are parsed with the project's decoders: the host feeds its own requests and the
answers into one decoder, exactly as a tap would see the line.

Usable from a thread: pass a ``threading.Event`` and set it to stop; the function returns
within about one time-out.
"""

from __future__ import annotations

import contextlib
import os
import select
import threading
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import Any

import can
import serial

from decoders import build
from decoders.eg2_can import Eg2CanDecoder
from decoders.eg2_serial import Cmd, Eg2SerialDecoder
from decoders.modbus_rtu import ModbusRtuDecoder
from decoders.model import REQUEST, RESPONSE, CanFrame, Chunk, Record
from decoders.registers import BY_KEY

from ..sources.can_message import frame_to_message, message_to_frame
from .endpoints import BAUDRATE

PROTOCOLS = ("serial", "modbus", "can")
ALIASES = {
    "eg2-serial": "serial",
    "rs232": "serial",
    "modbus-rtu": "modbus",
    "rs485": "modbus",
    "eg2-can": "can",
}

# CAN byte addresses (section 3.1)
CAN_SAVE, CAN_TARGET, CAN_SPEED, CAN_CATCH_MODE, CAN_FAULT_CLEAR, CAN_FORCE_ACT, CAN_FAULT = (
    BY_KEY[key].can_address
    for key in (
        "save",
        "target_opening",
        "speed",
        "catch_mode",
        "fault_clear",
        "measured_force",
        "fault",
    )
)
SILENCE_S = 0.002  # a pause this long ends a frame (3.5 characters are 0.3 ms at 115200)


@dataclass(slots=True)
class HostQuirks:
    """How this host differs from the manual (each seen in real client code, section 4)."""

    short_registers: bool = False  # Modbus: register 10 instead of 1010 (xArm SDK style)
    id_scan: int = 0  # probe IDs 1..N once before the cycles
    save_first: bool = False  # save the parameters once at start, then wait > 1 s
    continuous: bool = False  # continuous catch (serial MOVE_CATCH2_XG, Modbus/CAN catch mode 1)
    padded_reads: bool = False  # CAN: read requests with DLC 8, zero padded


@dataclass(slots=True)
class GripperReading:
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


class _Stopped(Exception):
    pass


class _Link:
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

    def close(self) -> None:
        pass

    def _pace(self) -> None:
        wait = self._last_send + self.min_gap_s - time.monotonic()
        if wait > 0 and self.stop.wait(wait):
            raise _Stopped
        if self.stop.is_set():
            raise _Stopped

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


class _ByteLink(_Link):
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


class _CanLink(_Link):
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


# -- the three dialects -----------------------------------------------------------------------


class _Driver:
    """The handful of things a pick-and-place host does, in one protocol."""

    def __init__(self, link: _Link, quirks: HostQuirks, speed: int, force: int) -> None:
        self.link = link
        self.quirks = quirks
        self.speed = speed
        self.force = force

    def setup(self, device: int) -> None: ...

    def close(self, device: int) -> bool:
        raise NotImplementedError

    def open(self, device: int) -> bool:
        raise NotImplementedError

    def poll(self, device: int) -> GripperReading | None:
        raise NotImplementedError

    def save(self, device: int) -> bool:
        raise NotImplementedError

    def clear_faults(self, device: int) -> bool:
        raise NotImplementedError

    def probe(self, device: int) -> bool:
        """One try, no retries: does anything answer at this ID?"""
        raise NotImplementedError


class _SerialDriver(_Driver):
    def _cmd(self, device: int, cmd: int, data: bytes = b"", **kw: Any) -> Record | None:
        def match(r: Record) -> bool:
            return r.device == device and r.code == cmd

        return self.link.transact(build.serial_frame(device, cmd, data), match, **kw)

    def _ok(self, device: int, cmd: int, data: bytes = b"", **kw: Any) -> bool:
        rec = self._cmd(device, cmd, data, **kw)
        return rec is not None and rec.fields.get("status") == "ok"

    def close(self, device: int) -> bool:
        cmd = Cmd.MOVE_CATCH2_XG if self.quirks.continuous else Cmd.MOVE_CATCH_XG
        return self._ok(device, cmd, build.u16le(self.speed, self.force))

    def open(self, device: int) -> bool:
        return self._ok(device, Cmd.MOVE_RELEASE, build.u16le(self.speed))

    def poll(self, device: int) -> GripperReading | None:
        rec = self._cmd(device, Cmd.READ_EG_RUNSTATE)
        if rec is None or "state" not in rec.fields:
            return None
        f = rec.fields
        return GripperReading(f["state"], f["position"], f["fault"], None)

    def save(self, device: int) -> bool:
        return self._ok(device, Cmd.PARA_SAVE, timeout_s=1.5, retries=0)

    def clear_faults(self, device: int) -> bool:
        return self._ok(device, Cmd.ERROR_CLR)

    def probe(self, device: int) -> bool:
        return self._cmd(device, Cmd.READ_EG_RUNSTATE, retries=0) is not None


class _ModbusDriver(_Driver):
    def _reg(self, number: int) -> int:
        return number - 1000 if self.quirks.short_registers else number

    def _match(self, device: int, fc: int) -> Callable[[Record], bool]:
        def match(r: Record) -> bool:
            return r.device == device and r.code in (fc, fc | 0x80)

        return match

    def _write(self, device: int, register: int, value: int, **kw: Any) -> bool:
        req = build.modbus_write_single(device, self._reg(register), value)
        rec = self.link.transact(req, self._match(device, 6), **kw)
        return rec is not None and "exception_code" not in rec.fields

    def _write_many(self, device: int, start: int, values: list[int]) -> bool:
        req = build.modbus_write_multiple(device, self._reg(start), values)
        rec = self.link.transact(req, self._match(device, 0x10))
        return rec is not None and "exception_code" not in rec.fields

    def _read(self, device: int, start: int, count: int, **kw: Any) -> dict[str, int] | None:
        req = build.modbus_read_request(device, self._reg(start), count)
        rec = self.link.transact(req, self._match(device, 3), **kw)
        if rec is None:
            return None
        values = rec.fields.get("values")
        return values if isinstance(values, dict) else None

    def setup(self, device: int) -> None:
        self._write_many(device, 1011, [self.speed, max(100, self.force)])
        self._write(device, 1005, 1 if self.quirks.continuous else 0)

    def close(self, device: int) -> bool:
        return self._write(device, 1010, 0)

    def open(self, device: int) -> bool:
        return self._write(device, 1010, 1000)

    def poll(self, device: int) -> GripperReading | None:
        v = self._read(device, 1060, 6)
        if v is None or "CMD_STATUS" not in v:
            return None
        return GripperReading(
            v["CMD_STATUS"],
            v.get("CMD_OPENLEN_ACT"),
            v.get("CMD_ERRORCODE"),
            v.get("CMD_FORCE_ACT"),
        )

    def save(self, device: int) -> bool:
        return self._write(device, 1001, 1, timeout_s=1.5, retries=0)

    def clear_faults(self, device: int) -> bool:
        return self._write(device, 1007, 1)

    def probe(self, device: int) -> bool:
        return self._read(device, 1065, 1, retries=0) is not None


class _CanDriver(_Driver):
    def _match(self, frame: CanFrame) -> Callable[[Record], bool]:
        aid = frame.arbitration_id

        def match(r: Record) -> bool:
            return r.pair_key == (aid,)

        return match

    def _write(self, device: int, address: int, values: list[int], **kw: Any) -> bool:
        frame = build.can_write_request(device, address, build.u16le(*values))
        rec = self.link.transact(frame, self._match(frame), **kw)
        return rec is not None and rec.fields.get("written_bytes") == len(frame.data)

    def _read(self, device: int, address: int, n: int, **kw: Any) -> dict[str, Any] | None:
        frame = build.can_read_request(device, address, n, padded=self.quirks.padded_reads)
        rec = self.link.transact(frame, self._match(frame), **kw)
        if rec is None:
            return None
        values = rec.fields.get("values")
        return values if isinstance(values, dict) else None

    def setup(self, device: int) -> None:
        self._write(device, CAN_SPEED, [self.speed, max(100, self.force)])
        self._write(device, CAN_CATCH_MODE, [1 if self.quirks.continuous else 0])

    def close(self, device: int) -> bool:
        return self._write(device, CAN_TARGET, [0])

    def open(self, device: int) -> bool:
        return self._write(device, CAN_TARGET, [1000])

    def poll(self, device: int) -> GripperReading | None:
        status = self._read(device, CAN_FAULT, 4)
        if status is None or "CMD_STATUS" not in status:
            return None
        act = self._read(device, CAN_FORCE_ACT, 4) or {}
        return GripperReading(
            status["CMD_STATUS"],
            act.get("CMD_OPENLEN_ACT"),
            status.get("CMD_ERRORCODE"),
            act.get("CMD_FORCE_ACT"),
        )

    def save(self, device: int) -> bool:
        return self._write(device, CAN_SAVE, [1], timeout_s=1.5, retries=0)

    def clear_faults(self, device: int) -> bool:
        return self._write(device, CAN_FAULT_CLEAR, [1])

    def probe(self, device: int) -> bool:
        return self._read(device, CAN_FAULT + 2, 2, retries=0) is not None


# -- the program ------------------------------------------------------------------------------


def run_host_cycle(
    protocol: str,
    port_or_bus: str | serial.Serial | can.BusABC,
    ids: Iterable[int] = (1,),
    cycles: int | None = 1,
    stop_event: threading.Event | None = None,
    quirks: HostQuirks | None = None,
    *,
    speed: int = 500,
    force: int = 100,
    poll_s: float = 0.025,
    timeout_s: float = 0.03,
    min_gap_s: float = 0.005,
    retries: int = 2,
    dwell_s: float = 0.1,
    motion_timeout_s: float = 3.0,
    result: HostResult | None = None,
) -> HostResult:
    """Run ``cycles`` pick-and-place cycles (None: until stop_event) on every gripper in ids.

    protocol: "serial", "modbus" or "can". port_or_bus: a serial port path (or an open
    pyserial port) for serial and Modbus; a python-can bus, or a virtual channel name, for CAN.
    Pass ``result`` to watch progress from another thread. Returns the HostResult.
    """
    name = ALIASES.get(protocol, protocol)
    if name not in PROTOCOLS:
        raise ValueError(f"unknown protocol {protocol!r}; choose one of {', '.join(PROTOCOLS)}")
    stop = stop_event if stop_event is not None else threading.Event()
    quirks = quirks if quirks is not None else HostQuirks()
    result = result if result is not None else HostResult()
    devices = list(ids)
    common = {
        "result": result,
        "stop": stop,
        "timeout_s": timeout_s,
        "min_gap_s": min_gap_s,
        "retries": retries,
    }
    link: _Link
    driver: _Driver
    if name == "can":
        if not isinstance(port_or_bus, can.BusABC | str):
            raise TypeError("CAN needs a python-can bus or a virtual channel name")
        link = _CanLink(port_or_bus, **common)
        driver = _CanDriver(link, quirks, speed, force)
    else:
        if not isinstance(port_or_bus, serial.Serial | str):
            raise TypeError(f"{name} needs a serial port path or a pyserial port")
        decoder: Any = Eg2SerialDecoder("host") if name == "serial" else ModbusRtuDecoder("host")
        link = _ByteLink(port_or_bus, decoder, **common)
        driver = (
            _SerialDriver(link, quirks, speed, force)
            if name == "serial"
            else _ModbusDriver(link, quirks, speed, force)
        )
    try:
        _program(driver, devices, cycles, stop, quirks, result, poll_s, dwell_s, motion_timeout_s)
    except _Stopped:
        pass
    finally:
        link.close()
    return result


def _program(
    driver: _Driver,
    devices: list[int],
    cycles: int | None,
    stop: threading.Event,
    quirks: HostQuirks,
    result: HostResult,
    poll_s: float,
    dwell_s: float,
    motion_timeout_s: float,
) -> None:
    if quirks.id_scan:
        for device in range(1, quirks.id_scan + 1):
            if driver.probe(device):
                result.found.append(device)
    for device in devices:
        result.grips.setdefault(device, 0)
        result.states_seen.setdefault(device, set())
        driver.setup(device)
    if quirks.save_first:
        for device in devices:
            driver.save(device)
        if stop.wait(1.05):  # the manual: allow more than 1 s after a save
            raise _Stopped
    done = 0
    while cycles is None or done < cycles:
        # pick: close every gripper on its object, wait for the catch
        for device in devices:
            driver.close(device)
        final = _wait_for(driver, devices, {2, 3, 6}, stop, result, poll_s, motion_timeout_s)
        for device, state in final.items():
            if state == 6:
                result.grips[device] += 1
        _dwell(driver, devices, stop, result, poll_s, dwell_s)  # the arm carries the object
        # place: open, wait until fully open
        for device in devices:
            driver.open(device)
        _wait_for(driver, devices, {1, 3}, stop, result, poll_s, motion_timeout_s)
        _dwell(driver, devices, stop, result, poll_s, dwell_s)  # the arm goes back
        done += 1
        result.cycles = done


def _poll_all(driver: _Driver, devices: list[int], result: HostResult) -> dict[int, int | None]:
    states: dict[int, int | None] = {}
    for device in devices:
        reading = driver.poll(device)
        states[device] = None if reading is None else reading.state
        if reading is not None:
            result.last[device] = reading
            if reading.state is not None:
                result.states_seen.setdefault(device, set()).add(reading.state)
            if reading.fault:
                driver.clear_faults(device)
    return states


def _wait_for(
    driver: _Driver,
    devices: list[int],
    done_states: set[int],
    stop: threading.Event,
    result: HostResult,
    poll_s: float,
    limit_s: float,
) -> dict[int, int | None]:
    """Poll until every gripper is in one of done_states (or limit_s passes)."""
    deadline = time.monotonic() + limit_s
    waiting = list(devices)
    final: dict[int, int | None] = {}
    while waiting and time.monotonic() < deadline:
        started = time.monotonic()
        states = _poll_all(driver, waiting, result)
        for device, state in states.items():
            if state in done_states:
                final[device] = state
                waiting.remove(device)
        if not waiting:
            break
        if stop.wait(max(0.0, poll_s - (time.monotonic() - started))):
            raise _Stopped
    for device in waiting:
        final[device] = None
    return final


def _dwell(
    driver: _Driver,
    devices: list[int],
    stop: threading.Event,
    result: HostResult,
    poll_s: float,
    dwell_s: float,
) -> None:
    """Keep polling (as controllers do) while the arm moves."""
    end = time.monotonic() + dwell_s
    while time.monotonic() < end:
        started = time.monotonic()
        _poll_all(driver, devices, result)
        if stop.wait(max(0.0, min(poll_s - (time.monotonic() - started), end - time.monotonic()))):
            raise _Stopped
