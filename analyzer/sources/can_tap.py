"""Live CAN tap (python-can): listen-only wherever the interface allows it, never sends.

``CanTap`` opens ``can.Bus(interface=..., channel=..., bitrate=..., receive_own_messages=False)``
with listen-only requested through the interface's own option (pcan/systec
``state=BusState.PASSIVE``, vector/slcan/nixnet ``listen_only=True``, kvaser
``driver_mode=False``; also cantact ``monitor=True`` and seeedstudio
``operation_mode="silent"``). socketcan has no such option: listen-only is a property of the
link (``ip link set can0 type can ... listen-only on``), so the tap reads
``ip -details link show <channel>`` to tell. The outcome is ``self.passive`` ("yes", "no",
"unknown"), ``self.settings`` and a "passive" SourceEvent.

Frames reach the TapQueue from the tap's own thread: it calls ``bus.recv`` in a loop and a
``can.Listener`` converts each ``can.Message`` to a ``CanFrame`` (``can_message``; the queue
never blocks). No ``can.Notifier``: its extra thread, lock and dispatch per frame cost a
quarter of the tap's time at 20,000 frames/s, and the tap's thread only waited for it. The
shared supervisor loop (``supervisor``) keeps the bus open: when the interface goes down (the
receive thread raises) the tap reports ``lost``, shuts the bus down and reopens it with
back-off (``reopened``, with the gap); an adapter that fails on every receive is reported as
one ``lost`` event with a count, not thousands. The tap never calls ``send``.

Settings that can never work raise ``UsageError`` when the tap is made: an interface python-can
does not know, an empty or malformed channel, a bit rate that is not a positive number. A bus
that does not open at the first attempt (no such CAN interface, a driver missing, an adapter
not plugged in) is reported by ``first_open`` in a user's words, so the command fails at once,
unless ``wait`` (``--wait``: waited for with back-off; a setting the interface refuses or a
driver missing still fails at once). A bus that was open and goes down is reopened with
back-off.
"""

from __future__ import annotations

import errno
import os
import re
import socket
import subprocess
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import can

from ..errors import UsageError
from ..model import INFO, WARNING, Item
from .can_message import message_to_frame
from .live import Tap, TapQueue, first_attempts_over
from .supervisor import MAX_RETRY_INTERVAL, RETRY_INTERVAL, Backoff, Device, Supervisor

RECV_TIMEOUT = 0.1  # the receive timeout: bounds how long stopping takes
# the kernel's receive buffer asked for socket-based interfaces (socketcan, udp_multicast); the
# kernel grants at most net.core.rmem_max. The default (~200 kB) holds about 10 ms of a busy
# bus: while decoding or the screen holds the GIL, the receive thread waits and frames are lost
# in the kernel, where no queue counts them (candump -r does the same)
RECEIVE_BUFFER = 8 << 20
JOIN_TIMEOUT = 2.0
REBASE_THRESHOLD = 24 * 3600.0  # timestamps further than this from time.time() are not epoch

# interface -> the keyword arguments that put it in listen-only mode
LISTEN_ONLY_KWARGS: dict[str, dict[str, Any]] = {
    "pcan": {"state": can.BusState.PASSIVE},
    "systec": {"state": can.BusState.PASSIVE},
    "vector": {"listen_only": True},
    "slcan": {"listen_only": True},
    "nixnet": {"listen_only": True},
    "kvaser": {"driver_mode": False},
    "cantact": {"monitor": True},
    "seeedstudio": {"operation_mode": "silent"},
}
# simulated buses: no wire, no controller; passive because the tap never sends
SIMULATED = {"virtual": "virtual bus (simulated)", "udp_multicast": "UDP multicast bus (simulated)"}

IFNAMSIZ = 16  # Linux network interface names: at most 15 characters
_MALFORMED_CHANNEL = re.compile(r"^$|\s|[\x00-\x1f]")

# errors a CAN bus gives when it is opened, in a user's words
BUS_ERRORS = {
    errno.ENODEV: "no such CAN interface",
    errno.ENOENT: "no such device or port",
    errno.EAFNOSUPPORT: "this kernel has no SocketCAN (address family AF_CAN not supported)",
    errno.ENETDOWN: "the interface is down",
    errno.EACCES: "permission denied",
    errno.EPERM: "permission denied",
}

NEVER_SENDS = "the tap never sends"
ACKS = "its controller acknowledges frames and may send error frames"


def _plain(value: Any) -> Any:
    if value is None or isinstance(value, str | int | float | bool):
        return value
    if isinstance(value, can.BusState):
        return value.name
    return str(value)


def _same_option(key: str, given: Any, wanted: Any) -> bool:
    if key == "state" and isinstance(given, str):
        return given.upper() == wanted.name
    return bool(given == wanted)


