"""The EG2-4X0 CAN decoder: the manual's frames, identifiers, direction, flags, foreign frames."""

from __future__ import annotations

import json
import random
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
from protocol_vectors import load, needs_vectors

from decoders import registers
from decoders.eg2_can import (
    BROADCAST,
    MEMO_LIMIT,
    PENDING_TIMEOUT_S,
    Eg2CanDecoder,
    can_error_text,
    pack_id,
    unpack_id,
)
from decoders.model import EG2_CAN, FOREIGN_CAN, FRAME, REQUEST, RESPONSE, CanFrame, Record

ROOT = Path(__file__).resolve().parents[2]
CAN_VECTORS = load("eg2_can")


def frame(aid: int, data: str | bytes, t: float | None = None, **kw: Any) -> CanFrame:
    raw = bytes.fromhex(data) if isinstance(data, str) else data
    return CanFrame(t, aid, raw, **kw)


def decode_all(frames: list[CanFrame], dec: Eg2CanDecoder | None = None) -> list[Record]:
    dec = dec or Eg2CanDecoder()
    return [dec.decode(f, i) for i, f in enumerate(frames)]


def values_by_key(rec: Record) -> dict[str, int]:
    """The record's register values under their short keys (target_opening, state, ...)."""
    by_name = {r.name: r.key for r in registers.REGISTERS}
    return {by_name.get(name, name): v for name, v in rec.fields["values"].items()}


def check_vector_fields(rec: Record, expected: dict[str, Any]) -> None:
    for key, want in expected.items():
        if key == "device":
            assert rec.device == want
        elif key == "values":
            assert values_by_key(rec) == want
        elif key in registers.BY_KEY:
            assert rec.fields["values"][registers.BY_KEY[key].name] == want, key
        else:
            assert rec.fields[key] == want, key


# -- the manual's frames (vectors.json) ------------------------------------------------------


@needs_vectors
def test_vectors_present() -> None:
    assert len(CAN_VECTORS) >= 3


VECTOR_CASES = [(v, False) for v in CAN_VECTORS] + [
    (v, True) for v in CAN_VECTORS if "alt_data_padded" in v
]


@needs_vectors
@pytest.mark.parametrize(
    "vec,padded",
    VECTOR_CASES,
    ids=[v["meaning"] + (" (padded)" if p else "") for v, p in VECTOR_CASES],
)
def test_vector(vec: dict[str, Any], padded: bool) -> None:
    data = vec["alt_data_padded"] if padded else vec["data"]
    aid = int(vec["id"], 16)
    dec = Eg2CanDecoder()
    req = dec.decode(frame(aid, data, 1.0), 0)
    assert req.protocol == EG2_CAN
    assert req.kind == FRAME
    assert req.direction == REQUEST
    assert req.errors == []
    assert req.code == ("read", "write").index(vec["fields"]["op"])
    assert req.fields["id"] == f"0x{aid:08X}"
    assert req.fields["dlc"] == len(bytes.fromhex(data))
    assert req.length == len(bytes.fromhex(data))
    assert req.raw == bytes.fromhex(data)
    assert req.expects_response
    assert req.pair_key == (aid,)
    check_vector_fields(req, vec["fields"])
    if padded:
        assert req.fields["padded"] is True

    resp_vec = vec["response"]
    assert int(resp_vec["id"], 16) == aid
    resp = dec.decode(frame(aid, resp_vec["data"], 1.001), 1)
    assert resp.protocol == EG2_CAN
    assert resp.direction == RESPONSE
    assert resp.errors == []
    assert resp.device == vec["fields"]["device"]
    assert resp.fields["address"] == vec["fields"]["address"]
    assert resp.pair_key == req.pair_key
    assert not resp.expects_response
    check_vector_fields(resp, resp_vec["fields"])
    flags = resp_vec.get("flags", [])
    for flag in flags:
        subject, _, rng = flag.partition(" out of range ")
        hits = [w for w in resp.warnings if w.startswith(subject) and "out of range" in w]
        assert hits, (flag, resp.warnings)
        assert rng in hits[0]
    if not flags:
        assert not [w for w in resp.warnings if "out of range" in w]


