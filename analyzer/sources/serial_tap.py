"""Live serial taps (pyserial): one port, one port per RS232 wire, or an inline bridge.

- ``SerialTap``: one port that sees both directions (an RS485 pair, or one RS232 wire).
- ``SerialPairTap``: one adapter per RS232 wire; each port is its own ``stream`` so the two
  directions are framed apart (the consumer merges them in time order by ``Chunk.t``).
- ``SerialBridge``: eg2scope sits in the line between host and device and relays every byte
  both ways unchanged; chunks carry their direction. Not passive.

Each port has its own capture thread running the shared supervisor loop (``supervisor``: open,
lost, back-off, reopen, each reported as a SourceEvent). It opens the port with
``serial_for_url`` (so ``rfc2217://`` and ``loop://`` work), reads whatever is waiting with a
short timeout, stamps each chunk with ``time.time()`` on arrival and puts
``Item(bus, Chunk(data, t), stream=port)`` into the TapQueue. The passive taps never write to
their ports. Nothing is raised or printed from the threads.

DTR and RTS: pyserial raises both when it opens a port, and many USB-RS485 adapters drive
their transmitter from RTS, so a "passive" tap could enable its driver on the bus. Every tap
here sets both lines (low by default) on the unopened port, so they are never raised, not even
for a moment; ``rts``/``dtr`` choose otherwise for adapters that need it. The states are in
``settings`` (and so in a recording's metadata).

Settings a port can never take (a negative baud rate, an unknown URL scheme, a malformed
``socket://`` URL, an empty port name) raise ``UsageError`` when the tap is made. A port that
does not open at the first attempt (no such port, permission denied) is reported by
``first_open``, so the command fails at once, unless ``wait`` (``--wait``: a device not plugged
in yet, waited for with back-off); a port that was open and goes away is reopened with back-off.
"""

from __future__ import annotations

import errno
import os
import threading
import time
from collections.abc import Callable, Sequence
from typing import Any

import serial

from decoders.model import REQUEST, RESPONSE, Chunk

from ..errors import UsageError
from ..model import INFO, WARNING, Item
from .live import Tap, TapQueue, first_attempts_over
from .supervisor import MAX_RETRY_INTERVAL, RETRY_INTERVAL, Backoff, Device, Supervisor

READ_TIMEOUT = 0.05  # read timeout: bounds how long stop() waits for a capture thread
WRITE_TIMEOUT = 0.5  # bridge relay writes
PATH_CHECK_INTERVAL = 0.5  # while idle, how often to check that a port's device path still exists
JOIN_TIMEOUT = 1.0
URL_SCHEMES_PARSED_AT_OPEN = ("rfc2217", "socket", "loop")  # checked when the tap is made

OnData = Callable[[bytes, float], None]


# errors a port gives when it is opened, in a user's words
PORT_ERRORS = {
    errno.ENOENT: "no such port",
    errno.ENODEV: "no such device",
    errno.ENXIO: "no such device",
    errno.EACCES: "permission denied (is the user in the port's group, e.g. dialout?)",
    errno.EBUSY: "the port is busy (another program has it open)",
}


def _describe(exc: BaseException) -> str:
    """An error as one short phrase: "no such port" rather than pyserial's "[Errno 2] could
    not open port X: [Errno 2] No such file or directory: 'X'"."""
    if isinstance(exc, OSError) and isinstance(exc.errno, int) and exc.errno > 0:
        return PORT_ERRORS.get(exc.errno) or f"[Errno {exc.errno}] {os.strerror(exc.errno)}"
    text = str(exc)
    return text if text else type(exc).__name__


def _plain(value: Any) -> Any:
    """A settings value as plain JSON data."""
    if value is None or isinstance(value, str | int | float | bool):
        return value
    return str(value)


def _level(high: bool) -> str:
    return "high" if high else "low"


BAUD_RATES = (300, 12_000_000)  # what UARTs and USB adapters run at (FTDI's fastest: 12M)


