"""What the matrix's cells share: running eg2scope, a decode's JSONL as records, what ``stats``
must say about them, the opening samples a plot must hold, the views of an .rrd's blueprint,
a session engine forced on an in-process command, and a TUI in a real pseudo-terminal."""

from __future__ import annotations

import re
import subprocess
import sys
import time
import uuid
from collections import Counter
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Generic, TypeVar

import orjson
import pytest
from can_wire import reference_bits
from e2e_inputs import EG2SCOPE, HEADLESS, ROOT
from native_core import require_native

from analyzer.model import StateSample
from analyzer.session.capture import CaptureOptions, run_capture
from analyzer.session.listener import Listener
from analyzer.session.session import Session, SessionOptions
from decoders.eg2_serial import COMMANDS
from decoders.registers import REGISTERS, opening_mm

sys.path.append(str(ROOT / "tests" / "rerun"))  # the .rrd reader the Rerun tests use
from rrd_helpers import Rrd, read_rrd

__all__ = ["Rrd", "read_rrd"]


def skip_unless_native() -> None:
    """A native cell runs where the core is complete; else it skips, saying why (no cargo: a
    pure-Python install) or fails (cargo is there, so the core should have been built)."""
    require_native()


def eg2scope(*argv: str, cwd: Path, timeout: float = 120) -> subprocess.CompletedProcess[bytes]:
    """``eg2scope ARGV`` as a real process on a headless machine."""
    return subprocess.run(
        [*EG2SCOPE, *argv], cwd=cwd, env=HEADLESS, capture_output=True, timeout=timeout
    )


T = TypeVar("T")
WORKERS = 3  # real processes at once (safe: each has a folder, a pty and a demo rig of its own)


class Prefetch(Generic[T]):
    """The slow part of a test function's cells (real processes) run a few at a time: when the
    first cell asks, every cell of that function pytest selected is started. ``start(**params)``
    runs here (it may make inputs) and gives what to run on a worker thread; each cell then
    takes its own result (or the exception it raised)."""

    def __init__(
        self,
        request: pytest.FixtureRequest,
        test: Callable[..., Any],
        start: Callable[..., Callable[[], T]],
    ) -> None:
        self.cells = [
            item.callspec.params
            for item in request.session.items
            if getattr(item, "function", None) is test and hasattr(item, "callspec")
        ]
        self.start = start
        self.pool = ThreadPoolExecutor(WORKERS)
        self.futures: dict[tuple[Any, ...], Future[T]] = {}

    def __call__(self, **params: Any) -> T:
        if not self.futures:
            for cell in self.cells or [params]:
                self._submit(cell)
        if self._key(params) not in self.futures:  # a cell pytest did not list up front
            self._submit(params)
        return self.futures[self._key(params)].result()

    def _submit(self, params: dict[str, Any]) -> None:
        future: Future[T]
        try:
            future = self.pool.submit(self.start(**params))
        except Exception as exc:  # its input could not be made: that cell reports it
            future = Future()
            future.set_exception(exc)
        self.futures[self._key(params)] = future

    @staticmethod
    def _key(params: dict[str, Any]) -> tuple[Any, ...]:
        return tuple(sorted(params.items()))

    def __enter__(self) -> Prefetch[T]:
        return self

    def __exit__(self, *exc: object) -> None:
        self.pool.shutdown(wait=True, cancel_futures=True)


@dataclass(frozen=True)
class Ran:
    """A finished ``eg2scope`` process and the folder it ran in (its relative outputs)."""

    cwd: Path
    proc: subprocess.CompletedProcess[bytes]


def eg2scope_runs(
    request: pytest.FixtureRequest,
    test: Callable[..., Any],
    folders: pytest.TempPathFactory,
    argv: Callable[..., list[str]],
) -> Prefetch[Ran]:
    """``Prefetch`` of one ``eg2scope argv(**params)`` process per cell, each in a new folder."""

    def start(**params: Any) -> Callable[[], Ran]:
        args, cwd = argv(**params), folders.mktemp(test.__name__[:30])
        return lambda: Ran(cwd, eg2scope(*args, cwd=cwd))

    return Prefetch(request, test, start)