SUMMARIES = [
    (
        0x04FF0001,
        "00 00 F4 01 F4 01",
        "06",
        "write 6 bytes at 1020: target_opening=0 (0.0 mm), speed=500, force=500 g",
        "-> wrote 6 bytes",
        "CMD_OPENLEN_SET..CMD_FORCE_SET",
    ),
    (
        0x01180001,
        "08",
        "F3 00 03 E8 00 00 00 22",
        "read 8 bytes at 1120 (measured_force..temperature_c)",
        "-> measured_force=243, measured_opening=59395 (4157.65 mm), current=0, "
        "temperature_c=8704 °C",
        "CMD_FORCE_ACT..CMD_TEMP",
    ),
    (
        0x011A0001,
        "04",
        "00 00 01 00",
        "read 4 bytes at 1128 (fault..state)",
        "-> fault=0 (no fault), state=1 (fully open, idle)",
        "CMD_ERRORCODE..CMD_STATUS",
    ),
    (
        pack_id(0, 1124, 2),
        "02",
        "FE FF",
        "read 2 bytes at 1124 (current)",
        "-> current=-2",
        "CMD_CURRENT",
    ),
    (
        pack_id(1, 1022, 3),
        "E8 03",
        "02",
        "write 2 bytes at 1022: speed=1000",
        "-> wrote 2 bytes",
        "CMD_SPEED_SET",
    ),
    (
        pack_id(0, 1128, 1),
        "02",
        "05 00",
        "read 2 bytes at 1128 (fault)",
        "-> fault=5 (stall, over-current)",
        "CMD_ERRORCODE",
    ),
]


@pytest.mark.parametrize("aid,req,resp,req_summary,resp_summary,name", SUMMARIES)
def test_summaries_and_names(
    aid: int, req: str, resp: str, req_summary: str, resp_summary: str, name: str
) -> None:
    a, b = decode_all([frame(aid, req), frame(aid, resp)])
    assert (a.direction, b.direction) == (REQUEST, RESPONSE)
    assert a.summary == req_summary
    assert b.summary == resp_summary
    assert a.name == b.name == name


def test_read_request_names_its_registers() -> None:
    (rec,) = decode_all([frame(0x01180001, "08")])
    assert rec.fields["registers"] == [
        "CMD_FORCE_ACT",
        "CMD_OPENLEN_ACT",
        "CMD_CURRENT",
        "CMD_TEMP",
    ]
    assert rec.fields["length"] == 8


def test_state_and_fault_text() -> None:
    recs = decode_all([frame(0x011A0001, "04"), frame(0x011A0001, "03 00 06 00")])
    assert recs[1].fields["state_text"] == registers.state_text(6)
    assert recs[1].fields["fault_text"] == ["stall", "over-temperature"]


def test_signed_current() -> None:
    aid = pack_id(0, 1124, 1)
    recs = decode_all([frame(aid, "02"), frame(aid, "FE FF")])
    assert recs[1].fields["values"] == {"CMD_CURRENT": -2}
    assert not recs[1].warnings


# -- identifiers -----------------------------------------------------------------------------

ID_TABLE = [
    (0x04FF0001, 1, 1020, 1, False),
    (0x01180001, 0, 1120, 1, False),
    (0x011A0001, 0, 1128, 1, False),
    (0x00FA8001, 0, 1002, 1, False),
    (0x04FF3FFF, 1, 1020, BROADCAST, False),
    (0x08FF0002, 2, 1020, 2, False),
    (0x0CFF3FFE, 3, 1020, 16382, False),
    (0x00000000, 0, 0, 0, False),
    (0x0FFFFFFF, 3, 4095, 16383, False),
    (0x14FF0001, 1, 1020, 1, True),
    (0x1FFFFFFF, 3, 4095, 16383, True),
    (0x03FFC000, 0, 4095, 0, False),
    (0x00004001, 0, 1, 1, False),
]


@pytest.mark.parametrize("aid,op,address,device,reserved", ID_TABLE)
def test_id_packing(aid: int, op: int, address: int, device: int, reserved: bool) -> None:
    assert unpack_id(aid) == (op, address, device, reserved)
    assert pack_id(op, address, device, reserved) == aid


