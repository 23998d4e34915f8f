"""The three dialects of a host: the handful of things a controller does to a gripper (set up,
catch, release, seek, stop, poll state and opening, clear faults, save, probe), each as the
regular serial protocol, Modbus RTU and the CAN register protocol put it on the wire
(docs/protocol.md). ``connect`` opens the link and the driver of a protocol.

Quirks of third-party clients (section 4) are options of ``HostQuirks``: Modbus registers
without the 1000 offset (xArm style: 10 for 1010), an ID scan that probes IDs 1-N, a save at
start, continuous catch, zero-padded CAN read requests.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import can
import serial

from decoders import build
from decoders.eg2_serial import Cmd, Eg2SerialDecoder
from decoders.modbus_rtu import ModbusRtuDecoder
from decoders.model import CanFrame, Record
from decoders.registers import BY_KEY

from .hostlink import (
    MIN_GAP_S,
    RETRIES,
    TIMEOUT_S,
    ByteLink,
    CanLink,
    GripperReading,
    HostResult,
    Link,
)

PROTOCOLS = ("serial", "modbus", "can")
ALIASES = {
    "eg2-serial": "serial",
    "rs232": "serial",
    "modbus-rtu": "modbus",
    "rs485": "modbus",
    "eg2-can": "can",
}

# CAN byte addresses (section 3.1)
(
    CAN_SAVE,
    CAN_TARGET,
    CAN_SPEED,
    CAN_CATCH_MODE,
    CAN_STOP,
    CAN_FAULT_CLEAR,
    CAN_FORCE_ACT,
    CAN_FAULT,
) = (
    BY_KEY[key].can_address
    for key in (
        "save",
        "target_opening",
        "speed",
        "catch_mode",
        "stop",
        "fault_clear",
        "measured_force",
        "fault",
    )
)
MODBUS_MIN_SPEED, MODBUS_MIN_FORCE = 10, 100  # the registers' ranges (1011, 1012)
SPEED, FORCE = 500, 100  # what the host sets: half speed, 100 g


@dataclass(slots=True)
class HostQuirks:
    """How this host differs from the manual (each seen in real client code, section 4)."""

    short_registers: bool = False  # Modbus: register 10 instead of 1010 (xArm SDK style)
    id_scan: int = 0  # probe IDs 1..N once before the cycles
    save_first: bool = False  # save the parameters once at start, then wait > 1 s
    continuous: bool = False  # continuous catch (serial MOVE_CATCH2_XG, Modbus/CAN catch mode 1)
    padded_reads: bool = False  # CAN: read requests with DLC 8, zero padded


class Driver:
    """The handful of things a pick-and-place host does, in one protocol. ``close`` is the
    pick-and-place program's close (catch or a target of 0, as the quirks say); ``catch``,
    ``seek`` and ``stop`` are a scripted scenario's motions. Each action returns True when the
    gripper answered that it did it."""

    def __init__(self, link: Link, quirks: HostQuirks, speed: int, force: int) -> None:
        self.link = link
        self.quirks = quirks
        self.speed = speed
        self.force = force
        self.catch_modes: dict[int, int] = {}  # Modbus/CAN: the catch mode last written, by ID

    def shutdown(self) -> None:
        """Let go of the link (a port or bus the driver opened itself)."""
        self.link.close()

    def setup(self, device: int) -> None: ...

    def close(self, device: int) -> bool:
        raise NotImplementedError

    def open(self, device: int) -> bool:
        raise NotImplementedError

    def catch(self, device: int, continuous: bool) -> bool:
        """Close with the driver's speed and force, stopping on contact at the force limit."""
        raise NotImplementedError

    def seek(self, device: int, position: int) -> bool:
        """Go to an opening 1-1000."""
        raise NotImplementedError

    def stop(self, device: int) -> bool:
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


class SerialDriver(Driver):
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

    def catch(self, device: int, continuous: bool) -> bool:
        cmd = Cmd.MOVE_CATCH2_XG if continuous else Cmd.MOVE_CATCH_XG
        return self._ok(device, cmd, build.u16le(self.speed, self.force))

    def seek(self, device: int, position: int) -> bool:
        return self._ok(device, Cmd.SEEKPOS, build.u16le(position))

    def stop(self, device: int) -> bool:
        return self._ok(device, Cmd.MOVE_STOPHERE)

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


