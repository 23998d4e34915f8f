"""The plot's fast path on the native core, against the Python reference on the same input:
a candump log read by the native core straight into the session's native decoding (the same
records, the same damage reported, the same exit status and .rrd as the Python reader gives),
and the logs' rows (``plot/logs.log_rows``) made from a native ``RecordBatch`` equal to
those made from its records as objects. Inputs: the sample capture, a capture whose every
command draws a warning (the benchmark's), a capture with faults and one with damaged lines
and a cut-off last line, plain and gzip compressed."""

from __future__ import annotations

import gzip
import math
import sys
from pathlib import Path
from typing import Any

import pytest
from native_core import needs_native
from rerun_inputs import CAPTURES, Collector, faults_can, write_candump
from rrd_helpers import read_rrd

from analyzer.cli import main
from analyzer.plot.listener import RerunListener
from analyzer.plot.logs import log_rows
from analyzer.session.batches import RecordSequence
from analyzer.session.capture import CaptureOptions, run_capture
from analyzer.session.listener import Listener
from analyzer.sources.source import CaptureSource

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
from traffic import warning_can_frames

pytestmark = needs_native


def warnings_log(tmp: Path) -> Path:
    return write_candump(tmp / "warnings.log", list(warning_can_frames(6000)))


def damaged_log(tmp: Path) -> Path:
    """Frames, lines that are no frames in the middle, and a last line cut short."""
    good = (CAPTURES / "can_pick_place.log").read_text().splitlines(keepends=True)
    lines = [*good[:40], "this is no frame\n", *good[40:80], "(12.5) can0 123#zz\n", *good[80:]]
    path = tmp / "damaged.log"
    path.write_text("".join(lines) + "(1763700200.000100) can0 0118")
    return path


def damaged_gz(tmp: Path) -> Path:
    path = tmp / "damaged.log.gz"
    path.write_bytes(gzip.compress(damaged_log(tmp).read_bytes()))
    return path


INPUTS = {
    "candump": lambda tmp: CAPTURES / "can_pick_place.log",
    "warnings": warnings_log,
    "faults": faults_can,
    "damaged": damaged_log,
    "damaged_gz": damaged_gz,
}


class RawWanted(Collector):
    """A listener that wants the raw items: the session must then read them in Python."""

    wants_raw = True

    def on_raw(self, items: list[Any]) -> None:
        pass


def session_of(path: Path, engine: str, listener: Listener) -> tuple[Any, Any]:
    opts = CaptureOptions(str(path), progress=False, engine=engine)
    return run_capture(opts, [listener])


@pytest.mark.parametrize("name", INPUTS)
def test_native_frames_give_the_python_readers_records_and_damage(
    tmp_path: Path, name: str
) -> None:
    path = INPUTS[name](tmp_path)
    python, native_ = Collector(), Collector()
    py_session, py_reader = session_of(path, "python", python)
    session, reader = session_of(path, "native", native_)
    assert session.source.frames is not None  # read by the native core
    assert py_session.source.frames is None
    assert RecordSequence(native_.records).jsonl() == RecordSequence(python.records).jsonl()
    assert session.counts.items == py_session.counts.items
    assert reader.errors == py_reader.errors
    assert reader.position == reader.size
    if name.startswith("damaged"):
        assert any("cannot parse" in e for e in reader.errors)
        assert any("truncated" in e for e in reader.errors)


def test_a_listener_that_wants_raw_items_gets_them_from_the_python_reader(
    tmp_path: Path,
) -> None:
    raw = RawWanted()
    session, _ = session_of(CAPTURES / "can_pick_place.log", "native", raw)
    assert session.source.frames is None
    plain = Collector()
    session_of(CAPTURES / "can_pick_place.log", "native", plain)
    assert RecordSequence(raw.records).jsonl() == RecordSequence(plain.records).jsonl()


def without_nan(rows: dict[Any, Any]) -> dict[Any, Any]:
    """NaN (no timestamp) as None, so that equal rows compare equal."""
    return {
        key: tuple(
            [None if isinstance(x, float) and math.isnan(x) else x for x in column]
            for column in value
        )
        for key, value in rows.items()
    }


class Batches(Listener):
    """The native RecordBatches the session hands out, as they come."""

    def __init__(self) -> None:
        self.batches: list[Any] = []

    def on_records(self, records: Any) -> None:
        self.batches.append(records)


