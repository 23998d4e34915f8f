"""A virtual multi-drop serial line (RS485, or RS232 with a converter) made of real ptys.

Each endpoint is a pseudo-terminal: a program opens the endpoint's slave path with pyserial as
if it were ``/dev/ttyUSB0``. A relay thread reads every master and copies what one endpoint
writes to all the *other* endpoints, in order and unchanged, as the wire of a multi-drop bus
does (a writer does not hear its own bytes back, as with a USB adapter whose receiver is off
while it transmits). A sniffer is just one more endpoint.

Each endpoint can have a stable symlink (like ``/dev/serial/by-id/...``). ``unplug`` closes the
endpoint's pty, as pulling a USB adapter does: a program holding the old path gets EIO or a
hang-up, the symlink vanishes. ``replug`` makes a new pty (a new ``/dev/pts/N``) and points the
same symlink at it, so a program that reopens by the symlink finds the adapter again.

Bytes arrive at pty speed, not at the line's baud rate: timing realism is the servers' job.
"""

from __future__ import annotations

import contextlib
import os
import select
import threading
import time
import tty
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field

from ..lifecycle import Closing

ByteCallback = Callable[[str, bytes, float], None]


@dataclass(slots=True)
class _Endpoint:
    name: str
    link: str | None
    master: int = -1
    slave: int = -1
    path: str = ""
    out: bytearray = field(default_factory=bytearray)  # bytes waiting to be written to master
    dropped: int = 0  # bytes dropped because the program on this endpoint did not read

    @property
    def plugged(self) -> bool:
        return self.master >= 0