def listen_only_plan(
    interface: str, kwargs: dict[str, Any], listen_only: bool = True
) -> tuple[dict[str, Any], str, str]:
    """For interfaces with a listen-only option (not socketcan): the keyword arguments to add,
    the resulting passive state and a sentence saying why."""
    if interface in SIMULATED:
        return {}, "yes", f"{SIMULATED[interface]}, {NEVER_SENDS}"
    wanted = LISTEN_ONLY_KWARGS.get(interface)
    if wanted is None:
        return (
            {},
            "unknown",
            f"python-can has no listen-only option for interface {interface!r}: unless the "
            f"adapter is configured listen-only, {ACKS}; {NEVER_SENDS}",
        )
    options = ", ".join(f"{k}={_plain(v)!r}" for k, v in wanted.items())
    if not listen_only:
        return {}, "no", f"listen-only not requested ({options} not set): {ACKS}"
    for key, value in wanted.items():
        if key in kwargs and not _same_option(key, kwargs[key], value):
            return (
                {},
                "no",
                f"listen-only overridden by {key}={_plain(kwargs[key])!r}: {ACKS}",
            )
    return dict(wanted), "yes", f"listen-only requested ({options}); {NEVER_SENDS}"


_VCAN = re.compile(r"^\s*vcan\b", re.MULTILINE)
_CAN_CTRLMODE = re.compile(r"\bcan\s+<([^>]*)>")
_CAN_LINK = re.compile(r"\blink/can\b")


def parse_ip_link_details(channel: str, text: str) -> tuple[str, str]:
    """Passive state of a socketcan link from ``ip -details link show <channel>`` output."""
    hint = (
        f"for a passive tap: sudo ip link set {channel} down && sudo ip link set {channel} "
        f"type can bitrate <bitrate> listen-only on && sudo ip link set {channel} up"
    )
    if _VCAN.search(text):
        return "yes", f"{channel} is a vcan (virtual kernel bus, no wire); {NEVER_SENDS}"
    match = _CAN_CTRLMODE.search(text)
    if match and "LISTEN-ONLY" in [m.strip() for m in match.group(1).split(",")]:
        return "yes", f"listen-only is on for {channel} (ip link); {NEVER_SENDS}"
    if _CAN_LINK.search(text):
        return "unknown", f"listen-only is off for {channel}: {ACKS}; {hint}"
    return "unknown", f"cannot tell whether {channel} is listen-only (ip link); {hint}"


def socketcan_passive(channel: str) -> tuple[str, str]:
    """Ask ``ip -details link show`` whether a socketcan link is listen-only."""
    try:
        proc = subprocess.run(
            ["ip", "-details", "link", "show", channel],
            capture_output=True,
            text=True,
            timeout=2.0,
            check=False,
        )
    except (OSError, subprocess.SubprocessError) as exc:
        return "unknown", f"cannot read the listen-only state of {channel} ({exc}); {NEVER_SENDS}"
    if proc.returncode != 0:
        why = proc.stderr.strip() or f"ip exited with {proc.returncode}"
        return "unknown", f"cannot read the listen-only state of {channel} ({why})"
    return parse_ip_link_details(channel, proc.stdout)


def _socketcan_link_down(channel: str) -> bool:
    """True when /sys says the interface exists but is administratively down."""
    try:
        with open(f"/sys/class/net/{channel}/flags") as f:
            flags = int(f.read().strip(), 16)
    except (OSError, ValueError):
        return False
    return not flags & 0x1  # IFF_UP


def bus_error(exc: BaseException) -> str:
    """Why a CAN bus did not open, in a user's words: "no such CAN interface", "driver not
    found (...)" (python-can's own words in brackets where they add something)."""
    text = str(exc).strip()
    cause: BaseException | None = exc
    while cause is not None:  # python-can wraps the OS's error (slcan: the serial port's)
        if isinstance(cause, OSError) and cause.errno in BUS_ERRORS:
            return BUS_ERRORS[cause.errno]
        cause = cause.__cause__ or cause.__context__
    missing = isinstance(exc, can.CanInterfaceNotImplementedError | ImportError)
    if missing or re.search(r"(library|driver|dll)\b.*\bnot (found|loaded)", text, re.I):
        return f"driver not found ({text or type(exc).__name__})"
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


