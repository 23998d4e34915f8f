"""The "Bus health" table of ``stats``' text output: one row per bus, then each gripper's
turnaround, then what a row cannot say (no timing, a latency timer, error-state periods)."""

from __future__ import annotations

from typing import Any

from rich.console import Console
from rich.table import Table

from .bus import CAN


def print_health(console: Console, buses: list[dict[str, Any]]) -> None:
    """The table, and the notes under it; nothing for a capture without buses."""
    if not buses:
        return
    table = Table(title="Bus health", title_justify="left")
    for col in ("bus", "kind", "rate", "frames", "frames/s", "load mean %", "p95 %", "max %"):
        table.add_column(col, no_wrap=True, justify="left" if col in ("bus", "kind") else "right")
    table.add_column("errors", justify="right")
    table.add_column("line")
    for b in buses:
        load = b["load_pct"]
        table.add_row(
            b["bus"], b["kind"], _rate(b), f"{b['frames']:,}", _num(b["frames_per_s"], 1),
            _num(load["mean"], 2), _num(load["p95"], 2), _num(load["max"], 2),
            _errors(b), _line(b),
        )  # fmt: skip
    console.print(table)
    _turnaround(console, buses)
    for b in buses:
        for note in _notes(b):
            console.print(f"[bold]{b['bus']}:[/] {note}", highlight=False)


def _rate(b: dict[str, Any]) -> str:
    if b["kind"] == CAN:
        return f"{b['bitrate'] / 1000:g} kbit/s ({b['bitrate_from']})"
    return f"{b['baud']} baud ({b['baud_from']})"


def _num(x: float | None, digits: int) -> str:
    return "-" if x is None else f"{x:,.{digits}f}"


def _errors(b: dict[str, Any]) -> str:
    counts = b["error_frames"]
    named = [f"{n} {k}" for k, n in counts.items() if n and k != "total"]
    return str(counts["total"]) + (f" ({', '.join(named)})" if named else "")


def _line(b: dict[str, Any]) -> str:
    """What the bus's timing says beyond its load."""
    if b["kind"] == CAN:
        states = b["error_states"]
        return f"{len(states)} error-state periods" if states else ""
    gaps, words = b["gaps_ms"], []
    if gaps["count"]:
        words.append(f"gaps {gaps['min']:g}/{gaps['median']:g}/{gaps['p95']:g} ms min/med/p95")
    if b["closer_than_t3_5"] is not None:
        words.append(f"{b['closer_than_t3_5']} closer than {b['modbus_t3_5_ms']:g} ms")
    return "; ".join(words)


def _turnaround(console: Console, buses: list[dict[str, Any]]) -> None:
    rows = [(b["bus"], t) for b in buses if b["kind"] != CAN for t in b["turnaround_ms"]]
    if not rows:
        return
    table = Table(title="Turnaround (request end to response start)", title_justify="left")
    for col in ("bus", "device", "count", "median ms", "p95 ms", "max ms", "unmeasured"):
        table.add_column(col, justify="left" if col == "bus" else "right")
    for bus, t in rows:
        table.add_row(bus, str(t["device"]), str(t["count"]), _num(t["median"], 3),
                      _num(t["p95"], 3), _num(t["max"], 3), str(t["unmeasured"]))  # fmt: skip
    console.print(table)


def _notes(b: dict[str, Any]) -> list[str]:
    notes = []
    if b["timing"]:
        notes.append(f"{b['timing']}: no load, rates or times, only counts")
    for s in b.get("error_states", []):
        until = "the end of the capture" if s["to_end"] else f"{s['end']:.6f}"
        notes.append(f"{s['state']} from {s['start']:.6f} to {until}")
    hint = b.get("latency_timer")
    if hint:
        notes.append(hint["message"] + (f"; fix: {hint['fix']}" if hint["fix"] else ""))
    if b.get("uncounted_frames"):
        notes.append(f"{b['uncounted_frames']} CAN FD frames: their bits are not counted")
    return notes