def test_id_roundtrip_random() -> None:
    rnd = random.Random(7)
    for _ in range(5000):
        op, address, device = rnd.randrange(4), rnd.randrange(4096), rnd.randrange(16384)
        reserved = rnd.random() < 0.1
        aid = pack_id(op, address, device, reserved)
        assert 0 <= aid <= 0x1FFFFFFF
        assert unpack_id(aid) == (op, address, device, reserved)


@pytest.mark.parametrize(
    "args", [(4, 1020, 1), (-1, 1020, 1), (0, 4096, 1), (0, -2, 1), (0, 1020, 16384), (1, 0, -1)]
)
def test_pack_id_rejects_out_of_range(args: tuple[int, int, int]) -> None:
    with pytest.raises(ValueError):
        pack_id(*args)


def test_reserved_bit_flagged() -> None:
    aid = pack_id(1, 1020, 1, reserved=True)
    (rec,) = decode_all([frame(aid, "00 00 F4 01 F4 01")])
    assert rec.protocol == EG2_CAN
    assert any("reserved" in w and "28" in w for w in rec.warnings)


def test_device_zero_flagged() -> None:
    (rec,) = decode_all([frame(pack_id(0, 1120, 0), "08")])
    assert rec.device == 0
    assert any("device 0" in w for w in rec.warnings)


# -- broadcast, operations 2 and 3 -----------------------------------------------------------


def test_broadcast_write_expects_no_response() -> None:
    aid = pack_id(1, 1020, BROADCAST)
    (rec,) = decode_all([frame(aid, "00 00 F4 01 F4 01")])
    assert rec.device == 16383
    assert rec.direction == REQUEST
    assert rec.expects_response is False
    assert rec.fields["broadcast"] is True
    assert rec.pair_key == (aid,)


def test_broadcast_is_never_pending() -> None:
    """Nobody answers a broadcast: the next shape-ambiguous frame on it is a request too."""
    aid = pack_id(1, 1012, BROADCAST)
    recs = decode_all([frame(aid, "01"), frame(aid, "01")])
    assert [r.direction for r in recs] == [REQUEST, REQUEST]


@pytest.mark.parametrize(
    "op,text", [(2, "positioning move"), (3, "servo follow")], ids=["op2", "op3"]
)
@pytest.mark.parametrize("data", ["", "01", "00 00 F4 01 F4 01", "01 02 03 04 05 06 07 08"])
def test_operations_2_and_3_raw(op: int, text: str, data: str) -> None:
    aid = pack_id(op, 1020, 5)
    (rec,) = decode_all([frame(aid, data)])
    assert rec.protocol == EG2_CAN
    assert rec.code == op
    assert rec.name == text
    assert rec.fields["op"] == text
    assert rec.fields["data"] == data.upper()
    assert rec.fields["address"] == 1020
    assert rec.device == 5
    assert rec.direction is None
    assert rec.pair_key is None
    assert not rec.expects_response
    assert rec.errors == []
    assert any(f"operation {op}" in w and "layout" in w for w in rec.warnings)
    assert text in rec.summary


# -- frames that are not EG2 -----------------------------------------------------------------