def check_port(port: str, serial_kwargs: dict[str, Any]) -> None:
    """UsageError if ``port`` with these settings can never be opened: an empty name, an
    unknown URL scheme, a malformed URL, a setting pyserial refuses, a baud rate no serial line
    runs at."""
    if not isinstance(port, str) or not port.strip() or "\0" in port:
        raise UsageError(f"malformed serial port name {port!r}")
    baudrate = serial_kwargs.get("baudrate")
    lo, hi = BAUD_RATES
    if not isinstance(baudrate, int) or isinstance(baudrate, bool) or not lo <= baudrate <= hi:
        raise UsageError(
            f"impossible baud rate {baudrate!r} for {port}: a serial line runs at "
            f"{lo:,} to {hi:,} baud"
        )
    try:
        probe = serial.serial_for_url(port, do_not_open=True, **serial_kwargs)
        scheme = port.partition("://")[0].lower() if "://" in port else ""
        if scheme in URL_SCHEMES_PARSED_AT_OPEN:
            probe.from_url(port)
    except (ValueError, TypeError, serial.SerialException) as exc:  # TypeError: "socket://x"
        raise UsageError(f"cannot use serial port {port}: {_describe(exc)}") from None


class _PortReader(Device[serial.SerialBase]):
    """One port: its capture thread runs the supervisor loop with this as the device."""

    lost_in_gap = "bytes on the line"
    fatal = (ValueError,)  # pyserial refusing a setting: retrying cannot help

    def __init__(
        self,
        tap: Tap,
        out: TapQueue,
        port: str,
        on_data: OnData,
        serial_kwargs: dict[str, Any],
        *,
        backoff: Backoff,
        wait: bool,
        read_timeout: float,
        rts: bool,
        dtr: bool,
    ) -> None:
        self.tap = tap
        self.out = out
        self.port = port
        self.label = port
        self.on_data = on_data
        self.serial_kwargs = serial_kwargs
        self.read_timeout = read_timeout
        self.rts = rts
        self.dtr = dtr
        self.bytes = 0
        self.chunks = 0
        self.supervisor = Supervisor(self, self._emit, backoff, wait)
        self._ser: serial.SerialBase | None = None
        self._lock = threading.Lock()  # guards _ser between the reader and a bridge's writer
        self._thread: threading.Thread | None = None
        # a device path (not a URL): checked while idle, so a vanished adapter is noticed
        self._is_path = port.startswith("/")

    @property
    def is_open(self) -> bool:
        return self.supervisor.is_open

    # -- called from other threads -----------------------------------------------------------

    def start(self, stop: threading.Event) -> None:
        self._thread = threading.Thread(
            target=self.supervisor.run,
            args=(stop,),
            name=f"eg2scope serial {self.port}",
            daemon=True,
        )
        self._thread.start()

    def join(self, timeout: float) -> None:
        if self._thread is not None:
            self._thread.join(timeout)

    def write(self, data: bytes) -> str | None:
        """Write to this port (bridge relay). None on success, else why it failed."""
        with self._lock:
            ser = self._ser
            if ser is None:
                return f"{self.port} is not open"
            try:
                ser.write(data)
            except Exception as exc:
                return f"{self.port}: {_describe(exc)}"
        return None

    # -- the device, on the capture thread -------------------------------------------------------

    def _emit(self, level: int, kind: str, message: str, count: int) -> None:
        self.tap.event(self.out, level, kind, message, count)

    def why(self, exc: BaseException) -> str:
        return _describe(exc)

    def open(self) -> serial.SerialBase:
        ser = serial.serial_for_url(
            self.port, do_not_open=True, timeout=self.read_timeout, **self.serial_kwargs
        )
        # set before open(): pyserial applies them while opening, so they are never raised
        ser.dtr = self.dtr
        ser.rts = self.rts
        ser.open()
        with self._lock:
            self._ser = ser
        return ser

    def describe(self, ser: serial.SerialBase) -> str:
        try:
            line = f" at {ser.baudrate} baud {ser.bytesize}{ser.parity}{ser.stopbits:g}"
        except Exception:
            line = ""
        return f"{line}, RTS {_level(self.rts)}, DTR {_level(self.dtr)}"

    def close(self, ser: serial.SerialBase) -> None:
        with self._lock:
            self._ser = None
        try:
            ser.close()
        except Exception:
            pass

    def capture(self, ser: serial.SerialBase, running: Callable[[], bool]) -> str | None:
        """Read until stopped (None) or the port fails (why)."""
        on_data = self.on_data
        read = ser.read
        last_check = time.monotonic()
        try:
            while running():
                data = read(max(1, ser.in_waiting))
                if data:
                    t = time.time()
                    self.bytes += len(data)
                    self.chunks += 1
                    on_data(data, t)
                elif self._is_path:
                    now = time.monotonic()
                    if now - last_check >= PATH_CHECK_INTERVAL:
                        last_check = now
                        if not os.path.exists(self.port):
                            return f"{self.port} disappeared"
        except Exception as exc:  # SerialException, OSError, or a driver oddity: never a traceback
            return _describe(exc)
        return None


