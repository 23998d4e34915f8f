"""Every line of a python-can text capture (.asc, .csv) accounted for.

python-can's text readers skip what they do not understand without a word and stop at the
first line they choke on. Fed through a :class:`LineFeed`, every line is checked instead:

- a line the reader skipped is either one the format allows besides frames (a header, a
  comment, a status or statistics line: ``TextFormat.known``) or reported as damage where it
  is ("line 12: not a frame: ...");
- a line the reader raised on is reported ("line 12: cannot parse: ...") and reading resumes
  on the next line (the reader is made again and the lines that set its state, such as the
  ASC start date, are fed to it again first);
- a last line that does not end is a frame when it is complete (``TextFormat.complete``: its
  last field is whole, and the reader checks its data against its length); one that may be
  cut short (a file cut mid-line) is reported as truncated and never given to the reader, so
  a cut frame is never read as a different, shorter one;
- what python-can logs while reading (``can.io.*``) is taken as notes on the current line,
  never printed.
"""

from __future__ import annotations

import logging
import re
import threading
import zlib
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any, TextIO

MAX_SHOWN = 80  # characters of a bad line quoted in its error

NOT_FRAME = "not a frame"


@dataclass(frozen=True)
class TextFormat:
    """What a text format allows besides frames, and what sets its reader's state."""

    #: a skipped line that belongs in the file: (stripped line, line number, python-can's notes)
    known: Callable[[str, int, list[str]], bool]
    #: a line to feed again when the reader is made again (a header, a start date)
    sets_state: Callable[[str, int], bool]
    #: fed after those lines, so the new reader's header scan stops before the real lines
    resume_tail: str = ""
    #: a complete last line a writer may leave without its line end ("End TriggerBlock")
    last_line: str | None = None
    #: a last line without its line end that cannot be the start of a longer one
    complete: Callable[[str], bool] = lambda line: False
    #: a line meant as a frame: one the reader skipped could not be parsed
    frame_shaped: Callable[[str], bool] = lambda line: False


_ASC_HEADER = re.compile(
    r"(date|base|(no\s+)?internal\s+events\s+logged|begin\s+triggerblock|end\s+triggerblock)\b",
    re.IGNORECASE,
)
_ASC_STATE = re.compile(r"(date|base|(no\s+)?internal\s+events|begin\s+triggerblock)\b", re.I)
_ASC_TIMESTAMP = re.compile(r"\d+\.\d+\s")
# channel, identifier, direction: a frame, whether or not python-can could read it
# (or a channel and a token that can only begin an identifier: a frame line cut or garbled)
_ASC_FRAME_SHAPED = re.compile(
    r"\d+\.\d+\s+(\d+\s+\S+\s+(rx|tx)\b|canfd\s|\d+\s+(\d\S*|[0-9a-f]+x?)(\s|$))",
    re.IGNORECASE,
)


_ASC_WHOLE_END = re.compile(r"(\s[0-9A-Fa-f]{2}|\s[dD]\s+0|\s[rR](\s+[0-9A-Fa-f])?)$")


def _asc_complete(line: str) -> bool:
    """A frame line that ends with a whole data byte, or a remote frame or one without data
    (a cut one can end in half a byte: "40 0D 0" must not be read as 40 0D 00)."""
    return bool(_ASC_FRAME_SHAPED.match(line) and _ASC_WHOLE_END.search(line))


def _asc_known(line: str, number: int, notes: list[str]) -> bool:
    if not line or line.startswith("//") or _ASC_HEADER.match(line):
        return True
    # "0.000 Start of measurement", "1.2 Statistic: ...", "1.2 1 Status: chip status ...",
    # J1939 and other events the format records between frames
    return bool(_ASC_TIMESTAMP.match(line)) and not _ASC_FRAME_SHAPED.match(line)


FORMATS: dict[str, TextFormat] = {
    ".asc": TextFormat(
        _asc_known,
        lambda line, n: bool(_ASC_STATE.match(line.strip())),
        resume_tail="\n",
        last_line="end triggerblock",
        complete=_asc_complete,
        frame_shaped=lambda line: bool(_ASC_FRAME_SHAPED.match(line)),
    ),
    # the data (base64) are last: a cut leaves bad padding or too few bytes for the DLC
    ".csv": TextFormat(
        lambda line, n, notes: not line or n == 1,
        lambda line, n: n == 1,
        complete=lambda line: line.count(",") == 6,
    ),
}


def quote(line: str) -> str:
    text = line.strip()
    if len(text) > MAX_SHOWN:
        text = text[: MAX_SHOWN - 3] + "..."
    return repr(text)


