"""The Modbus RTU decoder: the manual's frames (both CRC byte orders), the field evidence of
section 4 (short register numbers), a pymodbus-style decode table, and the framing guarantees:
frames found from the bytes alone, every byte accounted for, the same records however the bytes
arrive (whole, in chunks, one at a time, with or without timing)."""

from __future__ import annotations

import ast
import inspect
import json
import random
from typing import Any

import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st
from protocol_vectors import VECTORS_PATH, params
from pymodbus.framer import FramerRTU
from pymodbus.pdu import DecodePDU, ExceptionResponse, ModbusPDU
from pymodbus.pdu import bit_message as bm
from pymodbus.pdu import register_message as rm

from decoders import build as b
from decoders import flags as F
from decoders import messages as M
from decoders import modbus_framing, modbus_pdu, modbus_registers, modbus_rtu
from decoders.build import with_crc
from decoders.framing import NEED_MORE
from decoders.modbus_framing import (
    CRC_BAD,
    CRC_OK,
    CRC_SWAPPED_ORDER,
    KIND,
    candidates,
    crc_state,
)
from decoders.modbus_rtu import ModbusRtuDecoder
from decoders.model import FRAME, GARBAGE, MODBUS_RTU, REQUEST, RESPONSE, TRUNCATED, Chunk, Record

CRC_SWAPPED = M.MODBUS_CRC_SWAPPED.text()
NO_REQUEST = M.MODBUS_NO_REQUEST.text()


def h(text: str) -> bytes:
    return bytes.fromhex(text)


# -- frame builders --------------------------------------------------------------------------


def swap_crc(frame: bytes) -> bytes:
    return frame[:-2] + frame[-1:] + frame[-2:-1]


rd = b.modbus_read_request
rd_resp = b.modbus_read_response
wr = b.modbus_write_single
wrm = b.modbus_write_multiple
wrm_resp = b.modbus_write_multiple_response
exc = b.modbus_exception


_framer = FramerRTU(DecodePDU(False))


def pm(pdu: ModbusPDU) -> bytes:
    """A frame as pymodbus builds it: an independent encoder to check the decoder against."""
    return bytes(_framer.buildFrame(pdu))


def pm_exc(slave: int, fc: int, code: int) -> bytes:
    return pm(ExceptionResponse(fc, code, device_id=slave))


# -- feeding ---------------------------------------------------------------------------------


def decode(
    data: bytes,
    sizes: list[int] | None = None,
    times: list[float] | None = None,
    hints: list[str | None] | None = None,
    bus: str = "rs485",
) -> list[Record]:
    """Feed data in chunks of the given sizes (cycled; whole when None), optionally with a
    timestamp and a direction per chunk, then finish."""
    dec = ModbusRtuDecoder(bus)
    out: list[Record] = []
    if sizes is None:
        sizes = [max(1, len(data))]
    i = k = 0
    while i < len(data):
        n = sizes[k % len(sizes)]
        t = times[k] if times is not None else None
        d = hints[k] if hints is not None else None
        out += dec.feed(Chunk(data[i : i + n], t, d))
        i += n
        k += 1
    out += dec.finish()
    assert_accounting(out, data)
    return out


def frames_fed(frames: list[bytes], hints: list[str | None]) -> list[Record]:
    """One chunk per frame, each with the direction the source knows."""
    return decode(b"".join(frames), sizes=[len(f) for f in frames], hints=hints)


def one(data: bytes) -> Record:
    records = decode(data)
    assert len(records) == 1, [(r.kind, r.raw.hex()) for r in records]
    return records[0]


def last(*frames: bytes) -> Record:
    """The record of the last frame of a stream (earlier frames set up the bus state)."""
    records = decode(b"".join(frames))
    assert [r.length for r in records] == [len(f) for f in frames]
    return records[-1]


def assert_accounting(records: list[Record], data: bytes) -> None:
    """Every input byte in exactly one record, in order, and every record well formed."""
    pos = 0
    for r in records:
        assert r.offset == pos, (r.kind, r.offset, pos)
        assert r.length == len(r.raw) > 0
        assert data[pos : pos + r.length] == r.raw
        assert r.protocol == MODBUS_RTU
        assert r.kind in (FRAME, GARBAGE, TRUNCATED)
        assert (r.kind == FRAME and not r.errors) == r.ok
        if r.kind != FRAME:
            assert r.errors
        pos += r.length
    assert pos == len(data)
    assert_flags(records)


WORDLESS = frozenset({F.EXCEPTION_RESPONSE})  # said by the summary, not by a warning


def assert_flags(records: list[Record]) -> None:
    """Every error and warning has its code, each code at most once; no code without words
    but an exception response's."""
    for r in records:
        assert len(set(r.flags)) == len(r.flags), r.flags
        assert set(r.flags) <= F.ALL
        worded = set(r.flags) - WORDLESS
        assert bool(worded) == bool(r.errors or r.warnings), (r.flags, r.errors, r.warnings)
        assert len(worded) <= len(r.errors) + len(r.warnings)
        assert (F.EXCEPTION_RESPONSE in r.flags) == (r.name == "EXCEPTION")


def signature(records: list[Record]) -> list[tuple[Any, ...]]:
    return [
        (
            r.offset,
            r.length,
            r.kind,
            r.direction,
            r.device,
            r.code,
            r.name,
            json.dumps(r.fields, sort_keys=True),
            tuple(r.errors),
            tuple(r.warnings),
            r.summary,
            r.pair_key,
            r.expects_response,
            r.is_save,
            tuple(r.flags),
        )
        for r in records
    ]


def random_sizes(rng: random.Random, total: int) -> list[int]:
    sizes = []
    while total > 0:
        n = rng.choice((1, 2, 3, 5, 7, 8, 13, 64, 300))
        sizes.append(n)
        total -= n
    return sizes


# -- the manual's worked frames (section 2.3, vectors.json) ----------------------------------


def _vector_stream(form: str) -> tuple[list[dict[str, Any]], list[Record]]:
    entries = json.loads(VECTORS_PATH.read_text())["modbus_rtu"]
    return entries, decode(b"".join(h(e[form]) for e in entries))


@pytest.mark.parametrize(("index", "vector"), params("modbus_rtu", indexed=True))
def test_vector_wire_form(index: int, vector: dict[str, Any]) -> None:
    """Request then response in one stream, so read responses get their register names."""
    entries, records = _vector_stream("wire")
    assert len(records) == len(entries)
    r = records[index]
    assert r.kind == FRAME
    assert r.raw == h(vector["wire"])
    assert r.ok, r.errors
    assert r.warnings == []
    assert r.device == vector["fields"]["slave"]
    assert r.code == vector["fields"]["function"]
    for key, want in vector["fields"].items():
        assert r.fields[key] == want, key
    assert r.summary
    assert r.direction == (RESPONSE if vector["meaning"].startswith("its response") else REQUEST)


@pytest.mark.parametrize(("index", "vector"), params("modbus_rtu", indexed=True))
def test_vector_as_the_manual_prints_it(index: int, vector: dict[str, Any]) -> None:
    entries, records = _vector_stream("manual_prints")
    assert len(records) == len(entries)
    r = records[index]
    assert r.kind == FRAME
    assert r.raw == h(vector["manual_prints"])
    if index == 0:
        # 86 21 is wrong in either byte order
        assert r.errors == ["CRC error: expected 54 F2, got 86 21"]
        assert not r.ok
    else:
        assert r.ok, r.errors
        assert CRC_SWAPPED in r.warnings
    # the content decodes all the same (the read response is named from the request even
    # though that request's CRC failed, and says so)
    for key, want in vector["fields"].items():
        assert r.fields[key] == want, key


def test_vector_crc_error_alone() -> None:
    r = one(h("01 03 04 25 00 04 86 21"))
    assert r.kind == FRAME
    assert r.errors == ["CRC error: expected 54 F2, got 86 21"]
    assert r.fields["registers"] == ["CMD_OPENLEN_ACT", "CMD_CURRENT", "CMD_TEMP", "CMD_ERRORCODE"]


def test_manual_response_named_from_a_request_with_a_bad_crc() -> None:
    records = decode(h("01 03 04 25 00 04 86 21 01 03 08 00 00 FF FE 00 25 00 00 C7 B9"))
    assert [r.ok for r in records] == [False, True]
    assert records[1].fields["values"]["CMD_CURRENT"] == -2
    assert records[1].warnings == [CRC_SWAPPED, "registers named from a request with a CRC error"]


