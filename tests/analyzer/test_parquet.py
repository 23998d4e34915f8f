"""Parquet output (issue 10): the records as typed columns, exact and complete.

Every test reads the file back with pyarrow and rebuilds each JSONL record from its row by the
rules docs/contracts.md gives for the columns (an implementation of its own, here), so a value
that is lost, retyped or put in the wrong column fails. Inputs: the sample captures through the
real command line, streams that reach every decoder's fields (the manual's frames among them),
Hypothesis streams of frames, garbage and truncation, and JSONL in random pieces.
"""

from __future__ import annotations

import gzip
import json
import os
import pty
import random
import re
import subprocess
import sys
from pathlib import Path
from typing import Any

import orjson
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from hypothesis import given
from hypothesis import strategies as st
from protocol_vectors import load

from analyzer.model import Item, SourceEvent
from analyzer.parquet import writer as P
from analyzer.parquet.schema import FAMILY, RECORD_COLUMNS, SCHEMA
from analyzer.session.batches import RecordSequence
from analyzer.session.stage import Decoding
from decoders import build as b
from decoders.eg2_serial import Cmd
from decoders.model import EG2_SERIAL, MODBUS_RTU, CanFrame, Chunk
from decoders.registers import REGISTERS, opening_mm

ROOT = Path(__file__).resolve().parents[2]
CAPTURES = ROOT / "captures"
ENV = {**os.environ, "PYTHONPATH": str(ROOT), "NO_COLOR": "1"}
REGISTER_NAMES = [r.name for r in REGISTERS]
MM_NAMES = [r.name for r in REGISTERS if r.unit == "mm"]


# -- the contract, read back -------------------------------------------------------------------


def fields_from_row(row: dict[str, Any]) -> dict[str, Any]:
    """``fields`` of a record rebuilt from its Parquet row (docs/contracts.md, "Parquet")."""
    family = FAMILY.get(row["protocol"])
    fields: dict[str, Any] = {}
    prefix = f"{family}_"
    for column, value in row.items():
        if family is None or not column.startswith(prefix) or value is None:
            continue
        key = column.removeprefix(prefix)
        if family == "serial" and key.startswith("probable_"):
            fields.setdefault("probable", {})[key.removeprefix("probable_")] = value
        else:
            fields[key] = value
    values = {name: row[name] for name in REGISTER_NAMES if row[name] is not None}
    single_write = "name" in fields and "value" in fields
    if values and not single_write:
        fields["values"] = values
    for key, value in json.loads(row["other_fields"] or "{}").items():
        if key == "values" and isinstance(value, dict) and "values" in fields:
            fields["values"].update(value)
        else:
            fields[key] = value
    return fields


def comparable(record: dict[str, Any]) -> dict[str, Any]:
    """A JSONL record as its row can give it back: a null field and an empty ``values`` have
    no cell."""
    fields = {k: v for k, v in record["fields"].items() if v is not None and v != {}}
    return {**record, "fields": fields}


def assert_rows_are_records(table: pa.Table, jsonl: bytes) -> None:
    """Row i of the table is record i of the JSONL (events have no rows), nothing lost."""
    records = [orjson.loads(line) for line in jsonl.splitlines()]
    records = [r for r in records if r.get("kind") != "event"]
    rows = table.to_pylist()
    assert len(rows) == len(records)
    for row, record in zip(rows, records, strict=True):
        rebuilt = {name: row[name] for name, _, _ in RECORD_COLUMNS}
        rebuilt["fields"] = fields_from_row(row)
        assert rebuilt == comparable(record), record["summary"]
        for name in MM_NAMES:  # the millimetre twins
            want = None if row[name] is None else opening_mm(row[name])
            assert row[f"{name}_mm"] == want
        if "value" in record["fields"] and record["fields"].get("name") in REGISTER_NAMES:
            assert row[record["fields"]["name"]] == record["fields"]["value"]