class LineFeed:
    """The file a python-can text reader iterates, line by line, with every line checked.

    The caller tells it which lines gave a frame (``produced``) and which made the reader
    raise (``failed``); everything else the reader read is a skipped line. ``report`` receives
    each problem as text ("line N: ..."); ``read_error`` is set when the file itself could
    not be read further (a cut .gz).
    """

    def __init__(self, f: TextIO, fmt: TextFormat, report: Callable[[str], None]) -> None:
        self._f = f
        self.fmt = fmt
        self.report = report
        self.number = 0  # the last line handed out
        self.cut = False  # that line is the last, without its line end
        self.stop = False  # set by the owner: read no further (the file is no log)
        self.read_error: BaseException | None = None
        self._pending: str | None = None  # the last line handed out, not yet accounted for
        self._notes: list[tuple[int, str]] = []  # python-can's notes on that line: level, text
        self._state_lines: list[str] = []
        self._replay: list[str] = []

    def __iter__(self) -> Iterator[str]:
        return self

    def __next__(self) -> str:
        if self._replay:
            return self._replay.pop(0)
        self._settle()
        if self.stop:
            raise StopIteration
        try:
            line = next(self._f)
        except (
            OSError,
            EOFError,
            zlib.error,
        ) as exc:  # a cut or damaged .gz: the lines before it count
            self.read_error = exc
            raise StopIteration from None
        self.number += 1
        text = line.strip()
        if not line.endswith("\n") and text and text.lower() != self.fmt.last_line:
            if self.fmt.complete(text):
                self.cut = True
                line += "\n"
                self._pending = line
                self._notes = []
                return line
            self._truncated(line)
            raise StopIteration
        if self.fmt.sets_state(text, self.number):
            self._state_lines.append(line)
        self._pending = line
        self._notes = []
        return line

    def _truncated(self, line: str) -> None:
        self.report(
            f"line {self.number}: truncated: the file ends in the middle of this line "
            f"({quote(line)}), which is not read"
        )

    def close(self) -> None:
        """python-can's readers close their file at the end; the owner closes the real one."""

    # -- told by the caller ----------------------------------------------------------------------

    def note(self, record: logging.LogRecord) -> None:
        """python-can logged something while reading the current line."""
        if not self._replay:
            self._notes.append((record.levelno, record.getMessage()))

    def produced(self) -> list[tuple[int, str]]:
        """The current line gave a frame; python-can's notes on it (level, text), if any."""
        self._pending = None
        warnings = self._notes
        self._notes = []
        return warnings

    def failed(self, exc: BaseException) -> bool:
        """The reader raised on the current line: report it. True when reading can resume
        with a new reader (False: a header or start-date line failed, or nothing to blame)."""
        line, self._pending = self._pending, None
        if line is not None and self.cut:
            self._truncated(line)
            return True
        if line is None or self.fmt.sets_state(line.strip(), self.number):
            return False
        self.report(f"line {self.number}: cannot parse: {quote(line)} ({_exc_text(exc)})")
        self._replay = list(self._state_lines)
        if self.fmt.resume_tail:
            self._replay.append(self.fmt.resume_tail)
        return True

    def finish(self) -> None:
        """The reader is done: account for the last line."""
        self._settle()

    def _settle(self) -> None:
        line, self._pending = self._pending, None
        if line is None:
            return
        if self.cut:  # the last line, whole-looking, gave no frame: it was cut after all
            self._truncated(line)
            return
        notes = [text for _, text in self._notes]
        self._notes = []
        if not self.fmt.known(line.strip(), self.number, notes):
            what = "cannot parse" if self.fmt.frame_shaped(line.strip()) else NOT_FRAME
            why = f"{what} ({'; '.join(notes)})" if notes else what
            self.report(f"line {self.number}: {why}: {quote(line)}")


def _exc_text(exc: BaseException) -> str:
    text = str(exc)
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


# -- python-can's log records, routed to the reader that is reading -------------------------------


class _Notes(logging.Handler):
    def __init__(self) -> None:
        super().__init__(logging.INFO)
        self.local = threading.local()

    def emit(self, record: logging.LogRecord) -> None:
        sink = getattr(self.local, "sink", None)
        if sink is not None:
            sink(record)


_NOTES = _Notes()


def _install() -> threading.local:
    """python-can's io loggers report to the reader being read, never to the terminal."""
    log = logging.getLogger("can.io")
    if _NOTES not in log.handlers:
        log.addHandler(_NOTES)
        log.setLevel(logging.INFO)
        log.propagate = False
    return _NOTES.local


def next_noted(it: Iterator[Any], sink: Callable[[logging.LogRecord], None]) -> Any:
    """``next(it)``, with what python-can logs meanwhile sent to ``sink``."""
    local = _install()
    local.sink = sink
    try:
        return next(it)
    finally:
        local.sink = None