class _SerialTapBase(Tap):
    """Settings, threads, start and stop shared by the serial taps."""

    def __init__(
        self,
        bus: str,
        passive: str,
        settings: dict[str, Any],
        ports: Sequence[str],
        baudrate: int,
        serial_kwargs: dict[str, Any],
        *,
        retry_interval: float,
        max_retry_interval: float,
        wait: bool,
        read_timeout: float,
        rts: bool,
        dtr: bool,
    ) -> None:
        self.baudrate = baudrate
        self.wait = wait
        self.rts = rts
        self.dtr = dtr
        self.serial_kwargs = _serial_kwargs(baudrate, serial_kwargs)
        for port in ports:
            check_port(port, self.serial_kwargs)
        self.backoff = Backoff(retry_interval, max_retry_interval)
        self.read_timeout = read_timeout
        note = settings.pop("note")
        settings.update({k: _plain(v) for k, v in self.serial_kwargs.items()})
        settings.update(rts=_level(rts), dtr=_level(dtr), passive=passive, note=note)
        super().__init__(bus, passive, settings)
        self._readers: list[_PortReader] = []
        self._stop = threading.Event()
        self._out: TapQueue | None = None

    # subclasses --------------------------------------------------------------------------------

    def _make_readers(self, out: TapQueue) -> list[_PortReader]:
        raise NotImplementedError

    def _passive_message(self) -> tuple[int, str]:
        raise NotImplementedError

    # public ------------------------------------------------------------------------------------

    @property
    def running(self) -> bool:
        return self._out is not None

    @property
    def is_open(self) -> bool:
        return bool(self._readers) and all(r.is_open for r in self._readers)

    @property
    def failed(self) -> str | None:
        reasons = [f"{r.port}: {r.supervisor.failed}" for r in self._readers if r.supervisor.failed]
        return "; ".join(reasons) or None

    def first_open(self) -> str | None:
        first_attempts_over([r.supervisor.first_attempt for r in self._readers])
        return self.failed

    def start(self, out: TapQueue) -> None:
        if self._out is not None:
            raise RuntimeError(f"tap {self.bus!r} is already running")
        self._out = out
        self._stop = threading.Event()
        self._readers = self._make_readers(out)
        level, message = self._passive_message()
        self.event(out, level, "passive", message)
        for reader in self._readers:
            reader.start(self._stop)

    def stop(self) -> None:
        out = self._out
        if out is None:
            return
        self._stop.set()
        for reader in self._readers:
            reader.join(JOIN_TIMEOUT)
        for reader in self._readers:
            self.event(
                out,
                INFO,
                "closed",
                f"closed {reader.port} ({reader.bytes} bytes in {reader.chunks} chunks)",
            )
        self._out = None

    def _reader(self, out: TapQueue, port: str, on_data: OnData) -> _PortReader:
        return _PortReader(
            self,
            out,
            port,
            on_data,
            self.serial_kwargs,
            backoff=self.backoff,
            wait=self.wait,
            read_timeout=self.read_timeout,
            rts=self.rts,
            dtr=self.dtr,
        )