def test_vectors_agree_with_pymodbus() -> None:
    """pymodbus builds the same bytes as the 'wire' column."""
    wire = [
        pm(rm.ReadHoldingRegistersRequest(address=1061, count=4, dev_id=1)),
        pm(rm.ReadHoldingRegistersResponse(registers=[0, 0xFFFE, 37, 0], dev_id=1)),
        pm(rm.WriteSingleRegisterRequest(address=1010, registers=[0], dev_id=1)),
        pm(rm.WriteMultipleRegistersRequest(address=1010, registers=[0, 1000, 1000], dev_id=1)),
        pm(rm.WriteMultipleRegistersResponse(address=1010, count=3, dev_id=1)),
    ]
    entries = json.loads(VECTORS_PATH.read_text())["modbus_rtu"]
    assert wire == [h(e["wire"]) for e in entries]
    assert [r.ok for r in decode(b"".join(wire))] == [True] * 5


# -- section 4: what public clients send ----------------------------------------------------


@pytest.mark.parametrize("value", [3, 864])
def test_xarm_short_register_write(value: int) -> None:
    """UFACTORY's xArm SDK example: function 06 to register 0x000A, values 3 and 864."""
    frame = wr(1, 0x000A, value)
    assert frame == pm(rm.WriteSingleRegisterRequest(address=10, registers=[value], dev_id=1))
    r = one(frame)
    assert r.ok
    assert r.direction == REQUEST
    assert r.name == "CMD_OPENLEN_SET"
    assert r.fields == {
        "slave": 1,
        "function": 6,
        "register": 1010,
        "name": "CMD_OPENLEN_SET",
        "value": value,
        "numbering": "short",
        "address": 10,
    }
    assert len(r.warnings) == 1
    assert r.warnings[0].startswith("this host uses short register number: 10 means 1010")
    assert r.summary == f"write target_opening={value} ({value * 70 / 1000} mm)"
    # and its echo
    records = decode(frame + frame)
    assert [r.direction for r in records] == [REQUEST, RESPONSE]
    assert records[1].summary == "-> ok (echo)"
    assert records[1].fields["numbering"] == "short"
    # said once per device, not on every frame of a host that always does it
    assert records[0].warnings and not records[1].warnings


def test_short_register_read_61_to_65() -> None:
    records = decode(rd(1, 61, 5) + rd_resp(1, [497, 12, 36, 0, 1]))
    req, resp = records
    assert req.ok and resp.ok
    assert req.name == resp.name == "CMD_OPENLEN_ACT..CMD_STATUS"
    assert req.fields["start"] == 1061
    assert req.fields["address"] == 61
    assert req.fields["numbering"] == "short"
    assert req.fields["registers"] == [
        "CMD_OPENLEN_ACT",
        "CMD_CURRENT",
        "CMD_TEMP",
        "CMD_ERRORCODE",
        "CMD_STATUS",
    ]
    assert req.warnings == [
        "this host uses short register numbers: 61-65 mean 1061-1065 (the host leaves out the "
        "1000 offset, as some clients do)"
    ]
    assert resp.fields["numbering"] == "short" and not resp.warnings
    assert req.summary == "read 5 registers from 1061 (measured_opening..state)"
    assert resp.fields["values"] == {
        "CMD_OPENLEN_ACT": 497,
        "CMD_CURRENT": 12,
        "CMD_TEMP": 36,
        "CMD_ERRORCODE": 0,
        "CMD_STATUS": 1,
    }
    assert resp.fields["numbering"] == "short"
    assert resp.summary == (
        "-> measured_opening=497 (34.79 mm), current=12, temperature_c=36 °C, "
        "fault=0 (no fault), state=1 (fully open, idle)"
    )


@pytest.mark.parametrize(
    ("wire", "full", "name"),
    [
        (5, 1005, "CMD_CATCH_MOD"),
        (6, 1006, "CMD_STOP"),
        (7, 1007, "CMD_FAULTACK"),
        (11, 1011, "CMD_SPEED_SET"),
        (12, 1012, "CMD_FORCE_SET"),
        (61, 1061, "CMD_OPENLEN_ACT"),
        (65, 1065, "CMD_STATUS"),
        (8, 1008, "REG_1008"),
    ],
)
def test_short_numbers_resolve(wire: int, full: int, name: str) -> None:
    r = one(rd(1, wire, 1))
    assert r.name == name
    assert r.fields["start"] == full
    assert r.fields["numbering"] == "short"


# -- the decode table --------------------------------------------------------------------------

# (id, stream: setup frames then the frame checked, direction, code, name, fields subset,
#  summary, warnings (exact list), errors)
NOT_EG2 = "is not one the EG2 documents (3, 6 and 16)"
UNDOC_1008 = "undocumented register 1008 (not in the manual's map)"

