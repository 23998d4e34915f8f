"""The seam between the engines: what listeners are handed, a ``RecordSequence`` and a
``SampleSequence`` (Python engine, the reference) or the native core's ``RecordBatch`` and
``SampleBatch``, with the same bulk methods giving the same answers (analyzer/session/batches.py).

Every test runs on both implementations (the ``engine`` fixture, as markupsafe runs its suite
on both of its implementations): the records and samples a session's engine makes of real CAN
input. Without a native core the native half skips (with cargo on the PATH it fails:
tests/native_core.py). The byte-stream captures have no native session decoding: their
sequences are checked on the Python engine.
"""

from __future__ import annotations

import dataclasses
import gc
import io
from pathlib import Path
from typing import Any

import orjson
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from mcap.reader import make_reader
from native_core import require_native

from analyzer.fleet.tables import STATE_COLUMNS, states_table
from analyzer.model import Item, StateSample
from analyzer.parquet import native as native_parquet
from analyzer.plot.listener import _PLOTTED
from analyzer.plot.logs import _POLL_LIST, _QUIET_LIST, POLLS, QUIET_FLAGS, records_log_rows
from analyzer.session.batches import RecordSequence, SampleSequence, json_message, session_engine
from analyzer.session.capture import CaptureOptions, FilteredListener
from analyzer.session.listener import Listener, make_listener
from analyzer.session.parallel import resumed
from analyzer.sources.capture import open_capture
from analyzer.stats import stats_groups
from decoders.model import EG2_SERIAL, MODBUS_RTU, Record

CAPTURES = Path(__file__).resolve().parents[2] / "captures"
CAN_CAPTURE = CAPTURES / "can_pick_place.log"
BYTE_CAPTURES = {
    "serial": (CAPTURES / "serial_session.bin", EG2_SERIAL),
    "modbus": (CAPTURES / "modbus_session.bin", MODBUS_RTU),
}
RECORD_ATTRS = [f.name for f in dataclasses.fields(Record)]
SAMPLE_ATTRS = [f.name for f in dataclasses.fields(StateSample)]


def capture_items(path: Path) -> list[Item]:
    with open_capture(str(path)) as reader:
        return [x for x in reader if isinstance(x, Item)]


def decode(engine: str, items: list[Item], kind: str = "can", protocol: str | None = None) -> Any:
    """The records and samples ``engine``'s session decoding and tracker make of ``items``."""
    decoding, tracker = session_engine(engine, kind, False, protocol)
    records = decoding.feed_items(items)
    records += decoding.finish()
    return records, tracker.update_many(records)


@pytest.fixture(scope="module", params=["python", "native"])
def engine(request: pytest.FixtureRequest) -> str:
    """Which implementation: the native half needs the core (else skips or fails)."""
    if request.param == "native":
        require_native()
    return str(request.param)


@pytest.fixture(scope="module")
def can_items() -> list[Item]:
    return capture_items(CAN_CAPTURE)


@pytest.fixture(scope="module")
def decoded(engine: str, can_items: list[Item]) -> tuple[Any, Any]:
    return decode(engine, can_items)


@pytest.fixture(scope="module")
def reference(can_items: list[Item]) -> tuple[RecordSequence, SampleSequence]:
    """The Python engine's records and samples (the reference)."""
    records, samples = decode("python", can_items)
    return records, samples


def byte_stream(name: str) -> tuple[Any, Any]:
    path, protocol = BYTE_CAPTURES[name]
    return decode("python", capture_items(path), "bytes", protocol)


def check_records(records: Any) -> None:
    """Each bulk method of ``records`` against the records read one by one."""
    objects: list[Record] = list(records)
    assert objects, "the capture decodes to records"
    for name in RECORD_ATTRS:
        assert records.column(name) == [getattr(r, name) for r in objects], name
    assert records.error_count() == sum(1 for r in objects if r.errors)
    assert records.problems() == [i for i, r in enumerate(objects) if r.errors or r.warnings]
    assert records.messages() == [json_message(r.to_dict()) for r in objects]
    assert records.jsonl() == b"".join(orjson.dumps(r.to_dict()) + b"\n" for r in objects)
    rows = records.rerun_log_rows(_POLL_LIST, _QUIET_LIST)
    assert rows == records_log_rows(objects, POLLS, QUIET_FLAGS)
    assert records.stats_groups() == stats_groups(objects)