class ModbusDriver(Driver):
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
        self._write_many(device, 1011, [self.speed, max(MODBUS_MIN_FORCE, self.force)])
        self._catch_mode(device, self.quirks.continuous)

    def _catch_mode(self, device: int, continuous: bool) -> None:
        mode = int(continuous)
        if self.catch_modes.get(device) != mode and self._write(device, 1005, mode):
            self.catch_modes[device] = mode

    def close(self, device: int) -> bool:
        return self._write(device, 1010, 0)

    def open(self, device: int) -> bool:
        return self._write(device, 1010, 1000)

    def catch(self, device: int, continuous: bool) -> bool:
        """The registers that start a catch in one write: target 0, speed, force (1010-1012)."""
        self._catch_mode(device, continuous)
        speed = max(MODBUS_MIN_SPEED, self.speed)
        return self._write_many(device, 1010, [0, speed, max(MODBUS_MIN_FORCE, self.force)])

    def seek(self, device: int, position: int) -> bool:
        return self._write(device, 1010, position)

    def stop(self, device: int) -> bool:
        return self._write(device, 1006, 1)

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


class CanDriver(Driver):
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
        self._write(device, CAN_SPEED, [self.speed, max(MODBUS_MIN_FORCE, self.force)])
        self._catch_mode(device, self.quirks.continuous)

    def _catch_mode(self, device: int, continuous: bool) -> None:
        mode = int(continuous)
        if self.catch_modes.get(device) != mode and self._write(device, CAN_CATCH_MODE, [mode]):
            self.catch_modes[device] = mode

    def close(self, device: int) -> bool:
        return self._write(device, CAN_TARGET, [0])

    def open(self, device: int) -> bool:
        return self._write(device, CAN_TARGET, [1000])

    def catch(self, device: int, continuous: bool) -> bool:
        """The registers that start a catch in one write: target 0, speed, force."""
        self._catch_mode(device, continuous)
        speed = max(MODBUS_MIN_SPEED, self.speed)
        return self._write(device, CAN_TARGET, [0, speed, max(MODBUS_MIN_FORCE, self.force)])

    def seek(self, device: int, position: int) -> bool:
        return self._write(device, CAN_TARGET, [position])

    def stop(self, device: int) -> bool:
        return self._write(device, CAN_STOP, [1])

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


def connect(
    protocol: str,
    port_or_bus: str | serial.Serial | can.BusABC,
    stop: threading.Event,
    result: HostResult,
    quirks: HostQuirks,
    *,
    speed: int = SPEED,
    force: int = FORCE,
    timeout_s: float = TIMEOUT_S,
    min_gap_s: float = MIN_GAP_S,
    retries: int = RETRIES,
) -> Driver:
    """The driver of a protocol ("serial", "modbus", "can" or an alias) on its link: a serial
    port path or an open pyserial port for serial and Modbus; a python-can bus, or a virtual
    channel name, for CAN. ``shutdown()`` lets the link go."""
    name = ALIASES.get(protocol, protocol)
    if name not in PROTOCOLS:
        raise ValueError(f"unknown protocol {protocol!r}; choose one of {', '.join(PROTOCOLS)}")
    common: dict[str, Any] = {
        "result": result,
        "stop": stop,
        "timeout_s": timeout_s,
        "min_gap_s": min_gap_s,
        "retries": retries,
    }
    if name == "can":
        if not isinstance(port_or_bus, can.BusABC | str):
            raise TypeError("CAN needs a python-can bus or a virtual channel name")
        return CanDriver(CanLink(port_or_bus, **common), quirks, speed, force)
    if not isinstance(port_or_bus, serial.Serial | str):
        raise TypeError(f"{name} needs a serial port path or a pyserial port")
    if name == "serial":
        return SerialDriver(
            ByteLink(port_or_bus, Eg2SerialDecoder("host"), **common), quirks, speed, force
        )
    link = ByteLink(port_or_bus, ModbusRtuDecoder("host"), **common)
    return ModbusDriver(link, quirks, speed, force)