def write_read(jsonl: bytes, tmp_path: Path, pieces: int = 1) -> pa.Table:
    """JSONL through write_jsonl_batches in ``pieces`` random pieces, read back."""
    cuts = sorted(random.Random(pieces).sample(range(len(jsonl)), pieces - 1)) if pieces > 1 else []
    parts = [jsonl[i:j] for i, j in zip([0, *cuts], [*cuts, len(jsonl)], strict=True)]
    path = tmp_path / "records.parquet"
    rows = P.write_jsonl_batches(parts, str(path))
    table = pq.read_table(path)
    assert rows == table.num_rows
    return table


# -- streams that reach every field of every decoder ----------------------------------------------


def serial_stream() -> bytes:
    s = b.serial_frame
    frames = [bytes.fromhex(e[k]) for e in load("eg2_serial") for k in ("request", "response")]
    frames += [bytes.fromhex(e["bytes"]) for e in load("eg2_serial_bad")]
    frames += [
        s(1, Cmd.PARA_ID_SET, b"\x05\x00"),  # 2-byte new ID
        s(255, Cmd.PARA_ID_SET, b"\x00"),  # broadcast, out of range
        s(1, Cmd.MOVE_CATCH_XG, b"\x01\x00", response=True),  # malformed status
        s(1, Cmd.MOVE_RELEASE, b"\x55", response=True),  # write failure
        s(1, Cmd.MOVE_RELEASE, b"\x07", response=True),  # unknown status
        s(2, Cmd.READ_EG_RUNSTATE, bytes((6, 0x21, 40)) + b.u16le(1200, 20), response=True),
        s(2, Cmd.READ_EG_STATE, b.u16le(500, 80, 100), response=True),  # probable
        s(2, Cmd.READ_EG_STATE, b"\x01\x02", response=True),
        s(2, Cmd.SET_DRVALL_SPEED, b.u16le(1, 2) + b"\x03"),  # hand values with an extra byte
        s(2, Cmd.SET_DRVALL_SPEED, b"\x01", response=True),
        s(2, Cmd.SEEKPOS, b"\x01\x02\x03"),  # alias, mismatch with values
        s(2, Cmd.READ_ACTPOS, b.u16le(700), response=True),
        s(3, 0x77, b"\x01\x02"),  # unknown command
        s(0, Cmd.MOVE_STOPHERE),  # ID 0
        b"\x00\x13\x37",  # garbage
        s(1, Cmd.READ_EG_PARA)[:-2],  # truncated at the end
    ]
    return b"".join(frames)


def modbus_stream() -> bytes:
    frames = [bytes.fromhex(e["wire"]) for e in load("modbus_rtu")]
    frames += [
        b.modbus_read_request(1, 1061, 5),
        b.modbus_read_response(1, [700, 0xFFFE, 40, 0, 4]),
        b.modbus_write_single(1, 1010, 500),
        b.modbus_write_single(1, 1010, 500),
        b.modbus_write_single(1, 11, 300),  # short numbering
        b.modbus_write_single(1, 11, 300),
        b.modbus_write_multiple(2, 1010, [100, 200, 300]),
        b.modbus_write_multiple_response(2, 1010, 3),
        b.modbus_write_multiple(2, 1016, [900, 100]),
        b.modbus_write_multiple_response(2, 1016, 2),
        b.modbus_read_request(1, 1008, 1),  # undocumented
        b.modbus_exception(1, 3, 2),
        b.modbus_read_request(1, 2000, 3),  # outside the map: other_fields
        b.modbus_read_response(1, [1, 2, 3]),
        b.modbus_read_response(3, [9, 9]),  # no request: values_raw
        b.with_crc(bytes((1, 1, 0, 0, 0, 10))),  # read coils
        b.with_crc(bytes((1, 1, 2, 0b101, 0b11))),
        b.with_crc(bytes((1, 5, 0, 3, 0xFF, 0))),  # write coil
        b.with_crc(bytes((1, 5, 0, 3, 0xFF, 0))),
        b.with_crc(bytes((1, 15, 0, 0, 0, 4, 1, 0b1010))),  # write coils
        b.modbus_exception(1, 6, 9),  # unknown exception code
        b.modbus_read_request(1, 1061, 4)[:-3],  # truncated
    ]
    return b"".join(frames)