FOREIGN = [
    (
        CanFrame(0.5, 0x123, b"\x01\x02\x03", is_extended=False),
        "standard 0x123 [3] 01 02 03",
        [],
        [],
    ),
    (CanFrame(0.5, 0x7FF, b"", is_extended=False), "standard 0x7FF [0]", [], []),
    (
        CanFrame(0.5, 0x000, bytes(8), is_extended=False),
        "standard 0x000 [8] 00 00 00 00 00 00 00 00",
        [],
        [],
    ),
    (
        CanFrame(0.5, 0x123, b"", is_extended=False, is_remote=True, dlc=5),
        "remote standard 0x123 [5]",
        [],
        ["remote frame"],
    ),
    (
        CanFrame(0.5, 0x04FF0001, b"", is_remote=True, dlc=6),
        "remote extended 0x04FF0001 [6]",
        [],
        ["remote frame"],
    ),
    (
        CanFrame(0.5, 0x01ABCDEF, bytes(range(12)), is_fd=True),
        "FD extended 0x01ABCDEF [12] 00 01 02 03 04 05 06 07 08 09 0A 0B",
        [],
        [],
    ),
    (
        CanFrame(0.5, 0x123, b"\xaa" * 64, is_extended=False, is_fd=True),
        None,
        [],
        [],
    ),
    (
        CanFrame(0.5, 0x04FF0001, b"\x00\x00\xf4\x01\xf4\x01", is_fd=True),
        "FD extended 0x04FF0001 [6] 00 00 F4 01 F4 01",
        [],
        [],
    ),
    (
        CanFrame(0.5, 0x80, bytes(8), is_error=True),
        None,
        ["CAN error frame: bus error (class 0x080)"],
        [],
    ),
    (CanFrame(0.5, 0, b"", is_error=True), "CAN error frame [0]", ["CAN error frame"], []),
    (
        CanFrame(0.5, 0x24, bytes(8), is_error=True),
        None,
        ["CAN error frame: controller problem, no ACK on transmission (class 0x024)"],
        [],
    ),
    (
        CanFrame(0.5, 0x01180001, bytes(8), dlc=12),
        None,
        [],
        ["DLC 12 with 8 data bytes"],
    ),
    (CanFrame(0.5, 0x01180001, bytes(9)), None, [], ["9 data bytes in a classic CAN frame"]),
    (
        CanFrame(0.5, 0xFFF, b"\x01", is_extended=False),
        None,
        [],
        ["identifier 0xfff does not fit in 11 bits"],
    ),
    (
        CanFrame(0.5, 0x3FFFFFFF, b"\x01"),
        None,
        [],
        ["identifier 0x3fffffff does not fit in 29 bits"],
    ),
]


@pytest.mark.parametrize("fr,summary,errors,warnings", FOREIGN)
def test_foreign_frames(
    fr: CanFrame, summary: str | None, errors: list[str], warnings: list[str]
) -> None:
    dec = Eg2CanDecoder("can1")
    rec = dec.decode(fr, 42)
    assert rec.protocol == FOREIGN_CAN
    assert rec.bus == "can1"
    assert rec.kind == FRAME
    assert rec.index == 42
    assert rec.t == 0.5
    assert rec.device is None
    assert rec.name is None
    assert rec.code is None
    assert rec.direction is None
    assert rec.pair_key is None
    assert rec.raw == fr.data
    assert rec.length == fr.length
    assert rec.errors == errors
    assert rec.warnings == warnings
    if summary is not None:
        assert rec.summary == summary
    json.dumps(rec.to_dict())


def test_foreign_does_not_disturb_pending() -> None:
    aid = 0x01180001
    recs = decode_all(
        [
            frame(aid, "08"),
            CanFrame(None, 0x123, b"\x01", is_extended=False),
            CanFrame(None, aid, b"", is_remote=True, dlc=8),
            frame(aid, "08 00 00 00 00 00 00 00"),
        ]
    )
    assert [r.direction for r in recs] == [REQUEST, None, None, RESPONSE]


@pytest.mark.parametrize(
    "err,text", [(0x001, "TX timeout"), (0x040, "bus off"), (0x100, "restarted")]
)
def test_can_error_text(err: int, text: str) -> None:
    assert text in can_error_text(err)


def test_device_filter() -> None:
    dec = Eg2CanDecoder(devices={1, 2})
    recs = decode_all(
        [
            frame(pack_id(0, 1120, 1), "08"),
            frame(pack_id(0, 1120, 3), "08"),
            frame(pack_id(1, 1012, BROADCAST), "01 00"),
        ],
        dec,
    )
    assert [r.protocol for r in recs] == [EG2_CAN, FOREIGN_CAN, EG2_CAN]
    assert recs[1].summary == f"extended 0x{pack_id(0, 1120, 3):08X} [1] 08"
    assert recs[1].fields["eg2_device"] == 3


# -- odd spans, undocumented addresses, range ------------------------------------------------


