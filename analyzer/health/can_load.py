"""A CAN bus's load: its frames and their exact bits (``decoders.can_bits``) per whole second of
capture time, and the span they cover.

``can_seconds`` counts a batch of raw items (a list of Items, byte chunks among them skipped, or
the native core's ``FrameBatch`` of a candump log read natively): with the native core built it
is ``_native.can_seconds``, which makes no Python object per frame; ``python_can_seconds`` is
the reference it is tested against (tests/health/test_can_seconds_native.py) and the fallback.
"""

from __future__ import annotations

import math
from collections import Counter
from typing import Any, Final

from decoders.can_bits import frame_bits
from decoders.model import CanFrame

from ..session.engine import _native
from .figures import load_pct, per_second

# (bus, second, frames, bits, uncounted, first_t, first_bits, last_t): one bus's frames in one
# whole second (None: frames without a time); uncounted: frames whose bits are not counted (CAN
# FD); first_t and first_bits: the earliest frame's time and bits
Second = tuple[str, int | None, int, int, int, float | None, int, float | None]
# (bus, t, error class, data)
ErrorFrame = tuple[str, float | None, int, bytes]

_MEMO_LIMIT: Final = 1 << 16  # the bits of this many distinct frames are remembered


def can_seconds(items: Any) -> tuple[list[Second], list[ErrorFrame], int]:
    """The CAN frames of ``items`` per bus and second, in the order each first appears; the
    error frames; how many items were no CAN frames."""
    if _native is not None:
        try:
            return _native.can_seconds(items)
        except TypeError:  # a frame the core reads strictly (an int time): Python reads it
            pass
    return python_can_seconds(items)


def python_can_seconds(items: Any) -> tuple[list[Second], list[ErrorFrame], int]:
    """``can_seconds`` in Python (the reference)."""
    groups: dict[tuple[str, int | None], list[Any]] = {}
    errors: list[ErrorFrame] = []
    others = 0
    for item in items:
        frame = item.payload
        if not isinstance(frame, CanFrame):
            others += 1
            continue
        t = frame.t if frame.t is not None and math.isfinite(frame.t) else None
        if frame.is_error:
            errors.append((item.bus, t, frame.arbitration_id, bytes(frame.data)))
            continue
        bits = _bits(frame)
        key = (item.bus, None if t is None else math.floor(t))
        group = groups.get(key)
        if group is None:
            group = groups[key] = [item.bus, key[1], 0, 0, 0, t, bits or 0, t]
        _count(group, t, bits)
    return [tuple(g) for g in groups.values()], errors, others


def _count(group: list[Any], t: float | None, bits: int | None) -> None:
    group[2] += 1
    if bits is None:
        group[4] += 1
    else:
        group[3] += bits
    if t is not None:
        if t < group[5]:
            group[5], group[6] = t, bits or 0
        if t > group[7]:
            group[7] = t


_memo: dict[tuple[Any, ...], int | None] = {}


def _bits(frame: CanFrame) -> int | None:
    """``frame_bits``, None for a frame whose bits are not counted; remembered per frame (a
    gripper's polls repeat)."""
    key = (frame.arbitration_id, bytes(frame.data), frame.is_extended, frame.is_remote,
           frame.is_fd, frame.dlc)  # fmt: skip
    try:
        return _memo[key]
    except KeyError:
        pass
    try:
        bits: int | None = frame_bits(frame)
    except ValueError:
        bits = None
    if len(_memo) >= _MEMO_LIMIT:
        _memo.clear()
    _memo[key] = bits
    return bits


class CanLoad:
    """One CAN bus's frames and bits: per whole second, and in all."""

    def __init__(self) -> None:
        self.frames = 0
        self.bits = 0
        self.uncounted = 0  # frames whose bits are not counted (CAN FD)
        self.untimed = 0  # frames without a time
        self.seconds: Counter[int] = Counter()
        self.first_t: float | None = None
        self.first_bits = 0
        self.last_t: float | None = None

    def add(self, second: Second) -> None:
        _bus, sec, frames, bits, uncounted, first_t, first_bits, last_t = second
        self.frames += frames
        self.bits += bits
        self.uncounted += uncounted
        if sec is None or first_t is None or last_t is None:
            self.untimed += frames
            return
        self.seconds[sec] += bits
        if self.first_t is None or first_t < self.first_t:
            self.first_t, self.first_bits = first_t, first_bits
        if self.last_t is None or last_t > self.last_t:
            self.last_t = last_t

    def span(self, bitrate: int) -> tuple[float, float] | None:
        """From the start of the first frame (its time is its end: a frame is stamped when it
        is received) to the end of the last; None without times."""
        if self.first_t is None or self.last_t is None:
            return None
        return self.first_t - self.first_bits / bitrate, self.last_t

    def figures(self, bitrate: int) -> dict[str, Any]:
        """``frames``, ``uncounted_frames``, ``bits``, ``duration_s``, ``frames_per_s`` and
        ``load_pct`` (docs/contracts.md, statistics)."""
        span = self.span(bitrate)
        if self.frames - self.untimed < 2:
            span = None  # one frame spans only itself: always 100%, which says nothing
        start, end = span if span is not None else (None, None)
        load: dict[str, float | None] = {"mean": None, "p95": None, "max": None}
        if span is not None:
            timed_bits = sum(self.seconds.values())
            load = load_pct(self.seconds, span[0], span[1], timed_bits, bitrate)
        return {
            "frames": self.frames,
            "uncounted_frames": self.uncounted,
            "bits": self.bits,
            "duration_s": None if span is None else round(span[1] - span[0], 6),
            "frames_per_s": per_second(self.frames - self.untimed, start, end),
            "load_pct": load,
        }
