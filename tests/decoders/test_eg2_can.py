"""The EG2-4X0 CAN decoder: the manual's frames, identifiers, direction, flags, foreign frames."""

from __future__ import annotations

import json
import random
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
from protocol_vectors import load

from decoders import flags as F
from decoders import registers
from decoders.build import (
    can_id,
    can_read_request,
    can_read_response,
    can_write_request,
    can_write_response,
    candump_line,
    u16le,
)
from decoders.eg2_can import (
    _TAG_REQUEST,
    _TAG_RESPONSE,
    BROADCAST,
    MEMO_LIMIT,
    PENDING_TIMEOUT_S,
    RESERVED_BIT,
    Eg2CanDecoder,
    _Directions,
    can_error_text,
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


def test_vectors_present() -> None:
    assert len(CAN_VECTORS) >= 3


VECTOR_CASES = [(v, False) for v in CAN_VECTORS] + [
    (v, True) for v in CAN_VECTORS if "alt_data_padded" in v
]


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
        can_id(0, 1124, 2),
        "02",
        "FE FF",
        "read 2 bytes at 1124 (current)",
        "-> current=-2",
        "CMD_CURRENT",
    ),
    (
        can_id(1, 1022, 3),
        "E8 03",
        "02",
        "write 2 bytes at 1022: speed=1000",
        "-> wrote 2 bytes",
        "CMD_SPEED_SET",
    ),
    (
        can_id(0, 1128, 1),
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
    aid = can_id(0, 1124, 1)
    recs = decode_all([frame(aid, "02"), frame(aid, "FE FF")])
    assert recs[1].fields["values"] == {"CMD_CURRENT": -2}
    assert not recs[1].warnings


# -- identifiers -----------------------------------------------------------------------------

ID_TABLE = [
    (0x04FF0001, 1, 1020, 1),
    (0x01180001, 0, 1120, 1),
    (0x011A0001, 0, 1128, 1),
    (0x00FA8001, 0, 1002, 1),
    (0x04FF3FFF, 1, 1020, BROADCAST),
    (0x08FF0002, 2, 1020, 2),
    (0x0CFF3FFE, 3, 1020, 16382),
    (0x00000000, 0, 0, 0),
    (0x0FFFFFFF, 3, 4095, 16383),
    (0x03FFC000, 0, 4095, 0),
    (0x00004001, 0, 1, 1),
]


@pytest.mark.parametrize("aid,op,address,device", ID_TABLE)
def test_id_packing(aid: int, op: int, address: int, device: int) -> None:
    assert unpack_id(aid) == (op, address, device)
    assert can_id(op, address, device) == aid


def test_id_roundtrip_random() -> None:
    rnd = random.Random(7)
    for _ in range(5000):
        op, address, device = rnd.randrange(4), rnd.randrange(4096), rnd.randrange(16384)
        aid = can_id(op, address, device)
        assert 0 <= aid < RESERVED_BIT
        assert unpack_id(aid) == (op, address, device)


@pytest.mark.parametrize(
    "args", [(4, 1020, 1), (-1, 1020, 1), (0, 4096, 1), (0, -2, 1), (0, 1020, 16384), (1, 0, -1)]
)
def test_can_id_rejects_out_of_range(args: tuple[int, int, int]) -> None:
    with pytest.raises(ValueError):
        can_id(*args)


# J1939 traffic sharing the bus (seen in real Vector and PEAK files): bit 28 set. Below it they
# read as EG2 identifiers (device 16128 and 4325, "positioning move"), which they are not.
RESERVED_BIT_FRAMES = [
    (0x18EBFF00, "01 02 03 04 05 06 07 08"),
    (0x18FF50E5, "00 11 22 33 44 55 66 77"),
    (0x18EFC034, "FF"),
    (can_id(1, 1020, 1) | RESERVED_BIT, "00 00 F4 01 F4 01"),  # an EG2 write with bit 28 set
    (can_id(0, 1120, 1) | RESERVED_BIT, "08"),
    (0x1FFFFFFF, ""),
]


@pytest.mark.parametrize("aid,data", RESERVED_BIT_FRAMES)
@pytest.mark.parametrize("devices", [None, {1, 4325, 16128}], ids=["all", "filtered"])
def test_reserved_bit_frames_are_foreign(aid: int, data: str, devices: set[int] | None) -> None:
    (rec,) = decode_all([frame(aid, data, 2.0)], Eg2CanDecoder(devices=devices))
    assert rec.protocol == FOREIGN_CAN
    assert rec.flags == [F.FOREIGN]
    assert (rec.device, rec.code, rec.name, rec.direction, rec.pair_key) == (None,) * 5
    assert rec.errors == rec.warnings == []
    assert rec.summary == f"extended 0x{aid:08X} [{len(bytes.fromhex(data))}] {data}".rstrip()
    assert "eg2_device" not in rec.fields


def test_reserved_bit_frames_leave_eg2_pairing_alone() -> None:
    """A bit-28 frame with an EG2 request's identifier below it neither answers nor replaces
    the pending request."""
    aid = can_id(1, 1020, 1)
    recs = decode_all(
        [frame(aid, "00 00 F4 01 F4 01"), frame(aid | RESERVED_BIT, "06"), frame(aid, "06")]
    )
    assert [r.protocol for r in recs] == [EG2_CAN, FOREIGN_CAN, EG2_CAN]
    assert [r.direction for r in recs] == [REQUEST, None, RESPONSE]


def test_stats_lists_no_phantom_devices(tmp_path: Path) -> None:
    """J1939 traffic beside one gripper: ``stats`` shows the gripper and foreign frames only."""
    frames = [can_read_request(1, 1128, 4, t=1.0), can_read_response(1, 1128, u16le(0, 1), 1.001)]
    frames += [
        frame(aid, data, 1.002 + i / 1000) for i, (aid, data) in enumerate(RESERVED_BIT_FRAMES)
    ]
    log = tmp_path / "shared_bus.log"
    log.write_text("".join(candump_line(f) + "\n" for f in frames))
    result = subprocess.run(
        [sys.executable, "-m", "analyzer", "stats", str(log), "--format", "json"],
        cwd=ROOT,
        capture_output=True,
        check=True,
    )
    stats = json.loads(result.stdout)
    assert [d["device"] for d in stats["devices"]] == [1]
    assert stats["protocols"] == {EG2_CAN: 2, FOREIGN_CAN: len(RESERVED_BIT_FRAMES)}


def test_device_zero_flagged() -> None:
    (rec,) = decode_all([frame(can_id(0, 1120, 0), "08")])
    assert rec.device == 0
    assert any("device 0" in w for w in rec.warnings)
    assert rec.flags == [F.INVALID_ID]


# -- broadcast, operations 2 and 3 -----------------------------------------------------------


def test_broadcast_write_expects_no_response() -> None:
    aid = can_id(1, 1020, BROADCAST)
    (rec,) = decode_all([frame(aid, "00 00 F4 01 F4 01")])
    assert rec.device == 16383
    assert rec.direction == REQUEST
    assert rec.expects_response is False
    assert rec.fields["broadcast"] is True
    assert rec.pair_key == (aid,)


def test_broadcast_is_never_pending() -> None:
    """Nobody answers a broadcast: the next shape-ambiguous frame on it is a request too."""
    aid = can_id(1, 1012, BROADCAST)
    recs = decode_all([frame(aid, "01"), frame(aid, "01")])
    assert [r.direction for r in recs] == [REQUEST, REQUEST]


@pytest.mark.parametrize(
    "op,text", [(2, "positioning move"), (3, "servo follow")], ids=["op2", "op3"]
)
@pytest.mark.parametrize("data", ["", "01", "00 00 F4 01 F4 01", "01 02 03 04 05 06 07 08"])
def test_operations_2_and_3_raw(op: int, text: str, data: str) -> None:
    aid = can_id(op, 1020, 5)
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
            frame(can_id(0, 1120, 1), "08"),
            frame(can_id(0, 1120, 3), "08"),
            frame(can_id(1, 1012, BROADCAST), "01 00"),
        ],
        dec,
    )
    assert [r.protocol for r in recs] == [EG2_CAN, FOREIGN_CAN, EG2_CAN]
    assert recs[1].summary == f"extended 0x{can_id(0, 1120, 3):08X} [1] 08"
    assert recs[1].fields["eg2_device"] == 3