# fmt: off
TABLE: list[tuple[str, list[bytes], str, int, str | None, dict[str, Any], str, list[str]]] = [
    ("read request", [rd(1, 1061, 4)], REQUEST, 3, "CMD_OPENLEN_ACT..CMD_ERRORCODE",
     {"start": 1061, "count": 4}, "read 4 registers from 1061 (measured_opening..fault)", []),
    ("read response", [rd(1, 1061, 4), rd_resp(1, [0, -2, 37, 0])], RESPONSE, 3,
     "CMD_OPENLEN_ACT..CMD_ERRORCODE", {"byte_count": 8, "start": 1061, "count": 4},
     "-> measured_opening=0 (0.0 mm), current=-2, temperature_c=37 °C, fault=0 (no fault)", []),
    ("read one register", [rd(2, 1065, 1)], REQUEST, 3, "CMD_STATUS",
     {"slave": 2, "registers": ["CMD_STATUS"]}, "read 1 register from 1065 (state)", []),
    ("one-register response", [rd(2, 1065, 1), rd_resp(2, [4])], RESPONSE, 3, "CMD_STATUS",
     {"values": {"CMD_STATUS": 4}}, "-> state=4 (closing)", []),
    ("fault bits", [rd(1, 1064, 2), rd_resp(1, [0x05, 3])], RESPONSE, 3,
     "CMD_ERRORCODE..CMD_STATUS", {"values": {"CMD_ERRORCODE": 5, "CMD_STATUS": 3}},
     "-> fault=5 (stall, over-current), state=3 (stopped, idle)", []),
    ("measured force", [rd(1, 1060, 1), rd_resp(1, [243])], RESPONSE, 3, "CMD_FORCE_ACT",
     {"values": {"CMD_FORCE_ACT": 243}}, "-> measured_force=243", []),
    ("response without request", [rd_resp(1, [0, -2, 37, 0])], RESPONSE, 3, None,
     {"values_raw": [0, 0xFFFE, 37, 0], "byte_count": 8},
     "-> 4 values (registers unknown): 0, 65534, 37, 0", [NO_REQUEST]),
    ("response count mismatch", [rd(1, 1061, 2), rd_resp(1, [1, 2, 3])], RESPONSE, 3, None,
     {"values_raw": [1, 2, 3]}, "-> 3 values (registers unknown): 1, 2, 3",
     ["read response with 3 registers for a request of 2: registers unknown"]),
    ("write single", [wr(1, 1010, 0)], REQUEST, 6, "CMD_OPENLEN_SET",
     {"register": 1010, "name": "CMD_OPENLEN_SET", "value": 0},
     "write target_opening=0 (0.0 mm)", []),
    ("write single echo", [wr(1, 1010, 500), wr(1, 1010, 500)], RESPONSE, 6,
     "CMD_OPENLEN_SET", {"register": 1010, "value": 500}, "-> ok (echo)", []),
    ("write force", [wr(1, 1012, 200)], REQUEST, 6, "CMD_FORCE_SET", {"value": 200},
     "write force=200 g", []),
    ("write speed out of range", [wr(1, 1011, 5000)], REQUEST, 6, "CMD_SPEED_SET",
     {"value": 5000}, "write speed=5000", ["speed out of range (10-1000): 5000"]),
    ("write multiple", [wrm(1, 1010, [0, 1000, 1000])], REQUEST, 16,
     "CMD_OPENLEN_SET..CMD_FORCE_SET", {"start": 1010, "count": 3, "byte_count": 6},
     "write 3 registers from 1010: target_opening=0 (0.0 mm), speed=1000, force=1000 g", []),
    ("write multiple response", [wrm(1, 1010, [0, 1000, 1000]), wrm_resp(1, 1010, 3)],
     RESPONSE, 16, "CMD_OPENLEN_SET..CMD_FORCE_SET", {"start": 1010, "count": 3},
     "-> wrote 3 registers from 1010", []),
    ("write multiple response mismatch", [wrm(1, 1010, [1, 2, 3]), wrm_resp(1, 1011, 3)],
     RESPONSE, 16, "CMD_SPEED_SET..REG_1013", {"start": 1011, "count": 3},
     "-> wrote 3 registers from 1011",
     ["the response (start 1011, count 3) does not match the request (start 1010, count 3)",
      "undocumented register 1013 (not in the manual's map)"]),
    ("exception", [rd(1, 1061, 4), pm_exc(1, 3, 2)], RESPONSE, 0x83, "EXCEPTION",
     {"function": 3, "exception_code": 2, "exception_text": "illegal data address"},
     "exception 2: illegal data address", []),
    ("exception without request", [exc(1, 6, 3)], RESPONSE, 0x86, "EXCEPTION",
     {"function": 6, "exception_code": 3, "exception_text": "illegal data value"},
     "exception 3: illegal data value", []),
    ("exception 1", [pm_exc(9, 16, 1)], RESPONSE, 0x90, "EXCEPTION",
     {"exception_text": "illegal function"}, "exception 1: illegal function", []),
    ("exception 4", [exc(9, 16, 4)], RESPONSE, 0x90, "EXCEPTION",
     {"exception_text": "server device failure"}, "exception 4: server device failure", []),
    ("exception unknown code", [exc(9, 3, 0x42)], RESPONSE, 0x83, "EXCEPTION",
     {"exception_code": 0x42}, "exception 66: unknown exception code 66",
     ["exception code 66 is not a standard Modbus exception"]),
    ("undocumented write", [wr(1, 1008, 7)], REQUEST, 6, "REG_1008",
     {"register": 1008, "name": "REG_1008", "value": 7}, "write reg_1008=7", [UNDOC_1008]),
    ("undocumented read", [rd(1, 1008, 1), rd_resp(1, [0xBEEF])], RESPONSE, 3, "REG_1008",
     {"values": {"REG_1008": 0xBEEF}}, "-> reg_1008=48879", [UNDOC_1008]),
    ("undocumented span", [rd(1, 1012, 6)], REQUEST, 3, "CMD_FORCE_SET..CMD_MIN_OPENLEN",
     {"registers": ["CMD_FORCE_SET", "REG_1013", "REG_1014", "REG_1015", "CMD_MAX_OPENLEN",
                    "CMD_MIN_OPENLEN"]},
     "read 6 registers from 1012 (force..min_opening)",
     ["undocumented registers 1013-1015 (not in the manual's map)"]),
    ("outside the map", [wr(1, 2000, 1)], REQUEST, 6, "REG_2000",
     {"register": 2000, "name": "REG_2000", "value": 1}, "write reg_2000=1",
     ["register 2000 is outside the EG2 register map"]),
    ("outside the map, span", [rd(1, 1064, 4)], REQUEST, 3, "CMD_ERRORCODE..REG_1067",
     {"registers": ["CMD_ERRORCODE", "CMD_STATUS", "REG_1066", "REG_1067"]},
     "read 4 registers from 1064 (fault..reg_1067)",
     ["registers 1066-1067 are outside the EG2 register map"]),
    ("register 0", [rd(1, 0, 1)], REQUEST, 3, "REG_0", {"start": 0},
     "read 1 register from 0 (reg_0)", ["register 0 is outside the EG2 register map"]),
    ("write read-only", [wr(1, 1061, 5)], REQUEST, 6, "CMD_OPENLEN_ACT", {"value": 5},
     "write measured_opening=5 (0.35 mm)",
     ["write to read-only register 1061 (CMD_OPENLEN_ACT)"]),
    ("write multiple read-only", [wrm(1, 1062, [1, 2])], REQUEST, 16,
     "CMD_CURRENT..CMD_TEMP", {"values": {"CMD_CURRENT": 1, "CMD_TEMP": 2}},
     "write 2 registers from 1062: current=1, temperature_c=2 °C",
     ["write to read-only registers 1062 (CMD_CURRENT), 1063 (CMD_TEMP)"]),
    ("signed current", [rd(1, 1062, 1), rd_resp(1, [0x8000])], RESPONSE, 3, "CMD_CURRENT",
     {"values": {"CMD_CURRENT": -32768}}, "-> current=-32768",
     ["current out of range (-2000-2000): -32768"]),
    ("temperature out of range", [rd(1, 1063, 1), rd_resp(1, [8704])], RESPONSE, 3,
     "CMD_TEMP", {"values": {"CMD_TEMP": 8704}}, "-> temperature_c=8704 °C",
     ["temperature_c out of range (0-100): 8704"]),
    ("read count 0", [rd(1, 1061, 0)], REQUEST, 3, None, {"count": 0, "registers": []},
     "read 0 registers from 1061", ["count 0 outside the Modbus limit of 1-125 registers"]),
    ("broadcast write", [wr(0, 1006, 1)], REQUEST, 6, "CMD_STOP", {"slave": 0, "value": 1},
     "write stop=1", []),
    ("read input registers",
     [pm(rm.ReadInputRegistersRequest(address=1061, count=1, dev_id=1)),
      pm(rm.ReadInputRegistersResponse(registers=[10], dev_id=1))], RESPONSE, 4,
     "CMD_OPENLEN_ACT", {"values": {"CMD_OPENLEN_ACT": 10}}, "-> measured_opening=10 (0.7 mm)",
     [f"function 4 (read input registers) {NOT_EG2}"]),
    ("read coils", [pm(bm.ReadCoilsRequest(address=0, count=10, dev_id=2))], REQUEST, 1,
     "READ_COILS", {"start": 0, "count": 10}, "read 10 coils from 0",
     [f"function 1 (read coils) {NOT_EG2}"]),
    ("read coils response",
     [pm(bm.ReadCoilsRequest(address=0, count=10, dev_id=2)),
      pm(bm.ReadCoilsResponse(bits=[True, False, True] + [False] * 7, dev_id=2))],
     RESPONSE, 1, "READ_COILS", {"bits": [1, 0, 1, 0, 0, 0, 0, 0, 0, 0]},
     "-> coils 1010000000", [f"function 1 (read coils) {NOT_EG2}"]),
    ("write coil", [pm(bm.WriteSingleCoilRequest(address=3, bits=[True], dev_id=2))], REQUEST,
     5, "WRITE_SINGLE_COIL", {"coil": 3, "value": 0xFF00}, "write coil 3 on",
     [f"function 5 (write single coil) {NOT_EG2}"]),
    ("write coils",
     [pm(bm.WriteMultipleCoilsRequest(address=3, bits=[True] * 10, dev_id=2))], REQUEST, 15,
     "WRITE_MULTIPLE_COILS", {"start": 3, "count": 10, "byte_count": 2},
     "write 10 coils from 3: 1111111111", [f"function 15 (write multiple coils) {NOT_EG2}"]),
]
# fmt: on


@pytest.mark.parametrize(
    ("stream", "direction", "code", "name", "fields", "summary", "warnings"),
    [pytest.param(*row[1:], id=row[0]) for row in TABLE],
)
def test_decode_table(
    stream: list[bytes],
    direction: str,
    code: int,
    name: str | None,
    fields: dict[str, Any],
    summary: str,
    warnings: list[str],
) -> None:
    r = last(*stream)
    assert r.kind == FRAME
    assert r.ok, r.errors
    assert r.direction == direction
    assert r.code == code
    assert r.device == stream[-1][0] == r.fields["slave"]
    assert r.fields["function"] == code & 0x7F
    assert r.name == name
    for key, want in fields.items():
        assert r.fields[key] == want, key
    assert r.summary == summary
    assert r.warnings == warnings
    json.dumps(r.to_dict())  # the JSONL contract holds


