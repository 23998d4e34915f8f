"""Serving simulated grippers over the three wire protocols.

- ``SerialGripperServer``: the regular serial protocol (section 1) on a serial port (a PtyBus
  endpoint), 115200 8N1;
- ``ModbusGripperServer``: Modbus RTU (section 2) on a serial port;
- ``CanGripperServer``: the CAN register protocol (section 3) on a python-can bus.

One server thread per bus serves every model on it (several grippers with different IDs on
one line). Requests are framed and decoded by the project's own decoders (the same code the
analyzer uses); responses are built with ``decoders.build``. A broadcast (serial ID 255, Modbus
slave 0, CAN device 16383) is executed by every gripper and answered by none. A gripper in its
save pause (~850 ms) ignores everything; its save response comes after the pause.

Noise knobs, from a seeded ``random.Random`` so a run repeats: ``corrupt`` (probability that a
response carries a bad checksum/CRC; on CAN, whose CRC is checked by the controllers, an error
frame precedes the retransmitted response), ``garbage`` (probability that random bytes reach the
line before a response; on CAN a foreign 11-bit frame) and ``drop`` (probability that a
response is never sent).

Scripted trouble, for scenarios: ``mute`` (a gripper hears nothing until unmuted: a lost
command), ``place_jam`` (an obstruction that stalls the jaw) and, on CAN, ``bus_off`` (the
error frames of a node going error-passive and bus-off, silence, the restart).

The models are shared with the caller: hold ``server.lock`` while touching them from another
thread (or use the helpers ``place_object``, ``place_jam``, ``inject_fault``, ``snapshot``), and
pass time as ``server.clock()``.
"""

from __future__ import annotations

import contextlib
import heapq
import itertools
import os
import random
import select
import threading
import time
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from typing import Any, Final

import can
import serial

from decoders import build, eg2_can, eg2_serial
from decoders.eg2_can import OP_POSITIONING_MOVE, OP_READ, OP_SERVO_FOLLOW, OP_WRITE, Eg2CanDecoder
from decoders.eg2_serial import STATUS_FAILED, STATUS_OK, Cmd, Eg2SerialDecoder
from decoders.flags import BAD_CHECKSUM, SWAPPED_CRC
from decoders.modbus_framing import FIXED_SILENCE_S
from decoders.modbus_pdu import BROADCAST as MODBUS_BROADCAST
from decoders.modbus_rtu import ModbusRtuDecoder
from decoders.model import EG2_CAN, FRAME, REQUEST, CanFrame, Chunk, Record

from ..lifecycle import Running
from ..sources.can_message import frame_to_message, message_to_frame
from .can_trouble import bus_off_frames
from .gripper import ILLEGAL_ADDRESS, ILLEGAL_FUNCTION, ILLEGAL_VALUE, GripperModel

SERIAL_BROADCAST: Final = eg2_serial.BROADCAST
CAN_BROADCAST: Final = eg2_can.BROADCAST
BAUDRATE: Final = 115200
POLL_S: Final = 0.05  # the longest the server thread sleeps: stop() is quick
#: a Modbus slave answers after the standard's silence (t3.5: 1.75 ms at the demo's 115200
#: baud) and a little more, as a real one does: sooner, and ``stats`` rightly flags the frames
MODBUS_LATENCY_S: Final = (FIXED_SILENCE_S + 0.0005, FIXED_SILENCE_S + 0.0015)
SILENCE_S: Final = 0.002  # a pause this long after bytes ends a frame (as RTU's 3.5 chars)

Models = Mapping[int, GripperModel] | Iterable[GripperModel]


@dataclass(slots=True)
class ServerStats:
    requests: int = 0  # valid requests addressed to one of our grippers (or broadcast)
    responses: int = 0  # responses sent
    ignored: int = 0  # frames with errors, for other devices, or while paused
    dropped: int = 0  # responses left out by the drop knob
    corrupted: int = 0  # responses sent with a bad checksum/CRC (CAN: after an error frame)
    garbage: int = 0  # bursts of garbage (CAN: foreign frames) put on the line
    broadcasts: int = 0
    exceptions: int = 0  # Modbus exception responses


