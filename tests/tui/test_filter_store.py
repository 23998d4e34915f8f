"""The display-filter language and the compact store, on real decoded records (issue 8:
"Filter", "compact records")."""

from __future__ import annotations

import pytest
from conftest import CAPTURES

from analyzer.session.batches import RecordSequence
from analyzer.session.capture import CaptureOptions, run_capture
from analyzer.session.listener import Listener
from analyzer.tui.aggregates import HISTOGRAM_BINS, Aggregates, latency_stats
from analyzer.tui.export import raw_item
from analyzer.tui.filter import FilterError, parse
from analyzer.tui.spans import span_at, spans
from analyzer.tui.store import BLOCK, RecordStore
from decoders.model import Record


class Keep(Listener):
    def __init__(self) -> None:
        self.records: list[Record] = []

    def on_records(self, records: list[Record]) -> None:
        self.records += records


def decoded(name: str) -> list[Record]:
    keep = Keep()
    run_capture(CaptureOptions(str(CAPTURES / name), progress=False), [keep])
    return keep.records


@pytest.fixture(scope="module")
def records() -> RecordSequence:
    return RecordSequence(
        decoded("can_pick_place.log")
        + decoded("serial_session.bin")
        + decoded("modbus_session.bin")
    )


@pytest.fixture(scope="module")
def store(records: list[Record]) -> RecordStore:
    s = RecordStore()
    for k in range(0, len(records), 7):  # uneven batches across block boundaries
        s.append(RecordSequence(records[k : k + 7]))
    return s


def test_store_gives_back_every_record_as_decoded(records: list[Record], store: RecordStore):
    assert store.count == len(records)
    for i, rec in enumerate(records):
        assert store.record(i).to_dict() == rec.to_dict()


def test_a_store_that_keeps_the_newest_drops_the_oldest_and_the_rest_keep_their_index(
    records: list[Record],
) -> None:
    """``keep``: the oldest whole blocks go once a tenth more is held (never what the reader
    has not seen); every record kept reads back as decoded at its own index, the filter and
    the look-ups see only what is kept."""
    many = list(records) * 40  # a long session
    keep = 600
    store = RecordStore(keep)
    seen = dropped = 0
    for k in range(0, len(many), 50):
        store.append(RecordSequence(many[k : k + 50]))
        dropped += store.trim(below=seen)  # as the frame list does, at each update
        seen = store.count
        assert keep <= store.kept <= keep + 2 * BLOCK + 50 or store.first == 0
    assert dropped == store.first > max(len(many) - keep - 2 * BLOCK - 50, 0)
    assert store.first % BLOCK == 0 and store.count == len(many)
    for i in range(store.first, store.count):
        assert store.record(i).to_dict() == many[i].to_dict()
    with pytest.raises(IndexError):
        store.record(store.first - 1)
    with pytest.raises(IndexError):
        store.t[store.first - 1]
    assert [r.seq for r in store.records([0, store.first, store.count - 1])] == [
        many[store.first].seq,
        many[-1].seq,
    ]  # an export that runs on: what is left of the records it was asked for
    compiled = parse("dev == 1 and request")
    assert compiled is not None
    want = [
        i
        for i in range(store.first, len(many))
        if many[i].device == 1 and many[i].direction == "request"
    ]
    assert compiled.indices(store, 0) == want
    for seq in (many[0].seq, many[-1].seq):  # the copies kept: the first of them is found
        kept = [i for i in range(store.first, store.count) if many[i].seq == seq]
        assert store.index_of_seq(seq) == kept[0]
    at = store.first_index_at_or_after(-1e18)
    assert at is not None and at >= store.first


FILTERS = [
    ("dev == 1", lambda r: r.device == 1),
    ("dev == 1 and bus == can0", lambda r: r.device == 1 and r.bus == "can0"),
    ("dev != 1", lambda r: r.device != 1),
    ("dev == none", lambda r: r.device is None),
    ("dev >= 2", lambda r: r.device is not None and r.device >= 2),
    ("name ~ CATCH", lambda r: "catch" in (r.name or r.protocol).lower()),
    ("name == cmd_openlen_set", lambda r: (r.name or "").lower() == "cmd_openlen_set"),
    ("flag == unanswered", lambda r: "unanswered" in r.flags),
    ("flag != unanswered", lambda r: "unanswered" not in r.flags),
    ("latency > 5", lambda r: r.latency_ms is not None and r.latency_ms > 5),
    ("latency <= 5ms", lambda r: r.latency_ms is not None and r.latency_ms <= 5),
    ("errors", lambda r: bool(r.errors)),
    ("warnings", lambda r: not r.errors and bool(r.warnings)),
    ("problems", lambda r: bool(r.errors or r.warnings)),
    ("not foreign", lambda r: "foreign" not in r.flags),
    ("foreign or errors", lambda r: "foreign" in r.flags or bool(r.errors)),
    ("request", lambda r: r.direction == "request"),
    ("dir == response", lambda r: r.direction == "response"),
    ("protocol == modbus", lambda r: r.protocol == "modbus-rtu"),
    ("kind == garbage", lambda r: r.kind == "garbage"),
    ("summary ~ 'force=1\\d\\d'", lambda r: __import__("re").search("force=1\\d\\d", r.summary, 2)),
    ("bus ~ ^ser|can", lambda r: r.bus.startswith("ser") or "can" in r.bus),
    ("not (dev == 1 or dev == 2) && !errors", lambda r: r.device not in (1, 2) and not r.errors),
    ("seq < 10", lambda r: r.seq < 10),
]