# -- odd spans, undocumented addresses, range ------------------------------------------------


def test_odd_length_write_flagged_with_leftover_byte() -> None:
    aid = can_id(1, 1020, 1)
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
    aid = can_id(0, 1121, 1)
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
    aid = can_id(0, 1121, 1)
    recs = decode_all([frame(aid, "04"), frame(aid, "03 E8 03 22")])
    resp = recs[1]
    assert resp.fields["values"] == {"CMD_OPENLEN_ACT": 1000}
    assert [p["half"] for p in resp.fields["partial"]] == ["high", "low"]
    assert resp.fields["partial"][1]["register"] == "CMD_CURRENT"


def test_one_byte_read() -> None:
    aid = can_id(0, 1130, 1)
    recs = decode_all([frame(aid, "01"), frame(aid, "05")])
    assert [r.direction for r in recs] == [REQUEST, RESPONSE]
    assert recs[1].fields["partial"][0]["register"] == "CMD_STATUS"
    assert recs[1].fields["values"] == {}


@pytest.mark.parametrize(
    "address,text",
    [(1026, "undocumented address 1026 (register 1013)"), (1200, "outside the register map")],
)
def test_unknown_addresses_flagged(address: int, text: str) -> None:
    aid = can_id(1, address, 1)
    (rec,) = decode_all([frame(aid, "05 00")])
    assert any(text in w for w in rec.warnings), rec.warnings
    assert len(rec.fields["values"]) == 1