def can_frames() -> list[CanFrame]:
    frames = []
    for e in load("eg2_can"):
        frames.append(CanFrame(None, int(e["id"], 16), bytes.fromhex(e["data"])))
        r = e.get("response")
        if r:
            frames.append(CanFrame(None, int(r["id"], 16), bytes.fromhex(r["data"])))
    frames += [
        b.can_read_request(1, 1120, 8),
        b.can_read_response(1, 1120, b.u16le(100, 500, 0xFFF0, 37)),
        b.can_read_request(1, 1128, 4, padded=True),
        b.can_read_response(1, 1128, b.u16le(3, 6)),
        b.can_read_request(1, 1121, 3),  # odd span: partial bytes
        b.can_read_response(1, 1121, b"\x01\x02\x03"),
        b.can_write_request(16383, 1020, b.u16le(500)),  # broadcast
        b.can_write_request(2, 1020, b.u16le(10, 20, 30)),
        b.can_write_response(2, 1020, 6, padded=True),
        b.can_read_request(1, 1200, 2),  # outside the map: other_fields
        b.can_read_response(1, 1200, b.u16le(7)),
        CanFrame(None, b.can_id(2, 1020, 1), b"\x01\x02"),  # positioning move
        CanFrame(None, 0x123, b"\x01\x02\x03", is_extended=False),
        CanFrame(None, 0x18FF50E5, b"\x01"),  # reserved bit: foreign
        CanFrame(None, 0x123, b"", is_extended=False, is_remote=True, dlc=2),
        CanFrame(None, 0x4, b"\x00" * 8, is_error=True),
        CanFrame(None, 0x123, bytes(12), is_fd=True),
        CanFrame(None, b.can_id(0, 1120, 1), b""),  # no data
    ]
    return [CanFrame(1_763_700_000.0 + i / 1000, *_rest(f)) for i, f in enumerate(frames)]


def _rest(f: CanFrame) -> tuple[Any, ...]:
    return (f.arbitration_id, f.data, f.is_extended, f.is_remote, f.is_error, f.is_fd, f.dlc)


def decoded_jsonl(items: list[Item], protocol: str | None = None) -> bytes:
    """The Python engine's JSONL of items (Decoding with pairing and lint)."""
    records = list(Decoding(protocol=protocol, positional_seq=True).feed_many(items))
    return RecordSequence(records).jsonl()


def byte_items(data: bytes, bus: str = "serial") -> list[Item]:
    return [Item(bus, Chunk(data))]


def all_streams_jsonl() -> dict[str, bytes]:
    return {
        "serial": decoded_jsonl(byte_items(serial_stream()), EG2_SERIAL),
        "modbus": decoded_jsonl(byte_items(modbus_stream()), MODBUS_RTU),
        "can": decoded_jsonl([Item("can0", f) for f in can_frames()]),
    }


STREAMS = all_streams_jsonl()


# -- exact and complete --------------------------------------------------------------------------


@pytest.mark.parametrize("name", sorted(STREAMS))
@pytest.mark.parametrize("pieces", [1, 7, 300])
def test_every_record_comes_back_from_its_row(name: str, pieces: int, tmp_path: Path) -> None:
    jsonl = STREAMS[name]
    table = write_read(jsonl, tmp_path, pieces)
    assert_rows_are_records(table, jsonl)


def test_the_streams_reach_every_column(tmp_path: Path) -> None:
    """No column is dead: the decoders fill each one (so each is tested above)."""
    filled: set[str] = set()
    for jsonl in STREAMS.values():
        table = write_read(jsonl, tmp_path)
        filled |= {c for c in table.column_names if table.column(c).null_count < len(table)}
    never = {"can_eg2_device"}  # only with a decoder's device filter
    never |= {"CMD_SAVE", "CMD_SETDEFAULT", "CMD_ID", "CMD_BAUD", "CMD_CATCH_MOD", "CMD_STOP"}
    never |= {"CMD_FAULTACK"}  # registers the streams do not write
    assert set(SCHEMA.names) - filled == never