# -- decode's output ---------------------------------------------------------------------------


@dataclass
class Decoded:
    """``decode --format jsonl``: its bytes, the records and the source events (a recording
    replays its events in place, as records of kind ``event``)."""

    jsonl: bytes
    records: list[dict[str, Any]]
    events: list[dict[str, Any]]

    @classmethod
    def parse(cls, jsonl: bytes) -> Decoded:
        lines = [orjson.loads(line) for line in jsonl.splitlines()]
        records = [x for x in lines if x["kind"] != "event"]
        return cls(jsonl, records, [x for x in lines if x["kind"] == "event"])

    def by_bus(self) -> dict[str, list[dict[str, Any]]]:
        buses: dict[str, list[dict[str, Any]]] = {}
        for r in self.records:
            buses.setdefault(r["bus"], []).append(r)
        return buses

    def cmd_names(self) -> set[str]:
        """Every ``CMD_...`` word anywhere in the output: names, summaries, fields."""
        return set(CMD_WORD.findall(self.jsonl.decode()))


def seq_names(records: list[dict[str, Any]]) -> list[tuple[int, str | None]]:
    return [(r["seq"], r["name"]) for r in records]


# -- what stats must say -----------------------------------------------------------------------

COUNTS = ("requests", "responses", "unanswered", "retransmissions", "errors", "warnings")


def _count(table: dict[Any, Counter[str]], key: Any, r: dict[str, Any]) -> None:
    c = table.setdefault(key, Counter({name: 0 for name in COUNTS}))
    request, response = r["direction"] == "request", r["direction"] == "response"
    c["requests"] += request
    c["responses"] += response
    c["unanswered"] += request and "unanswered" in r["flags"]
    c["retransmissions"] += request and "retransmission" in r["flags"]
    c["errors"] += bool(r["errors"])
    c["warnings"] += bool(r["warnings"])
    if response and r["latency_ms"] is not None:
        c["max_ms"] = max(c.get("max_ms", 0), round(r["latency_ms"], 3))


def stats_of(decoded: Decoded) -> dict[str, Any]:
    """What ``stats --format json`` must report, counted from decode's records as
    docs/contracts.md defines their keys (latency percentiles aside: a histogram's)."""
    recs = decoded.records
    frames = [r for r in recs if r["kind"] == "frame"]
    times = [r["t"] for r in recs if r["t"] is not None]
    devices: dict[Any, Counter[str]] = {}
    commands: dict[Any, Counter[str]] = {}
    for r in frames:
        if r["device"] is None:
            continue
        key = (r["bus"], r["protocol"], r["device"])
        _count(devices, key, r)
        _count(commands, (*key, r["name"] or f"code {r['code']}"), r)
    return {
        "records": len(recs),
        "frames": len(frames),
        "valid_frames": sum(1 for r in frames if not r["errors"]),
        "garbage_bytes": sum(r["length"] for r in recs if r["kind"] == "garbage"),
        "truncated": sum(1 for r in recs if r["kind"] == "truncated"),
        "duration_s": round(max(times) - min(times), 6) if times else None,
        "protocols": dict(Counter(r["protocol"] for r in recs)),
        "flags": dict(Counter(f for r in recs for f in r["flags"])),
        "events": dict(Counter(e["event"] for e in decoded.events)),
        "devices": {k: _counts(c) for k, c in devices.items()},
        "commands": {k: _counts(c) for k, c in commands.items()},
    }


def _counts(c: Counter[str] | dict[str, Any]) -> dict[str, Any]:
    return {name: c[name] for name in COUNTS} | {"max_ms": c.get("max_ms")}


def stats_view(data: dict[str, Any]) -> dict[str, Any]:
    """``stats --format json`` in the shape of ``stats_of``."""
    top = ("records", "frames", "valid_frames", "garbage_bytes", "truncated", "duration_s")
    view = {k: data[k] for k in top} | {k: data[k] for k in ("protocols", "flags", "events")}
    view["devices"] = {(d["bus"], d["protocol"], d["device"]): _counts(d) for d in data["devices"]}
    view["commands"] = {
        (c["bus"], c["protocol"], c["device"], c["name"]): _counts(c) for c in data["commands"]
    }
    return view