@pytest.mark.parametrize(("text", "expected"), FILTERS, ids=[f[0] for f in FILTERS])
def test_filter_selects_what_it_says(text, expected, records, store) -> None:
    compiled = parse(text)
    assert compiled is not None
    want = [i for i, r in enumerate(records) if expected(r)]
    assert compiled.indices(store) == want
    # evaluated in pieces (a live store grows) it finds the same
    half = store.count // 2
    assert compiled.indices(store, 0, half) + compiled.indices(store, half) == want


BAD = [
    ("dev ==", "a value is expected", 6),
    ("foo == 1", "unknown field 'foo'", 0),
    ("name ~ '('", "bad regular expression", 7),
    ("flag == nope", "unknown flag 'nope'", 8),
    ("dev == 1 and", "expression expected", 12),
    ("(dev == 1", "missing ')'", 9),
    ("latency > x", "compares with a number", 10),
    ("bus > 1", "bus takes == != or ~", 6),
    ("dev == 1 dev == 2", "missing and/or", 9),
    ("dir == up", "dir is request, response or none", 7),
    ("'open", "unterminated string", 0),
    ("wat", "unknown word 'wat'", 0),
    ("dev", "dev needs a comparison", 0),
]


@pytest.mark.parametrize(("text", "message", "position"), BAD, ids=[b[0] for b in BAD])
def test_a_bad_filter_says_what_and_where(text: str, message: str, position: int) -> None:
    with pytest.raises(FilterError) as caught:
        parse(text)
    assert message in caught.value.message
    assert caught.value.position == position


def test_an_empty_filter_shows_everything() -> None:
    assert parse("   ") is None


def test_every_byte_of_a_field_selects_that_field(records: list[Record]) -> None:
    for rec in records:
        found = spans(rec)
        assert all(0 <= s.start < s.end <= len(rec.raw) for s in found)
        for s in found:
            if len(s.path) and s.path[0] != "frame" and s.path[0] in rec.fields:
                assert span_at(found, s.start) == s


def test_an_exported_record_rebuilds_its_raw_input(records: list[Record]) -> None:
    for rec in records:
        item = raw_item(rec)
        assert item.payload.data == rec.raw and item.bus == rec.bus


@pytest.mark.parametrize(
    "values",
    [[0.0], [0.0, 0.0], [1.0], [0.1, 0.2, 0.3, 0.4], [0.5] * 9 + [4.0], [i / 7 for i in range(50)]],
)
def test_latency_histogram_counts_each_value_in_its_bin(values: list[float]) -> None:
    stats = latency_stats(values)
    assert stats is not None
    top = max(values)
    expected = [0] * HISTOGRAM_BINS
    for v in values:
        expected[min(HISTOGRAM_BINS - 1, int(v / top * HISTOGRAM_BINS)) if top else 0] += 1
    assert stats.histogram == expected
    assert (stats.count, stats.max) == (len(values), top)


def test_latency_panels_follow_batches_split_anywhere(records: list[Record]) -> None:
    # percentiles are redone only for the keys a batch touched: the result must not depend
    # on how the records were batched, nor on how often the panels asked
    whole = Aggregates()
    whole.add(records, 0)
    expected = whole.snapshot()
    pieces = Aggregates()
    for k in range(0, len(records), 5):
        pieces.add(RecordSequence(records[k : k + 5]), k)
        if k % 15 == 0:
            pieces.snapshot()
    got = pieces.snapshot()
    assert expected.latency_by_command  # the captures hold answered requests
    assert got.latency_by_command == expected.latency_by_command
    assert got.latency_by_device == expected.latency_by_device
    assert [vars(g) for g in got.problems] == [vars(g) for g in expected.problems]