def test_write_to_read_only_flagged() -> None:
    (rec,) = decode_all([frame(can_id(1, 1122, 1), "00 00")])
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
    (rec,) = decode_all([frame(can_id(1, address, 1), raw)])
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
    (rec,) = decode_all([frame(can_id(1, address, 1), raw)])
    assert rec.is_save is save


def test_write_response_is_not_a_save() -> None:
    aid = can_id(1, 1002, 1)
    recs = decode_all([frame(aid, "01 00"), frame(aid, "02")])
    assert [r.is_save for r in recs] == [True, False]


# -- direction ------------------------------------------------------------------------------


def test_one_byte_write_request_vs_response_by_pending_table() -> None:
    aid = can_id(1, 1012, 1)  # stop
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
    aid = can_id(1, 1020, 1)
    recs = decode_all([frame(aid, "00 00 F4 01 F4 01"), frame(aid, "04"), frame(aid, "01")])
    # 04 is not the answer to a 6-byte write: it is a new (1-byte) write request
    assert [r.direction for r in recs] == [REQUEST, REQUEST, RESPONSE]


def test_padded_write_response() -> None:
    aid = can_id(1, 1020, 1)
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
    aid = can_id(0, 1130, 1)
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
    aid = can_id(1, 1012, 1)
    late = PENDING_TIMEOUT_S + 0.5
    recs = decode_all([frame(aid, "01", 10.0), frame(aid, "01", 10.0 + late)])
    assert [r.direction for r in recs] == [REQUEST, REQUEST]
    # without times there is no expiry
    recs = decode_all([frame(aid, "01"), frame(aid, "01")])
    assert [r.direction for r in recs] == [REQUEST, RESPONSE]


def test_reset_forgets_pending() -> None:
    dec = Eg2CanDecoder()
    aid = can_id(1, 1012, 1)
    assert dec.decode(frame(aid, "01"), 0).direction == REQUEST
    dec.reset()
    assert dec.decode(frame(aid, "01"), 1).direction == REQUEST


@pytest.mark.parametrize("op", [0, 1])
def test_empty_read_or_write(op: int) -> None:
    (rec,) = decode_all([frame(can_id(op, 1020, 1), "")])
    assert rec.protocol == EG2_CAN
    assert rec.direction is None
    assert rec.errors and "without data" in rec.errors[0]


def test_pairs_are_per_identifier() -> None:
    a, b = can_id(0, 1120, 1), can_id(0, 1120, 2)
    recs = decode_all([frame(a, "08"), frame(b, "08"), frame(b, "01" * 8), frame(a, "02" * 8)])
    assert [r.direction for r in recs] == [REQUEST, REQUEST, RESPONSE, RESPONSE]
    assert [r.device for r in recs] == [1, 2, 2, 1]
    assert [r.pair_key for r in recs] == [(a,), (b,), (b,), (a,)]


