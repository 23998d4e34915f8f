"""Timing rules from the manual (section 1.4), applied to requests as they pass.

- at least 5 ms between commands to one gripper;
- more than 1 s after a parameter save before the next command to that gripper.

Both need timestamps; records without ``t`` pass untouched. Value ranges, write-failure status
and CRC byte order are flagged by the protocol decoders themselves, where the values are known.
"""

from __future__ import annotations

from . import messages as M
from .model import FRAME, REQUEST, Record

MIN_GAP_S = 0.005
AFTER_SAVE_S = 1.0


class TimingLinter:
    """Flags requests that break the manual's timing rules (each rule once per request)."""

    def __init__(self, min_gap_s: float = MIN_GAP_S, after_save_s: float = AFTER_SAVE_S) -> None:
        self.min_gap_s = min_gap_s
        self.after_save_s = after_save_s
        self._last: dict[tuple[str, str, int | None], float] = {}
        self._save: dict[tuple[str, str, int | None], float] = {}

    def check(self, rec: Record) -> None:
        if rec.direction != REQUEST or rec.kind != FRAME or rec.t is None:
            return
        key = (rec.bus, rec.protocol, rec.device)
        t = rec.t
        saved = self._save.get(key)
        if saved is not None:
            dt = t - saved
            if dt < self.after_save_s:
                wait = f"{self.after_save_s:g}"
                _note(rec, M.LINT_DURING_SAVE, ms=dt * 1000, wait=wait)
            else:
                del self._save[key]
        last = self._last.get(key)
        if last is not None and t - last < self.min_gap_s:
            gap_ms = self.min_gap_s * 1000
            _note(rec, M.LINT_TOO_CLOSE, ms=(t - last) * 1000, min_gap_ms=gap_ms)
        self._last[key] = t
        if rec.is_save:
            self._save[key] = t


def _note(rec: Record, message: M.Message, **values: object) -> None:
    """A warning and its code (appended even when the record has the code, as in the crate)."""
    rec.warnings.append(message.text(**values))
    rec.flags.append(message.code)