# -- what stats' bus health must say ------------------------------------------------------------

CAN_PROTOCOLS = ("eg2-can", "can")
NO_TIMING = "no timing in this capture"


def buses_of(decoded: Decoded, timed: bool) -> dict[str, dict[str, Any]]:
    """What ``stats --format json``'s ``buses`` must say of each bus, counted from decode's
    records (``timed``: the input carries times): a CAN bus's frames and their bits by the
    second count (tests/can_wire.py), its error frames; a serial line's frames, its bytes (every
    byte is in exactly one record) and their bits, 10 a byte."""
    out = {}
    for bus, records in decoded.by_bus().items():
        if records[0]["protocol"] in CAN_PROTOCOLS:
            errors = [r for r in records if "can_error_frame" in r["flags"]]
            frames = [r for r in records if "can_error_frame" not in r["flags"]]
            out[bus] = {"kind": "can", "frames": len(frames), "bits": sum(map(_bits, frames)),
                        "error_frames": len(errors)}  # fmt: skip
        else:
            size = sum(r["length"] for r in records)
            frames = sum(1 for r in records if r["kind"] == "frame")
            out[bus] = {"kind": "serial", "frames": frames, "bytes": size, "bits": 10 * size}
        out[bus]["timing"] = None if timed else NO_TIMING
    return out


def _bits(r: dict[str, Any]) -> int:
    """A CAN record's frame's bits on the wire, from its identifier, DLC and data."""
    fields = r["fields"]
    remote = r["summary"].startswith("remote")
    data = b"" if remote else bytes.fromhex(r["raw"])
    return reference_bits(int(fields["id"], 16), fields.get("extended", True), remote,
                          fields.get("dlc", r["length"]), data)  # fmt: skip


def buses_view(data: dict[str, Any]) -> dict[str, dict[str, Any]]:
    """``stats --format json``'s ``buses`` in the shape of ``buses_of``."""
    out = {}
    for b in data["buses"]:
        keys = ("frames", "bits") + (("bytes",) if b["kind"] == "serial" else ())
        out[b["bus"]] = {"kind": b["kind"], **{k: b[k] for k in keys}}
        if b["kind"] == "can":
            out[b["bus"]]["error_frames"] = b["error_frames"]["total"]
        out[b["bus"]]["timing"] = b["timing"]
    return out


# -- sessions: a forced engine, state samples ---------------------------------------------------


#: the rates cells: each command given these rates (``-b`` as tui's and plot's live sources
#: spell it), on inputs with CAN and serial buses, their rates recorded or not
GIVEN_RATES = ("-b", "1000000", "--baud", "9600")
RATES_KINDS = ("mixed-recording", "candump")


def check_given_rates(buses: list[dict[str, Any]]) -> None:
    """Every bus of ``stats --format json ... GIVEN_RATES`` is counted at the rate given, and
    says the option."""
    assert buses
    for b in buses:
        if b["kind"] == "can":
            assert (b["bitrate"], b["bitrate_from"]) == (1_000_000, "--bitrate"), b["bus"]
        else:
            assert (b["baud"], b["baud_from"]) == (9600, "--baud"), b["bus"]


def force_session_engine(monkeypatch: pytest.MonkeyPatch, engine: str) -> None:
    """Every session made from here on that leaves its engine to the session (``"auto"``)
    runs on ``engine`` (``SessionOptions.engine``, the way a session chooses its decoding and
    tracker): the commands that have no --engine of their own (stats, plot, tui) run in this
    process on the engine a cell asks for, while a reference that names its engine keeps it."""
    make = Session.__init__

    def init(self: Session, source: Any, listeners: list[Listener], options: Any = None) -> None:
        options = options or SessionOptions()
        if options.engine == "auto":
            options = replace(options, engine=engine)
        make(self, source, listeners, options)

    monkeypatch.setattr(Session, "__init__", init)


