"""Live serial taps (pyserial): one port, one port per RS232 wire, or an inline bridge.

- ``SerialTap``: one port that sees both directions (an RS485 pair, or one RS232 wire).
- ``SerialPairTap``: one adapter per RS232 wire; each port is its own ``stream`` so the two
  directions are framed apart (the consumer merges them in time order by ``Chunk.t``).
- ``SerialBridge``: eg2scope sits in the line between host and device and relays every byte
  both ways unchanged; chunks carry their direction. Not passive.

Each port has its own capture thread. It opens the port with ``serial_for_url`` (so
``rfc2217://`` and ``loop://`` work), reads whatever is waiting with a short timeout, stamps each
chunk with ``time.time()`` on arrival and puts ``Item(bus, Chunk(data, t), stream=port)`` into
the TapQueue. The passive taps never write to their ports. A port that vanishes (adapter
unplugged) is reported as ``lost`` and retried every ``retry_interval`` seconds until it comes
back (``reopened``, with the length of the gap); a port that cannot be opened at start is
reported as an ERROR and retried the same way. Nothing is raised or printed from the threads.
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

from ..pipeline import Item
from .live import ERROR, INFO, WARNING, Tap, TapQueue

RETRY_INTERVAL = 0.5  # seconds between attempts to (re)open a port
READ_TIMEOUT = 0.05  # read timeout: bounds how long stop() waits for a capture thread
WRITE_TIMEOUT = 0.5  # bridge relay writes
PATH_CHECK_INTERVAL = 0.5  # while idle, how often to check that a port's device path still exists
JOIN_TIMEOUT = 1.0

OnData = Callable[[bytes, float], None]


def _describe(exc: BaseException) -> str:
    """An error as one short phrase: "[Errno 2] No such file or directory" rather than
    pyserial's "[Errno 2] could not open port X: [Errno 2] No such file or directory: 'X'"."""
    if isinstance(exc, OSError) and isinstance(exc.errno, int) and exc.errno > 0:
        text = f"[Errno {exc.errno}] {os.strerror(exc.errno)}"
        if exc.errno == errno.EACCES:
            text += " (is the user in the port's group, e.g. dialout?)"
        return text
    text = str(exc)
    return text if text else type(exc).__name__


def _plain(value: Any) -> Any:
    """A settings value as plain JSON data."""
    if value is None or isinstance(value, str | int | float | bool):
        return value
    return str(value)