def _serial_kwargs(baudrate: int, extra: dict[str, Any]) -> dict[str, Any]:
    for key in ("timeout", "port", "do_not_open", "url"):
        if key in extra:
            hint = " (use read_timeout)" if key == "timeout" else ""
            raise TypeError(f"serial option {key!r} is set by the tap{hint}")
    return {"baudrate": baudrate, **extra}


def _stream_emitter(out: TapQueue, bus: str, stream: str, direction: str | None) -> OnData:
    put = out.put

    def emit(data: bytes, t: float) -> None:
        put(Item(bus, Chunk(data, t, direction), stream))

    return emit


class SerialTap(_SerialTapBase):
    """Passive tap on one serial port carrying both directions (RS485, or one RS232 wire).

    ``serial_kwargs`` go to pyserial (``bytesize``, ``parity``, ``stopbits``, ...). ``rts`` /
    ``dtr``: the modem lines' state from the moment the port opens (low: never raised).
    """

    def __init__(
        self,
        bus: str,
        port: str,
        baudrate: int = 115200,
        *,
        retry_interval: float = RETRY_INTERVAL,
        max_retry_interval: float = MAX_RETRY_INTERVAL,
        wait: bool = False,
        read_timeout: float = READ_TIMEOUT,
        rts: bool = False,
        dtr: bool = False,
        **serial_kwargs: Any,
    ) -> None:
        self.port = port
        settings: dict[str, Any] = {
            "kind": "serial",
            "port": port,
            "note": "read-only tap: eg2scope never writes to the port",
        }
        super().__init__(
            bus,
            "yes",
            settings,
            [port],
            baudrate,
            serial_kwargs,
            retry_interval=retry_interval,
            max_retry_interval=max_retry_interval,
            wait=wait,
            read_timeout=read_timeout,
            rts=rts,
            dtr=dtr,
        )

    def _make_readers(self, out: TapQueue) -> list[_PortReader]:
        return [self._reader(out, self.port, _stream_emitter(out, self.bus, self.port, None))]

    def _passive_message(self) -> tuple[int, str]:
        return INFO, f"passive: eg2scope only reads {self.port} and never writes to it"


class SerialPairTap(_SerialTapBase):
    """Passive tap with one adapter per RS232 wire: one capture thread per port, each port its
    own ``stream`` (framed separately). ``directions``, if the wiring is known, gives each
    port's Chunk.direction ("request" for the wire the host drives, "response" for the other).
    """

    def __init__(
        self,
        bus: str,
        ports: Sequence[str],
        baudrate: int = 115200,
        *,
        directions: Sequence[str | None] | None = None,
        retry_interval: float = RETRY_INTERVAL,
        max_retry_interval: float = MAX_RETRY_INTERVAL,
        wait: bool = False,
        read_timeout: float = READ_TIMEOUT,
        rts: bool = False,
        dtr: bool = False,
        **serial_kwargs: Any,
    ) -> None:
        self.ports = list(ports)
        if not self.ports:
            raise UsageError("SerialPairTap needs at least one port")
        if len(set(self.ports)) != len(self.ports):
            raise UsageError(f"the ports of a serial pair must be distinct: {self.ports}")
        dirs = list(directions) if directions is not None else [None] * len(self.ports)
        if len(dirs) != len(self.ports):
            raise ValueError("directions must give one entry per port")
        for d in dirs:
            if d not in (None, REQUEST, RESPONSE):
                raise ValueError(f"direction must be {REQUEST!r}, {RESPONSE!r} or None: {d!r}")
        self.directions = dirs
        settings: dict[str, Any] = {
            "kind": "serial-pair",
            "ports": list(self.ports),
            "directions": list(dirs),
            "note": "read-only tap, one adapter per wire: eg2scope never writes to the ports",
        }
        super().__init__(
            bus,
            "yes",
            settings,
            self.ports,
            baudrate,
            serial_kwargs,
            retry_interval=retry_interval,
            max_retry_interval=max_retry_interval,
            wait=wait,
            read_timeout=read_timeout,
            rts=rts,
            dtr=dtr,
        )

    def _make_readers(self, out: TapQueue) -> list[_PortReader]:
        return [
            self._reader(out, port, _stream_emitter(out, self.bus, port, direction))
            for port, direction in zip(self.ports, self.directions, strict=True)
        ]

    def _passive_message(self) -> tuple[int, str]:
        ports = ", ".join(self.ports)
        return INFO, f"passive: eg2scope only reads {ports} (one per wire) and never writes to them"