class Samples(Listener):
    """A session's state samples."""

    wants_states = True

    def __init__(self) -> None:
        self.samples: list[StateSample] = []

    def on_records(self, records: Any) -> None:
        pass  # the records are decode's to give

    def on_states(self, samples: Any) -> None:
        self.samples += list(samples)


def python_samples(path: Path) -> list[StateSample]:
    """The state samples of a Python-engine session over ``path`` (the reference tracker)."""
    kept = Samples()
    run_capture(CaptureOptions(str(path), progress=False, engine="python"), [kept])
    return kept.samples


def opening_series(samples: list[StateSample]) -> dict[str, list[tuple[int, float]]]:
    """Per gripper, its opening readings as docs/rerun.md files them: entity
    ``/<bus>/<device>/opening_mm/measured``, (frame = the record's seq, millimetres)."""
    series: dict[str, list[tuple[int, float]]] = {}
    for s in samples:
        value = s.changed.get("opening")
        if value is not None:
            entity = f"/{s.bus}/{s.device}/opening_mm/measured"
            series.setdefault(entity, []).append((s.seq, opening_mm(value)))
    return series


def recorded_openings(mcap: Path) -> dict[str, list[tuple[int, float]]]:
    """Per gripper, the opening readings of a recording's ``/state/<bus>/<device>`` messages
    (docs/contracts.md), filed as ``opening_series`` files them."""
    from mcap.reader import make_reader

    series: dict[str, list[tuple[int, float]]] = {}
    with mcap.open("rb") as f:
        for _, channel, message in make_reader(f).iter_messages():
            if not channel.topic.startswith("/state/"):
                continue
            state = orjson.loads(message.data)
            if "opening" in state["changed"]:
                entity = f"/{state['bus']}/{state['device']}/opening_mm/measured"
                series.setdefault(entity, []).append((state["seq"], state["opening_mm"]))
    return {entity: sorted(rows) for entity, rows in series.items()}


def plotted_series(rrd: Rrd, entity: str) -> list[tuple[int | None, float]]:
    """An entity's (frame, value) rows in frame order."""
    if entity not in rrd.entities:
        return []
    return [(frame, value) for _, frame, value in rrd[entity].rows()]


# -- the blueprint's views ----------------------------------------------------------------------


@dataclass(frozen=True)
class View:
    name: str
    kind: str
    origin: str
    query: tuple[str, ...]

    def shows(self, path: str) -> bool:
        """Whether ``path`` is in this view's contents (Rerun's entity path query: ``+``/``-``
        rules, ``$origin``, ``/**`` for a subtree)."""
        included = excluded = False
        for rule in self.query:
            rule = rule.strip()
            sign = "+"
            if rule[:1] in "+-":
                sign, rule = rule[0], rule[1:].strip()
            rule = rule.replace("$origin", self.origin).replace("//", "/")
            if rule.endswith("/**"):
                base = rule[:-3].rstrip("/")
                hit = path == (base or "/") or path.startswith(base + "/")
            else:
                hit = path == rule
            if hit and sign == "+":
                included = True
            elif hit:
                excluded = True
        return included and not excluded


def blueprint_views(rrd: Rrd) -> list[View]:
    """The views of the blueprint the viewer shows (the one sent last), reached from the
    viewport's root container; each entity's newest value of each component."""
    assert rrd.blueprints, "the .rrd holds no blueprint"
    store = max(rrd.blueprints, key=lambda s: max(max(c.get("log_time") or [0]) for c in s))
    latest: dict[str, dict[str, Any]] = {}
    for chunk in sorted(store, key=lambda c: max(c.get("log_time") or [0])):
        for name, column in chunk.items():
            if ":" in name and column:
                latest.setdefault(chunk["entity"], {})[name] = column[-1]
    root = latest["/viewport"]["ViewportBlueprint:root_container"][0]
    views: list[View] = []

    def walk(part: str) -> None:
        entity = latest.get(f"/{part}", {})
        if part.startswith("view/"):
            query = latest.get(f"/{part}/ViewContents", {}).get("ViewContents:query")
            views.append(
                View(
                    name=(entity.get("ViewBlueprint:display_name") or [part])[0],
                    kind=entity["ViewBlueprint:class_identifier"][0],
                    origin=entity["ViewBlueprint:space_origin"][0],
                    query=tuple(query or ["$origin/**"]),
                )
            )
            return
        for child in entity.get("ContainerBlueprint:contents") or []:
            walk(child)

    walk(f"container/{uuid.UUID(bytes=bytes(root))}")
    return views