class PtyBus(Closing):
    """N pty endpoints joined like the drops of one RS485 line.

    ``on_bytes(name, data, t)``, if given, is called from the relay thread for every chunk an
    endpoint writes (t from time.time()); keep it short. ``max_pending`` bounds the bytes held
    for an endpoint whose program does not read; beyond it bytes are dropped and counted.
    """

    def __init__(
        self,
        names: Iterable[str] = (),
        *,
        link_dir: str | None = None,
        on_bytes: ByteCallback | None = None,
        max_pending: int = 1 << 20,
    ) -> None:
        self.link_dir = link_dir
        self.on_bytes = on_bytes
        self.max_pending = max_pending
        self._lock = threading.Lock()
        self._eps: dict[str, _Endpoint] = {}
        self._generation = 0
        self._closed = False
        self._wake_r, self._wake_w = os.pipe()
        os.set_blocking(self._wake_r, False)
        os.set_blocking(self._wake_w, False)
        self._thread = threading.Thread(target=self._relay, name="ptybus-relay", daemon=True)
        self._thread.start()
        try:
            for name in names:
                self.add_endpoint(name)
        except BaseException:
            self.close()
            raise

    # -- endpoints --------------------------------------------------------------------------

    def add_endpoint(self, name: str, link: str | None = None) -> str:
        """A new endpoint; returns the slave path to open. link: a stable symlink to keep
        pointing at it (default: link_dir/name when the bus has a link_dir)."""
        if link is None and self.link_dir is not None:
            link = os.path.join(self.link_dir, name)
        with self._lock:
            if self._closed:
                raise RuntimeError("the bus is closed")
            if name in self._eps:
                raise ValueError(f"endpoint {name!r} exists")
            ep = _Endpoint(name, link)
            self._open(ep)
            self._eps[name] = ep
            self._changed()
            return ep.path

    def path(self, name: str) -> str:
        """The endpoint's current slave path ('' while unplugged)."""
        with self._lock:
            return self._eps[name].path

    def link(self, name: str) -> str | None:
        """The endpoint's stable symlink, if it has one."""
        with self._lock:
            return self._eps[name].link

    def names(self) -> list[str]:
        with self._lock:
            return list(self._eps)

    def dropped(self, name: str) -> int:
        with self._lock:
            return self._eps[name].dropped

    def plugged(self, name: str) -> bool:
        with self._lock:
            return self._eps[name].plugged

    def unplug(self, name: str) -> None:
        """Pull the adapter: close the pty (its users get EIO / hang-up), drop the symlink."""
        with self._lock:
            ep = self._eps[name]
            self._close_ep(ep)
            self._changed()

    def replug(self, name: str) -> str:
        """Plug the adapter back in: a new pty, the same symlink. Returns the new slave path."""
        with self._lock:
            ep = self._eps[name]
            if ep.plugged:
                self._close_ep(ep)
            self._open(ep)
            self._changed()
            return ep.path

    def send(self, name: str, data: bytes) -> None:
        """Put bytes on the line as if endpoint name had written them (noise, tests)."""
        now = time.time()
        with self._lock:
            self._distribute(name, data)
            self._changed()
        if self.on_bytes is not None:
            self.on_bytes(name, data, now)

    # -- life cycle -------------------------------------------------------------------------

    def close(self) -> None:
        """Stop the relay and close every pty (idempotent)."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
            self._changed()
        if self._thread is not threading.current_thread():
            self._thread.join(timeout=2.0)
        with self._lock:
            for ep in self._eps.values():
                self._close_ep(ep)
        for fd in (self._wake_r, self._wake_w):
            with contextlib.suppress(OSError):
                os.close(fd)

    # -- internals (called with the lock held) ----------------------------------------------

    def _open(self, ep: _Endpoint) -> None:
        master, slave = os.openpty()
        try:
            tty.setraw(slave)
            tty.setraw(master)
            os.set_blocking(master, False)
            path = os.ttyname(slave)
            if ep.link is not None:
                tmp = f"{ep.link}.{os.getpid()}.tmp"
                with contextlib.suppress(FileNotFoundError):
                    os.unlink(tmp)
                os.symlink(path, tmp)
                os.replace(tmp, ep.link)
        except BaseException:
            os.close(master)
            os.close(slave)
            raise
        ep.master, ep.slave, ep.path = master, slave, path
        ep.out.clear()

    def _close_ep(self, ep: _Endpoint) -> None:
        for fd in (ep.master, ep.slave):
            if fd >= 0:
                with contextlib.suppress(OSError):
                    os.close(fd)
        if ep.link is not None and ep.plugged:
            with contextlib.suppress(FileNotFoundError):
                if os.path.islink(ep.link) and os.readlink(ep.link) == ep.path:
                    os.unlink(ep.link)
        ep.master = ep.slave = -1
        ep.path = ""
        ep.out.clear()

    def _changed(self) -> None:
        self._generation += 1
        with contextlib.suppress(BlockingIOError, OSError):
            os.write(self._wake_w, b"x")

    def _distribute(self, source: str, data: bytes) -> None:
        for ep in self._eps.values():
            if ep.name == source or not ep.plugged:
                continue
            room = self.max_pending - len(ep.out)
            if room < len(data):
                ep.dropped += len(data) - max(room, 0)
                data_in = data[: max(room, 0)]
            else:
                data_in = data
            ep.out += data_in
            self._flush(ep)

    def _flush(self, ep: _Endpoint) -> None:
        if not ep.out or not ep.plugged:
            return
        try:
            n = os.write(ep.master, ep.out)
        except BlockingIOError:
            return
        except OSError:
            ep.dropped += len(ep.out)
            ep.out.clear()
            return
        del ep.out[:n]

    # -- the relay thread -------------------------------------------------------------------

    def _relay(self) -> None:
        poller = select.poll()
        generation = -1
        fds: dict[int, str] = {}
        while True:
            with self._lock:
                if self._closed:
                    return
                if generation != self._generation:
                    generation = self._generation
                    poller = select.poll()
                    poller.register(self._wake_r, select.POLLIN)
                    fds = {}
                    for ep in self._eps.values():
                        if ep.plugged:
                            fds[ep.master] = ep.name
                            mask = select.POLLIN | (select.POLLOUT if ep.out else 0)
                            poller.register(ep.master, mask)
            try:
                events = poller.poll(200)
            except InterruptedError:
                continue
            chunks: list[tuple[str, bytes]] = []
            with self._lock:
                if self._closed:
                    return
                if generation != self._generation:
                    # endpoints changed while polling: the fds may be stale, poll again
                    with contextlib.suppress(BlockingIOError, OSError):
                        os.read(self._wake_r, 4096)
                    continue
                pending_before = {n for n, ep in self._eps.items() if ep.out}
                for fd, ev in events:
                    if fd == self._wake_r:
                        with contextlib.suppress(BlockingIOError, OSError):
                            os.read(self._wake_r, 4096)
                        continue
                    name = fds.get(fd)
                    if name is None:
                        continue
                    ep = self._eps[name]
                    if ev & select.POLLOUT:
                        self._flush(ep)
                    if ev & (select.POLLIN | select.POLLHUP | select.POLLERR):
                        try:
                            data = os.read(fd, 65536)
                        except (BlockingIOError, InterruptedError):
                            continue
                        except OSError:
                            data = b""
                        if data:
                            self._distribute(name, data)
                            chunks.append((name, data))
                pending_after = {n for n, ep in self._eps.items() if ep.out}
                if pending_after != pending_before:
                    # who waits to write changed: re-register POLLOUT
                    self._generation += 1
            if self.on_bytes is not None and chunks:
                now = time.time()
                for name, data in chunks:
                    self.on_bytes(name, data, now)