# (id, stream: setup frames then the frame checked, direction hints or None, its flags)
MANUAL_READ_BAD_CRC = h("01 03 04 25 00 04 86 21")
MANUAL_RESPONSE = h("01 03 08 00 00 FF FE 00 25 00 00 C7 B9")  # CRC high byte first
COIL_0x1234 = with_crc(h("02 05 00 03 12 34"))
# fmt: off
FLAGS: list[tuple[str, list[bytes], list[str | None] | None, list[str]]] = [
    ("read request", [rd(1, 1061, 4)], None, []),
    ("read response", [rd(1, 1061, 4), rd_resp(1, [0, 2, 37, 0])], None, []),
    ("swapped CRC", [swap_crc(wr(1, 1010, 0))], None, [F.SWAPPED_CRC]),
    ("bad CRC", [MANUAL_READ_BAD_CRC], None, [F.BAD_CHECKSUM]),
    ("named from a bad request", [MANUAL_READ_BAD_CRC, MANUAL_RESPONSE], None,
     [F.SWAPPED_CRC, F.UNTRUSTED_REQUEST]),
    ("read response alone", [rd_resp(1, [1, 2])], None, [F.ORPHAN_RESPONSE]),
    ("count mismatch", [rd(1, 1061, 2), rd_resp(1, [1, 2, 3])], None, [F.LENGTH_MISMATCH]),
    ("value out of range (fast path)", [rd(1, 1063, 1), rd_resp(1, [8704])], None,
     [F.OUT_OF_RANGE]),
    ("two values out of range: one code", [rd(1, 1062, 2), rd_resp(1, [0x8000, 8704])], None,
     [F.OUT_OF_RANGE]),
    ("write out of range", [wr(1, 1011, 5000)], None, [F.OUT_OF_RANGE]),
    ("write multiple out of range", [wrm(1, 1010, [2000, 5, 5])], None, [F.OUT_OF_RANGE]),
    ("read count 0", [rd(1, 1061, 0)], None, [F.OUT_OF_RANGE]),
    ("read count 126", [rd(1, 1001, 126)], None, [F.UNDOCUMENTED, F.OUT_OF_RANGE]),
    ("write to read-only", [wr(1, 1061, 5)], None, [F.READ_ONLY_WRITE]),
    ("undocumented register", [wr(1, 1008, 7)], None, [F.UNDOCUMENTED]),
    ("outside the map", [rd(1, 1064, 4)], None, [F.UNDOCUMENTED]),
    ("short numbers, first frame", [rd(1, 61, 5)], None, [F.SHORT_REGISTER_NUMBERS]),
    ("short numbers, later frames", [rd(1, 61, 5), rd_resp(1, [1, 2, 3, 4, 1])], None, []),
    ("short numbers, later frame out of range", [rd(1, 63, 1), rd_resp(1, [8704])], None,
     [F.OUT_OF_RANGE]),
    ("exception", [rd(1, 1061, 4), exc(1, 3, 2)], None, [F.EXCEPTION_RESPONSE]),
    ("exception, unknown code", [exc(9, 3, 0x42)], None,
     [F.EXCEPTION_RESPONSE, F.UNDOCUMENTED]),
    ("echo", [wr(1, 1010, 500), wr(1, 1010, 500)], None, []),
    ("echo differs", [wr(1, 1010, 500), wr(1, 1010, 501)], [REQUEST, RESPONSE],
     [F.RESPONSE_MISMATCH]),
    ("echo without request", [wr(1, 1010, 500)], [RESPONSE], [F.ORPHAN_RESPONSE]),
    ("write response without request", [wrm_resp(1, 1010, 3)], None, [F.ORPHAN_RESPONSE]),
    ("write response mismatch", [wrm(1, 1010, [1, 2, 3]), wrm_resp(1, 1011, 3)], None,
     [F.RESPONSE_MISMATCH, F.UNDOCUMENTED]),
    ("response from address 0", [rd_resp(0, [1])], None, [F.BROADCAST, F.ORPHAN_RESPONSE]),
    ("broadcast write", [wr(0, 1006, 1)], None, []),
    ("not an EG2 function", [pm(bm.ReadCoilsRequest(address=0, count=10, dev_id=2))], None,
     [F.UNDOCUMENTED]),
    ("coil value neither on nor off", [COIL_0x1234], None, [F.UNDOCUMENTED, F.OUT_OF_RANGE]),
]
# fmt: on


@pytest.mark.parametrize(
    ("stream", "hints", "flags"), [pytest.param(*row[1:], id=row[0]) for row in FLAGS]
)
def test_flags_table(stream: list[bytes], hints: list[str | None] | None, flags: list[str]) -> None:
    """Every error and warning text carries its code (issue 6); each code once per record."""
    per_byte = None if hints is None else [d for f, d in zip(stream, hints, strict=True) for _ in f]
    for sizes, chunk_hints in (([len(f) for f in stream], hints), ([1], per_byte)):
        records = decode(b"".join(stream), sizes, hints=chunk_hints)
        assert [r.length for r in records] == [len(f) for f in stream]
        r = records[-1]
        assert r.flags == flags, (r.errors, r.warnings)
        assert json.loads(json.dumps(r.to_dict()))["flags"] == flags


def test_exception_pairing_attributes() -> None:
    req, resp = decode(rd(7, 1061, 4) + exc(7, 3, 2))
    assert req.pair_key == (7, 3) and req.expects_response
    assert resp.pair_key == (7, 3) and not resp.expects_response
    assert resp.code == 0x83


@pytest.mark.parametrize(
    ("frame", "expects"),
    [
        (rd(1, 1061, 4), True),
        (wr(1, 1010, 1), True),
        (wrm(3, 1010, [1, 2, 3]), True),
        (wr(0, 1010, 1), False),
        (wrm(0, 1010, [1, 2, 3]), False),
    ],
)
def test_expects_response(frame: bytes, expects: bool) -> None:
    r = one(frame)
    assert r.direction == REQUEST
    assert r.pair_key == (frame[0], frame[1])
    assert r.expects_response is expects


def test_broadcast_sets_no_pending_request() -> None:
    """After a broadcast write nothing answers, so an identical write is a new request."""
    records = decode(wr(0, 1010, 5) + wr(0, 1010, 5))
    assert [r.direction for r in records] == [REQUEST, REQUEST]


@pytest.mark.parametrize(
    ("frames", "save"),
    [
        ([wr(1, 1001, 1)], True),
        ([wr(1, 1002, 1)], True),
        ([wr(1, 1001, 0)], False),
        ([wr(1, 1, 1)], True),
        ([wr(1, 2, 1)], True),
        ([wr(1, 1003, 1)], False),
        ([wrm(1, 1001, [1, 0])], True),
        ([wrm(1, 1001, [0, 1])], True),
        ([wrm(1, 1001, [0, 0, 1])], False),
        ([wr(1, 1001, 1), wr(1, 1001, 1)], False),
    ],
)
def test_is_save(frames: list[bytes], save: bool) -> None:
    """A write of 1 to 1001/1002 (or 1/2): the gripper pauses ~850 ms. Not the echo."""
    assert last(*frames).is_save is save


def test_write_echo_that_differs() -> None:
    """The source knows the direction: an echo with another value is flagged."""
    records = frames_fed([wr(1, 1010, 500), wr(1, 1010, 501)], [REQUEST, RESPONSE])
    assert records[1].direction == RESPONSE
    assert records[1].warnings == [
        "the echo differs from the request (address 1010 value 500, echo address 1010 value 501)"
    ]
    assert records[1].summary == "-> echo differs: target_opening=501 (35.07 mm)"


def test_write_single_direction_from_the_pending_request() -> None:
    same = wr(1, 1010, 500)
    other_value = wr(1, 1010, 501)
    other_register = wr(1, 1011, 500)
    other_slave = wr(2, 1010, 500)
    # no hint: an identical frame (or same slave, function and register) is the echo
    assert [r.direction for r in decode(same + same)] == [REQUEST, RESPONSE]
    assert [r.direction for r in decode(same + other_value)] == [REQUEST, RESPONSE]
    assert [r.direction for r in decode(same + other_register)] == [REQUEST, REQUEST]
    assert [r.direction for r in decode(same + other_slave)] == [REQUEST, REQUEST]
    # three in a row: request, echo, request
    assert [r.direction for r in decode(same * 3)] == [REQUEST, RESPONSE, REQUEST]
    # the hint wins where it is known
    hinted = frames_fed([same, same], [REQUEST, REQUEST])
    assert [r.direction for r in hinted] == [REQUEST, REQUEST]
    hinted = frames_fed([same], [RESPONSE])
    assert hinted[0].direction == RESPONSE
    assert hinted[0].warnings == ["write response without a known request"]
    assert hinted[0].summary == "-> echo target_opening=500 (35.0 mm)"


def test_same_response_bytes_named_by_their_request() -> None:
    """The memo is keyed by the pending request: the same bytes, other registers."""
    resp = rd_resp(1, [37])
    records = decode(rd(1, 1063, 1) + resp + rd(1, 1061, 1) + resp + resp)
    assert [r.name for r in records] == [
        "CMD_TEMP",
        "CMD_TEMP",
        "CMD_OPENLEN_ACT",
        "CMD_OPENLEN_ACT",
        None,
    ]
    assert records[1].summary == "-> temperature_c=37 °C"
    assert records[3].summary == "-> measured_opening=37 (2.59 mm)"
    assert records[4].warnings == [NO_REQUEST]


# -- retransmissions: a host resends the same request before the answer (issue 7 item 17) --------

POLL = pm(rm.ReadHoldingRegistersRequest(address=1061, count=2, dev_id=1))  # as pymodbus sends it
POLL_NAME = "CMD_OPENLEN_ACT..CMD_CURRENT"
SET = pm(rm.WriteMultipleRegistersRequest(address=1010, registers=[0, 500], dev_id=1))
SET_DONE = pm(rm.WriteMultipleRegistersResponse(address=1010, count=2, dev_id=1))