# -- retransmissions -------------------------------------------------------------------------


def test_retransmitted_write_expects_two_answers() -> None:
    """A host that times out sends the same write again; the gripper answers both copies."""
    write, ack = can_write_request(1, 1020, u16le(0, 500, 500)), can_write_response(1, 1020, 6)
    recs = decode_all([write, write, ack, ack, ack])
    # the third 06 answers nothing: a 1-byte write request (of the value 6)
    assert [r.direction for r in recs] == [REQUEST, REQUEST, RESPONSE, RESPONSE, REQUEST]


def test_retransmitted_read_expects_two_answers() -> None:
    read, answer = can_read_request(1, 1130, 2), can_read_response(1, 1130, u16le(1))
    ack_shaped = can_read_response(1, 1130, b"\x01\x00")  # state 1 reads like a request of 1
    recs = decode_all([read, read, answer, ack_shaped])
    assert [r.direction for r in recs] == [REQUEST, REQUEST, RESPONSE, RESPONSE]


def test_after_an_answer_the_same_request_is_a_new_one() -> None:
    write, ack = can_write_request(1, 1020, u16le(0)), can_write_response(1, 1020, 2)
    # two copies, one answer; the next identical write starts afresh: one answer due
    recs = decode_all([write, write, ack, write, ack, ack])
    assert [r.direction for r in recs] == [REQUEST, REQUEST, RESPONSE, REQUEST, RESPONSE, REQUEST]


def test_a_different_request_replaces_the_pending_one() -> None:
    aid = can_id(1, 1020, 1)
    recs = decode_all(
        [frame(aid, "00 00"), frame(aid, "E8 03"), frame(aid, "02"), frame(aid, "02")]
    )
    assert [r.direction for r in recs] == [REQUEST, REQUEST, RESPONSE, REQUEST]


def test_the_direction_state_machine_on_its_own() -> None:
    """``_Directions``: the pending table per identifier, its copies, time-out and broadcasts."""
    directions = _Directions()
    read, write = can_id(0, 1120, 1), can_id(1, 1020, 1)
    steps = [
        (read, b"\x08", 0.0, "request", 1),
        (read, b"\x08", 0.03, "request", 1),  # the same again: two answers due
        (write, b"\x00\x00", 0.04, "request", 2),
        (read, bytes(range(8)), 0.05, "response", 2),
        (write, b"\x02", 0.06, "response", 1),
        (read, bytes(range(8)), 0.07, "response", 0),
        (write, b"\x00\x00", 1.0, "request", 1),
        (write, b"\x02", 1.0 + PENDING_TIMEOUT_S + 0.1, "request", 1),  # too late: a request
        (can_id(1, 1020, BROADCAST), b"\x00\x00", 5.0, "request", 1),  # never pending
    ]
    names = {_TAG_REQUEST: "request", _TAG_RESPONSE: "response"}
    for aid, data, t, direction, pending in steps:
        assert names[directions.tag(aid, aid >> 26, data, t)] == direction, (hex(aid), data, t)
        assert len(directions) == pending
    directions.reset()
    assert len(directions) == 0


# -- flags: a code for every warning and error -----------------------------------------------

