"""The one loop that keeps a live device open: open, capture, lost, back off, reopen.

Both live taps run it on their capture threads (one per serial port, one per CAN channel); the
tap supplies a :class:`Device` (how to open, capture from and close it) and receives
SourceEvents:

- ``open``: opened (INFO, once); or "cannot open ..." (ERROR) when the first attempt fails:
  a device that never opened is an error of the command line, not something to wait for, so
  the loop ends and ``failed`` says why (the source fails the command at once: ``SourceError``).
  With ``wait`` (``--wait``: a device not plugged in yet) a first attempt that fails is
  reported once ("waiting for ...", WARNING) and retried with back-off until the device
  appears; a setting the device refuses (a ``Device.fatal`` exception) ends the loop even so;
- ``lost``: the device failed while capturing (WARNING);
- ``reopened``: open again after a loss, with the length of the gap (INFO). A device that was
  open and went away is always reopened with back-off.

``first_attempt`` is set once the first attempt is over, opened or not, so the tap's starter can
wait for it and fail at once.

Waits between attempts double from ``Backoff.first`` up to ``Backoff.cap`` and start over once
the device has stayed open for ``cap`` seconds. A device that keeps failing right after each
reopen (a CAN adapter stuck in bus-off, a flaky USB cable) is a *series*: after its first
``lost``/``reopened`` pair, further losses are counted, not reported one by one, and reported
as one ``lost`` event whose ``count`` is the number of losses it stands for, when the device
stays open again, cannot be reopened, fails differently, when the tap stops, and at least every
``Backoff.summary_every`` seconds. The counts of all ``lost`` events add up to every loss.
"""

from __future__ import annotations

import threading
import time
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass
from typing import Generic, TypeVar

from ..model import ERROR, INFO, WARNING

RETRY_INTERVAL = 0.5  # the first wait after a failure
MAX_RETRY_INTERVAL = 5.0  # waits double up to this
SUMMARIES_PER_CAP = 6  # a series of losses is summarised at least every 6 caps (30 s)

H = TypeVar("H")
Emit = Callable[[int, str, str, int], None]  # level, kind, message, count


@dataclass(frozen=True, slots=True)
class Backoff:
    """Waits between attempts: ``first``, doubling up to ``cap``. A device open for ``cap``
    seconds is working again (the waits start over)."""

    first: float = RETRY_INTERVAL
    cap: float = MAX_RETRY_INTERVAL

    def __post_init__(self) -> None:
        if not 0 < self.first <= self.cap:
            raise ValueError(f"back-off must have 0 < first <= cap, not {self.first}, {self.cap}")

    @property
    def summary_every(self) -> float:
        return SUMMARIES_PER_CAP * self.cap

    def text(self) -> str:
        return f"retrying with back-off from {self.first:g} s up to {self.cap:g} s"


class Device(ABC, Generic[H]):
    """What the supervisor keeps open. ``open`` raises when it cannot (any exception: the loop
    retries, except ``fatal`` ones); ``capture`` runs until ``running()`` turns False (returns
    None) or the device fails (returns why, in words); ``close`` never raises."""

    #: "serial port /dev/ttyUSB0", "virtual channel vcan0": the device in event messages
    label: str = ""
    #: what a gap loses, for the "reopened" message: "bytes on the line", "frames on the bus"
    lost_in_gap: str = "input"
    #: exceptions from ``open`` that retrying cannot cure (a setting the device refuses)
    fatal: tuple[type[BaseException], ...] = ()

    @abstractmethod
    def open(self) -> H: ...

    @abstractmethod
    def capture(self, handle: H, running: Callable[[], bool]) -> str | None: ...

    @abstractmethod
    def close(self, handle: H) -> None: ...

    def describe(self, handle: H) -> str:
        """Details for the "opened" message (" at 115200 baud 8N1")."""
        return ""

    def reopened(self, handle: H) -> None:
        """Called after every reopen (the CAN tap checks socketcan's listen-only state)."""

    def why(self, exc: BaseException) -> str:
        """An exception as one short phrase."""
        text = str(exc)
        return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


@dataclass(slots=True)
class _Series:
    """Losses right after reopens, counted instead of reported one by one."""

    since: float  # monotonic time of the first loss counted
    why: str
    losses: int = 0
    reopens: int = 0
    gaps: float = 0.0  # seconds without capture, over the reopens