class _FrameListener(can.Listener):
    """can.Message -> CanFrame -> TapQueue, on the tap's thread. Never blocks."""

    def __init__(self, tap: CanTap, out: TapQueue) -> None:
        self.tap = tap
        self.out = out
        self.frames = 0
        self._offset: float | None = None

    def on_message_received(self, msg: can.Message) -> None:
        ts = msg.timestamp
        if not ts:
            t = time.time()
        else:
            if self._offset is None:
                self._offset = self._rebase(ts)
            t = ts + self._offset
        frame = message_to_frame(msg, t)
        if frame.channel is None:
            frame.channel = self.tap.channel_name
        self.frames += 1
        self.out.put(Item(self.tap.bus, frame))

    def _rebase(self, ts: float) -> float:
        now = time.time()
        if abs(now - ts) <= REBASE_THRESHOLD:
            return 0.0
        self.tap.event(
            self.out,
            INFO,
            "info",
            f"{self.tap.interface} timestamps are not on the host clock (first {ts:.6f}); "
            "frames are rebased to the host clock at the first frame",
        )
        return now - ts


def check_can_source(interface: str, channel: Any, bitrate: int | None) -> None:
    """UsageError if these can never open a bus: an interface python-can does not know, an
    empty or malformed channel (socketcan: not a network interface name), a bit rate that is
    not a positive number."""
    if interface not in can.VALID_INTERFACES:
        known = ", ".join(sorted(can.VALID_INTERFACES))
        raise UsageError(f"unknown python-can interface {interface!r}; python-can has: {known}")
    name = str(channel)
    if channel is None or _MALFORMED_CHANNEL.search(name):
        raise UsageError(f"malformed CAN channel {name!r} for interface {interface}")
    if interface == "socketcan" and (len(name) >= IFNAMSIZ or "/" in name):
        raise UsageError(
            f"malformed CAN channel {name!r}: a socketcan channel is a network interface name "
            f"(at most {IFNAMSIZ - 1} characters, no '/'), e.g. can0"
        )
    if bitrate is not None and (
        not isinstance(bitrate, int) or isinstance(bitrate, bool) or bitrate <= 0
    ):
        raise UsageError(f"impossible CAN bit rate {bitrate!r}: it must be a positive number")


@dataclass(slots=True)
class _OpenBus:
    bus: can.BusABC
    listener: _FrameListener


class _Channel(Device[_OpenBus]):
    """The tap's interface/channel as the supervisor's device."""

    lost_in_gap = "frames on the bus"
    # a setting the interface refuses, or its driver missing: retrying cannot help
    fatal = (can.CanInterfaceNotImplementedError, ValueError, TypeError)

    def __init__(self, tap: CanTap, out: TapQueue) -> None:
        self.tap = tap
        self.out = out
        self.label = f"{tap.interface} channel {tap.channel_name}"

    def open(self) -> _OpenBus:
        return _OpenBus(self.tap.open_bus(), _FrameListener(self.tap, self.out))

    def why(self, exc: BaseException) -> str:
        return bus_error(exc)

    def describe(self, handle: _OpenBus) -> str:
        return f" at {self.tap.bitrate} bit/s" if self.tap.bitrate else ""

    def reopened(self, handle: _OpenBus) -> None:
        # the link may have been (re)created meanwhile, with its default settings
        if self.tap.interface == "socketcan":
            before = self.tap.passive
            self.tap.check_socketcan()
            if self.tap.passive != before:
                self.tap.passive_event(self.out)

    def capture(self, handle: _OpenBus, running: Callable[[], bool]) -> str | None:
        recv, timeout = handle.bus.recv, self.tap.recv_timeout
        received = handle.listener.on_message_received
        try:
            while running():
                msg = recv(timeout)
                if msg is not None:
                    received(msg)
        except Exception as exc:  # the interface went down, the adapter was unplugged ...
            return self.why(exc)
        return None

    def close(self, handle: _OpenBus) -> None:
        _shutdown(handle.bus)
        self.tap.frames += handle.listener.frames