class _Server(Running):
    """What the three servers share: models, lock, thread, response schedule, noise."""

    name = "server"

    def __init__(
        self,
        models: Models,
        *,
        latency: tuple[float, float] = (0.0002, 0.001),
        corrupt: float = 0.0,
        garbage: float = 0.0,
        drop: float = 0.0,
        seed: int | None = 0,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self._models: list[GripperModel] = list(
            models.values() if isinstance(models, Mapping) else models
        )
        self.latency = latency
        self.corrupt = corrupt
        self.garbage = garbage
        self.drop = drop
        self.rng = random.Random(seed)
        self.clock = clock
        self.lock = threading.RLock()
        self.stats = ServerStats()
        self.error: BaseException | None = None  # what stopped the thread, if anything
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._heap: list[tuple[float, int, Any]] = []
        self._seq = itertools.count()
        self._muted: set[int] = set()  # IDs that hear nothing (scripted trouble)

    # -- models -----------------------------------------------------------------------------

    @property
    def models(self) -> dict[int, GripperModel]:
        """The grippers by their current ID (an ID can change by command)."""
        with self.lock:
            return {m.device_id: m for m in self._models}

    def add_model(self, model: GripperModel) -> None:
        with self.lock:
            self._models.append(model)

    def model(self, device: int) -> GripperModel:
        with self.lock:
            for m in self._models:
                if m.device_id == device:
                    return m
        raise KeyError(f"no simulated gripper with ID {device}")

    def place_object(self, device: int, width: float | None) -> None:
        with self.lock:
            self.model(device).place_object(width, self.clock())

    def place_jam(self, device: int, at: float | None) -> None:
        with self.lock:
            self.model(device).place_jam(at, self.clock())

    def inject_fault(self, device: int, kind: str, permanent: bool = False) -> None:
        with self.lock:
            self.model(device).inject_fault(kind, self.clock(), permanent)

    def mute(self, device: int, muted: bool) -> None:
        """The gripper hears nothing (neither acts nor answers) until unmuted."""
        with self.lock:
            if muted:
                self._muted.add(device)
            else:
                self._muted.discard(device)

    def bus_off(self, off_s: float) -> None:
        """Only a CAN bus goes bus-off."""
        raise NotImplementedError(f"{self.name}: only a CAN bus goes bus-off")

    def snapshot(self, device: int) -> dict[str, Any]:
        with self.lock:
            m = self.model(device)
            m.step(self.clock())
            return m.snapshot()

    def _targets(self, device: int, broadcast: int, now: float) -> list[GripperModel]:
        """The grippers a request to device reaches (awake and listening ones only)."""
        awake = [m for m in self._models if not m.busy(now) and m.device_id not in self._muted]
        if device == broadcast:
            return awake
        return [m for m in awake if m.device_id == device]

    # -- life cycle -------------------------------------------------------------------------

    def start(self) -> None:
        if self._thread is not None:
            raise RuntimeError("already started")
        self._stop.clear()
        self._open()
        self._thread = threading.Thread(target=self._main, name=self.name, daemon=True)
        self._thread.start()

    def stop(self, timeout: float = 1.0) -> None:
        self._stop.set()
        thread = self._thread
        if thread is not None and thread is not threading.current_thread():
            thread.join(timeout)
        self._thread = None
        self._close()

    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def _main(self) -> None:
        try:
            while not self._stop.is_set():
                self._once(self._timeout())
                self._send_due()
        except BaseException as exc:  # keep it for the owner, do not die silently
            self.error = exc
            raise

    # -- to be supplied ---------------------------------------------------------------------

    def _open(self) -> None:
        raise NotImplementedError

    def _close(self) -> None:
        raise NotImplementedError

    def _once(self, timeout: float) -> None:
        """Wait up to timeout for input and handle it."""
        raise NotImplementedError

    def _emit(self, payload: Any) -> None:
        """Put one scheduled item on the bus."""
        raise NotImplementedError

    # -- the response schedule --------------------------------------------------------------

    def _timeout(self) -> float:
        if not self._heap:
            return POLL_S
        return min(POLL_S, max(0.0, self._heap[0][0] - self.clock()))

    def _schedule(self, due: float, payload: Any) -> None:
        heapq.heappush(self._heap, (due, next(self._seq), payload))

    def _send_due(self) -> None:
        now = self.clock()
        while True:
            with self.lock:  # scripted trouble is scheduled from another thread
                if not self._heap or self._heap[0][0] > now:
                    return
                _, _, payload = heapq.heappop(self._heap)
            self._emit(payload)

    def _respond(self, model: GripperModel, now: float, frame: Any) -> None:
        """Schedule a response after the gripper's latency (after its pause, if it saves)."""
        if self.drop and self.rng.random() < self.drop:
            self.stats.dropped += 1
            return
        lo, hi = self.latency
        due = max(now, model.busy_until) + self.rng.uniform(lo, hi)
        if self.garbage and self.rng.random() < self.garbage:
            self.stats.garbage += 1
            self._schedule(due - lo / 2, self._noise())
        if self.corrupt and self.rng.random() < self.corrupt:
            self.stats.corrupted += 1
            frame = self._corrupted(frame)
        self.stats.responses += 1
        self._schedule(due, frame)

    def _noise(self) -> Any:
        return bytes(self.rng.randrange(256) for _ in range(self.rng.randint(1, 6)))

    def _corrupted(self, frame: Any) -> Any:
        """A byte frame with its last (checksum/CRC) byte damaged."""
        b = bytearray(frame)
        b[-1] ^= self.rng.randint(1, 255)
        return bytes(b)


class _ByteServer(_Server):
    """A server on a serial port (a PtyBus endpoint or a real adapter)."""

    def __init__(self, port: str, models: Models, **kwargs: Any) -> None:
        super().__init__(models, **kwargs)
        self.port = port
        self._ser: serial.Serial | None = None
        self._retry_at = 0.0
        self._held = False  # the decoder holds bytes not decided yet
        self._wake_r = self._wake_w = -1  # a pipe that wakes the thread for stop()

    def _open(self) -> None:
        self._ser = serial.Serial(self.port, BAUDRATE, timeout=0, write_timeout=1.0)

    def _close(self) -> None:
        if self._ser is not None:
            with contextlib.suppress(Exception):
                self._ser.close()
            self._ser = None

    def _decoder(self) -> Any:
        raise NotImplementedError

    def _handle(self, rec: Record, now: float) -> None:
        raise NotImplementedError

    def _once(self, timeout: float) -> None:
        ser = self._ser
        if ser is None:  # the port went away: try again now and then (an unplugged adapter)
            if self.clock() >= self._retry_at:
                self._retry_at = self.clock() + 0.2
                with contextlib.suppress(Exception):
                    self._open()
                    self._dec = self._decoder()
            self._stop.wait(timeout)
            return
        fd = ser.fileno()
        try:
            wait = min(timeout, SILENCE_S) if self._held else timeout
            ready, _, _ = select.select([fd, self._wake_r], [], [], wait)
            if self._wake_r in ready:
                return  # stop() wants the thread
            if ready:
                data = os.read(fd, 4096)
                if not data:
                    raise OSError("the port hung up")
        except (OSError, ValueError):
            self._close()
            return
        now = self.clock()
        with self.lock:
            if ready:
                records = self._dec.feed(Chunk(data, now, REQUEST))
                self._held = True
            elif self._held:
                # silence after bytes ends a frame (the RTU rule): decide what is held
                records = self._dec.finish()
                self._held = False
            else:
                return
            for rec in records:
                if rec.kind == FRAME and rec.direction == REQUEST:
                    self._handle(rec, now)
                else:
                    self.stats.ignored += 1

    def start(self) -> None:
        self._dec = self._decoder()
        self._held = False
        self._wake_r, self._wake_w = os.pipe()
        try:
            super().start()
        except BaseException:
            self._close_wake()
            raise

    def stop(self, timeout: float = 1.0) -> None:
        self._stop.set()
        if self._wake_w >= 0:
            with contextlib.suppress(OSError):
                os.write(self._wake_w, b"x")
        super().stop(timeout)
        self._close_wake()

    def _close_wake(self) -> None:
        for fd in (self._wake_r, self._wake_w):
            if fd >= 0:
                with contextlib.suppress(OSError):
                    os.close(fd)
        self._wake_r = self._wake_w = -1

    def _emit(self, payload: Any) -> None:
        ser = self._ser
        if ser is None:
            return
        try:
            ser.write(payload)
        except (OSError, serial.SerialException):
            self._close()


class SerialGripperServer(_ByteServer):
    """Grippers speaking the regular serial protocol (EB 90 / EE 16 frames) on a port.

    ``SerialGripperServer(port, models, latency=(lo, hi), corrupt=0, garbage=0, drop=0,
    seed=0)``: models is a dict ID -> GripperModel or an iterable of models.
    """

    name = "sim-serial"

    def _decoder(self) -> Any:
        return Eg2SerialDecoder("sim")

    def _handle(self, rec: Record, now: float) -> None:
        if BAD_CHECKSUM in rec.flags:
            self.stats.ignored += 1  # the gripper does not answer
            return
        device = rec.device if rec.device is not None else -1
        targets = self._targets(device, SERIAL_BROADCAST, now)
        if not targets:
            self.stats.ignored += 1
            return
        self.stats.requests += 1
        if device == SERIAL_BROADCAST:
            self.stats.broadcasts += 1
        for m in targets:
            code = rec.code if rec.code is not None else -1
            data = serial_reply(m, code, rec.fields, now)
            if data is not None and device != SERIAL_BROADCAST:
                self._respond(m, now, build.serial_frame(device, code, data, response=True))


def _status(ok: bool) -> bytes:
    return bytes((STATUS_OK if ok else STATUS_FAILED,))


def serial_reply(m: GripperModel, code: int, fields: Mapping[str, Any], now: float) -> bytes | None:
    """Execute one serial command (its decoded fields) on a gripper; the response DATA, or
    None for no answer."""
    f = fields
    try:
        if code == Cmd.PARA_SAVE:
            return _status(m.save(now))
        if code == Cmd.PARA_ID_SET:
            return _status(m.set_id(int(f["new_id"]), now))
        if code in (Cmd.MOVE_CATCH_XG, Cmd.MOVE_CATCH2_XG):
            continuous = code == Cmd.MOVE_CATCH2_XG
            return _status(m.catch(f["speed"], f["force_g"], now, continuous=continuous))
        if code == Cmd.MOVE_RELEASE:
            return _status(m.release(f["speed"], now))
        if code == Cmd.SEEKPOS:
            return _status(m.seek(f["position"], now))
        if code == Cmd.MOVE_STOPHERE:
            return _status(m.stop(now))
        if code == Cmd.SET_EG_PARA:
            return _status(m.set_limits(f["max"], f["min"], now))
        if code == Cmd.ERROR_CLR:
            return _status(m.clear_faults(now))
        if code == Cmd.SET_DRVALL_SPEED:
            return _status(m.set_speed(f["values"][0], now))
        if code == Cmd.SET_DRVALL_YBP_THRESHOLD:
            return _status(m.set_force(f["values"][0], now))
    except (KeyError, IndexError, TypeError):
        return _status(False)  # a payload that does not fit the command
    m.step(now)
    if code == Cmd.READ_EG_PARA:
        return build.u16le(m.max_opening, m.min_opening)
    if code == Cmd.READ_ACTPOS:
        return build.u16le(m.position)
    if code == Cmd.READ_EG_STATE:  # not documented; the layout one client reads (section 4)
        return build.u16le(m.position, m.measured_force, m.force)
    if code == Cmd.READ_EG_RUNSTATE:
        temperature = min(255, max(0, m.temperature_c))
        return bytes((m.state, m.fault, temperature)) + build.u16le(m.position, m.force)
    if code == Cmd.READ_DRVALL_SEEKGYHANGLE:
        return build.u16le(round(m.target))
    if code == Cmd.READ_DRVALL_SPEED:
        return build.u16le(m.speed)
    if code == Cmd.READ_DRVALL_YBP_THRESHOLD:
        return build.u16le(m.force)
    if code == Cmd.READ_HAND_STATUS:
        return bytes((m.state,))
    return None  # unknown command: no answer


class ModbusGripperServer(_ByteServer):
    """Grippers speaking Modbus RTU (functions 03, 06, 16) on a port.

    Registers are accepted as N or 1000 + N (the short numbering of section 4); the response
    echoes the numbering the host used. Exceptions: 1 illegal function, 2 unknown or read-only
    register, 3 bad value or count, 4 the gripper refused (a move while faulted).
    ``accept_swapped_crc``: also answer frames whose CRC is sent high byte first (as the manual
    prints it); off by default, as a standard slave ignores them.
    """

    name = "sim-modbus"

    def __init__(
        self, port: str, models: Models, *, accept_swapped_crc: bool = False, **kwargs: Any
    ) -> None:
        kwargs.setdefault("latency", MODBUS_LATENCY_S)
        super().__init__(port, models, **kwargs)
        self.accept_swapped_crc = accept_swapped_crc

    def _decoder(self) -> Any:
        return ModbusRtuDecoder("sim")

    def _handle(self, rec: Record, now: float) -> None:
        if rec.errors or (SWAPPED_CRC in rec.flags and not self.accept_swapped_crc):
            self.stats.ignored += 1
            return
        slave = rec.device if rec.device is not None else -1
        targets = self._targets(slave, MODBUS_BROADCAST, now)
        if not targets:
            self.stats.ignored += 1
            return
        self.stats.requests += 1
        if slave == MODBUS_BROADCAST:
            self.stats.broadcasts += 1
        for m in targets:
            reply = modbus_reply(m, rec, now)
            if reply is not None and slave != MODBUS_BROADCAST:
                if reply[1] & 0x80:
                    self.stats.exceptions += 1
                self._respond(m, now, reply)


def modbus_reply(m: GripperModel, rec: Record, now: float) -> bytes | None:
    """Execute one Modbus request on a gripper; the response frame (CRC included)."""
    slave = rec.device if rec.device is not None else 0
    fc = rec.code if rec.code is not None else 0
    f = rec.fields
    raw = rec.raw
    if fc not in (0x03, 0x06, 0x10):
        return build.modbus_exception(slave, fc, ILLEGAL_FUNCTION)
    wire_start = raw[2] << 8 | raw[3]  # as sent: 1010, or 10 in the short numbering
    start = int(f.get("start", f.get("register", wire_start)))
    if fc == 0x03:
        count = raw[4] << 8 | raw[5]
        if not 1 <= count <= 125:
            return build.modbus_exception(slave, fc, ILLEGAL_VALUE)
        values = [m.read_register(start + i, now) for i in range(count)]
        if any(v is None for v in values):
            return build.modbus_exception(slave, fc, ILLEGAL_ADDRESS)
        return build.modbus_read_response(slave, [v for v in values if v is not None])
    if fc == 0x06:
        code = m.write_register(start, raw[4] << 8 | raw[5], now)
        if code:
            return build.modbus_exception(slave, fc, code)
        return raw  # the response echoes the request
    count, bc = raw[4] << 8 | raw[5], raw[6]
    if not 1 <= count <= 123 or bc != 2 * count or len(raw) != 9 + bc:
        return build.modbus_exception(slave, fc, ILLEGAL_VALUE)
    words = [raw[7 + 2 * i] << 8 | raw[8 + 2 * i] for i in range(count)]
    code = m.write_registers(start, words, now)
    if code:
        return build.modbus_exception(slave, fc, code)
    return build.modbus_write_multiple_response(slave, wire_start, count)


# -- CAN --------------------------------------------------------------------------------------

# the first and the last byte of registers 1001 ... 1065
CAN_FIRST, CAN_LAST = eg2_can.MAP_FIRST, eg2_can.MAP_LAST + 1
CAN_MAX_ID: Final = 16382


def can_read_bytes(m: GripperModel, address: int, n: int, now: float) -> bytes | None:
    """n bytes of the register image from a CAN byte address (registers low byte first);
    undocumented registers inside the map read 0; None outside the map."""
    if n < 1 or address < CAN_FIRST or address + n - 1 > CAN_LAST:
        return None
    out = bytearray()
    for a in range(address, address + n):
        number = 1000 + ((a & ~1) - 1000) // 2
        value = m.read_register(number, now) or 0
        out.append(value >> 8 if a & 1 else value & 0xFF)
    return bytes(out)


def can_write_bytes(m: GripperModel, address: int, data: bytes, now: float) -> int:
    """Write bytes into the register image at a CAN byte address: all or nothing. Odd spans
    keep the untouched half of a register. Returns 0 or a Modbus-style error code."""
    n = len(data)
    if n < 1 or address < CAN_FIRST or address + n - 1 > CAN_LAST:
        return ILLEGAL_ADDRESS
    first, last = address & ~1, (address + n - 1) & ~1
    numbers = [1000 + (a - 1000) // 2 for a in range(first, last + 1, 2)]
    words: list[int] = []
    for number, a in zip(numbers, range(first, last + 1, 2), strict=True):
        old = m.read_register(number, now)
        if old is None:
            return ILLEGAL_ADDRESS
        lo = data[a - address] if address <= a < address + n else old & 0xFF
        hi = data[a + 1 - address] if address <= a + 1 < address + n else old >> 8
        words.append(lo | hi << 8)
    return m.write_registers(numbers[0], words, now)


class CanGripperServer(_Server):
    """Grippers speaking the CAN register protocol on a python-can bus.

    ``CanGripperServer(models, interface="virtual", channel="eg2scope-sim", bitrate=None,
    bus=None, pad_responses=False, **noise)``: give ``bus`` to serve on a bus you own, else one
    is opened (and closed by stop()). Reads answer DLC N with the register bytes (low byte
    first), writes DLC 1 with N (DLC 8 zero padded when pad_responses). A read or write outside
    the register map, or a write the gripper refuses (bad value, read-only register), gets no
    answer: the CAN protocol has no way to say no (inference). Operation 2 ("positioning move")
    is taken as target, speed, force u16 LE and answered like a write (inference: the manual
    gives no layout); operation 3 is ignored.
    """

    name = "sim-can"

    def __init__(
        self,
        models: Models,
        *,
        interface: str = "virtual",
        channel: str = "eg2scope-sim",
        bitrate: int | None = None,
        bus: can.BusABC | None = None,
        pad_responses: bool = False,
        **kwargs: Any,
    ) -> None:
        super().__init__(models, **kwargs)
        self.interface = interface
        self.channel = channel
        self.bitrate = bitrate
        self.pad_responses = pad_responses
        self._bus = bus
        self._own_bus = bus is None
        self._dec = Eg2CanDecoder("sim")
        self._index = 0
        self._off_bus = False  # bus-off: the grippers neither hear nor answer
        for m in self._models:
            m.id_max = CAN_MAX_ID  # CAN device IDs go to 16382

    def add_model(self, model: GripperModel) -> None:
        model.id_max = CAN_MAX_ID
        super().add_model(model)

    @property
    def bus(self) -> can.BusABC | None:
        return self._bus

    def _open(self) -> None:
        if self._bus is None:
            kwargs: dict[str, Any] = {"receive_own_messages": False}
            if self.bitrate is not None:
                kwargs["bitrate"] = self.bitrate
            self._bus = can.Bus(interface=self.interface, channel=self.channel, **kwargs)
            self._own_bus = True

    def _close(self) -> None:
        if self._bus is not None and self._own_bus:
            with contextlib.suppress(Exception):
                self._bus.shutdown()
            self._bus = None

    def _once(self, timeout: float) -> None:
        bus = self._bus
        if bus is None:
            self._stop.wait(timeout)
            return
        msg = bus.recv(timeout)
        if msg is None:
            return
        now = self.clock()
        frame = message_to_frame(msg)
        with self.lock:
            # everything a gripper receives is a request: judge each frame by its own shape
            self._dec.reset()
            rec = self._dec.decode(frame, self._index)
            self._index += 1
            if rec.protocol != EG2_CAN or rec.direction not in (REQUEST, None) or rec.errors:
                self.stats.ignored += 1
                return
            self._handle(rec, now)

    def bus_off(self, off_s: float) -> None:
        """The grippers' node goes bus-off: the error frames of the ramp (``can_trouble``), then
        for ``off_s`` it hears and answers nothing, then the restart."""
        frames = bus_off_frames(off_s)
        restart = len(frames) - 2  # the restart frame ends the silence
        with self.lock:
            now = self.clock()
            for i, (delay, frame) in enumerate(frames):
                self._schedule(now + delay, _Trouble(frame, off_bus=i < restart))

    def _handle(self, rec: Record, now: float) -> None:
        if self._off_bus:
            self.stats.ignored += 1
            return
        device = rec.device if rec.device is not None else -1
        op = rec.code
        address = int(rec.fields.get("address", -1))
        targets = self._targets(device, CAN_BROADCAST, now)
        if not targets or op == OP_SERVO_FOLLOW:
            self.stats.ignored += 1
            return
        self.stats.requests += 1
        if device == CAN_BROADCAST:
            self.stats.broadcasts += 1
        for m in targets:
            reply: CanFrame | None = None
            if op == OP_READ and rec.direction == REQUEST:
                data = can_read_bytes(m, address, int(rec.fields["length"]), now)
                if data is not None:
                    reply = build.can_read_response(device, address, data)
            elif op == OP_WRITE and rec.direction == REQUEST:
                if can_write_bytes(m, address, rec.raw, now) == 0:
                    reply = self._write_ack(device, address, len(rec.raw))
            elif op == OP_POSITIONING_MOVE and len(rec.raw) == 6:
                target, speed, force = (
                    int.from_bytes(rec.raw[i : i + 2], "little") for i in (0, 2, 4)
                )
                if m.check_write(1011, speed) == 0 and m.check_write(1012, force) == 0:
                    m.speed, m.force = speed, force
                    if m.move_to(target, now):
                        reply = CanFrame(None, build.can_id(op, address, device), bytes((6,)))
            if reply is not None and device != CAN_BROADCAST:
                self._respond(m, now, reply)

    def _write_ack(self, device: int, address: int, n: int) -> CanFrame:
        return build.can_write_response(device, address, n, padded=self.pad_responses)

    def _noise(self) -> Any:
        ident = self.rng.randrange(0x800)
        data = bytes(self.rng.randrange(256) for _ in range(self.rng.randint(0, 8)))
        return CanFrame(None, ident, data, is_extended=False)

    def _corrupted(self, frame: Any) -> Any:
        # a damaged frame never reaches the application: its sender sees an error frame and
        # sends it again
        return ("retransmit", frame)

    def _emit(self, payload: Any) -> None:
        bus = self._bus
        if bus is None:
            return
        frames: list[CanFrame]
        if isinstance(payload, _Trouble):
            self._off_bus = payload.off_bus
            frames = [payload.frame]
        elif isinstance(payload, tuple):
            error = CanFrame(None, 0x008, bytes(8), is_error=True)  # protocol violation
            frames = [error, payload[1]]
        else:
            frames = [payload]
        for frame in frames:
            try:
                bus.send(frame_to_message(frame))
            except can.CanError:
                pass


@dataclass(frozen=True, slots=True)
class _Trouble:
    """One error frame of a bus-off episode; ``off_bus``: the grippers are off the bus after it."""

    frame: CanFrame
    off_bus: bool