@pytest.mark.parametrize("name", INPUTS)
def test_log_rows_of_a_native_batch_equal_the_reference(tmp_path: Path, name: str) -> None:
    got = Batches()
    session_of(INPUTS[name](tmp_path), "native", got)
    assert got.batches and all(type(b).__name__ == "RecordBatch" for b in got.batches)
    shown = 0
    for batch in got.batches:
        buses, grippers = log_rows(batch)
        want_buses, want_grippers = log_rows(RecordSequence(batch))  # the records as objects
        assert list(buses) == list(want_buses)  # the same keys, in the same order
        assert list(grippers) == list(want_grippers)
        assert without_nan(buses) == without_nan(want_buses)
        assert without_nan(grippers) == without_nan(want_grippers)
        shown += sum(len(rows[0]) for rows in buses.values())
    assert shown or name in ("candump", "faults")  # these two have no problem records


def test_every_command_of_the_warning_capture_is_in_the_logs(tmp_path: Path) -> None:
    """The warning-heavy capture: each request is a warning in its bus's log; commands (not
    polls) are in their gripper's log, at WARN when flagged."""
    collected = Collector()
    session_of(warnings_log(tmp_path), "native", collected)
    buses, grippers = log_rows(RecordSequence(collected.records))
    requests = [r for r in collected.records if r.direction == "request"]
    warned = [r for r in collected.records if r.warnings and not r.errors]
    _, seq, text, level = buses["can0"][:4]
    assert seq == [r.seq for r in collected.records if r.errors or r.warnings]
    assert level.count("WARN") == len(warned) >= len(requests)
    assert all(": " in x for x in text if x)
    commands = sum(len(rows[0]) for rows in grippers.values())
    writes = [r for r in requests if r.code == 1]  # eg2-can OP_WRITE
    assert commands == len(writes) > 0
    logged = {
        seq: lv for rows in grippers.values() for seq, lv in zip(rows[1], rows[3], strict=True)
    }
    assert logged == {r.seq: "WARN" if r.warnings else "INFO" for r in writes}
    assert list(logged.values()).count("WARN") > 0.9 * len(writes)  # all but the first few


@pytest.mark.parametrize("name", ["damaged", "damaged_gz"])
def test_plot_of_a_damaged_capture_is_the_same_on_both_engines(
    tmp_path: Path, name: str, capsys: pytest.CaptureFixture[str]
) -> None:
    path = INPUTS[name](tmp_path)
    errs, rrds = {}, {}
    for engine in ("python", "native"):
        out = tmp_path / f"{engine}.rrd"
        argv = ["plot", str(path), "--save", str(out), "--no-progress", "--engine", engine]
        assert main(argv) == 3  # decoded, but the input is damaged
        errs[engine] = [x for x in capsys.readouterr().err.splitlines() if "line " in x]
        rrds[engine] = read_rrd(out)
    assert errs["python"] == errs["native"] and errs["native"]
    content = {
        engine: {path: (e.rows(), sorted(e.levels, key=str)) for path, e in rrd.entities.items()}
        for engine, rrd in rrds.items()
    }
    assert content["python"] == content["native"]


def test_the_rerun_listener_on_native_frames_logs_every_problem(tmp_path: Path) -> None:
    collected, out = Collector(), tmp_path / "w.rrd"
    opts = CaptureOptions(str(warnings_log(tmp_path)), progress=False, engine="native")
    session, _ = run_capture(opts, [collected, RerunListener(str(out))])
    assert session.source.frames is not None
    log = read_rrd(out)["/can0/errors"]
    problems = [r for r in collected.records if r.errors or r.warnings]
    assert sorted(log.frame) == [r.seq for r in problems]
    assert log.levels.count("WARN") == len(problems)


def test_eg2scope_plot_reads_a_candump_log_natively(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``eg2scope plot`` itself (its listeners: the Rerun listener with its bus health, and the
    check for an unreadable capture) lets the native core read the log, and plots what the
    Python reader gives."""
    sources: list[CaptureSource] = []
    started = CaptureSource.start

    def start(self: CaptureSource) -> None:
        sources.append(self)
        started(self)

    monkeypatch.setattr(CaptureSource, "start", start)
    rrds = {}
    for engine in ("native", "python"):
        out = tmp_path / f"{engine}.rrd"
        argv = ["plot", str(warnings_log(tmp_path)), "--save", str(out), "--no-progress"]
        assert main([*argv, "--engine", engine]) == 0
        rrds[engine] = read_rrd(out)
    assert sources[0].frames is not None and sources[1].frames is None
    native, python = rrds["native"], rrds["python"]
    assert native.entities.keys() == python.entities.keys()
    assert all(native[p].rows() == e.rows() for p, e in python.entities.items())