def test_only_what_no_column_holds_is_in_other_fields(tmp_path: Path) -> None:
    rows = []
    for jsonl in STREAMS.values():
        rows += write_read(jsonl, tmp_path).to_pylist()
    other = [json.loads(r["other_fields"]) for r in rows if r["other_fields"]]
    assert other == [
        {"values": {"REG_2000": 1, "REG_2001": 2, "REG_2002": 3}},  # Modbus outside the map
        {"values": {"ADDR_1200": 7}},  # CAN outside the map
    ]


@pytest.mark.parametrize(
    ("column", "type_", "unit"),
    [
        ("t", pa.float64(), b"s"),
        ("latency_ms", pa.float64(), b"ms"),
        ("seq", pa.int64(), None),
        ("flags", pa.list_(pa.string()), None),
        ("CMD_OPENLEN_ACT", pa.int64(), b"1/1000 of the stroke"),
        ("CMD_OPENLEN_ACT_mm", pa.float64(), b"mm"),
        ("CMD_FORCE_SET", pa.int64(), b"g"),
        ("CMD_TEMP", pa.int64(), "°C".encode()),
        ("CMD_CURRENT", pa.int64(), None),
        ("serial_force_g", pa.int64(), b"g"),
        ("serial_position_mm", pa.float64(), b"mm"),
        ("serial_temperature_c", pa.int64(), "°C".encode()),
        ("serial_fault_text", pa.list_(pa.string()), None),
        ("serial_values", pa.list_(pa.int64()), None),
        ("modbus_bits", pa.list_(pa.int64()), None),
        ("can_padded", pa.bool_(), None),
        ("other_fields", pa.string(), None),
    ],
)
def test_columns_are_typed_with_units(column: str, type_: pa.DataType, unit: bytes | None) -> None:
    for jsonl in STREAMS.values():
        sink = pa.BufferOutputStream()
        P.write_jsonl_batches([jsonl], sink)
        field = pq.read_schema(pa.BufferReader(sink.getvalue())).field(column)
        assert field.type == type_
        assert (field.metadata or {}).get(b"unit") == unit


def test_every_capture_gets_the_same_columns(tmp_path: Path) -> None:
    schemas = []
    for jsonl in [*STREAMS.values(), b""]:
        schemas.append(write_read(jsonl, tmp_path).schema)
    for schema in schemas:  # (a list's item is named "element" in Parquet: not compared)
        assert schema.equals(SCHEMA) and schema.metadata == SCHEMA.metadata
        assert [f.metadata for f in schema] == [f.metadata for f in SCHEMA]


def test_the_record_columns_are_the_jsonl_keys() -> None:
    keys = [k for k in orjson.loads(STREAMS["can"].splitlines()[0]) if k != "fields"]
    assert [name for name, _, _ in RECORD_COLUMNS] == keys == SCHEMA.names[: len(keys)]


def test_the_register_description_is_in_the_metadata() -> None:
    meta = SCHEMA.field("CMD_OPENLEN_SET").metadata
    assert meta[b"description"] == b"1010 target_opening: target"


def test_the_contract_names_every_field_column() -> None:
    """docs/contracts.md lists the family columns as SCHEMA has them, in order."""
    text = (ROOT / "docs" / "contracts.md").read_text(encoding="utf-8")
    parquet = text[text.index("## Parquet") : text.index("## MCAP recordings")]
    rows = re.findall(r"^\| (serial|modbus|can) \| (.*) \|$", parquet, re.MULTILINE)
    documented = [c for _, cells in rows for c in re.findall(r"`([^`]+)`", cells)]
    field_columns = [f.name for f in SCHEMA if f.name.split("_")[0] in ("serial", "modbus", "can")]
    assert documented == field_columns
    for name in MM_NAMES:
        assert f"`{name}`" in parquet


# -- JSONL the fast path does not fit ---------------------------------------------------------


