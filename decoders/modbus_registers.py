"""The registers a Modbus (start, count) addresses, named once and memoised (section 2.1).

Registers are named from ``registers`` in both numberings (1010, or 10 as some hosts send it,
section 4; the first register's numbering, as ``registers.by_modbus`` resolves it, holds for a
whole range). A ``Plan`` holds what every frame over the same registers says (names, fields,
numbering, undocumented or outside the map, read-only); values are memoised per register, so a
response with new values costs little more than a dictionary lookup per register.
"""

from __future__ import annotations

import struct
from collections.abc import Iterable
from typing import Any

from . import messages as M
from .modbus_framing import READ_HOLDING
from .notes import Notes
from .registers import (
    BY_NUMBER,
    FIRST,
    LAST,
    SAVE_REGISTERS,
    Register,
    by_modbus,
    undocumented,
)


def _register(number: int) -> Register:
    """The register at a full (1000-numbered) number; a placeholder where the map has none."""
    reg = BY_NUMBER.get(number)
    if reg is not None:
        return reg
    if FIRST <= number <= LAST:
        return undocumented(number)
    return undocumented(number, f"register {number}, outside the EG2 register map")


def _outside(reg: Register) -> bool:
    return not FIRST <= reg.number <= LAST


def _spans(numbers: list[int]) -> str:
    """1013, 1014, 1015, 1018 -> '1013-1015, 1018'."""
    parts: list[str] = []
    i = 0
    while i < len(numbers):
        j = i
        while j + 1 < len(numbers) and numbers[j + 1] == numbers[j] + 1:
            j += 1
        parts.append(str(numbers[i]) if i == j else f"{numbers[i]}-{numbers[j]}")
        i = j + 1
    return ", ".join(parts)


def _map_notes(
    wire_start: int, start: int, count: int, short: bool, regs: tuple[Register, ...]
) -> Notes:
    """What every frame over registers start .. start + count - 1 says about them: the short
    numbering, undocumented registers, registers outside the map (regs: those a frame can
    list)."""
    notes = Notes()
    if short:
        if count <= 1:
            notes.warn_of(M.MODBUS_SHORT_NUMBER, wire=wire_start, number=start)
        else:
            notes.warn_of(
                M.MODBUS_SHORT_NUMBERS,
                wire_first=wire_start,
                wire_last=wire_start + count - 1,
                first=start,
                last=start + count - 1,
            )
    undoc = [r.number for r in regs if not r.documented and not _outside(r)]
    if undoc:
        what = "register" if len(undoc) == 1 else "registers"
        notes.warn_of(M.MODBUS_UNDOCUMENTED_REGISTERS, what=what, numbers=_spans(undoc))
    outside = [r.number for r in regs if _outside(r)]
    unlisted = range(start + len(regs), start + count)
    outside += [n for n in unlisted if not FIRST <= n <= LAST]
    if outside:
        if len(outside) == 1:
            notes.warn_of(M.MODBUS_OUTSIDE_MAP, number=outside[0])
        else:
            notes.warn_of(M.MODBUS_OUTSIDE_MAP_SPANS, numbers=_spans(outside))
    return notes