# (id, frames, what each response is named (None: not a response), the last response's
#  warnings)
RETRIES: list[tuple[str, list[bytes], list[str | None], list[str]]] = [
    (
        "two answers",
        [POLL, POLL, rd_resp(1, [10, 1]), rd_resp(1, [11, 1])],
        [None, None, POLL_NAME, POLL_NAME],
        [],
    ),
    (
        "three tries, three answers",
        [POLL, POLL, POLL, rd_resp(1, [10, 1]), rd_resp(1, [11, 1]), rd_resp(1, [12, 1])],
        [None, None, None, POLL_NAME, POLL_NAME, POLL_NAME],
        [],
    ),
    (
        "one answer, then the next poll",
        [POLL, POLL, rd_resp(1, [10, 1]), POLL, rd_resp(1, [11, 1])],
        [None, None, POLL_NAME, None, POLL_NAME],
        [],
    ),
    (
        "one answer, then other registers",
        [POLL, POLL, rd_resp(1, [10, 1]), rd(1, 1063, 1), rd_resp(1, [36])],
        [None, None, POLL_NAME, None, "CMD_TEMP"],
        [],
    ),
    (
        # the copy left unanswered is given up by the next request: no stale third answer
        "a stale copy is dropped",
        [POLL, POLL, rd_resp(1, [10, 1]), POLL, rd_resp(1, [11, 1]), rd_resp(1, [12, 1])],
        [None, None, POLL_NAME, None, POLL_NAME, None],
        [NO_REQUEST],
    ),
    (
        "more answers than tries",
        [POLL, POLL, rd_resp(1, [10, 1]), rd_resp(1, [11, 1]), rd_resp(1, [12, 1])],
        [None, None, POLL_NAME, POLL_NAME, None],
        [NO_REQUEST],
    ),
    (
        "write multiple",
        [SET, SET, SET_DONE, SET_DONE],
        [None, None, "CMD_OPENLEN_SET..CMD_SPEED_SET", "CMD_OPENLEN_SET..CMD_SPEED_SET"],
        [],
    ),
]


@pytest.mark.parametrize(
    ("frames", "names", "warnings"), [pytest.param(*row[1:], id=row[0]) for row in RETRIES]
)
def test_retransmitted_request_each_answer_decoded_against_its_request(
    frames: list[bytes], names: list[str | None], warnings: list[str]
) -> None:
    data = b"".join(frames)
    whole = decode(data)
    assert [r.length for r in whole] == [len(f) for f in frames]
    assert [r.name if r.direction == RESPONSE else None for r in whole] == names
    for r in whole:
        if r.direction == RESPONSE and r.name == POLL_NAME:
            assert set(r.fields["values"]) == {"CMD_OPENLEN_ACT", "CMD_CURRENT"}
    assert whole[-1].warnings == warnings
    assert all(not r.warnings for r in whole[:-1])
    # however the bytes arrive
    assert signature(decode(data, [1])) == signature(whole)
    assert signature(decode(data, [len(f) for f in frames])) == signature(whole)
    assert signature(decode(data, random_sizes(random.Random(2), len(data)))) == signature(whole)


def test_retransmitted_write_single_with_known_directions() -> None:
    """A write single and its echo are the same bytes: with the directions known (a tap on
    each wire), both echoes of a retried write answer it."""
    write = wr(1, 1010, 500)
    records = frames_fed([write] * 4, [REQUEST, REQUEST, RESPONSE, RESPONSE])
    assert [r.direction for r in records] == [REQUEST, REQUEST, RESPONSE, RESPONSE]
    assert [r.summary for r in records[2:]] == ["-> ok (echo)", "-> ok (echo)"]
    assert not any(r.warnings for r in records)


def test_outstanding_requests_are_counted() -> None:
    dec = ModbusRtuDecoder()
    dec.feed(Chunk(POLL + POLL, None, REQUEST))
    assert (dec.pending, dec.outstanding) == ((1, 3, 1061, 2, True), 2)
    dec.feed(Chunk(rd_resp(1, [10, 1]), None, RESPONSE))
    assert dec.outstanding == 1
    dec.feed(Chunk(rd_resp(1, [11, 1]), None, RESPONSE))
    assert (dec.pending, dec.outstanding) == (None, 0)


def test_records_do_not_share_lists() -> None:
    frame = swap_crc(wr(1, 1011, 5000))
    a, b = decode(frame + frame)[0], decode(frame + frame)[0]
    records = decode(frame + frame + frame)
    assert records[0].warnings == records[2].warnings
    assert records[0].warnings is not records[2].warnings
    assert records[0].errors is not records[2].errors
    records[0].warnings.append("added by the linter")
    records[0].flags.append(F.CLOSER_THAN_5MS)
    assert "added by the linter" not in records[2].warnings
    assert records[2].flags == [F.SWAPPED_CRC, F.OUT_OF_RANGE]
    assert a.warnings == b.warnings == [CRC_SWAPPED, "speed out of range (10-1000): 5000"]


def test_framing_and_meaning_are_separate_modules() -> None:
    """Framing (candidate lengths, CRC) knows nothing of what frames mean; the decoder class
    joins the two and stays importable from modbus_rtu."""

    def imports(module: Any) -> set[str]:
        tree = ast.parse(inspect.getsource(module))
        return {n.module or "" for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)}

    assert imports(modbus_framing).isdisjoint({"modbus_pdu", "modbus_registers", "modbus_rtu"})
    assert imports(modbus_registers).isdisjoint({"modbus_pdu", "modbus_rtu"})
    assert "modbus_rtu" not in imports(modbus_pdu)
    assert {"modbus_framing", "modbus_pdu"} <= imports(modbus_rtu)
    assert issubclass(ModbusRtuDecoder, modbus_framing.ModbusFramer)
    assert ModbusRtuDecoder.__module__ == "decoders.modbus_rtu"
    # frames are built in decoders.build only
    for name in ("with_crc", "crc_bytes"):
        for module in (modbus_rtu, modbus_framing, modbus_pdu, modbus_registers):
            assert not hasattr(module, name), (module.__name__, name)


def test_bus_name_and_defaults() -> None:
    assert ModbusRtuDecoder().bus == "rs485"
    assert ModbusRtuDecoder.protocol == MODBUS_RTU
    r = decode(rd(1, 1061, 1), bus="tty-a")[0]
    assert r.bus == "tty-a"
    assert r.to_dict()["raw"] == rd(1, 1061, 1).hex(" ").upper()


# -- CRC --------------------------------------------------------------------------------------


def test_crc_states() -> None:
    good = rd(1, 1061, 4)
    assert good == h("01 03 04 25 00 04 54 F2")
    assert crc_state(good, 0, 8) == CRC_OK
    assert crc_state(swap_crc(good), 0, 8) == CRC_SWAPPED_ORDER
    assert crc_state(h("01 03 04 25 00 04 86 21"), 0, 8) == CRC_BAD


def test_crc_error_in_data_states_expected_and_actual() -> None:
    good = wr(1, 1010, 0)
    bad = good[:5] + b"\x01" + good[6:]  # value 0 -> 1, CRC left alone
    r = one(bad)
    exp = with_crc(bad[:6])[6:]
    assert r.errors == [
        f"CRC error: expected {exp[0]:02X} {exp[1]:02X}, got {bad[6]:02X} {bad[7]:02X}"
    ]
    assert r.fields["value"] == 1  # the rest of the decode is kept


def test_crc_symmetric_bytes_are_not_flagged_as_swapped() -> None:
    """A CRC whose two bytes are equal reads the same either way round: no warning."""
    rng = random.Random(5)
    while True:
        frame = wr(1, 1010, rng.randint(0, 1000))
        if frame[-1] == frame[-2]:
            break
    assert one(frame).warnings == []


# -- framing ----------------------------------------------------------------------------------


def test_frame_at_results() -> None:
    dec = ModbusRtuDecoder()
    req = rd(1, 1061, 4)
    assert dec.frame_at(bytearray(req), 0, True) == 8
    # 01 03 04 ..: also a 9-byte response reading (byte count 4), one byte longer: it must be
    # checked before the request reading is taken (see test_crc_collisions_*)
    assert dec.frame_at(bytearray(req), 0, False) == NEED_MORE
    assert dec.frame_at(bytearray(req + b"\xff"), 0, False) == 8
    assert dec.frame_at(bytearray(rd(1, 1010, 4)), 0, False) == 8  # 03 F2: odd, no rival
    assert dec.frame_at(bytearray(req[:5]), 0, False) == NEED_MORE
    assert dec.frame_at(bytearray(req[:1]), 0, False) == NEED_MORE
    assert dec.frame_at(bytearray(b"\xff\x03"), 0, False) == 0  # 255 is never an address
    assert dec.frame_at(bytearray(b"\x01\x07\x00"), 0, False) == 0  # unknown function
    assert dec.frame_at(bytearray(b"\x01\x83"), 0, False) == NEED_MORE
    assert dec.frame_at(bytearray(exc(1, 3, 2)), 0, False) == 5
    assert dec.frame_at(bytearray(h("01 03 04 25 00 04 86 21")), 0, True) == -8
    # a bad CRC with nothing after it: undecided until the stream ends or more bytes come
    assert dec.frame_at(bytearray(h("01 03 04 25 00 04 86 21")), 0, False) == NEED_MORE
    bad_then_good = bytearray(h("01 03 04 25 00 04 86 21") + wr(1, 1010, 0))
    assert dec.frame_at(bad_then_good, 0, False) == -8
    bad_then_junk = bytearray(h("01 03 04 25 00 04 86 21 FF FF FF FF FF FF FF FF"))
    assert dec.frame_at(bad_then_junk, 0, False) == 0