def test_several_families_in_one_batch(tmp_path: Path) -> None:
    """A recording of several buses: serial, Modbus and CAN records interleaved."""
    lines = [s.splitlines() for s in STREAMS.values()]
    mixed = [line for group in zip(*lines, strict=False) for line in group]
    jsonl = b"\n".join(mixed) + b"\n"
    assert_rows_are_records(write_read(jsonl, tmp_path), jsonl)


def test_source_events_have_no_rows(tmp_path: Path) -> None:
    event = SourceEvent(1.0, "can0", "lost", "lost can0")
    first, rest = STREAMS["can"].split(b"\n", 1)
    jsonl = first + b"\n" + orjson.dumps(event.to_dict()) + b"\n" + rest
    table = write_read(jsonl, tmp_path)
    assert_rows_are_records(table, jsonl)
    assert table.num_rows == STREAMS["can"].count(b"\n")


@pytest.mark.parametrize(
    ("fields", "other"),
    [
        ({"slave": 1, "function": 3, "new_key": [1, 2]}, {"new_key": [1, 2]}),
        ({"slave": 1.5, "function": 3}, {"slave": 1.5}),  # not an integer: kept as it is
        ({"slave": 1 << 63}, {"slave": 1 << 63}),  # beyond int64
        ({"slave": True}, {"slave": True}),
        ({"registers": ["A", 1]}, {"registers": ["A", 1]}),
        ({"values": {"CMD_TEMP": 30, "CMD_X": 1}}, {"values": {"CMD_X": 1}}),
        ({"values": {"CMD_TEMP": "hot"}}, {"values": {"CMD_TEMP": "hot"}}),
        ({"values": [1, 2]}, {"values": [1, 2]}),
    ],
)
def test_a_value_no_column_fits_goes_to_other_fields(
    fields: dict[str, Any], other: dict[str, Any], tmp_path: Path
) -> None:
    record = orjson.loads(STREAMS["modbus"].splitlines()[0])
    record["fields"] = fields
    jsonl = STREAMS["modbus"] + orjson.dumps(record) + b"\n"
    rows = write_read(jsonl, tmp_path).to_pylist()
    assert json.loads(rows[-1]["other_fields"]) == other
    assert_rows_are_records(write_read(jsonl, tmp_path), jsonl)


def test_a_protocol_without_columns_keeps_its_fields_as_json(tmp_path: Path) -> None:
    record = orjson.loads(STREAMS["can"].splitlines()[0])
    record.update(protocol="plug-in", fields={"x": 1, "y": {"z": [1.5]}})
    table = write_read(orjson.dumps(record) + b"\n", tmp_path)
    assert json.loads(table.column("other_fields")[0].as_py()) == {"x": 1, "y": {"z": [1.5]}}


def test_a_protocol_without_columns_among_a_family_with_its_keys(tmp_path: Path) -> None:
    """Fields that look like CAN's, of a protocol that has no columns: kept as JSON."""
    record = orjson.loads(STREAMS["can"].splitlines()[0])
    record.update(protocol="plug-in")
    jsonl = STREAMS["can"] + orjson.dumps(record) + b"\n"
    rows = write_read(jsonl, tmp_path).to_pylist()
    assert json.loads(rows[-1]["other_fields"]) == record["fields"]
    assert rows[-1]["can_op"] is None


def test_the_fast_and_the_line_by_line_paths_agree() -> None:
    for jsonl in STREAMS.values():
        fast = P.jsonl_to_table(jsonl)
        exact = P.pj.read_json(pa.BufferReader(P._line_by_line(jsonl)), P._READ, P._PARSE)
        slow = P.flatten(P._leaves(exact), exact.num_rows)
        assert fast.equals(slow, check_metadata=True)