_READ_8 = can_read_request(1, 1120, 8)
FLAG_CASES: list[tuple[str, list[CanFrame], list[str]]] = [
    ("clean request", [_READ_8], []),
    ("clean response", [_READ_8, can_read_response(1, 1120, u16le(243, 1000, 0, 34))], []),
    (
        "the manual's 1120 response: two values out of range, one code",
        [_READ_8, frame(0x01180001, "F3 00 03 E8 00 00 00 22")],
        [F.OUT_OF_RANGE],
    ),
    ("speed below 10", [can_write_request(1, 1022, u16le(5))], [F.OUT_OF_RANGE]),
    ("odd start address", [can_read_request(1, 1121, 2)], [F.ODD_SPAN]),
    ("odd address and length, one code", [can_read_request(1, 1121, 4)], [F.ODD_SPAN]),
    ("odd length response", [can_read_request(1, 1130, 1), frame(0x011A8001, "09")], [F.ODD_SPAN]),
    (
        "a 1-byte write that reads like an answer, a span that ends inside a register",
        [can_write_request(1, 1012, b"\x01")],
        [F.ODD_SPAN, F.AMBIGUOUS_DIRECTION],
    ),
    ("undocumented address", [can_write_request(1, 1026, u16le(5))], [F.UNDOCUMENTED]),
    ("two undocumented, one code", [can_write_request(1, 1026, u16le(5, 6))], [F.UNDOCUMENTED]),
    ("outside the register map", [can_read_request(1, 1200, 2)], [F.UNDOCUMENTED]),
    ("write to read-only", [can_write_request(1, 1122, u16le(0))], [F.READ_ONLY_WRITE]),
    (
        "response length mismatch",
        [_READ_8, can_read_response(1, 1120, u16le(243, 1000))],
        [F.LENGTH_MISMATCH],
    ),
    (
        "a padded read answer that reads like a request",
        [can_read_request(1, 1120, 8, padded=True), frame(0x01180001, "08" + " 00" * 7)],
        [F.AMBIGUOUS_DIRECTION],
    ),
    (
        "a padded 8-byte write that reads like an answer",
        [can_write_request(1, 1002, b"\x01" + bytes(7))],
        [F.AMBIGUOUS_DIRECTION],
    ),
    ("device 0", [can_read_request(0, 1120, 8)], [F.INVALID_ID]),
    ("positioning move", [frame(can_id(2, 1020, 1), "00 00 F4 01 F4 01")], [F.UNDOCUMENTED]),
    ("read without data", [frame(can_id(0, 1020, 1), "")], [F.MALFORMED]),
    ("11-bit frame", [CanFrame(1.0, 0x123, b"\x01", is_extended=False)], [F.FOREIGN]),
    ("remote frame", [CanFrame(1.0, 0x04FF0001, b"", is_remote=True, dlc=6)], [F.FOREIGN]),
    ("J1939 frame", [frame(0x18FF50E5, "01 02")], [F.FOREIGN]),
    (
        "error frame",
        [CanFrame(1.0, 0x80, bytes(8), is_error=True)],
        [F.FOREIGN, F.CAN_ERROR_FRAME],
    ),
    ("DLC mismatch", [CanFrame(1.0, 0x01180001, bytes(8), dlc=12)], [F.FOREIGN, F.MALFORMED]),
    ("9 bytes", [CanFrame(1.0, 0x01180001, bytes(9))], [F.FOREIGN, F.MALFORMED]),
    ("identifier too wide", [CanFrame(1.0, 0x3FFFFFFF, b"\x01")], [F.FOREIGN, F.MALFORMED]),
    (
        "decoder error",
        [CanFrame(1.0, "nonsense", b"\x01")],  # type: ignore[arg-type]
        [F.FOREIGN, F.DECODER_ERROR],
    ),
]


@pytest.mark.parametrize(
    "frames,flags", [c[1:] for c in FLAG_CASES], ids=[c[0] for c in FLAG_CASES]
)
def test_flags(frames: list[CanFrame], flags: list[str]) -> None:
    rec = decode_all(frames)[-1]
    assert rec.flags == flags
    assert bool(rec.flags) == bool(rec.errors or rec.warnings or rec.protocol == FOREIGN_CAN)


def _check_flags(rec: Record) -> None:
    """Codes from flags.py, each once, one for every problem; `foreign` exactly on `can`."""
    assert set(rec.flags) <= F.ALL
    assert len(rec.flags) == len(set(rec.flags))
    assert (F.FOREIGN in rec.flags) == (rec.protocol == FOREIGN_CAN)
    others = [f for f in rec.flags if f != F.FOREIGN]
    assert len(others) <= len(rec.errors) + len(rec.warnings)
    if rec.errors or rec.warnings:
        assert rec.flags


@pytest.mark.parametrize("seed", range(3))
def test_every_record_of_random_traffic_has_its_flags(seed: int) -> None:
    dec = Eg2CanDecoder()
    for i, (fr, _, _, _) in enumerate(_random_traffic(seed, 3000, retransmit=0.1)):
        _check_flags(dec.decode(fr, i))


# -- random request/response traffic ---------------------------------------------------------

DOCUMENTED = sorted(registers.BY_CAN_ADDRESS)


