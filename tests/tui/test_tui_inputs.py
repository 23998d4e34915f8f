"""The TUI on every kind of input (issue 17): a raw serial dump, a raw Modbus dump (with and
without ``--protocol``, as the command line names it), a candump log, python-can ``.asc`` and
``.blf`` files written from it, a mixed three-bus recording from ``eg2scope record --demo`` and
a CAN-only one; on the Python engine and, for CAN, the native one. The app is the one the
command makes (its own plan and option conversions), run headless at 80x24 with Textual's
Pilot: the store must hold exactly the records ``eg2scope decode`` writes (per bus, in the
same order), in capture-time order across buses, and the session must not fail."""

from __future__ import annotations

import asyncio
import json
import math
from pathlib import Path

import pytest
from conftest import SIZES, capture_app, driving, eg2scope, until
from native_core import needs_native

from analyzer.tui.layout import row_layout
from analyzer.tui.rows import ELLIPSIS, plain_row


def decoded(path: Path, *argv: str) -> list[dict]:
    """What ``eg2scope decode`` says the capture holds (records, no events)."""
    done = eg2scope("decode", str(path), "--format", "jsonl", *argv)
    assert done.returncode in (0, 3), done.stderr
    lines = [json.loads(line) for line in done.stdout.splitlines()]
    return [r for r in lines if r.get("kind") != "event"]


def per_bus(rows: list[tuple[str, int, str]]) -> dict[str, list[tuple[int, str]]]:
    out: dict[str, list[tuple[int, str]]] = {}
    for bus, seq, name in rows:
        out.setdefault(bus, []).append((seq, name))
    return out


CASES = [
    ("serial dump", ()),
    ("serial dump", ("--protocol", "serial")),
    ("serial dump", ("--protocol", "auto", "--engine", "python")),
    ("modbus dump", ()),
    ("modbus dump", ("--protocol", "modbus")),
    ("modbus dump", ("-p", "rs485")),
    ("candump log", ()),
    ("candump log", ("--engine", "python")),
    (".asc", ()),
    (".blf", ("--engine", "python")),
    ("demo recording", ()),
    ("demo recording", ("--engine", "python")),
    ("can recording", ()),
    ("can recording", ("--engine", "python")),
]


@pytest.mark.parametrize(("kind", "argv"), CASES, ids=[f"{k} {' '.join(a)}" for k, a in CASES])
def test_every_input_is_replayed_whole_and_in_time_order(
    inputs: dict[str, Path], kind: str, argv: tuple[str, ...]
) -> None:
    path = inputs[kind]
    decode_argv = [a for a in argv if a not in ("--engine", "python")]
    want = decoded(path, *decode_argv)
    assert want, f"decode found nothing in {path}"

    async def scenario() -> None:
        app = capture_app(path, *argv)
        async with driving(app, SIZES["80x24"]) as pilot:
            await until(pilot, lambda: app.done, timeout=60)
            await until(pilot, lambda: app.frames.known == app.store.count)
            assert app.failure is None
            store = app.store
            got = [(store.bus_of(i), store.seq[i], store.name_of(i)) for i in range(store.count)]
            # every record decode writes, each bus in its own order
            names = [
                r["name"] or (r["protocol"] if r["kind"] == "frame" else r["kind"]) for r in want
            ]
            expected = [(r["bus"], r["seq"], n) for r, n in zip(want, names, strict=True)]
            assert per_bus(got) == per_bus(expected)
            # across buses, in capture time: the time column never runs backwards, but where
            # a bus's own clock steps back (its stream order is kept)
            reached: dict[str, float] = {}
            keys = []
            for i in range(store.count):
                t, bus = store.t[i], store.bus_of(i)
                if not math.isnan(t):
                    reached[bus] = max(t, reached.get(bus, t))
                    keys.append(reached[bus])
            assert keys == sorted(keys)
            # on an 80-column list, a name is whole or ends in an ellipsis
            width = app.frames.scrollable_content_region.width
            cols = row_layout(width)
            start = 1 + (cols.seq + 1 if cols.seq else 0) + cols.time + cols.bus + 5 + cols.device
            for i in range(0, store.count, max(1, store.count // 200)):
                row = plain_row(store, i, width=width)
                assert len(row) <= width
                shown = row[start : start + cols.name].rstrip()
                name = store.name_of(i)
                assert shown == name or (shown.endswith(ELLIPSIS) and name.startswith(shown[:-1]))
            await pilot.press("q")
        assert app.failure is None and app.return_code == 0

    asyncio.run(scenario())


@needs_native
@pytest.mark.parametrize(
    "kind", ["candump log", ".asc", "can recording", "serial dump", "modbus dump"]
)
def test_native_and_python_engines_fill_the_same_store(inputs: dict[str, Path], kind: str) -> None:
    """The TUI picks the native engine for all-CAN input and a raw dump's one byte stream;
    ``--engine python`` the Python one: the screens' data must be the same."""

    async def store_of(*argv: str) -> list[tuple]:
        app = capture_app(inputs[kind], *argv)
        async with driving(app, SIZES["80x24"]) as pilot:
            await until(pilot, lambda: app.done, timeout=60)
            store = app.store
            rows = [
                (store.seq[i], store.bus_of(i), store.summary[i], store.flag_codes(i))
                for i in range(store.count)
            ]
            await pilot.press("q")
        return rows

    async def both() -> None:
        assert await store_of("--engine", "native") == await store_of("--engine", "python")

    asyncio.run(both())