def empty_views(rrd: Rrd) -> list[str]:
    """The views of the blueprint in which no entity has a single row of data."""
    with_data = [path for path, e in rrd.entities.items() if e.values]
    return [
        f"{v.name} ({v.kind} {v.origin})"
        for v in blueprint_views(rrd)
        if not any(v.shows(path) for path in with_data)
    ]


# -- the TUI in a real pseudo-terminal ----------------------------------------------------------

CMD_WORD = re.compile(r"CMD_[A-Z0-9_]*…?")
QUIET_S = 0.5  # a screen this long unchanged has taken in the capture
LIVE_S = 2.0  # a live screen never stops changing: looked at this long after it is ready


def manual_names() -> set[str]:
    """Every command and register name of the manual that eg2scope knows (a live session's
    names are not known in advance)."""
    commands = COMMANDS.values()
    return (
        {r.name for r in REGISTERS}
        | {c.name for c in commands}
        | {c.alias for c in commands if c.alias is not None}
    )


class Terminal:
    """A process in a real pseudo-terminal of ``columns`` x ``lines``, its screen read back
    through a terminal emulator (pyte)."""

    def __init__(self, argv: list[str], columns: int, lines: int, cwd: Path) -> None:
        import pexpect
        import pyte

        self.pexpect = pexpect
        self.screen = pyte.Screen(columns, lines)
        self.stream = pyte.ByteStream(self.screen)
        env = {"TERM": "xterm-256color", "PATH": "/usr/bin:/bin", "TEXTUAL_ANIMATIONS": "none"}
        self.child = pexpect.spawn(
            argv[0], argv[1:], cwd=str(cwd), dimensions=(lines, columns), env=env
        )

    def read(self, most_s: float = 0.2) -> bool:
        """Feed what the process wrote to the screen (for at most ``most_s``: a live screen
        never stops drawing); whether there was anything."""
        got, end = False, time.monotonic() + most_s
        while time.monotonic() < end:
            try:
                data = self.child.read_nonblocking(65536, timeout=0.05)
            except (self.pexpect.TIMEOUT, self.pexpect.EOF):
                return got
            if not data:
                return got
            got = True
            self.stream.feed(data)
        return got

    def text(self) -> str:
        return "\n".join(self.screen.display)

    def settle(self, ready: Callable[[str], bool], timeout: float = 15.0) -> str:
        """The screen once ``ready(screen)`` holds and it has stopped changing (the process
        may redraw the same text) or, live, ``LIVE_S`` later; at ``timeout``, whatever it
        shows."""
        end = time.monotonic() + timeout
        shown, since, ready_at = "", time.monotonic(), None
        while time.monotonic() < end and self.child.isalive():
            self.read()
            text, now = self.text(), time.monotonic()
            if text != shown:
                shown, since = text, now
            if ready_at is None and ready(text):
                ready_at = now
            if ready_at is not None and (now - since >= QUIET_S or now - ready_at >= LIVE_S):
                break
            time.sleep(0.1)
        self.read()
        return self.text()

    def quit(self, key: str = "q", timeout: float = 20.0) -> int | None:
        """Send ``key`` and wait for the process to end; its exit status."""
        self.child.send(key)
        end = time.monotonic() + timeout
        while self.child.isalive() and time.monotonic() < end:
            self.read()
        if self.child.isalive():
            self.child.terminate(force=True)
        self.child.close()
        return self.child.exitstatus

    def close(self) -> None:
        if self.child.isalive():
            self.child.terminate(force=True)