def test_odd_length_write_flagged_with_leftover_byte() -> None:
    aid = pack_id(1, 1020, 1)
    (rec,) = decode_all([frame(aid, "E8 03 F4")])
    assert rec.direction == REQUEST
    assert rec.fields["values"] == {"CMD_OPENLEN_SET": 1000}
    assert rec.fields["partial"] == [
        {"address": 1022, "byte": "F4", "register": "CMD_SPEED_SET", "half": "low"}
    ]
    assert any("low byte of CMD_SPEED_SET" in w for w in rec.warnings)
    assert rec.summary == "write 3 bytes at 1020: target_opening=1000 (70.0 mm), byte 1022=0xF4"
    assert rec.name == "CMD_OPENLEN_SET..CMD_SPEED_SET"


def test_odd_address_read_flagged() -> None:
    aid = pack_id(0, 1121, 1)
    recs = decode_all([frame(aid, "03"), frame(aid, "03 E8 03")])
    req, resp = recs
    assert req.direction == REQUEST and resp.direction == RESPONSE
    assert any("odd start address 1121" in w for w in req.warnings)
    assert req.fields["registers"] == ["CMD_FORCE_ACT", "CMD_OPENLEN_ACT"]
    assert resp.fields["values"] == {"CMD_OPENLEN_ACT": 1000}
    assert resp.fields["partial"] == [
        {"address": 1121, "byte": "03", "register": "CMD_FORCE_ACT", "half": "high"}
    ]
    assert resp.summary == "-> byte 1121=0x03, measured_opening=1000 (70.0 mm)"
    assert any("high byte of CMD_FORCE_ACT" in w for w in resp.warnings)


def test_odd_address_odd_length_both_ends_partial() -> None:
    aid = pack_id(0, 1121, 1)
    recs = decode_all([frame(aid, "04"), frame(aid, "03 E8 03 22")])
    resp = recs[1]
    assert resp.fields["values"] == {"CMD_OPENLEN_ACT": 1000}
    assert [p["half"] for p in resp.fields["partial"]] == ["high", "low"]
    assert resp.fields["partial"][1]["register"] == "CMD_CURRENT"


def test_one_byte_read() -> None:
    aid = pack_id(0, 1130, 1)
    recs = decode_all([frame(aid, "01"), frame(aid, "05")])
    assert [r.direction for r in recs] == [REQUEST, RESPONSE]
    assert recs[1].fields["partial"][0]["register"] == "CMD_STATUS"
    assert recs[1].fields["values"] == {}


@pytest.mark.parametrize(
    "address,text",
    [(1026, "undocumented address 1026 (register 1013)"), (1200, "outside the register map")],
)
def test_unknown_addresses_flagged(address: int, text: str) -> None:
    aid = pack_id(1, address, 1)
    (rec,) = decode_all([frame(aid, "05 00")])
    assert any(text in w for w in rec.warnings), rec.warnings
    assert len(rec.fields["values"]) == 1


def test_write_to_read_only_flagged() -> None:
    (rec,) = decode_all([frame(pack_id(1, 1122, 1), "00 00")])
    assert any("read-only" in w and "CMD_OPENLEN_ACT" in w for w in rec.warnings)


@pytest.mark.parametrize(
    "address,raw,flagged",
    [
        (1022, "05 00", True),  # speed 5 < 10
        (1022, "0A 00", False),
        (1024, "E9 03", True),  # force 1001
        (1020, "E8 03", False),
        (1020, "E9 03", True),
        (1006, "FF 00", True),  # ID 255
    ],
)
def test_write_range_warnings(address: int, raw: str, flagged: bool) -> None:
    (rec,) = decode_all([frame(pack_id(1, address, 1), raw)])
    assert any("out of range" in w for w in rec.warnings) == flagged


@pytest.mark.parametrize(
    "address,raw,save",
    [
        (1002, "01 00", True),
        (1004, "01 00", True),
        (1002, "00 00", False),
        (1006, "01 00", False),
        (1000, "00 00 01 00", True),
        (1002, "00 00 01 00", True),
    ],
)
def test_is_save(address: int, raw: str, save: bool) -> None:
    (rec,) = decode_all([frame(pack_id(1, address, 1), raw)])
    assert rec.is_save is save