class CanTap(Tap):
    """Listen-only tap on one CAN interface/channel, python-can's way of naming them.

    ``settings``: ``kind`` "can", ``interface``, ``channel``, ``bitrate``,
    ``listen_only_options`` (the keyword arguments added for listen-only), ``options`` (the
    other bus keyword arguments), ``passive`` and ``passive_reason``.
    """

    def __init__(
        self,
        bus_name: str,
        interface: str,
        channel: Any,
        bitrate: int | None = None,
        *,
        listen_only: bool = True,
        retry_interval: float = RETRY_INTERVAL,
        max_retry_interval: float = MAX_RETRY_INTERVAL,
        wait: bool = False,
        recv_timeout: float = RECV_TIMEOUT,
        **kwargs: Any,
    ) -> None:
        check_can_source(interface, channel, bitrate)
        self.interface = interface
        self.channel = channel
        self.channel_name = str(channel)
        self.bitrate = bitrate
        self.listen_only = listen_only
        self.backoff = Backoff(retry_interval, max_retry_interval)
        self.wait = wait
        self.recv_timeout = recv_timeout
        self.kwargs = dict(kwargs)
        self.frames = 0
        self._extra, passive, self.passive_reason = self._plan()
        super().__init__(bus_name, passive, {})
        self._update_settings()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._out: TapQueue | None = None
        self._supervisor: Supervisor[_OpenBus] | None = None

    # -- passive state ---------------------------------------------------------------------

    def _plan(self) -> tuple[dict[str, Any], str, str]:
        if self.interface == "socketcan":
            # the state is read from the link at start (and at every reopen)
            return {}, "unknown", "socketcan: listen-only state not read yet"
        return listen_only_plan(self.interface, self.kwargs, self.listen_only)

    def check_socketcan(self) -> None:
        if self.interface == "socketcan":
            self.passive, self.passive_reason = socketcan_passive(self.channel_name)
            self._update_settings()

    def _update_settings(self) -> None:
        self.settings = {
            "kind": "can",
            "interface": self.interface,
            "channel": self.channel_name,
            "bitrate": self.bitrate,
            "listen_only_options": {k: _plain(v) for k, v in self._extra.items()},
            "options": {k: _plain(v) for k, v in self.kwargs.items()},
            "passive": self.passive,
            "passive_reason": self.passive_reason,
        }

    def passive_event(self, out: TapQueue) -> None:
        level = INFO if self.passive == "yes" else WARNING
        word = {"yes": "passive", "no": "not passive"}.get(self.passive, "passive: unknown")
        self.event(out, level, "passive", f"{word}: {self.passive_reason}")

    # -- public ----------------------------------------------------------------------------

    @property
    def running(self) -> bool:
        return self._out is not None

    @property
    def is_open(self) -> bool:
        return self._supervisor is not None and self._supervisor.is_open

    @property
    def failed(self) -> str | None:
        return None if self._supervisor is None else self._supervisor.failed

    def first_open(self) -> str | None:
        if self._supervisor is None:
            return None
        first_attempts_over([self._supervisor.first_attempt])
        why = self._supervisor.failed
        return None if why is None else f"{self._label()}: {why}"

    def start(self, out: TapQueue) -> None:
        if self._out is not None:
            raise RuntimeError(f"tap {self.bus!r} is already running")
        self._out = out
        self._stop = threading.Event()
        self.check_socketcan()
        self.passive_event(out)
        channel = _Channel(self, out)

        def emit(level: int, kind: str, message: str, count: int) -> None:
            self.event(out, level, kind, message, count)

        self._supervisor = Supervisor(channel, emit, self.backoff, self.wait)
        self._thread = threading.Thread(
            target=self._supervisor.run,
            args=(self._stop,),
            name=f"eg2scope can {self.interface}:{self.channel_name}",
            daemon=True,
        )
        self._thread.start()

    def stop(self) -> None:
        out = self._out
        if out is None:
            return
        self._stop.set()
        if self._thread is not None:
            self._thread.join(JOIN_TIMEOUT)
        self.event(out, INFO, "closed", f"closed {self._label()} ({self.frames} frames)")
        self._out = None

    def _label(self) -> str:
        return f"{self.interface} channel {self.channel_name}"

    def open_bus(self) -> can.BusABC:
        """A python-can bus on the tap's interface and channel, listen-only where it can be."""
        kwargs = {**self.kwargs, **self._extra}
        kwargs.pop("receive_own_messages", None)  # never: the tap only listens
        if self.bitrate is not None:
            kwargs["bitrate"] = self.bitrate
        bus = can.Bus(
            interface=self.interface,
            channel=self.channel,
            receive_own_messages=False,
            **kwargs,
        )
        if self.interface == "socketcan" and _socketcan_link_down(self.channel_name):
            _shutdown(bus)
            raise OSError(errno.ENETDOWN, f"interface {self.channel_name} is down")
        enlarge_receive_buffer(bus)
        return bus


def enlarge_receive_buffer(bus: can.BusABC, size: int = RECEIVE_BUFFER) -> int | None:
    """Ask for a ``size`` bytes kernel receive buffer on the bus's socket, if it has one;
    the size granted (Linux reports twice the usable bytes), None for buses without a socket."""
    try:
        fd = bus.fileno()
    except (NotImplementedError, AttributeError, OSError, ValueError):
        return None
    if not isinstance(fd, int) or fd < 0:
        return None
    try:
        copy = os.dup(fd)
    except OSError:
        return None
    try:
        sock = socket.socket(fileno=copy)  # a second handle on the same socket
    except OSError:
        os.close(copy)
        return None  # not a socket (a serial adapter's port)
    try:
        if sock.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF) < size:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, size)
        return int(sock.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF))
    except OSError:
        return None
    finally:
        sock.close()


def _shutdown(bus: can.BusABC) -> None:
    try:
        bus.shutdown()
    except Exception:
        pass