class Plan:
    """The registers a (start, count) on the wire addresses, named once and memoised."""

    __slots__ = (
        "cells",
        "count",
        "extra",
        "flags",
        "items",
        "name",
        "names",
        "notes",
        "read_only",
        "regs",
        "response_fields",
        "save_names",
        "short",
        "start",
        "summary_keys",
        "unpack",
        "warnings",
    )

    def __init__(self, wire_start: int, count: int) -> None:
        # the numbering is the first register's (10 = 1010), as registers.by_modbus says
        first_lookup = by_modbus(wire_start)
        self.short = short = first_lookup is not None and first_lookup.short
        self.start = start = wire_start + 1000 if short else wire_start
        self.count = count
        # the fields every frame over these registers carries
        self.extra: dict[str, Any] = {"start": start, "count": count}
        if short:
            self.extra.update(numbering="short", address=wire_start)
        # a read response's fields, in order; slave and values filled in per frame
        self.response_fields: dict[str, Any] = {
            "slave": None,
            "function": READ_HOLDING,
            "byte_count": 2 * count,
            **self.extra,
            "values": None,
        }
        listed = min(count, 127)  # the most registers a byte count can carry
        self.regs = regs = tuple(_register(start + i) for i in range(listed))
        self.names = [r.name for r in regs]
        self.cells = tuple(_cell(r.number) for r in regs)
        self.items = tuple(zip(self.names, self.cells, regs, strict=True))
        self.unpack = struct.Struct(f">{listed}H").unpack_from
        if count == 0:
            self.name: str | None = None
            self.summary_keys = ""
        else:
            first, last = regs[0], _register(start + count - 1)
            self.name = first.name if count == 1 else f"{first.name}..{last.name}"
            self.summary_keys = first.key if count == 1 else f"{first.key}..{last.key}"
        notes = _map_notes(wire_start, start, count, short, regs)
        # every frame over these registers says the same: kept as texts and codes for the fast
        # path, and as the Notes to copy into a frame's own
        self.notes = notes
        self.warnings = tuple(notes.warnings)
        self.flags = tuple(notes.flags)
        # what a write to these registers needs to know: MODBUS_READ_ONLY_WRITE's text
        read_only = [f"{r.number} ({r.name})" for r in regs if r.access == "ro"]
        self.read_only: str | None = None
        if read_only:
            what = "register" if len(read_only) == 1 else "registers"
            self.read_only = M.MODBUS_READ_ONLY_WRITE.text(
                what=what, registers=", ".join(read_only)
            )
        self.save_names = tuple(r.name for r in regs if r.number in SAVE_REGISTERS)

    def note(self, notes: Notes) -> None:
        """Add what every frame over these registers says (numbering, undocumented, outside
        the map) to a frame's notes."""
        mine = self.notes
        notes.warnings += mine.warnings
        for code in mine.flags:
            notes.flag(code)

    def values(self, raw: bytes, at: int, end: int) -> tuple[dict[str, int], str, list[str]]:
        """Values in raw[at:end] as {name: value}, their texts joined, their range warnings."""
        if end - at >= 2 * len(self.regs):
            wire: Iterable[int] = self.unpack(raw, at)
        else:
            wire = words(raw, at, end)
        values: dict[str, int] = {}
        texts: list[str] = []
        warns: list[str] = []
        for (name, cell, reg), w in zip(self.items, wire):  # noqa: B905 (hot loop)
            v = cell.get(w)
            if v is None:
                v = _fill(cell, reg, w)
            values[name] = v[0]
            texts.append(v[1])
            if v[2] is not None:
                warns.append(v[2])
        return values, ", ".join(texts), warns


_plans: dict[tuple[int, int], Plan] = {}


def plan(wire_start: int, count: int) -> Plan:
    key = (wire_start, count)
    p = _plans.get(key)
    if p is None:
        if len(_plans) >= 4096:
            _plans.clear()
        p = _plans[key] = Plan(wire_start, count)
    return p


# per register number: 16-bit wire value -> (value, "key=value unit", range warning)
Cell = dict[int, tuple[int, str, str | None]]
_cells: dict[int, Cell] = {}


def _cell(number: int) -> Cell:
    c = _cells.get(number)
    if c is None:
        if len(_cells) >= 4096:
            _cells.clear()
        c = _cells[number] = {}
    return c


def _fill(cell: Cell, reg: Register, raw: int) -> tuple[int, str, str | None]:
    if len(cell) >= 4096:
        cell.clear()
    value = reg.value(raw)
    v = cell[raw] = (value, reg.describe(value), reg.range_warning(value))
    return v


def value_of(reg: Register, raw: int) -> tuple[int, str, str | None]:
    """(value, 'key=value unit', range warning) of a 16-bit wire value, memoised."""
    cell = _cell(reg.number)
    return cell.get(raw) or _fill(cell, reg, raw)


def words(raw: bytes, lo: int, hi: int) -> list[int]:
    """The 16-bit values (high byte first) in raw[lo:hi]."""
    return [raw[i] << 8 | raw[i + 1] for i in range(lo, hi - 1, 2)]
