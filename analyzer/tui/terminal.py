"""The terminal going away under the TUI: its window closed, the ssh connection dropped, the
script driving it killed. Textual's Linux driver then reads an input that has ended in a busy
loop, and its writer thread ends at the first write that fails; every later write of the app
waits for that thread forever, so the app neither draws nor quits, whatever signal comes.

Here the app's writes to a terminal that has gone are dropped (``DroppingStream``, in the
driver ``driver_class`` makes), and ``TerminalWatch`` notices the hang-up on a thread of its
own and ends the app as SIGHUP does. Textual is imported only when the driver is made."""

from __future__ import annotations

import os
import select
import threading
from collections.abc import Callable
from typing import IO, Any

from ..lifecycle import Running

GONE = select.POLLHUP | select.POLLERR | select.POLLNVAL  # reported whatever is asked for


class DroppingStream:
    """A text stream that drops what it cannot write (the terminal has gone) and says so to
    ``on_error``, instead of raising in Textual's writer thread."""

    def __init__(self, stream: IO[str], on_error: Callable[[], None]) -> None:
        self._stream = stream
        self._on_error = on_error

    def write(self, text: str) -> int:
        try:
            return self._stream.write(text)
        except OSError:
            self._on_error()
            return len(text)

    def flush(self) -> None:
        try:
            self._stream.flush()
        except OSError:
            self._on_error()

    def fileno(self) -> int:
        return self._stream.fileno()


class TerminalWatch(Running):
    """While running, watches the standard streams that are a terminal for a hang-up (or a
    write to them failing). When the terminal goes, what is still written to stdout and
    stderr goes to /dev/null (the summary, Python's last flush: nothing fails for want of a
    terminal) and ``on_gone`` is called, once, on the watch's thread."""

    def __init__(self, on_gone: Callable[[], None]) -> None:
        self.fds = [fd for fd in (0, 1, 2) if os.isatty(fd)]
        self.gone = False
        self._on_gone = on_gone
        self._lock = threading.Lock()
        self._wake_r = self._wake_w = -1
        self._thread = threading.Thread(target=self._watch, name="eg2scope terminal", daemon=True)

    def start(self) -> TerminalWatch:
        self._wake_r, self._wake_w = os.pipe()
        self._thread.start()
        return self

    def stop(self) -> None:
        """Stop watching. A hang-up that came meanwhile still sends the output to /dev/null
        (``on_gone`` is not called: whatever ended the app did it already)."""
        os.write(self._wake_w, b"x")
        self._thread.join()
        if self._hung_up(timeout_ms=0):
            self._silence()
        os.close(self._wake_r)
        os.close(self._wake_w)

    def driver_class(self, base: type[Any]) -> type[Any]:
        """Textual's driver ``base`` with its output through a ``DroppingStream`` (only the
        Linux driver writes from a thread of its own; any other is given back as it is)."""
        from textual.drivers.linux_driver import LinuxDriver

        if not issubclass(base, LinuxDriver):
            return base
        went = self._went

        class HangupSafeDriver(base):
            def __init__(self, *args: Any, **kwargs: Any) -> None:
                super().__init__(*args, **kwargs)
                stream: Any = self._file  # type: ignore[has-type]  # sys.__stderr__
                self._file = DroppingStream(stream, went)

        return HangupSafeDriver

    def _watch(self) -> None:
        if self._hung_up(timeout_ms=-1):
            self._went()

    def _hung_up(self, timeout_ms: int) -> bool:
        """Whether a terminal stream hung up, waiting up to ``timeout_ms`` (-1: until one does
        or ``stop`` is called)."""
        poll = select.poll()
        for fd in self.fds:
            poll.register(fd, 0)  # nothing asked: only a hang-up or an error wakes it
        poll.register(self._wake_r, select.POLLIN)
        events = poll.poll(timeout_ms)
        return any(fd != self._wake_r and mask & GONE for fd, mask in events)

    def _went(self) -> None:
        with self._lock:
            if self.gone:
                return
            self.gone = True
        self._silence()
        self._on_gone()

    def _silence(self) -> None:
        null = os.open(os.devnull, os.O_WRONLY)
        try:
            for fd in (1, 2):
                if fd in self.fds:
                    os.dup2(null, fd)
        finally:
            os.close(null)