def test_write_response_is_not_a_save() -> None:
    aid = pack_id(1, 1002, 1)
    recs = decode_all([frame(aid, "01 00"), frame(aid, "02")])
    assert [r.is_save for r in recs] == [True, False]


# -- direction ------------------------------------------------------------------------------


def test_one_byte_write_request_vs_response_by_pending_table() -> None:
    aid = pack_id(1, 1012, 1)  # stop
    recs = decode_all(
        [
            frame(aid, "01", 0.000),  # nothing pending: a 1-byte write request of 1
            frame(aid, "01", 0.001),  # a 1-byte write is pending: the response
            frame(aid, "01", 0.010),  # request again
            frame(aid, "01", 0.011),  # response
        ]
    )
    assert [r.direction for r in recs] == [REQUEST, RESPONSE, REQUEST, RESPONSE]
    assert recs[0].fields["values"] == {}  # one byte: the low half of CMD_STOP, shown raw
    assert recs[0].fields["partial"][0]["register"] == "CMD_STOP"
    assert recs[1].fields["written_bytes"] == 1
    assert any("could also be the response" in w for w in recs[0].warnings)


def test_write_response_must_match_pending_length() -> None:
    aid = pack_id(1, 1020, 1)
    recs = decode_all([frame(aid, "00 00 F4 01 F4 01"), frame(aid, "04"), frame(aid, "01")])
    # 04 is not the answer to a 6-byte write: it is a new (1-byte) write request
    assert [r.direction for r in recs] == [REQUEST, REQUEST, RESPONSE]


def test_padded_write_response() -> None:
    aid = pack_id(1, 1020, 1)
    recs = decode_all([frame(aid, "00 00 F4 01 F4 01"), frame(aid, "06 00 00 00 00 00 00 00")])
    assert recs[1].direction == RESPONSE
    assert recs[1].fields["written_bytes"] == 6
    assert recs[1].fields["padded"] is True


def test_padded_read_request_vs_response() -> None:
    aid = 0x01180001
    recs = decode_all(
        [
            frame(aid, "08 00 00 00 00 00 00 00"),  # request (padded)
            frame(aid, "08 00 00 00 00 00 00 00"),  # the response: force 8, the rest 0
            frame(aid, "08 00 00 00 00 00 00 00"),  # request again
        ]
    )
    assert [r.direction for r in recs] == [REQUEST, RESPONSE, REQUEST]
    assert recs[1].fields["values"]["CMD_FORCE_ACT"] == 8
    assert any("could also be a repeated read request" in w for w in recs[1].warnings)


def test_one_byte_read_response_vs_request() -> None:
    aid = pack_id(0, 1130, 1)
    recs = decode_all([frame(aid, "01"), frame(aid, "01"), frame(aid, "01")])
    assert [r.direction for r in recs] == [REQUEST, RESPONSE, REQUEST]


def test_response_without_pending_request() -> None:
    aid = 0x01180001
    (rec,) = decode_all([frame(aid, "F3 00 03 E8 00 00 00 22")])
    assert rec.direction == RESPONSE
    assert rec.fields["values"]["CMD_FORCE_ACT"] == 243


def test_response_length_mismatch() -> None:
    aid = 0x01180001
    recs = decode_all([frame(aid, "08"), frame(aid, "F3 00 03 E8")])
    assert recs[1].direction == RESPONSE
    assert any("mismatch" in w and "8 bytes" in w for w in recs[1].warnings)
    assert recs[1].fields["values"] == {"CMD_FORCE_ACT": 243, "CMD_OPENLEN_ACT": 59395}


def test_pending_expires() -> None:
    aid = pack_id(1, 1012, 1)
    late = PENDING_TIMEOUT_S + 0.5
    recs = decode_all([frame(aid, "01", 10.0), frame(aid, "01", 10.0 + late)])
    assert [r.direction for r in recs] == [REQUEST, REQUEST]
    # without times there is no expiry
    recs = decode_all([frame(aid, "01"), frame(aid, "01")])
    assert [r.direction for r in recs] == [REQUEST, RESPONSE]


def test_reset_forgets_pending() -> None:
    dec = Eg2CanDecoder()
    aid = pack_id(1, 1012, 1)
    assert dec.decode(frame(aid, "01"), 0).direction == REQUEST
    dec.reset()
    assert dec.decode(frame(aid, "01"), 1).direction == REQUEST