@pytest.mark.parametrize("slave", [0, 1, 2, 127, 247, 248, 253, 254])
def test_every_gripper_address_frames(slave: int) -> None:
    """Modbus says 1-247; the gripper takes IDs up to 254."""
    records = decode(rd(slave, 1061, 5) + rd_resp(slave, [1, 2, 3, 4, 5]))
    assert [r.ok for r in records] == [True, True]
    assert records[1].device == slave


def test_ambiguity_request_read_as_request_although_a_response_is_expected() -> None:
    """A read of 0x02xx looks like a one-register response (02 = byte count) for 7 bytes; an
    unanswered request before it makes the decoder try the response shape first."""
    unanswered = rd(1, 1061, 1)
    req = rd(1, 0x0210, 1)  # 01 03 02 10 00 01 ..: as a response, 7 bytes with count 2
    dec = ModbusRtuDecoder()
    dec.feed(Chunk(unanswered))
    dec.finish()
    assert dec.pending is not None
    assert candidates(bytearray(req), 0, 8, KIND[3], True) == [7, 8]
    assert crc_state(req, 0, 7) == CRC_BAD  # the 7-byte reading fails its CRC
    records = decode(unanswered + req + rd_resp(1, [9]))
    assert [(r.length, r.direction, r.ok) for r in records] == [
        (8, REQUEST, True),
        (8, REQUEST, True),
        (7, RESPONSE, True),
    ]
    assert records[1].fields["start"] == 0x0210
    assert records[2].fields["values"] == {"REG_528": 9}
    # the same with the source saying "response" for every chunk
    hinted = frames_fed([req], [RESPONSE])
    assert (hinted[0].length, hinted[0].direction, hinted[0].ok) == (8, REQUEST, True)


def test_ambiguity_response_read_as_response_although_a_request_is_expected() -> None:
    """A one-register response (7 bytes) with no request seen: the 8-byte request shape is
    tried first (it takes the next frame's first byte) and the CRC picks 7."""
    resp = rd_resp(1, [1000])
    for after in (rd(1, 1061, 4), wr(1, 1010, 0), b""):
        records = decode(resp + after)
        assert records[0].length == 7
        assert records[0].direction == RESPONSE
        assert records[0].ok
        assert all(r.ok for r in records)
    hinted = frames_fed([resp, rd(1, 1061, 4)], [REQUEST, REQUEST])
    assert [(r.length, r.direction) for r in hinted] == [(7, RESPONSE), (8, REQUEST)]


def test_both_candidates_need_their_bytes() -> None:
    """A frame with a second reading close to it in length is not decided until that reading
    can be checked too (or the stream ends)."""
    dec = ModbusRtuDecoder()
    # nothing pending: the request shape first, but the 9-byte response reading is one byte
    # longer, and a good frame followed by 00 is a good frame one byte longer
    assert dec.feed(Chunk(rd(1, 1061, 4))) == []
    records = dec.feed(Chunk(b"\xff"))
    assert [(r.kind, r.length, r.direction) for r in records] == [(FRAME, 8, REQUEST)]
    # a response is now expected: the 9-byte reading is tried first, and it needs its bytes
    assert dec.feed(Chunk(rd(1, 1061, 4))) == []
    assert [r.length for r in dec.feed(Chunk(b"\xff"))] == [1, 8]  # the held FF, the frame
    assert [(r.kind, r.length) for r in dec.finish()] == [(GARBAGE, 1)]
    # the end of the stream decides
    dec = ModbusRtuDecoder()
    assert dec.feed(Chunk(rd(1, 1061, 4))) == []
    assert [r.length for r in dec.finish()] == [8]
    # a known direction decides at once
    dec = ModbusRtuDecoder()
    assert [r.length for r in dec.feed(Chunk(rd(1, 1061, 4), None, REQUEST))] == [8]
    # readings far apart in length need no waiting: 5 registers answer in 15 bytes
    dec = ModbusRtuDecoder()
    assert [r.length for r in dec.feed(Chunk(rd(1, 1061, 5) + rd_resp(1, [0] * 5)))] == [8, 15]


def _find(make: Any, good: Any) -> bytes:
    """The first frame make(i) for which good(frame) holds."""
    for i in range(100_000):
        frame = make(i)
        if good(frame):
            return bytes(frame)
    raise AssertionError("none found")


def test_crc_collisions_are_frequent() -> None:
    """Why close readings are checked: CRC-16's structure, not a 1 in 65536 chance."""
    rng = random.Random(1)
    for _ in range(200):
        frame = with_crc(rng.randbytes(rng.randint(3, 20)))
        # a good frame followed by 00 is a good frame one byte longer
        assert crc_state(frame + b"\x00", 0, len(frame) + 1) == CRC_OK
    # one 2-register response in about 256 has a good 8-byte prefix
    hits = sum(crc_state(rd_resp(1, [i, 7]), 0, 8) != CRC_BAD for i in range(25_600))
    assert 50 < hits < 300


@settings(max_examples=300, deadline=None)
@given(body=st.binary(min_size=1, max_size=40), after=st.binary(min_size=1, max_size=2))
def test_crc_longer_reading_holds_exactly_after_zeros(body: bytes, after: bytes) -> None:
    """The shortcut frame_at takes: after a frame whose CRC holds (low byte first), a reading
    1 or 2 bytes longer holds, in either byte order, exactly when those bytes are 00."""
    frame = with_crc(body)
    longer = frame + after
    holds = crc_state(longer, 0, len(longer)) != CRC_BAD
    assert holds == (set(after) == {0})


def test_crc_collision_response_with_a_good_prefix() -> None:
    """A 2-register response with no request seen: its first 8 bytes also make a good read
    request (count 63488, not one a host sends); what follows it settles the reading."""
    resp = _find(lambda i: rd_resp(1, [i, 7]), lambda f: crc_state(f, 0, 8) != CRC_BAD)
    records = decode(resp + rd(1, 1061, 2) + rd_resp(1, [1, 2]))
    assert [(r.length, r.direction, r.ok) for r in records] == [
        (9, RESPONSE, True),
        (8, REQUEST, True),
        (9, RESPONSE, True),
    ]
    assert signature(decode(resp + rd(1, 1061, 2), [1])) == signature(decode(resp + rd(1, 1061, 2)))
    assert [r.length for r in decode(resp)] == [9]


def test_crc_collision_stray_zero_after_a_request() -> None:
    """A 00 byte after a request (a bus turnaround glitch) makes a good 9-byte 'response';
    the request reading is the expected one and sensible, so it wins."""
    for req in (rd(1, 1061, 5), rd(1, 1061, 2), rd(7, 1024, 1)):
        records = decode(req + b"\x00" + rd_resp(req[0], [5] * req[5]))
        assert [(r.kind, r.length) for r in records] == [
            (FRAME, 8),
            (GARBAGE, 1),
            (FRAME, 5 + 2 * req[5]),
        ]
        assert records[2].fields["values"]


def test_crc_collision_stray_zero_after_a_one_register_response() -> None:
    records = decode(rd(1, 1065, 1) + rd_resp(1, [4]) + b"\x00" + rd(1, 1065, 1))
    assert [(r.kind, r.length) for r in records] == [
        (FRAME, 8),
        (FRAME, 7),
        (GARBAGE, 1),
        (FRAME, 8),
    ]
    assert records[1].summary == "-> state=4 (closing)"


def test_crc_collision_request_with_a_good_prefix_after_an_unanswered_one() -> None:
    """An unanswered read, then a read of 0x02xx whose first 7 bytes make a good one-register
    'response': the 7-byte reading does not fit the pending request, and what follows the
    8-byte reading is its response."""
    req = _find(
        lambda i: rd(1, 0x0200 + (i & 0xFF), 1 + (i >> 8) % 125),
        lambda f: crc_state(f, 0, 7) != CRC_BAD,
    )
    records = decode(rd(1, 1061, 5) + req + rd_resp(1, [3] * req[5]))
    assert [(r.length, r.direction) for r in records] == [
        (8, REQUEST),
        (8, REQUEST),
        (5 + 2 * req[5], RESPONSE),
    ]


def test_garbage_between_frames() -> None:
    frames = [rd(1, 1061, 5), rd_resp(1, [1, 2, 3, 4, 5]), wr(1, 1010, 300), wr(1, 1010, 300)]
    junk = [b"\xff\xff\xff", b"\x00", b"\xff" * 10, b"\x07\x07"]
    data = b"".join(j + f for j, f in zip(junk, frames, strict=True))
    records = decode(data)
    kinds = [(r.kind, r.length) for r in records]
    assert kinds == [
        (GARBAGE, 3),
        (FRAME, 8),
        (GARBAGE, 1),
        (FRAME, 15),
        (GARBAGE, 10),
        (FRAME, 8),
        (GARBAGE, 2),
        (FRAME, 8),
    ]
    assert all(r.ok for r in records if r.kind == FRAME)
    assert records[3].name == "CMD_OPENLEN_ACT..CMD_STATUS"  # the pairing survived the junk
    assert [r.direction for r in records if r.kind == FRAME] == [
        REQUEST,
        RESPONSE,
        REQUEST,
        RESPONSE,
    ]
    assert records[0].errors == ["garbage: 3 bytes belong to no frame (no frame starts here)"]