class _PortReader:
    """One port's capture thread: open (retrying), read, report loss, reopen."""

    def __init__(
        self,
        tap: Tap,
        out: TapQueue,
        port: str,
        on_data: OnData,
        serial_kwargs: dict[str, Any],
        *,
        retry_interval: float,
        read_timeout: float,
        rts: bool | None = None,
        dtr: bool | None = None,
    ) -> None:
        self.tap = tap
        self.out = out
        self.port = port
        self.on_data = on_data
        self.serial_kwargs = serial_kwargs
        self.retry_interval = retry_interval
        self.read_timeout = read_timeout
        self.rts = rts
        self.dtr = dtr
        self.bytes = 0
        self.chunks = 0
        self.is_open = False
        self._ser: serial.SerialBase | None = None
        self._lock = threading.Lock()  # guards _ser between the reader and a bridge's writer
        self._thread: threading.Thread | None = None
        # a device path (not a URL): checked while idle, so a vanished adapter is noticed
        self._is_path = port.startswith("/")

    # -- called from other threads -----------------------------------------------------------

    def start(self, stop: threading.Event) -> None:
        self._thread = threading.Thread(
            target=self._run, args=(stop,), name=f"eg2scope serial {self.port}", daemon=True
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

    # -- the capture thread ------------------------------------------------------------------

    def _event(self, level: int, kind: str, message: str) -> None:
        self.tap.event(self.out, level, kind, message)

    def _run(self, stop: threading.Event) -> None:
        every = f"retrying every {self.retry_interval:g} s"
        lost_at: float | None = None  # monotonic time the port was lost
        first_try = time.monotonic()
        reported = False  # the current open failure has been reported
        ever_open = False
        while not stop.is_set():
            try:
                ser = self._open()
            except Exception as exc:
                if not reported and not ever_open:
                    self._event(
                        ERROR, "open", f"cannot open {self.port}: {_describe(exc)}; {every}"
                    )
                reported = True
                stop.wait(self.retry_interval)
                continue
            reported = False
            now = time.monotonic()
            if not ever_open:
                waited = now - first_try
                after = f" after {waited:.2f} s of retries" if waited >= self.retry_interval else ""
                self._event(INFO, "open", f"opened {self.port}{self._line_settings(ser)}{after}")
            else:
                gap = now - (lost_at if lost_at is not None else now)
                self._event(
                    INFO,
                    "reopened",
                    f"reopened {self.port} after a {gap:.2f} s gap "
                    "(bytes on the line during the gap were not captured)",
                )
            ever_open = True
            self.is_open = True
            error = self._capture(ser, stop)
            self.is_open = False
            self._close()
            if error is None:
                break
            lost_at = time.monotonic()
            self._event(WARNING, "lost", f"lost {self.port}: {error}; {every}")

    def _line_settings(self, ser: serial.SerialBase) -> str:
        try:
            return f" at {ser.baudrate} baud {ser.bytesize}{ser.parity}{ser.stopbits:g}"
        except Exception:
            return ""

    def _open(self) -> serial.SerialBase:
        ser = serial.serial_for_url(
            self.port, do_not_open=True, timeout=self.read_timeout, **self.serial_kwargs
        )
        if self.rts is not None:
            ser.rts = self.rts
        if self.dtr is not None:
            ser.dtr = self.dtr
        ser.open()
        with self._lock:
            self._ser = ser
        return ser

    def _close(self) -> None:
        with self._lock:
            ser, self._ser = self._ser, None
        if ser is not None:
            try:
                ser.close()
            except Exception:
                pass

    def _capture(self, ser: serial.SerialBase, stop: threading.Event) -> str | None:
        """Read until stopped (None) or the port fails (why)."""
        on_data = self.on_data
        read = ser.read
        last_check = time.monotonic()
        try:
            while not stop.is_set():
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
    """Threads, start and stop shared by the serial taps."""

    def __init__(
        self,
        bus: str,
        passive: str,
        settings: dict[str, Any],
        *,
        retry_interval: float,
        read_timeout: float,
    ) -> None:
        super().__init__(bus, passive, settings)
        self.retry_interval = retry_interval
        self.read_timeout = read_timeout
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

    def _reader(
        self, out: TapQueue, port: str, on_data: OnData, serial_kwargs: dict[str, Any], **kw: Any
    ) -> _PortReader:
        return _PortReader(
            self,
            out,
            port,
            on_data,
            serial_kwargs,
            retry_interval=self.retry_interval,
            read_timeout=self.read_timeout,
            **kw,
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
    ``dtr``: set these modem lines before opening (None: pyserial's default); some RS485
    adapters drive their transmitter from RTS.
    """

    def __init__(
        self,
        bus: str,
        port: str,
        baudrate: int = 115200,
        *,
        retry_interval: float = RETRY_INTERVAL,
        read_timeout: float = READ_TIMEOUT,
        rts: bool | None = None,
        dtr: bool | None = None,
        **serial_kwargs: Any,
    ) -> None:
        self.port = port
        self.baudrate = baudrate
        self.rts = rts
        self.dtr = dtr
        self.serial_kwargs = _serial_kwargs(baudrate, serial_kwargs)
        settings: dict[str, Any] = {
            "kind": "serial",
            "port": port,
            **{k: _plain(v) for k, v in self.serial_kwargs.items()},
            "passive": "yes",
            "note": "read-only tap: eg2scope never writes to the port",
        }
        super().__init__(
            bus, "yes", settings, retry_interval=retry_interval, read_timeout=read_timeout
        )

    def _make_readers(self, out: TapQueue) -> list[_PortReader]:
        emit = _stream_emitter(out, self.bus, self.port, None)
        return [self._reader(out, self.port, emit, self.serial_kwargs, rts=self.rts, dtr=self.dtr)]

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
        read_timeout: float = READ_TIMEOUT,
        rts: bool | None = None,
        dtr: bool | None = None,
        **serial_kwargs: Any,
    ) -> None:
        self.ports = list(ports)
        if not self.ports:
            raise ValueError("SerialPairTap needs at least one port")
        if len(set(self.ports)) != len(self.ports):
            raise ValueError(f"SerialPairTap ports must be distinct: {self.ports}")
        dirs = list(directions) if directions is not None else [None] * len(self.ports)
        if len(dirs) != len(self.ports):
            raise ValueError("directions must give one entry per port")
        for d in dirs:
            if d not in (None, REQUEST, RESPONSE):
                raise ValueError(f"direction must be {REQUEST!r}, {RESPONSE!r} or None: {d!r}")
        self.directions = dirs
        self.baudrate = baudrate
        self.rts = rts
        self.dtr = dtr
        self.serial_kwargs = _serial_kwargs(baudrate, serial_kwargs)
        settings: dict[str, Any] = {
            "kind": "serial-pair",
            "ports": list(self.ports),
            "directions": list(dirs),
            **{k: _plain(v) for k, v in self.serial_kwargs.items()},
            "passive": "yes",
            "note": "read-only tap, one adapter per wire: eg2scope never writes to the ports",
        }
        super().__init__(
            bus, "yes", settings, retry_interval=retry_interval, read_timeout=read_timeout
        )

    def _make_readers(self, out: TapQueue) -> list[_PortReader]:
        return [
            self._reader(
                out,
                port,
                _stream_emitter(out, self.bus, port, direction),
                self.serial_kwargs,
                rts=self.rts,
                dtr=self.dtr,
            )
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
    and reported as WARNING events.
    """

    def __init__(
        self,
        bus: str,
        host_port: str,
        device_port: str,
        baudrate: int = 115200,
        *,
        retry_interval: float = RETRY_INTERVAL,
        read_timeout: float = READ_TIMEOUT,
        write_timeout: float = WRITE_TIMEOUT,
        **serial_kwargs: Any,
    ) -> None:
        if host_port == device_port:
            raise ValueError("host_port and device_port must differ")
        self.host_port = host_port
        self.device_port = device_port
        self.baudrate = baudrate
        self.serial_kwargs = _serial_kwargs(
            baudrate, {"write_timeout": write_timeout, **serial_kwargs}
        )
        self.unrelayed = {"host": 0, "device": 0}  # bytes from that side not relayed (total)
        settings: dict[str, Any] = {
            "kind": "serial-bridge",
            "host_port": host_port,
            "device_port": device_port,
            **{k: _plain(v) for k, v in self.serial_kwargs.items()},
            "passive": "no",
            "inline": True,
            "note": "inline bridge: eg2scope relays every byte between host and device; "
            "not passive, the link depends on eg2scope running",
        }
        super().__init__(
            bus, "no", settings, retry_interval=retry_interval, read_timeout=read_timeout
        )

    def _make_readers(self, out: TapQueue) -> list[_PortReader]:
        host = self._reader(out, self.host_port, _noop, self.serial_kwargs)
        device = self._reader(out, self.device_port, _noop, self.serial_kwargs)
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