def check_samples(samples: Any) -> None:
    """Each bulk method of ``samples`` against the samples read one by one."""
    objects: list[StateSample] = list(samples)
    assert objects, "the capture has state readings"
    for name in SAMPLE_ATTRS:
        assert samples.column(name) == [getattr(s, name) for s in objects], name
    assert samples.keys() == [(s.bus, s.device) for s in objects]
    assert samples.messages() == [json_message(s.to_dict()) for s in objects]
    series = samples.series(_PLOTTED)
    assert series == SampleSequence(objects).series(_PLOTTED)
    plotted = sum(len(times) for _bus, _device, _names, times, _seqs, _columns in series)
    assert plotted == sum(1 for s in objects if any(f in s.changed for f in _PLOTTED))


def test_the_engines_hand_out_their_own_kind(decoded: tuple[Any, Any], engine: str) -> None:
    records, samples = decoded
    if engine == "python":
        assert type(records) is RecordSequence and type(samples) is SampleSequence
    else:
        assert type(records).__name__ == "RecordBatch"
        assert type(samples).__name__ == "SampleBatch"


def test_record_methods_read_what_the_records_say(decoded: tuple[Any, Any]) -> None:
    check_records(decoded[0])


def test_sample_methods_read_what_the_samples_say(decoded: tuple[Any, Any]) -> None:
    check_samples(decoded[1])


@pytest.mark.parametrize("name", sorted(BYTE_CAPTURES))
def test_byte_stream_sequences(name: str) -> None:
    records, samples = byte_stream(name)
    check_records(records)
    check_samples(samples)


def test_both_engines_give_the_same_answers(
    decoded: tuple[Any, Any], reference: tuple[RecordSequence, SampleSequence]
) -> None:
    records, samples = decoded
    want_records, want_samples = reference
    assert records.jsonl() == want_records.jsonl()
    assert records.problems() == want_records.problems()
    assert samples.messages() == want_samples.messages()
    assert samples.series(_PLOTTED) == want_samples.series(_PLOTTED)


def test_take_gives_the_records_asked_for_in_a_sequence_of_the_same_kind(
    decoded: tuple[Any, Any],
) -> None:
    records = decoded[0]
    picks = [5, 0, 5, len(records) - 1, *records.problems()]
    taken = records.take(picks)
    assert type(taken) is type(records)
    assert list(taken) == [records[i] for i in picks]
    assert taken.jsonl() == b"".join(orjson.dumps(records[i].to_dict()) + b"\n" for i in picks)
    assert len(records.take([])) == 0
    with pytest.raises(IndexError):
        records.take([len(records)])


def arrow_table(samples: Any) -> pa.Table:
    rows, parts = samples.arrow(native_parquet.columns(STATE_COLUMNS))
    assert rows == len(samples)
    return native_parquet.batch_table(parts, STATE_COLUMNS)


def test_sample_arrow_columns_hold_what_the_samples_say(
    decoded: tuple[Any, Any], reference: tuple[RecordSequence, SampleSequence]
) -> None:
    """``arrow`` (the fleet dataset's states) on both kinds: the same table, and that table
    is the samples' own values column by column."""
    table = arrow_table(decoded[1])
    assert table.equals(arrow_table(reference[1]))
    samples = list(reference[1])
    assert table.column("t").to_pylist() == [s.t for s in samples]
    assert table.column("bus").to_pylist() == [s.bus for s in samples]
    assert table.column("changed").to_pylist() == [list(s.changed) for s in samples]
    assert table.column("opening").to_pylist() == [s.values["opening"] for s in samples]
    assert states_table(decoded[1]).equals(states_table(reference[1]))