@pytest.mark.parametrize("op", [0, 1])
def test_empty_read_or_write(op: int) -> None:
    (rec,) = decode_all([frame(pack_id(op, 1020, 1), "")])
    assert rec.protocol == EG2_CAN
    assert rec.direction is None
    assert rec.errors and "without data" in rec.errors[0]


def test_pairs_are_per_identifier() -> None:
    a, b = pack_id(0, 1120, 1), pack_id(0, 1120, 2)
    recs = decode_all([frame(a, "08"), frame(b, "08"), frame(b, "01" * 8), frame(a, "02" * 8)])
    assert [r.direction for r in recs] == [REQUEST, REQUEST, RESPONSE, RESPONSE]
    assert [r.device for r in recs] == [1, 2, 2, 1]
    assert [r.pair_key for r in recs] == [(a,), (b,), (b,), (a,)]


# -- random request/response traffic ---------------------------------------------------------

DOCUMENTED = sorted(registers.BY_CAN_ADDRESS)


def _random_traffic(seed: int, count: int) -> list[tuple[CanFrame, str | None, int, int]]:
    """(frame, true direction, device, address): requests and responses of several devices,
    interleaved across identifiers, each identifier strictly request-then-response."""
    rnd = random.Random(seed)
    devices = [1, 2, 3, 7, 254, 16382]
    pending: dict[int, tuple[int, int, bytes]] = {}  # aid -> (op, n, response data)
    out: list[tuple[CanFrame, str | None, int, int]] = []
    t = 1000.0
    while len(out) < count:
        t += rnd.uniform(0.0001, 0.01)
        if pending and rnd.random() < 0.5:
            aid = rnd.choice(list(pending))
            op, n, data = pending.pop(aid)
            out.append((CanFrame(t, aid, data), RESPONSE, aid & 0x3FFF, (aid >> 14) & 0xFFF))
            continue
        device = rnd.choice(devices) if rnd.random() > 0.05 else BROADCAST
        op = rnd.choice((0, 1))
        address = rnd.choice(DOCUMENTED) if rnd.random() > 0.1 else rnd.randrange(4096)
        aid = pack_id(op, address, device)
        if aid in pending:
            continue
        n = rnd.choice((2, 4, 6, 8)) if rnd.random() > 0.1 else rnd.randint(1, 8)
        if op == 0:
            req = bytes([n]) + (bytes(7) if rnd.random() < 0.3 else b"")
            resp = bytes(rnd.randrange(256) for _ in range(n))
            if rnd.random() < 0.1:
                resp = bytes([rnd.randint(1, 8)]) + bytes(n - 1)  # request-shaped answer
        else:
            req = bytes(rnd.randrange(256) for _ in range(n))
            if rnd.random() < 0.1:
                req = bytes([rnd.randint(1, 8)]) + bytes(n - 1)
            resp = bytes([n]) + (bytes(7) if rnd.random() < 0.3 else b"")
        out.append((CanFrame(t, aid, req), REQUEST, device, address))
        if device != BROADCAST:
            pending[aid] = (op, n, resp)
    return out


@pytest.mark.parametrize("seed", range(8))
def test_random_traffic_directions(seed: int) -> None:
    traffic = _random_traffic(seed, 3000)
    dec = Eg2CanDecoder()
    for i, (fr, direction, device, address) in enumerate(traffic):
        rec = dec.decode(fr, i)
        assert rec.protocol == EG2_CAN
        assert rec.direction == direction, (i, fr, rec.summary)
        assert rec.device == device
        assert rec.fields["address"] == address
        assert rec.index == i
        assert rec.t == fr.t
        assert rec.raw == fr.data
        assert rec.errors == []
        assert rec.pair_key == (fr.arbitration_id,)
        assert rec.expects_response == (direction == REQUEST and device != BROADCAST)