class SerialBridge(_SerialTapBase):
    """Inline tap: host <-> [host_port | eg2scope | device_port] <-> device.

    Every byte is relayed unchanged as soon as it arrives, then emitted as an Item: bytes from
    the host as ``Chunk(direction="request")`` on stream "host", bytes from the device as
    ``"response"`` on stream "device". Not passive: the link depends on eg2scope running.
    Bytes that cannot be relayed (the other port is down or stuck) are still emitted, counted,
    and reported as WARNING events. DTR and RTS stay low on both ports unless asked otherwise.
    """

    def __init__(
        self,
        bus: str,
        host_port: str,
        device_port: str,
        baudrate: int = 115200,
        *,
        retry_interval: float = RETRY_INTERVAL,
        max_retry_interval: float = MAX_RETRY_INTERVAL,
        wait: bool = False,
        read_timeout: float = READ_TIMEOUT,
        write_timeout: float = WRITE_TIMEOUT,
        rts: bool = False,
        dtr: bool = False,
        **serial_kwargs: Any,
    ) -> None:
        if host_port == device_port:
            raise UsageError("the bridge's host port and device port must differ")
        self.host_port = host_port
        self.device_port = device_port
        self.unrelayed = {"host": 0, "device": 0}  # bytes from that side not relayed (total)
        settings: dict[str, Any] = {
            "kind": "serial-bridge",
            "host_port": host_port,
            "device_port": device_port,
            "inline": True,
            "note": "inline bridge: eg2scope relays every byte between host and device; "
            "not passive, the link depends on eg2scope running",
        }
        super().__init__(
            bus,
            "no",
            settings,
            [host_port, device_port],
            baudrate,
            {"write_timeout": write_timeout, **serial_kwargs},
            retry_interval=retry_interval,
            max_retry_interval=max_retry_interval,
            wait=wait,
            read_timeout=read_timeout,
            rts=rts,
            dtr=dtr,
        )

    def _make_readers(self, out: TapQueue) -> list[_PortReader]:
        host = self._reader(out, self.host_port, _noop)
        device = self._reader(out, self.device_port, _noop)
        host.on_data = self._relay(out, "host", REQUEST, device)
        device.on_data = self._relay(out, "device", RESPONSE, host)
        return [host, device]

    def _relay(self, out: TapQueue, side: str, direction: str, to: _PortReader) -> OnData:
        bus = self.bus
        put = out.put
        other = "device" if side == "host" else "host"
        pending = 0  # bytes not relayed in the current outage (this thread only)

        def relay(data: bytes, t: float) -> None:
            nonlocal pending
            error = to.write(data)
            put(Item(bus, Chunk(data, t, direction), side))
            if error is not None:
                if pending == 0:
                    self.event(
                        out,
                        WARNING,
                        "info",
                        f"bridge: bytes from the {side} are not being relayed to the {other} "
                        f"({error})",
                    )
                pending += len(data)
                self.unrelayed[side] += len(data)
            elif pending:
                self.event(
                    out,
                    INFO,
                    "info",
                    f"bridge: relay {side} -> {other} resumed; {pending} bytes from the {side} "
                    "were not relayed",
                )
                pending = 0

        return relay

    def _passive_message(self) -> tuple[int, str]:
        return (
            WARNING,
            f"not passive: inline bridge between host port {self.host_port} and device port "
            f"{self.device_port}; every byte is relayed unchanged, but the link depends on "
            "eg2scope running",
        )


def _noop(data: bytes, t: float) -> None:
    pass