def test_empty_sequences() -> None:
    records, samples = RecordSequence(), SampleSequence()
    assert records.column("t") == [] and records.problems() == [] and records.jsonl() == b""
    assert samples.series(_PLOTTED) == [] and samples.keys() == []
    assert arrow_table(samples).num_rows == 0


# -- the listeners, handed either kind ------------------------------------------------------


class Kept(Listener):
    """What a filter passes on: the sequences themselves."""

    def __init__(self) -> None:
        self.batches: list[Any] = []

    def on_records(self, records: RecordSequence) -> None:
        self.batches.append(records)


def records_in_memory() -> int:
    gc.collect()
    return sum(1 for o in gc.get_objects() if type(o) is Record)


@pytest.mark.parametrize(
    ("device", "errors_only"), [(None, True), (1, False), (1, True), (4, False)]
)
def test_a_filter_passes_on_a_sequence_of_the_same_kind_without_reading_records(
    decoded: tuple[Any, Any], engine: str, device: int | None, errors_only: bool
) -> None:
    """``--device`` and ``--errors-only`` keep what they say; a native batch stays lazy."""
    records = decoded[0]
    if engine == "native":  # a fresh batch: the checks above made its Record objects
        records = decode(engine, capture_items(CAN_CAPTURE))[0]
    opts = CaptureOptions(path=str(CAN_CAPTURE), device=device, errors_only=errors_only)
    keep = opts.record_filter()
    assert keep is not None
    kept = Kept()
    filtered = FilteredListener(kept, keep)
    before = records_in_memory()
    filtered.on_records(records)
    if engine == "native":
        assert records_in_memory() == before
    assert all(type(x) is type(records) for x in kept.batches)
    got = [r.to_dict() for batch in kept.batches for r in batch]
    want = [
        r.to_dict()
        for r in decoded[0]
        if (device is None or r.device == device) and (not errors_only or r.errors or r.warnings)
    ]
    assert got == want
    assert filtered.kept == len(want)


def test_a_resumed_listener_gets_the_records_from_its_position_on(
    decoded: tuple[Any, Any],
) -> None:
    records = decoded[0]
    middle = records[len(records) // 2].index
    kept = Kept()
    resumed(kept, middle).on_records(records)
    assert [r.index for batch in kept.batches for r in batch] == [
        r.index for r in records if r.index >= middle
    ]
    assert all(type(x) is type(records) for x in kept.batches)


def output(name: str, records: Any, samples: Any, tmp_path: Path) -> Any:
    """What the listener registered as ``name`` makes of these records and samples."""
    tmp_path.mkdir()
    if name == "mcap":
        path = tmp_path / "out.mcap"
        listener = make_listener(name, str(path), metadata={"test": "sequences"})
    elif name == "parquet":
        binary = io.BytesIO()
        listener = make_listener(name, binary)
    else:
        out: Any = io.BytesIO() if name == "jsonl" else io.StringIO()
        listener = make_listener(name, out)
    listener.on_records(records)
    if listener.wants_states:
        listener.on_states(samples)
    listener.close()
    if name == "mcap":
        with path.open("rb") as f:
            return [(c.topic, m.log_time, m.data) for _s, c, m in make_reader(f).iter_messages()]
    if name == "parquet":
        return pq.read_table(io.BytesIO(binary.getvalue()))
    return out.getvalue()


@pytest.mark.parametrize("name", ["jsonl", "csv", "text", "parquet", "mcap"])
def test_every_output_makes_the_same_of_either_kind(
    decoded: tuple[Any, Any],
    reference: tuple[RecordSequence, SampleSequence],
    name: str,
    tmp_path: Path,
) -> None:
    got = output(name, *decoded, tmp_path / "got")
    want = output(name, *reference, tmp_path / "want")
    if name == "parquet":
        assert got.equals(want)
    else:
        assert got == want
    assert got  # the outputs hold the records