class Supervisor(Generic[H]):
    """Runs ``device`` on the calling thread until ``stop`` is set (or a fatal error)."""

    def __init__(
        self, device: Device[H], emit: Emit, backoff: Backoff | None = None, wait: bool = False
    ) -> None:
        self.device = device
        self.emit = emit
        self.backoff = backoff or Backoff()
        self.wait = wait  # a device not there at the first attempt is waited for
        self.is_open = False
        self.failed: str | None = None  # why the loop gave up (a fatal error), else None
        self.first_attempt = threading.Event()  # the first open attempt is over
        self._stop = threading.Event()
        self._series: _Series | None = None
        self._delay = self.backoff.first
        self._first_try = 0.0
        self._told_cannot_open = False
        self._opens = 0
        self._opened_at = 0.0
        self._lost_at = 0.0

    def run(self, stop: threading.Event) -> None:
        self._stop = stop
        self._first_try = time.monotonic()
        try:
            while not stop.is_set():
                try:
                    handle = self._open()
                finally:
                    self.first_attempt.set()
                if handle is None:
                    if self.failed is not None:
                        return
                    self._wait()
                    continue
                error = self._capture(handle)
                if error is None or stop.is_set():
                    return
                self._lost(error)
                self._wait()
        finally:
            self.is_open = False
            self.first_attempt.set()  # stopped before its first attempt
            self._report_series()

    # -- the steps -----------------------------------------------------------------------------

    def _open(self) -> H | None:
        """The open device, or None (reported: the first failure, or a fatal one)."""
        device = self.device
        try:
            handle = device.open()
        except device.fatal as exc:
            self.failed = device.why(exc)
            self._event(ERROR, "open", f"cannot open {device.label}: {self.failed}; not retrying")
            return None
        except Exception as exc:
            if not self._opens and not self.wait:  # never opened: fail, do not retry
                self.failed = device.why(exc)
                self._event(ERROR, "open", f"cannot open {device.label}: {self.failed}")
                return None
            if not self._opens and not self._told_cannot_open:
                self._told_cannot_open = True
                why = f"{device.why(exc)}; {self.backoff.text()}"
                self._event(WARNING, "open", f"waiting for {device.label} ({why})")
            self._report_series()  # lost and not back: a series of losses ends here
            return None
        self._opened_at = now = time.monotonic()
        self._opens += 1
        if self._opens == 1:
            waited = now - self._first_try
            after = f" after waiting {waited:.2f} s" if self._told_cannot_open else ""
            self._event(INFO, "open", f"opened {device.label}{device.describe(handle)}{after}")
            return handle
        gap = now - self._lost_at
        if self._series is not None:
            self._series.reopens += 1
            self._series.gaps += gap
        else:
            self._event(
                INFO,
                "reopened",
                f"reopened {device.label} after a {gap:.2f} s gap "
                f"({device.lost_in_gap} during the gap were not captured)",
            )
        device.reopened(handle)
        return handle

    def _capture(self, handle: H) -> str | None:
        self.is_open = True
        try:
            return self.device.capture(handle, self._running)
        finally:
            self.is_open = False
            self.device.close(handle)

    def _wait(self) -> None:
        self._stop.wait(self._delay)
        self._delay = min(2 * self._delay, self.backoff.cap)

    def _lost(self, why: str) -> None:
        self._lost_at = now = time.monotonic()
        worked = now - self._opened_at >= self.backoff.cap
        if worked:
            self._delay = self.backoff.first  # it worked for a while: the back-off starts over
        series = self._series
        if series is not None and series.why != why:
            self._report_series()
            series = None
        if self._opens > 1 and not worked:  # failed again soon after a reopen: count it
            if series is None:
                series = self._series = _Series(now, why)
            series.losses += 1
            return
        self._report_series()
        self._event(WARNING, "lost", f"lost {self.device.label}: {why}; {self.backoff.text()}")

    def _running(self) -> bool:
        """Polled by ``Device.capture``: False once the tap stops. Reports a series of losses
        once the device has stayed open again."""
        series = self._series
        if series is not None:
            now = time.monotonic()
            stable = now - self._opened_at >= self.backoff.cap
            if stable or now - series.since >= self.backoff.summary_every:
                self._report_series()
        return not self._stop.is_set()

    # -- events --------------------------------------------------------------------------------

    def _event(self, level: int, kind: str, message: str, count: int = 1) -> None:
        self.emit(level, kind, message, count)

    def _report_series(self) -> None:
        series, self._series = self._series, None
        if series is None or not series.losses:
            return
        n = series.losses
        span = time.monotonic() - series.since
        times = "time" if n == 1 else "times"
        if series.reopens == n:
            reopened = "reopened after each"
        else:
            reopened = f"reopened after {series.reopens} of them"
        if self.is_open:
            state = "open again now"
        elif self._stop.is_set():
            state = "stopped"
        else:
            state = self.backoff.text()
        self._event(
            WARNING,
            "lost",
            f"lost {self.device.label} {n} more {times} in {span:.1f} s, each soon after "
            f"reopening ({series.why}); {reopened}, {series.gaps:.2f} s not captured in all; "
            f"{state}",
            n,
        )