def _random_traffic(
    seed: int, count: int, retransmit: float = 0.0
) -> list[tuple[CanFrame, str | None, int, int]]:
    """(frame, true direction, device, address): requests and responses of several devices,
    interleaved across identifiers, each identifier strictly request-then-response. With
    ``retransmit``, a host sends a pending request again now and then, before its first answer
    (when the copy cannot be taken for that answer), and the gripper answers every copy."""
    rnd = random.Random(seed)
    devices = [1, 2, 3, 7, 254, 16382]
    # aid -> [request, response data, copies, answered, time of the last copy]
    pending: dict[int, list[Any]] = {}
    out: list[tuple[CanFrame, str | None, int, int]] = []
    t = 1000.0
    while len(out) < count:
        t += rnd.uniform(0.0001, 0.01)
        if pending and rnd.random() < retransmit:
            aid = rnd.choice(list(pending))
            req, resp, copies, answered, _ = pending[aid]
            op, n = aid >> 26, len(resp) if aid >> 26 == 0 else len(req)
            if answered:
                continue  # the next request would be a new one
            if len(req) == n if op == 0 else req == bytes([n]) + bytes(n - 1) and n in (1, 8):
                continue  # shaped like its own answer: the copy would be taken as one
            pending[aid][2] += 1
            pending[aid][4] = t
            out.append((CanFrame(t, aid, req), REQUEST, aid & 0x3FFF, (aid >> 14) & 0xFFF))
            continue
        oldest = min(pending, key=lambda a: pending[a][4], default=None)
        if oldest is not None and (rnd.random() < 0.5 or t - pending[oldest][4] > 1.0):
            # answer, the oldest before the decoder forgets it (PENDING_TIMEOUT_S)
            aid = oldest if t - pending[oldest][4] > 1.0 else rnd.choice(list(pending))
            req, resp, copies, answered, _ = pending[aid]
            if copies == 1:
                del pending[aid]
            else:
                pending[aid][2:4] = [copies - 1, True]
            out.append((CanFrame(t, aid, resp), RESPONSE, aid & 0x3FFF, (aid >> 14) & 0xFFF))
            continue
        device = rnd.choice(devices) if rnd.random() > 0.05 else BROADCAST
        op = rnd.choice((0, 1))
        address = rnd.choice(DOCUMENTED) if rnd.random() > 0.1 else rnd.randrange(4096)
        aid = can_id(op, address, device)
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
            pending[aid] = [req, resp, 1, False, t]
    return out


@pytest.mark.parametrize("retransmit", [0.0, 0.15], ids=["once", "retransmitted"])
@pytest.mark.parametrize("seed", range(8))
def test_random_traffic_directions(seed: int, retransmit: float) -> None:
    traffic = _random_traffic(seed, 3000, retransmit)
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
    traffic = _random_traffic(99, 2000, retransmit=0.1)
    cached = Eg2CanDecoder()
    for i, (fr, _, _, _) in enumerate(traffic):
        fresh = Eg2CanDecoder()
        fresh._directions._pending = dict(cached._directions._pending)
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
        _check_flags(rec)
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
    recs[1].flags.append("added")
    recs[2].flags.append("added")
    assert recs[3].flags == [F.OUT_OF_RANGE] and recs[0].flags == []


def test_caches_are_bounded() -> None:
    dec = Eg2CanDecoder()
    for i in range(MEMO_LIMIT + 10):
        aid = can_id(0, 1000 + 2 * (i // 16000), 1 + i % 16000)
        dec.decode(frame(aid, "02"), 2 * i)  # distinct read requests: the memo
        dec.decode(frame(aid, "01 02"), 2 * i + 1)  # their responses: the last-value cache
    assert 0 < len(dec._memo) <= MEMO_LIMIT
    assert 0 < len(dec._last) <= MEMO_LIMIT
    assert len(dec._directions) == 0


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


def test_module_is_pure() -> None:
    code = (
        "import sys, decoders.eg2_can; "
        "bad = [m for m in ('can', 'serial', 'mcap', 'rerun', 'textual') if m in sys.modules]; "
        "sys.exit(bool(bad))"
    )
    result = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env={"PYTHONPATH": str(ROOT)})
    assert result.returncode == 0