def test_random_traffic_matches_uncached_decoding() -> None:
    """The caches change nothing: a fresh decoder per frame (with the same pending state)
    gives equal records."""
    traffic = _random_traffic(99, 2000)
    cached = Eg2CanDecoder()
    for i, (fr, _, _, _) in enumerate(traffic):
        fresh = Eg2CanDecoder()
        fresh._pending = dict(cached._pending)
        a = cached.decode(fr, i)
        b = fresh.decode(fr, i)
        assert a.to_dict() == b.to_dict()
        assert (a.pair_key, a.expects_response, a.is_save) == (
            b.pair_key,
            b.expects_response,
            b.is_save,
        )


def test_random_garbage_never_raises() -> None:
    rnd = random.Random(3)
    dec = Eg2CanDecoder()
    for i in range(20000):
        fr = CanFrame(
            rnd.choice([None, rnd.random()]),
            rnd.randrange(-5, 1 << 30),
            bytes(rnd.randrange(256) for _ in range(rnd.choice([0, 1, 2, 8, 9, 64]))),
            is_extended=rnd.random() < 0.8,
            is_remote=rnd.random() < 0.05,
            is_error=rnd.random() < 0.05,
            is_fd=rnd.random() < 0.05,
            dlc=rnd.choice([None, None, None, rnd.randrange(16)]),
        )
        rec = dec.decode(fr, i)
        assert rec.protocol in (EG2_CAN, FOREIGN_CAN)
        assert not any("internal decoder error" in e for e in rec.errors), rec.errors
        json.dumps(rec.to_dict())


def test_internal_error_becomes_a_record() -> None:
    rec = Eg2CanDecoder().decode(CanFrame(1.0, "nonsense", b"\x01"), 3)  # type: ignore[arg-type]
    assert rec.protocol == FOREIGN_CAN
    assert rec.errors and "internal decoder error" in rec.errors[0]
    assert rec.index == 3


# -- record hygiene, memo ---------------------------------------------------------------------


def test_lists_are_not_shared_between_records() -> None:
    aid = 0x01180001
    recs = decode_all([frame(aid, "08"), frame(aid, "F3 00 03 E8 00 00 00 22")] * 2)
    recs[1].warnings.append("added by the linter")
    recs[1].errors.append("added by the pairer")
    assert "added by the linter" not in recs[3].warnings
    assert recs[3].errors == []
    recs[0].warnings.append("x")
    assert recs[2].warnings == []


def test_caches_are_bounded() -> None:
    dec = Eg2CanDecoder()
    for i in range(MEMO_LIMIT + 10):
        aid = pack_id(0, 1000 + 2 * (i // 16000), 1 + i % 16000)
        dec.decode(frame(aid, "02"), 2 * i)  # distinct read requests: the memo
        dec.decode(frame(aid, "01 02"), 2 * i + 1)  # their responses: the last-value cache
    assert 0 < len(dec._memo) <= MEMO_LIMIT
    assert 0 < len(dec._last) <= MEMO_LIMIT
    assert len(dec._pending) == 0


def test_bytearray_data() -> None:
    (rec,) = decode_all([CanFrame(None, 0x04FF0001, bytearray.fromhex("0000F401F401"))])  # type: ignore[arg-type]
    assert rec.fields["values"]["CMD_SPEED_SET"] == 500
    assert isinstance(rec.raw, bytes)


def test_record_json_roundtrip() -> None:
    recs = decode_all([frame(0x011A0001, "04", 1.0), frame(0x011A0001, "00 00 01 00", 1.001)])
    for rec in recs:
        d = json.loads(json.dumps(rec.to_dict()))
        assert d["protocol"] == "eg2-can"
        assert d["fields"]["address"] == 1128
        back = Record.from_dict(d)
        assert back.raw == rec.raw
    assert recs[1].to_dict()["raw"] == "00 00 01 00"


def test_finish_returns_nothing() -> None:
    dec = Eg2CanDecoder()
    dec.decode(frame(0x01180001, "08"), 0)
    assert dec.finish() == []


def test_module_is_pure() -> None:
    code = (
        "import sys, decoders.eg2_can; "
        "bad = [m for m in ('can', 'serial', 'mcap', 'rerun', 'textual') if m in sys.modules]; "
        "sys.exit(bool(bad))"
    )
    result = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env={"PYTHONPATH": str(ROOT)})
    assert result.returncode == 0