def test_leading_partial_frame_is_garbage() -> None:
    """A capture that starts in the middle of a frame: its tail is garbage, then frames."""
    frames = [rd(1, 1061, 5), rd_resp(1, [1, 2, 3, 4, 5]), rd(1, 1061, 5)]
    data = b"".join(frames)
    for cut in range(1, 8):
        records = decode(data[cut:])
        assert [(r.kind, r.length) for r in records] == [
            (GARBAGE, 8 - cut),
            (FRAME, 15),
            (FRAME, 8),
        ]
        assert records[1].warnings == [NO_REQUEST]  # its request was cut off


def test_corrupted_crc_in_the_middle() -> None:
    rng = random.Random(7)
    frames = mixed_frames(rng, 200)
    for k in (0, 1, 57, 100, 151, 199):
        bad = bytearray(frames[k])
        bad[-1] ^= 0x5A
        stream = [*frames[:k], bytes(bad), *frames[k + 1 :]]
        records = decode(b"".join(stream))
        assert [(r.kind, r.length) for r in records] == [(FRAME, len(f)) for f in stream], k
        body = frames[k][:-2]
        exp = with_crc(body)[-2:]
        assert records[k].errors == [
            f"CRC error: expected {exp[0]:02X} {exp[1]:02X}, got {bad[-2]:02X} {bad[-1]:02X}"
        ]
        assert all(r.ok for i, r in enumerate(records) if i != k)


def test_corrupted_byte_inside_a_frame() -> None:
    """A flipped data byte: the frame keeps its length (the byte count is intact), its CRC
    fails, and the next frames decode."""
    frames = [rd(1, 1061, 5), rd_resp(1, [1, 2, 3, 4, 5]), wr(1, 1010, 300), wr(1, 1010, 300)]
    bad = bytearray(frames[1])
    bad[6] ^= 0x10
    stream = [frames[0], bytes(bad), *frames[2:]]
    records = decode(b"".join(stream))
    assert [(r.kind, r.length, r.ok) for r in records] == [
        (FRAME, 8, True),
        (FRAME, 15, False),
        (FRAME, 8, True),
        (FRAME, 8, True),
    ]
    assert records[1].errors[0].startswith("CRC error: expected ")
    assert records[2].direction == REQUEST and records[3].direction == RESPONSE


def test_truncated_frame_at_the_end() -> None:
    rng = random.Random(3)
    frames = mixed_frames(rng, 50)
    tail = rd_resp(1, [1, 2, 3, 4, 5])[:9]
    records = decode(b"".join(frames) + rd(1, 1061, 5) + tail)
    assert all(r.ok for r in records[:-1])
    assert len(records) == len(frames) + 2
    r = records[-1]
    assert r.kind == TRUNCATED
    assert r.raw == tail
    assert r.errors == [
        "truncated frame: the stream ended after 9 of 15 bytes (read holding registers)"
    ]


@pytest.mark.parametrize(
    ("tail", "reason"),
    [
        (b"\x01", "truncated frame: the stream ended after 1 byte"),
        (
            b"\x01\x06\x03",
            "truncated frame: the stream ended after 3 of 8 bytes (write single register)",
        ),
        (
            b"\x01\x83",
            "truncated frame: the stream ended after 2 of 5 bytes "
            "(exception response to read holding registers)",
        ),
        (
            b"\x01\x10\x03\xf2\x00\x03\x06\x00",
            "truncated frame: the stream ended after 8 of 15 bytes (write multiple registers)",
        ),
        (
            b"\x01\x03\x04\x25",
            "truncated frame: the stream ended after 4 of 8 or 9 bytes (read holding registers)",
        ),
        (
            b"\x01\x10\x03",
            "truncated frame: the stream ended after 3 of 8 bytes (write multiple registers)",
        ),
    ],
)
def test_truncated_reasons(tail: bytes, reason: str) -> None:
    records = decode(wr(1, 1010, 1) + wr(1, 1010, 1) + tail)
    assert records[-1].kind == TRUNCATED
    assert records[-1].errors == [reason]


# -- random streams: whole, chunked, byte by byte, with and without timing --------------------


def mixed_frames(rng: random.Random, pairs: int) -> list[bytes]:
    """A host polling and commanding a few grippers: request/response pairs of every shape,
    some broadcasts and some unanswered reads, both register numberings, both CRC orders."""
    frames: list[bytes] = []
    for _ in range(pairs):
        slave = rng.choice((1, 1, 2, 3, 254))
        short = rng.random() < 0.2
        off = 0 if short else 1000
        kind = rng.random()
        swap = rng.random() < 0.05
        pair: list[bytes]
        if kind < 0.45:
            start = rng.choice((1061, 1060, 1064, 1065, 1010, 1001, 1016)) - 1000 + off
            count = rng.randint(1, 5)
            values = [rng.randint(0, 0xFFFF) for _ in range(count)]
            pair = [rd(slave, start, count), rd_resp(slave, values)]
            if rng.random() < 0.05:
                pair = pair[:1]  # unanswered
        elif kind < 0.65:
            frame = wr(
                slave, rng.choice((1010, 1011, 1012, 1006)) - 1000 + off, rng.randint(0, 1000)
            )
            pair = [frame, frame]
            if rng.random() < 0.1:
                pair = [wr(0, 1010 - 1000 + off, rng.randint(0, 1000))]  # broadcast
        elif kind < 0.85:
            count = rng.randint(1, 4)
            start = 1010 - 1000 + off
            pair = [
                wrm(slave, start, [rng.randint(0, 1000) for _ in range(count)]),
                wrm_resp(slave, start, count),
            ]
        else:
            fc = rng.choice((3, 6, 16))
            req = {3: rd(slave, 1100, 2), 6: wr(slave, 1100, 1), 16: wrm(slave, 1100, [1])}[fc]
            pair = [req, exc(slave, fc, rng.randint(1, 4))]
        if swap:
            pair = [swap_crc(f) for f in pair]
        frames += pair
    return frames


def expected_directions(frames: list[bytes]) -> list[str]:
    """What the generator meant: a response follows its request."""
    out: list[str] = []
    pending = False
    for f in frames:
        fc, n = f[1], len(f)
        by_shape = fc & 0x80 or (fc == 3 and n != 8) or (fc == 16 and n == 8)
        echo = fc == 6 and pending and frames[len(out) - 1] == f
        if by_shape or echo:
            out.append(RESPONSE)
            pending = False
        else:
            out.append(REQUEST)
            pending = f[0] != 0
    return out


@pytest.mark.parametrize("seed", range(4))
def test_random_streams_any_chunking(seed: int) -> None:
    rng = random.Random(seed)
    frames = mixed_frames(rng, 1500)
    data = b"".join(frames)
    whole = decode(data)
    assert [(r.kind, r.length) for r in whole] == [(FRAME, len(f)) for f in frames]
    assert all(r.ok for r in whole)
    assert [r.direction for r in whole] == expected_directions(frames)
    named = [r for r in whole if r.direction == RESPONSE and r.code == 3]
    assert all(r.fields.get("values") for r in named if NO_REQUEST not in r.warnings)
    want = signature(whole)
    assert signature(decode(data, random_sizes(rng, len(data)))) == want
    assert signature(decode(data, [rng.randint(1, 40)])) == want
    if seed == 0:
        assert signature(decode(data, [1])) == want  # one byte at a time


@pytest.mark.parametrize("seed", range(3))
def test_random_streams_with_corruption_any_chunking(seed: int) -> None:
    """Garbage and corrupted frames too: still the same records however the bytes arrive."""
    rng = random.Random(100 + seed)
    parts: list[bytes] = []
    for f in mixed_frames(rng, 600):
        roll = rng.random()
        if roll < 0.03:
            f = f[:-1] + bytes((f[-1] ^ 0xFF,))  # bad CRC
        elif roll < 0.05:
            f = f[: rng.randint(1, len(f) - 1)]  # cut short
        parts.append(f)
        if rng.random() < 0.05:
            parts.append(rng.randbytes(rng.randint(1, 12)))  # line noise
    data = b"".join(parts)
    whole = decode(data)
    want = signature(whole)
    assert signature(decode(data, random_sizes(rng, len(data)))) == want
    assert signature(decode(data, [1])) == want
    assert sum(r.ok for r in whole) > 0.8 * len(parts)