@given(
    st.lists(
        st.one_of(
            st.sampled_from(
                [b.serial_frame(1, Cmd.READ_EG_RUNSTATE), b.serial_frame(1, Cmd.READ_ACTPOS)]
            ),
            st.builds(
                lambda d, p: b.serial_frame(1, Cmd.READ_EG_RUNSTATE, d, response=True)[:p],
                st.binary(min_size=7, max_size=7),
                st.integers(1, 13),
            ),
            st.builds(b.modbus_read_response, st.integers(0, 3), st.lists(st.integers(0, 65535))),
            st.binary(max_size=20),
        ),
        max_size=30,
    ),
    st.sampled_from([EG2_SERIAL, MODBUS_RTU]),
)
def test_streams_with_garbage_and_truncation_come_back_exactly(
    parts: list[bytes], protocol: str
) -> None:
    jsonl = decoded_jsonl(byte_items(b"".join(parts)), protocol)
    sink = pa.BufferOutputStream()
    P.write_jsonl_batches([jsonl], sink)
    assert_rows_are_records(pq.read_table(pa.BufferReader(sink.getvalue())), jsonl)


# -- streaming --------------------------------------------------------------------------------


def test_row_groups_are_written_as_they_fill(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    monkeypatch.setattr(P, "ROW_GROUP_ROWS", 16)
    monkeypatch.setattr(P, "PARSE_BYTES", 2000)
    jsonl = STREAMS["can"] * 3
    path = tmp_path / "r.parquet"
    writer = P.ParquetRecordWriter(str(path))
    held = []
    for line in jsonl.splitlines(keepends=True):
        writer.write_jsonl(line)
        held.append(writer.groups.table_rows)
    written_before_close = writer.rows
    writer.close()
    meta = pq.ParquetFile(path).metadata
    sizes = [meta.row_group(i).num_rows for i in range(meta.num_row_groups)]
    assert sizes[:-1] == [16] * (len(sizes) - 1) and 0 < sizes[-1] <= 16
    assert sum(sizes) == jsonl.count(b"\n")
    assert written_before_close >= sum(sizes) - 16 - jsonl[:2000].count(b"\n")
    assert max(held) < 16  # never more than a row group waits
    assert_rows_are_records(pq.read_table(path), jsonl)


def test_a_listener_whose_output_failed_writes_nothing_more(tmp_path: Path) -> None:
    """Detached by the session after an error, then collected after its file was closed: no
    footer written to the closed file, no "Exception ignored" on stderr."""
    script = (
        "import gc, sys\n"
        "from analyzer.parquet.writer import ParquetListener\n"
        f"f = open({str(tmp_path / 'x.parquet')!r}, 'wb')\n"
        "listener = ParquetListener(f)\n"
        "listener.on_error(OSError(28, 'No space left on device'))\n"
        "f.close()\n"
        "del listener\n"
        "gc.collect()\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, env=ENV, cwd=ROOT, timeout=60
    )
    assert done.returncode == 0 and done.stderr == b""


def test_records_already_in_arrow_skip_json(tmp_path: Path) -> None:
    """write_parsed: a producer that builds Arrow (in PARSE_SCHEMA's layout) gets the same file."""
    for jsonl in STREAMS.values():
        parsed = P.pj.read_json(pa.BufferReader(P._line_by_line(jsonl)), P._READ, P._PARSE)
        path = tmp_path / "parsed.parquet"
        writer = P.ParquetRecordWriter(str(path))
        for i in range(0, parsed.num_rows, 7):
            writer.write_parsed(parsed.slice(i, 7))
        writer.close()
        assert pq.read_table(path).equals(write_read(jsonl, tmp_path))


def test_arrow_with_a_value_no_column_holds_is_refused(tmp_path: Path) -> None:
    writer = P.ParquetRecordWriter(str(tmp_path / "r.parquet"))
    with pytest.raises(ValueError, match=r"no column holds fields_can\.colour"):
        writer.write_parsed(pa.table({"fields_can": [{"colour": "red"}]}))


def test_no_records_make_an_empty_file_with_the_columns(tmp_path: Path) -> None:
    table = write_read(b"", tmp_path)
    assert table.num_rows == 0 and table.schema.equals(SCHEMA)


# -- the command line -------------------------------------------------------------------------


def eg2scope(*args: str, **kw: Any) -> subprocess.CompletedProcess[bytes]:
    return subprocess.run(
        [sys.executable, "-m", "analyzer", *args],
        capture_output=True,
        timeout=60,
        env=ENV,
        cwd=ROOT,
        **kw,
    )


@pytest.mark.parametrize(
    "capture", ["serial_session.bin", "modbus_session.bin", "can_pick_place.log"]
)
def test_decode_format_parquet_holds_the_jsonl_records(capture: str, tmp_path: Path) -> None:
    out = tmp_path / "records.parquet"
    path = str(CAPTURES / capture)
    jsonl = eg2scope("decode", path, "--format", "jsonl", "--engine", "python")
    done = eg2scope("decode", path, "--format", "parquet", "-o", str(out), "--engine", "python")
    assert done.returncode == jsonl.returncode, done.stderr
    assert done.stdout == b""
    assert_rows_are_records(pq.read_table(out), jsonl.stdout)


def test_parquet_to_a_pipe(tmp_path: Path) -> None:
    done = eg2scope("decode", str(CAPTURES / "can_pick_place.log"), "-f", "parquet")
    table = pq.read_table(pa.BufferReader(done.stdout))
    assert table.num_rows == 91 and table.schema.equals(SCHEMA)


def test_parquet_refuses_a_terminal() -> None:
    command = [sys.executable, "-m", "analyzer", "decode", "captures/can_pick_place.log"]
    leader, follower = pty.openpty()
    try:
        done = subprocess.run(
            [*command, "-f", "parquet"],
            stdout=follower,
            stderr=subprocess.PIPE,
            timeout=60,
            env=ENV,
            cwd=ROOT,
        )
        os.set_blocking(leader, False)
        try:
            shown = os.read(leader, 1 << 16)
        except BlockingIOError:  # nothing on the terminal
            shown = b""
    finally:
        os.close(follower)
        os.close(leader)
    assert done.returncode == 2
    assert b"--format parquet writes a binary file, not to a terminal: give -o FILE.parquet" in (
        done.stderr
    )
    assert shown == b""


def test_a_damaged_capture_keeps_every_record_before_the_damage(tmp_path: Path) -> None:
    data = gzip.compress(serial_stream())
    damaged = tmp_path / "cut.bin.gz"
    damaged.write_bytes(data[: len(data) * 2 // 3])
    out = tmp_path / "cut.parquet"
    args = ["decode", str(damaged), "-p", "serial", "--engine", "python"]
    jsonl = eg2scope(*args, "-f", "jsonl")
    done = eg2scope(*args, "-f", "parquet", "-o", str(out))
    assert done.returncode == jsonl.returncode == 3
    assert b"the compressed file is cut short after" in done.stderr
    assert_rows_are_records(pq.read_table(out), jsonl.stdout)


# -- other readers ------------------------------------------------------------------------------


def test_pandas_reads_it(tmp_path: Path) -> None:
    pd = pytest.importorskip("pandas")
    path = tmp_path / "r.parquet"
    P.write_jsonl_batches([STREAMS["can"]], str(path))
    df = pd.read_parquet(path)
    moving = df[df["CMD_OPENLEN_ACT"].notna()]
    assert list(moving["CMD_OPENLEN_ACT_mm"]) == [opening_mm(v) for v in moving["CMD_OPENLEN_ACT"]]


def test_duckdb_reads_it(tmp_path: Path) -> None:
    duckdb = pytest.importorskip("duckdb")
    path = tmp_path / "r.parquet"
    P.write_jsonl_batches([STREAMS["modbus"]], str(path))
    rows = duckdb.sql(f"SELECT count(*) FROM '{path}' WHERE CMD_OPENLEN_SET = 500").fetchall()
    assert rows == [(2,)]


def test_polars_reads_it(tmp_path: Path) -> None:
    pl = pytest.importorskip("polars")
    path = tmp_path / "r.parquet"
    P.write_jsonl_batches([STREAMS["serial"]], str(path))
    assert pl.read_parquet(path).height == STREAMS["serial"].count(b"\n")