def test_timing_gives_the_same_frames() -> None:
    """Chunks with arrival times (gaps between frames, bursts from a USB adapter) give the
    same frames as the bare bytes."""
    rng = random.Random(11)
    frames = mixed_frames(rng, 400)
    data = b"".join(frames)
    bare = signature(decode(data))
    # one chunk per frame, 2-20 ms apart (gaps longer than 1.75 ms)
    t, times = 0.0, []
    for _ in frames:
        t += rng.uniform(0.002, 0.02)
        times.append(t)
    timed = decode(data, sizes=[len(f) for f in frames], times=times)
    assert signature(timed) == bare
    assert timed[-1].t == times[-1]
    # adapter bursts: 64-byte chunks every millisecond (no gap ever seen)
    sizes = [64] * (len(data) // 64 + 1)
    assert signature(decode(data, sizes=sizes, times=[i * 0.001 for i in range(len(sizes))])) == (
        bare
    )


def test_timing_gap_makes_a_bad_frame_plausible() -> None:
    """A bad-CRC candidate followed by noise: a silence after it says it was a frame."""
    bad = bytearray(rd_resp(1, [1, 2, 3]))
    bad[-1] ^= 0xFF
    noise = b"\xff\xff"
    data = rd(1, 1061, 3) + bytes(bad) + noise
    bare = decode(data)
    assert [(r.kind, r.offset) for r in bare][:2] == [(FRAME, 0), (GARBAGE, 8)]
    timed = decode(data, sizes=[8, len(bad), 2], times=[0.0, 0.001, 0.010])
    assert [(r.kind, r.length, r.ok) for r in timed] == [
        (FRAME, 8, True),
        (FRAME, len(bad), False),
        (GARBAGE, 2, False),
    ]
    assert timed[1].fields["values"] == {"CMD_OPENLEN_ACT": 1, "CMD_CURRENT": 2, "CMD_TEMP": 3}


def test_memo_is_bounded(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(modbus_rtu, "MEMO_LIMIT", 500)
    dec = ModbusRtuDecoder()
    records = dec.feed(Chunk(b"".join(rd_resp(1, [i, 7]) for i in range(2000))))
    assert len(records) == 2000
    assert 0 < len(dec._memo) <= 500
    # what was evicted decodes the same again
    again = ModbusRtuDecoder().feed(Chunk(b"".join(rd_resp(1, [i, 7]) for i in range(2000))))
    assert signature(again) == signature(records)


# -- hypothesis --------------------------------------------------------------------------------

_chunkings = st.lists(st.integers(1, 40), min_size=1, max_size=20)


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.binary(max_size=600), sizes=_chunkings)
def test_arbitrary_bytes(data: bytes, sizes: list[int]) -> None:
    """Never raises, every byte accounted for, the same records in any chunking."""
    whole = decode(data)
    assert signature(decode(data, sizes)) == signature(whole)


# arbitrary bytes biased towards frame-like content: addresses, known function codes, CRCs
_frame_bytes = st.sampled_from([0x00, 0x01, 0x02, 0x03, 0x04, 0x06, 0x10, 0x83, 0x90, 0xFF])


@st.composite
def noisy_streams(draw: st.DrawFn) -> bytes:
    parts = draw(
        st.lists(
            st.one_of(
                st.lists(_frame_bytes, max_size=12).map(bytes),
                st.binary(max_size=20).map(with_crc),
                st.binary(max_size=6),
            ),
            max_size=30,
        )
    )
    return b"".join(parts)


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=noisy_streams(), sizes=_chunkings)
def test_frame_like_noise(data: bytes, sizes: list[int]) -> None:
    whole = decode(data)
    assert signature(decode(data, sizes)) == signature(whole)
    assert signature(decode(data, [1])) == signature(whole)


_slaves = st.integers(0, 254)
_u16 = st.integers(0, 0xFFFF)


@st.composite
def valid_frames(draw: st.DrawFn) -> bytes:
    slave = draw(_slaves)
    shape = draw(st.sampled_from(["rd", "rd_resp", "wr", "wrm", "wrm_resp", "exc", "coils"]))
    if shape == "rd":
        start, count = draw(_u16), draw(st.integers(1, 125))
        if draw(st.booleans()):
            frame = rd(slave, start, count)
        else:
            frame = pm(rm.ReadInputRegistersRequest(address=start, count=count, dev_id=slave))
    elif shape == "rd_resp":
        frame = rd_resp(slave, draw(st.lists(_u16, min_size=1, max_size=125)))
    elif shape == "wr":
        frame = wr(slave, draw(_u16), draw(_u16))
    elif shape == "wrm":
        frame = wrm(slave, draw(_u16), draw(st.lists(_u16, min_size=1, max_size=123)))
    elif shape == "wrm_resp":
        frame = wrm_resp(slave, draw(_u16), draw(st.integers(1, 123)))
    elif shape == "exc":
        frame = exc(slave, draw(st.sampled_from((1, 2, 3, 4, 5, 6, 15, 16))), draw(_u16) & 0xFF)
    else:
        bits = draw(st.lists(st.booleans(), min_size=1, max_size=40))
        frame = pm(bm.WriteMultipleCoilsRequest(address=draw(_u16), bits=bits, dev_id=slave))
    return swap_crc(frame) if draw(st.booleans()) else frame


def _no_other_reading(stream: bytes, starts: list[int], lengths: list[int]) -> bool:
    """No frame start has a second reading with a good CRC (a CRC collision would make the
    bytes genuinely ambiguous)."""
    for pos, length in zip(starts, lengths, strict=True):
        kind = KIND[stream[pos + 1]]
        for c in candidates(stream, pos, len(stream), kind, False):
            if c > 0 and c != length and pos + c <= len(stream) and crc_state(stream, pos, pos + c):
                return False
    return True


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    items=st.lists(st.tuples(st.integers(0, 6), valid_frames()), min_size=1, max_size=12),
    trailing=st.integers(0, 6),
    sizes=_chunkings,
)
def test_valid_frames_between_garbage_are_found(
    items: list[tuple[int, bytes]], trailing: int, sizes: list[int]
) -> None:
    """0xFF is never a slave address, so 0xFF runs never hide a frame."""
    stream = b""
    starts, lengths = [], []
    for junk, frame in items:
        stream += b"\xff" * junk
        starts.append(len(stream))
        lengths.append(len(frame))
        stream += frame
    stream += b"\xff" * trailing
    assume(_no_other_reading(stream, starts, lengths))
    records = decode(stream, sizes)
    found = [(r.offset, r.length) for r in records if r.kind == FRAME]
    assert found == list(zip(starts, lengths, strict=True))
    assert all(r.ok for r in records if r.kind == FRAME)
    assert all(set(r.raw) == {0xFF} for r in records if r.kind == GARBAGE)


@settings(max_examples=300, deadline=None)
@given(frame=valid_frames(), hint=st.sampled_from([None, REQUEST, RESPONSE]))
def test_decode_any_frame(frame: bytes, hint: str | None) -> None:
    for pending in (None, (frame[0], frame[1] & 0x7F, 1061, 5, True), (frame[0], 3, 0, 0, False)):
        e = modbus_pdu.decode(frame, pending, hint)
        direction, fields, summary, errors, nxt = e[0], e[2], e[3], e[4], e[9]
        assert fields["slave"] == frame[0]
        assert errors == ()
        assert direction in (REQUEST, RESPONSE)
        assert isinstance(summary, str) and summary
        json.dumps(fields)
        assert (nxt is not None) == (direction == REQUEST and frame[0] != 0)


@pytest.mark.parametrize(
    ("raw", "error"),
    [(h("01 03 00"), "frame too short (3 bytes)"),
     (h("01 03 04 25 00"), "5 bytes are no Modbus frame shape (read holding registers)"),
     (h("01 07 00 00 00 00"), "6 bytes are no Modbus frame shape (code 0x07)"),
     (h("01 10 03 F2 00 03 06 00 00"), "9 bytes are no Modbus frame shape "
                                       "(write multiple registers)")],
)  # fmt: skip
def test_decode_rejects_shapeless_bytes(raw: bytes, error: str) -> None:
    """decode() is public: bytes no framer would hand it get an error, not an exception."""
    e = modbus_pdu.decode(raw)
    assert e[4] == (error,)
    assert e[0] is None


@settings(max_examples=200, deadline=None)
@given(
    slave=_slaves,
    start=_u16,
    values=st.lists(_u16, min_size=1, max_size=30),
    swapped=st.booleans(),
)
def test_read_response_fast_path_matches_the_general_decode(
    slave: int, start: int, values: list[int], swapped: bool
) -> None:
    frame = rd_resp(slave, values)
    if swapped:
        frame = swap_crc(frame)
    pending = (slave, 3, start, len(values), True)
    fast = modbus_pdu.decode(frame, pending, None)
    general = modbus_pdu._decode(frame, pending, None, None)
    assert fast == general
