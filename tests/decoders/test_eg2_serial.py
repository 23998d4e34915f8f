"""The EG2 regular serial decoder: the manual's frames, the field evidence of section 4, and the
framing guarantees (every byte accounted for, the same records however the bytes arrive)."""

from __future__ import annotations

import json
import random
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from protocol_vectors import VECTORS_PATH, params

from decoders import eg2_serial
from decoders import flags as F
from decoders.build import serial_frame
from decoders.eg2_serial import COMMANDS, Cmd, Eg2SerialDecoder
from decoders.framing import NEED_MORE
from decoders.model import FRAME, GARBAGE, REQUEST, RESPONSE, TRUNCATED, Chunk, Record


def h(text: str) -> bytes:
    return bytes.fromhex(text)


# -- helpers ---------------------------------------------------------------------------------


def decode(data: bytes, sizes: list[int] | None = None, bus: str = "serial") -> list[Record]:
    """Feed data in chunks of the given sizes (cycled; whole when None), then finish."""
    dec = Eg2SerialDecoder(bus)
    out: list[Record] = []
    if sizes is None:
        out += dec.feed(Chunk(data))
    else:
        i = k = 0
        while i < len(data):
            n = sizes[k % len(sizes)]
            out += dec.feed(Chunk(data[i : i + n]))
            i += n
            k += 1
    return out + dec.finish()


def one(data: bytes) -> Record:
    records = decode(data)
    assert len(records) == 1, [(r.kind, r.raw.hex()) for r in records]
    return records[0]


def random_sizes(rng: random.Random, total: int) -> list[int]:
    sizes = []
    while total > 0:
        n = rng.choice((1, 2, 3, 5, 7, 13, 64, 300))
        sizes.append(n)
        total -= n
    return sizes


def signature(records: list[Record]) -> list[tuple[Any, ...]]:
    return [(r.offset, r.length, r.kind, r.raw, tuple(r.errors), tuple(r.flags)) for r in records]


def assert_flags(records: list[Record]) -> None:
    """Every error and warning has its code, each code at most once; no code without words."""
    for r in records:
        assert len(set(r.flags)) == len(r.flags), r.flags
        assert set(r.flags) <= F.ALL
        assert bool(r.flags) == bool(r.errors or r.warnings), (r.flags, r.errors, r.warnings)
        assert len(r.flags) <= len(r.errors) + len(r.warnings)


def assert_accounting(records: list[Record], data: bytes) -> None:
    """Every input byte in exactly one record, in order, each with its flags."""
    pos = 0
    for r in records:
        assert r.offset == pos, (r.kind, r.offset, pos)
        assert r.length == len(r.raw) > 0
        assert data[pos : pos + r.length] == r.raw
        pos += r.length
    assert pos == len(data)
    assert_flags(records)


# payload sizes of the documented layouts, so generated frames are mostly well formed
_REQUEST_SIZES = {0x04: (1, 2), 0x10: (4,), 0x18: (4,), 0x11: (2,), 0x54: (2,), 0x12: (4,)}
_RESPONSE_SIZES = {0x13: (4,), 0xD9: (2,), 0x14: (6,), 0x41: (7,)}


def random_frames(rng: random.Random, n: int) -> list[bytes]:
    """n valid frames: every known CMD both ways, some hand codes and unknown codes, any ID."""
    codes = [*COMMANDS, 0x00, 0x99, 0xFF]
    frames = []
    for _ in range(n):
        code = rng.choice(codes)
        direction = rng.choice((REQUEST, RESPONSE))
        if direction == REQUEST:
            size = rng.choice(_REQUEST_SIZES.get(code, (0,)))
        else:
            size = rng.choice(_RESPONSE_SIZES.get(code, (1,)))
        if code in (0x00, 0x99, 0xFF, 0x51, 0xDC):
            size = rng.randint(0, 13)
        device = rng.choice((1, 1, 2, 3, 254, 255, rng.randint(0, 255)))
        frames.append(serial_frame(device, code, rng.randbytes(size), direction == RESPONSE))
    return frames


# -- the manual's worked frames -----------------------------------------------------------


@pytest.mark.parametrize("vector", params("eg2_serial"))
@pytest.mark.parametrize("side", ["request", "response"])
def test_vector(vector: dict[str, Any], side: str) -> None:
    code_text, short = vector["request_fields"]["cmd"].split()
    code = int(code_text, 16)
    r = one(h(vector[side]))
    assert r.kind == FRAME
    assert r.errors == []
    assert r.warnings == []
    assert r.direction == side
    assert r.device == 1
    assert r.code == code
    assert r.name is not None and short in r.name
    assert r.name == COMMANDS[code].name
    assert r.summary
    for key, want in vector[f"{side}_fields"].items():
        if key == "cmd":
            continue  # checked above as code and name
        if key == "id":
            assert r.device == want
        assert r.fields[key] == want, key


def test_vectors_cover_every_gripper_command() -> None:
    entries = json.loads(VECTORS_PATH.read_text())["eg2_serial"]
    seen = {int(e["request_fields"]["cmd"].split()[0], 16) for e in entries}
    gripper = {code for code, c in COMMANDS.items() if "hand-compatible" not in c.verb}
    assert seen == gripper - {0x14}  # the manual prints no 0x14 frame


def test_bad_vector_checksum() -> None:
    r = one(h("EE 16 01 03 D9 E8 03 74"))
    assert r.kind == FRAME
    assert r.errors == ["checksum error: expected 0xC8, got 0x74"]
    assert not r.ok
    # the rest of the decode is kept
    assert r.name == "CMD_MC_READ_ACTPOS"
    assert r.fields["position"] == 1000
    assert r.fields["position_mm"] == 70.0


def test_bad_vector_write_failure() -> None:
    r = one(h("EE 16 01 02 12 55 6A"))
    assert r.ok
    assert r.direction == RESPONSE
    assert r.name == "CMD_MC_SET_EG_PARA"
    assert r.fields["status"] == "failure"
    assert r.summary == "-> FAILED (0x55)"
    assert r.warnings == ["write failure status 0x55 (the host should resend)"]


@pytest.mark.parametrize("vector", params("eg2_serial_bad"))
def test_bad_vectors_are_flagged(vector: dict[str, Any]) -> None:
    r = one(h(vector["bytes"]))
    assert r.kind == FRAME
    assert r.errors or r.warnings


# -- the decode table (pymodbus style: bytes in, decode out) ----------------------------------


def frame(direction: str, device: int, code: int, data: str = "") -> bytes:
    return serial_frame(device, code, h(data), direction == RESPONSE)


Q, A = REQUEST, RESPONSE

# (bytes, name, summary, fields subset, errors, warnings)
DECODES: list[tuple[bytes, str, str, dict[str, Any], list[str], list[str]]] = [
    # the manual's frames and their summaries
    (h("EB 90 01 01 01 03"), "CMD_MC_PARA_SAVE", "save parameters", {}, [], []),
    (h("EE 16 01 02 01 01 05"), "CMD_MC_PARA_SAVE", "-> ok", {"status": "ok"}, [], []),
    (
        h("EB 90 01 02 04 03 0A"),
        "CMD_MC_PARA_ID_SET",
        "set ID 1 -> 3",
        {"new_id": 3, "id_width": 1},
        [],
        [],
    ),
    (
        h("EB 90 01 05 10 F4 01 64 00 6F"),
        "CMD_MC_MOVE_CATCH_XG",
        "catch speed=500 force=100 g",
        {"speed": 500, "force_g": 100},
        [],
        [],
    ),
    (
        h("EB 90 01 05 18 F4 01 64 00 77"),
        "CMD_MC_MOVE_CATCH2_XG",
        "continuous catch speed=500 force=100 g",
        {"speed": 500, "force_g": 100},
        [],
        [],
    ),
    (
        h("EB 90 01 03 11 F4 01 0A"),
        "CMD_MC_MOVE_RELEASE",
        "release speed=500",
        {"speed": 500},
        [],
        [],
    ),
    (
        h("EB 90 01 03 54 F4 01 4D"),
        "CMD_MC_SEEKPOS",
        "seek position=500 (35.0 mm)",
        {"position": 500, "position_mm": 35.0, "alias": "CMD_MC_SET_DRVALL_SEEKANGLE_GYH"},
        [],
        [],
    ),
    (h("EB 90 01 01 16 18"), "CMD_MC_MOVE_STOPHERE", "stop", {}, [], []),
    (
        h("EB 90 01 05 12 E8 03 70 00 73"),
        "CMD_MC_SET_EG_PARA",
        "set limits max=1000 (70.0 mm) min=112 (7.84 mm)",
        {"max": 1000, "min": 112, "max_mm": 70.0, "min_mm": 7.84},
        [],
        [],
    ),
    (h("EB 90 01 01 13 15"), "CMD_MC_READ_EG_PARA", "read limits", {}, [], []),
    (
        h("EE 16 01 05 13 E8 03 70 00 74"),
        "CMD_MC_READ_EG_PARA",
        "-> max=1000 (70.0 mm) min=112 (7.84 mm)",
        {"max": 1000, "min": 112},
        [],
        [],
    ),
    (
        h("EE 16 01 03 D9 F1 01 CF"),
        "CMD_MC_READ_ACTPOS",
        "-> position=497 (34.79 mm)",
        {"position": 497, "position_mm": 34.79, "alias": "CMD_MC_READ_DRVALL_CURANGLE_GYH"},
        [],
        [],
    ),
    (
        h("EE 16 01 08 41 01 00 23 E8 03 64 00 BD"),
        "CMD_MC_READ_EG_RUNSTATE",
        "-> state=1 fully open, idle, no fault, 35 °C, position=1000 (70.0 mm), "
        "force setting=100 g",
        {
            "state": 1,
            "state_text": "fully open, idle",
            "fault": 0,
            "fault_text": [],
            "temperature_c": 35,
            "position": 1000,
            "position_mm": 70.0,
            "force_setting_g": 100,
        },
        [],
        [],
    ),
    (h("EB 90 01 01 17 19"), "CMD_MC_ERROR_CLR", "clear faults", {}, [], []),
    # run state with faults and an unknown state
    (
        frame(A, 2, 0x41, "04 05 51 F4 01 C8 00"),
        "CMD_MC_READ_EG_RUNSTATE",
        "-> state=4 closing, stall, over-current, 81 °C, position=500 (35.0 mm), "
        "force setting=200 g",
        {"fault": 5, "fault_text": ["stall", "over-current"], "temperature_c": 81},
        [],
        ["gripper reports fault: stall, over-current"],
    ),
    (
        frame(A, 2, 0x41, "09 00 20 F4 01 C8 00"),
        "CMD_MC_READ_EG_RUNSTATE",
        "-> state=9 unknown state 9, no fault, 32 °C, position=500 (35.0 mm), force setting=200 g",
        {"state": 9},
        [],
        ["state out of range (1-6): 9"],
    ),
    # set ID with a two-byte value (section 4), and to an invalid ID
    (
        frame(Q, 1, 0x04, "03 00"),
        "CMD_MC_PARA_ID_SET",
        "set ID 1 -> 3 (2-byte value)",
        {"new_id": 3, "id_width": 2},
        [],
        [],
    ),
    (
        frame(Q, 1, 0x04, "00"),
        "CMD_MC_PARA_ID_SET",
        "set ID 1 -> 0",
        {"new_id": 0},
        [],
        ["new_id out of range (1-254): 0"],
    ),
    (
        frame(Q, 1, 0x04, "2C 01"),
        "CMD_MC_PARA_ID_SET",
        "set ID 1 -> 300 (2-byte value)",
        {"new_id": 300, "id_width": 2},
        [],
        ["new_id out of range (1-254): 300"],
    ),
    # 0x14: undocumented reply, a probable layout when six bytes come back
    (frame(Q, 1, 0x14), "CMD_MC_READ_EG_STATE", "read state", {}, [], []),
    (
        frame(A, 1, 0x14, "F4 01 20 00 64 00"),
        "CMD_MC_READ_EG_STATE",
        "-> F4 01 20 00 64 00, probable layout (unverified): opening=500 (35.0 mm) force=32 "
        "force threshold=100",
        {
            "data": "F4 01 20 00 64 00",
            "probable": {"opening": 500, "force": 32, "force_threshold": 100},
        },
        [],
        [],
    ),
    (
        frame(A, 1, 0x14, "F4 01 20"),
        "CMD_MC_READ_EG_STATE",
        "-> 3 data bytes F4 01 20 (layout not documented)",
        {"data": "F4 01 20"},
        [],
        [],
    ),
    # out-of-range values (section 4: a client sends speed 5000)
    (
        frame(Q, 1, 0x11, "88 13"),
        "CMD_MC_MOVE_RELEASE",
        "release speed=5000",
        {"speed": 5000},
        [],
        ["speed out of range (1-1000): 5000"],
    ),
    (
        frame(Q, 1, 0x10, "88 13 14 00"),
        "CMD_MC_MOVE_CATCH_XG",
        "catch speed=5000 force=20 g",
        {"speed": 5000, "force_g": 20},
        [],
        ["speed out of range (1-1000): 5000", "force out of range (50-1000): 20"],
    ),
    (
        frame(Q, 1, 0x54, "00 00"),
        "CMD_MC_SEEKPOS",
        "seek position=0 (0.0 mm)",
        {"position": 0},
        [],
        ["position out of range (1-1000): 0"],
    ),
    (
        frame(Q, 1, 0x12, "D0 07 00 00"),
        "CMD_MC_SET_EG_PARA",
        "set limits max=2000 (140.0 mm) min=0 (0.0 mm)",
        {"max": 2000, "min": 0},
        [],
        ["max out of range (0-1000): 2000"],
    ),
    # statuses
    (
        frame(A, 1, 0x10, "55"),
        "CMD_MC_MOVE_CATCH_XG",
        "-> FAILED (0x55)",
        {"status": "failure"},
        [],
        ["write failure status 0x55 (the host should resend)"],
    ),
    (
        frame(A, 1, 0x17, "07"),
        "CMD_MC_ERROR_CLR",
        "-> unknown status 0x07",
        {"status": "unknown 0x07"},
        [],
        ["unknown status byte 0x07 (0x01 is ok, 0x55 failure)"],
    ),
    # payloads that do not fit the documented layout: raw data and an error, no crash
    (
        frame(Q, 1, 0x10, "F4 01 64"),
        "CMD_MC_MOVE_CATCH_XG",
        "catch unexpected data F4 01 64",
        {"data": "F4 01 64"},
        ["CMD_MC_MOVE_CATCH_XG request: expected 4 data bytes, got 3"],
        [],
    ),
    (
        frame(Q, 1, 0x16, "01"),
        "CMD_MC_MOVE_STOPHERE",
        "stop unexpected data 01",
        {"data": "01"},
        ["CMD_MC_MOVE_STOPHERE request: expected 0 data bytes, got 1"],
        [],
    ),
    (
        frame(A, 1, 0x10),
        "CMD_MC_MOVE_CATCH_XG",
        "-> unexpected data (none)",
        {"data": ""},
        ["CMD_MC_MOVE_CATCH_XG response: expected 1 data byte (status), got 0"],
        [],
    ),
    (
        frame(A, 1, 0x41, "01 00 23 E8 03 64"),
        "CMD_MC_READ_EG_RUNSTATE",
        "-> unexpected data 01 00 23 E8 03 64",
        {"data": "01 00 23 E8 03 64"},
        ["CMD_MC_READ_EG_RUNSTATE response: expected 7 data bytes, got 6"],
        [],
    ),
    (
        frame(Q, 1, 0x04, "01 02 03"),
        "CMD_MC_PARA_ID_SET",
        "set ID unexpected data 01 02 03",
        {"data": "01 02 03"},
        ["CMD_MC_PARA_ID_SET request: expected 1 or 2 data bytes, got 3"],
        [],
    ),
    # the hand's form of 0x54 (six u16): not the gripper's layout, values shown
    (
        frame(Q, 1, 0x54, "E8 03 E8 03 E8 03 E8 03 E8 03 E8 03"),
        "CMD_MC_SEEKPOS",
        "seek unexpected data E8 03 E8 03 E8 03 E8 03 E8 03 E8 03",
        {"values": [1000] * 6, "alias": "CMD_MC_SET_DRVALL_SEEKANGLE_GYH"},
        ["CMD_MC_SEEKPOS request: expected 2 data bytes, got 12"],
        [],
    ),
    # hand-compatible codes: u16 values by LEN, an odd byte shown raw
    (
        frame(Q, 1, 0x51, "F4 01 F4 01"),
        "CMD_MC_SET_DRVALL_SPEED",
        "set speed (hand-compatible) values=500,500",
        {"values": [500, 500]},
        [],
        [],
    ),
    (frame(A, 1, 0x51, "01"), "CMD_MC_SET_DRVALL_SPEED", "-> ok", {"status": "ok"}, [], []),
    (
        frame(Q, 1, 0x52, "64 00 07"),
        "CMD_MC_SET_DRVALL_YBP_THRESHOLD",
        "set force threshold (hand-compatible) values=100 extra=07",
        {"values": [100], "extra": "07"},
        [],
        [],
    ),
    (frame(Q, 1, 0xD2), "CMD_MC_READ_DRVALL_SPEED", "read speed (hand-compatible)", {}, [], []),
    (
        frame(A, 1, 0xD2, "F4 01"),
        "CMD_MC_READ_DRVALL_SPEED",
        "-> values=500",
        {"values": [500]},
        [],
        [],
    ),
    (
        frame(A, 1, 0xD3, "64 00"),
        "CMD_MC_READ_DRVALL_YBP_THRESHOLD",
        "-> values=100",
        {"values": [100]},
        [],
        [],
    ),
    (
        frame(A, 1, 0xD7, "E8 03"),
        "CMD_MC_READ_DRVALL_SEEKGYHANGLE",
        "-> values=1000",
        {"values": [1000]},
        [],
        [],
    ),
    (
        frame(A, 1, 0xDC, "01 00 02"),
        "CMD_MC_READ_HAND_STATUS",
        "-> values=1 extra=02",
        {"values": [1], "extra": "02"},
        [],
        [],
    ),
    # unknown commands are frames too (section 1.2), named by code, bytes shown
    (
        frame(Q, 1, 0x99, "01 02"),
        "UNKNOWN_0x99",
        "unknown command 0x99: 01 02",
        {"data": "01 02"},
        [],
        ["unknown command 0x99 (in neither the gripper's nor the hand's table)"],
    ),
    (
        frame(A, 7, 0x00),
        "UNKNOWN_0x00",
        "unknown command 0x00",
        {"id": 7, "data": ""},
        [],
        ["unknown command 0x00 (in neither the gripper's nor the hand's table)"],
    ),
    # IDs
    (frame(Q, 0, 0x16), "CMD_MC_MOVE_STOPHERE", "stop", {"id": 0}, [], ["ID 0 is not a valid ID"]),
    (
        frame(A, 255, 0x16, "01"),
        "CMD_MC_MOVE_STOPHERE",
        "-> ok",
        {"id": 255},
        [],
        ["response from broadcast ID 255 (broadcasts get no response)"],
    ),
    (
        frame(Q, 255, 0x04, "05"),
        "CMD_MC_PARA_ID_SET",
        "set ID 255 -> 5",
        {"new_id": 5},
        [],
        ["set ID sent to broadcast: every gripper on the bus takes the new ID"],
    ),
    # a bad checksum keeps the decode and adds the error first
    (
        h("EB 90 01 05 10 88 13 64 00 00"),
        "CMD_MC_MOVE_CATCH_XG",
        "catch speed=5000 force=100 g",
        {"speed": 5000},
        ["checksum error: expected 0x15, got 0x00"],
        ["speed out of range (1-1000): 5000"],
    ),
]


@pytest.mark.parametrize(
    ("raw", "name", "summary", "fields", "errors", "warnings"),
    DECODES,
    ids=[f"{d[0].hex()}" for d in DECODES],
)
def test_decode_table(
    raw: bytes,
    name: str,
    summary: str,
    fields: dict[str, Any],
    errors: list[str],
    warnings: list[str],
) -> None:
    r = one(raw)
    assert r.kind == FRAME
    assert r.name == name
    assert r.code == raw[4]
    assert r.device == raw[2] == r.fields["id"]
    assert r.direction == (REQUEST if raw[0] == 0xEB else RESPONSE)
    assert r.summary == summary
    for key, want in fields.items():
        assert r.fields[key] == want, key
    assert r.errors == errors
    assert r.warnings == warnings
    # JSONL-safe: the fields serialise as they are
    assert json.loads(json.dumps(r.to_dict()))["fields"] == r.fields


# (bytes, the record's flags): every error and warning text carries its code (issue 6)
FLAGS: list[tuple[str, bytes, list[str]]] = [
    ("valid", h("EB 90 01 05 10 F4 01 64 00 6F"), []),
    ("bad checksum", h("EE 16 01 03 D9 E8 03 74"), [F.BAD_CHECKSUM]),
    ("bad checksum, speed", h("EB 90 01 05 10 88 13 64 00 00"), [F.BAD_CHECKSUM, F.OUT_OF_RANGE]),
    ("short payload", frame(Q, 1, 0x10, "F4 01"), [F.MALFORMED]),
    ("status without data", frame(A, 1, 0x16), [F.MALFORMED]),
    ("run state of 6 bytes", frame(A, 1, 0x41, "01 00 23 E8 03 64"), [F.MALFORMED]),
    ("write failed", h("EE 16 01 02 12 55 6A"), [F.WRITE_FAILED]),
    ("unknown status", frame(A, 1, 0x10, "07"), [F.UNDOCUMENTED]),
    ("speed", frame(Q, 1, 0x11, "88 13"), [F.OUT_OF_RANGE]),
    ("speed and force: one code", frame(Q, 1, 0x10, "88 13 10 27"), [F.OUT_OF_RANGE]),
    ("limits", frame(Q, 1, 0x12, "D0 07 00 00"), [F.OUT_OF_RANGE]),
    ("seek position 0", frame(Q, 1, 0x54, "00 00"), [F.OUT_OF_RANGE]),
    ("run state fault", frame(A, 1, 0x41, "03 05 23 E8 03 64 00"), [F.DEVICE_FAULT]),
    (
        "run state: state, fault, position, force",
        frame(A, 1, 0x41, "09 01 23 D0 07 0A 00"),
        [F.OUT_OF_RANGE, F.DEVICE_FAULT],
    ),
    ("new ID 0", frame(Q, 1, 0x04, "00"), [F.OUT_OF_RANGE]),
    ("set ID to broadcast", frame(Q, 255, 0x04, "05"), [F.BROADCAST]),
    ("broadcast catch", frame(Q, 255, 0x10, "F4 01 64 00"), []),
    ("response from broadcast", frame(A, 255, 0x16, "01"), [F.BROADCAST]),
    ("ID 0", frame(Q, 0, 0x16), [F.INVALID_ID]),
    ("ID 0, bad checksum", h("EB 90 00 01 16 00"), [F.BAD_CHECKSUM, F.INVALID_ID]),
    ("unknown command", frame(Q, 3, 0xA5, "10 20 30"), [F.UNDOCUMENTED]),
    ("hand code write failed", frame(A, 1, 0x51, "55"), [F.WRITE_FAILED]),
    ("0x14 reply of 4 bytes", frame(A, 1, 0x14, "01 02 03 04"), []),
]


@pytest.mark.parametrize(("raw", "flags"), [pytest.param(*row[1:], id=row[0]) for row in FLAGS])
def test_flags_table(raw: bytes, flags: list[str]) -> None:
    r = one(raw)
    assert r.flags == flags
    assert_flags([r])
    assert json.loads(json.dumps(r.to_dict()))["flags"] == flags


def test_unknown_command_summary() -> None:
    r = one(frame(Q, 3, 0xA5, "10 20 30"))
    assert r.ok
    assert r.name == "UNKNOWN_0xA5"
    assert r.summary.startswith("unknown command 0xA5")
    assert "10 20 30" in r.summary
    assert r.fields["data"] == "10 20 30"


# -- the record around the decode -------------------------------------------------------------


def test_record_attributes() -> None:
    raw = h("EB 90 01 05 10 F4 01 64 00 6F")
    dec = Eg2SerialDecoder("ttyUSB0")
    assert dec.feed(Chunk(b"\x00" * 3, t=10.0)) == []  # garbage waits for its end
    garbage, r = dec.feed(Chunk(raw, t=10.5))
    assert (garbage.kind, garbage.t, garbage.length) == (GARBAGE, 10.0, 3)
    assert r.t == 10.5
    assert r.bus == "ttyUSB0"
    assert r.protocol == "eg2-serial"
    assert r.kind == FRAME
    assert r.offset == 3
    assert r.index is None
    assert r.length == len(raw) == 10
    assert r.raw == raw
    assert (r.seq, r.pair, r.latency_ms) == (-1, None, None)
    d = r.to_dict()
    assert d["raw"] == "EB 90 01 05 10 F4 01 64 00 6F"
    assert d["direction"] == "request"
    assert d["code"] == 0x10


@pytest.mark.parametrize(
    ("raw", "pair_key", "expects_response", "is_save"),
    [
        (h("EB 90 01 01 01 03"), (1, 0x01), True, True),
        (h("EE 16 01 02 01 01 05"), (1, 0x01), False, False),
        (h("EB 90 01 05 10 F4 01 64 00 6F"), (1, 0x10), True, False),
        (h("EE 16 01 02 10 01 14"), (1, 0x10), False, False),
        (frame(Q, 255, 0x10, "F4 01 64 00"), (255, 0x10), False, False),
        (frame(Q, 255, 0x01), (255, 0x01), False, True),
        (frame(Q, 9, 0x99), (9, 0x99), True, False),
    ],
)
def test_pairing_attributes(
    raw: bytes, pair_key: tuple[int, int], expects_response: bool, is_save: bool
) -> None:
    r = one(raw)
    assert r.pair_key == pair_key
    assert r.expects_response is expects_response
    assert r.is_save is is_save


def test_records_do_not_share_lists() -> None:
    raw = h("EE 16 01 03 D9 E8 03 74") + h("EE 16 01 03 D9 E8 03 74")
    a, b = decode(raw)
    a.errors.append("added by a later stage")
    a.warnings.append("added by a later stage")
    a.flags.append(F.UNANSWERED)
    assert b.errors == ["checksum error: expected 0xC8, got 0x74"]
    assert b.warnings == []
    assert b.flags == [F.BAD_CHECKSUM]
    (c,) = decode(raw[:8])
    assert c.errors == ["checksum error: expected 0xC8, got 0x74"]
    assert c.warnings == []
    assert c.flags == [F.BAD_CHECKSUM]


def test_cache_stays_bounded(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(eg2_serial, "_CACHE_MAX", 16)
    frames = [frame(Q, 1, 0x54, f"{v:02X} 01") for v in range(100)]
    records = decode(b"".join(frames))
    assert [r.fields["position"] for r in records] == [256 + v for v in range(100)]
    assert len(eg2_serial._CACHE) <= 16


def test_make_record_never_raises_on_odd_bytes() -> None:
    dec = Eg2SerialDecoder()
    for raw in (b"", b"\xeb", h("EB 90 01"), h("EB 90 01 05 10"), h("AA BB 01 01 16 18")):
        r = dec.make_record(raw, 0, None, False)
        assert r.errors and r.errors[0].startswith("malformed frame")
        assert r.flags == [F.MALFORMED]


def test_command_table_is_keyed_by_cmd() -> None:
    """Every CMD byte is named once, in Cmd; the table describes each and takes its name."""
    assert set(COMMANDS) == set(Cmd)
    for code, cmd in COMMANDS.items():
        assert isinstance(code, Cmd) and cmd.code is code
        assert cmd.name == f"CMD_MC_{code.name}"
    assert Cmd(0x10).name == "MOVE_CATCH_XG"
    assert one(frame(Q, 1, Cmd.PARA_SAVE)).is_save


# -- frame_at and next_start ---------------------------------------------------------------


@pytest.mark.parametrize(
    ("buf", "pos", "want"),
    [
        (h("EB 90 01 01 16 18"), 0, 6),
        (h("EE 16 01 02 16 01 1A"), 0, 7),
        (h("00 EE 16 01 02 16 01 1A"), 1, 7),
        (h("EB 90 01 01 16 19"), 0, -6),  # bad SUM
        (h("EB 90 01 01 16"), 0, NEED_MORE),
        (h("EB 90 01"), 0, NEED_MORE),
        (h("EB 90"), 0, NEED_MORE),
        (h("EB"), 0, NEED_MORE),
        (h("EE"), 0, NEED_MORE),
        (h("EB 91"), 0, 0),
        (h("EE 90 01"), 0, 0),
        (h("90 EB 01 01 16 18"), 0, 0),
        (h("01"), 0, 0),
        (h("EB 90 01 00 01"), 0, 0),  # LEN 0: no CMD
        (h("EB 90 02 FF") + bytes(256), 0, -260),  # the longest frame
        (h("EB 90 01 FF") + bytes(256), 0, 260),
        (h("EB 90 02 FF") + bytes(255), 0, NEED_MORE),
    ],
)
def test_frame_at(buf: bytes, pos: int, want: int) -> None:
    dec = Eg2SerialDecoder()
    assert dec.frame_at(bytearray(buf), pos, False) == want
    assert dec.frame_at(bytearray(buf), pos, True) == want


@pytest.mark.parametrize(
    ("buf", "pos", "want"),
    [
        (h("EB 90 01"), 0, 0),
        (h("00 00 EE 16"), 0, 2),
        (h("00 EB 00 EE 16 EB 90"), 0, 3),
        (h("00 EB 00 EE 16 EB 90"), 4, 5),
        (h("00 00 00"), 0, 3),
        (h("00 00 EB"), 0, 2),  # a header may be arriving
        (h("00 00 EE"), 1, 2),
        (h("EB EB 90"), 0, 1),
        (h("EE EE 16"), 0, 1),
        (h("16 90 EB"), 0, 2),
        (b"", 0, 0),
    ],
)
def test_next_start(buf: bytes, pos: int, want: int) -> None:
    assert Eg2SerialDecoder().next_start(bytearray(buf), pos) == want


# -- framing does not depend on how the bytes arrive --------------------------------------


def _vector_stream() -> bytes:
    vectors = json.loads(VECTORS_PATH.read_text())
    parts = [h(v[side]) for v in vectors["eg2_serial"] for side in ("request", "response")]
    parts += [h(v["bytes"]) for v in vectors["eg2_serial_bad"]]
    return b"".join(parts)


def _random_stream() -> bytes:
    return b"".join(random_frames(random.Random(7), 3000))


def _dirty_stream() -> bytes:
    """Frames with garbage, bad checksums and bad lengths between them."""
    rng = random.Random(11)
    parts = []
    for f in random_frames(rng, 1500):
        roll = rng.random()
        if roll < 0.1:
            parts.append(rng.randbytes(rng.randint(1, 12)))
        elif roll < 0.15:
            f = f[:-1] + bytes(((f[-1] + 1) & 0xFF,))  # bad SUM
        elif roll < 0.18:
            f = f[:3] + bytes((rng.randint(1, 40),)) + f[4:]  # bad LEN
        parts.append(f)
    return b"".join(parts)


@pytest.mark.parametrize("make", [_vector_stream, _random_stream, _dirty_stream])
def test_chunking_does_not_matter(make: Any) -> None:
    data = make()
    whole = decode(data)
    assert_accounting(whole, data)
    rng = random.Random(3)
    for _ in range(3):
        chunks = decode(data, random_sizes(rng, len(data)))
        assert signature(chunks) == signature(whole)
    bytewise = decode(data, [1])
    assert signature(bytewise) == signature(whole)


def test_vector_stream_is_all_frames() -> None:
    data = _vector_stream()
    records = decode(data)
    assert all(r.kind == FRAME for r in records)
    assert sum(1 for r in records if not r.ok) == 1  # the manual's bad 0xD9 reply


def test_random_stream_is_all_valid_frames() -> None:
    frames = random_frames(random.Random(7), 3000)
    records = decode(b"".join(frames))
    assert [r.raw for r in records] == frames
    assert all(r.kind == FRAME and not any("checksum" in e for e in r.errors) for r in records)


# -- garbage, bad checksums, bad lengths, truncation --------------------------------------

STOP = h("EB 90 01 01 16 18")
OK = h("EE 16 01 02 16 01 1A")
CATCH = h("EB 90 01 05 10 F4 01 64 00 6F")


def kinds(records: list[Record]) -> list[tuple[str, bytes]]:
    return [(r.kind, r.raw) for r in records]


@pytest.mark.parametrize(
    ("data", "want"),
    [
        # garbage between frames is one record per run, holding exactly those bytes
        (
            h("01 02 03") + STOP + h("AA BB") + OK,
            [(GARBAGE, h("01 02 03")), (FRAME, STOP), (GARBAGE, h("AA BB")), (FRAME, OK)],
        ),
        # header-like bytes that are not a header
        (h("EB 00 EE 90 EB") + CATCH, [(GARBAGE, h("EB 00 EE 90 EB")), (FRAME, CATCH)]),
        # LEN 0 is not a frame
        (h("EB 90 01 00 01") + STOP, [(GARBAGE, h("EB 90 01 00 01")), (FRAME, STOP)]),
        # trailing garbage
        (STOP + h("00 11 22"), [(FRAME, STOP), (GARBAGE, h("00 11 22"))]),
        # truncated frame at the end of the stream
        (STOP + OK + CATCH[:5], [(FRAME, STOP), (FRAME, OK), (TRUNCATED, CATCH[:5])]),
        (STOP + h("EB 90 01"), [(FRAME, STOP), (TRUNCATED, h("EB 90 01"))]),
        (STOP + h("EE"), [(FRAME, STOP), (TRUNCATED, h("EE"))]),
        (h("55") + CATCH[:9], [(GARBAGE, h("55")), (TRUNCATED, CATCH[:9])]),
    ],
)
def test_stream_shapes(data: bytes, want: list[tuple[str, bytes]]) -> None:
    for sizes in (None, [1], [3, 1, 4]):
        records = decode(data, sizes)
        assert kinds(records) == want
        assert_accounting(records, data)


def test_bad_checksum_then_decoding_continues() -> None:
    bad = CATCH[:-1] + b"\x70"
    data = STOP + bad + OK + CATCH
    records = decode(data)
    assert kinds(records) == [(FRAME, STOP), (FRAME, bad), (FRAME, OK), (FRAME, CATCH)]
    assert records[1].errors == ["checksum error: expected 0x6F, got 0x70"]
    assert records[1].fields["speed"] == 500
    assert all(r.ok for i, r in enumerate(records) if i != 1)
    assert_accounting(records, data)


def test_corrupted_len_resynchronises_inside_the_candidate() -> None:
    # EB 90 01 0A claims 15 bytes; the valid STOP frame starts inside that span
    bad_head = h("EB 90 01 0A")
    data = bad_head + STOP + OK + CATCH
    dec = Eg2SerialDecoder()
    assert dec.frame_at(bytearray(data), 0, False) == -15  # a complete, failing candidate
    for sizes in (None, [1], [2, 5]):
        records = decode(data, sizes)
        assert kinds(records) == [(GARBAGE, bad_head), (FRAME, STOP), (FRAME, OK), (FRAME, CATCH)]
        assert records[0].errors and "garbage" in records[0].errors[0]
        assert_accounting(records, data)


def test_truncated_record_says_why() -> None:
    records = decode(STOP + CATCH[:7])
    assert records[-1].kind == TRUNCATED
    assert records[-1].offset == len(STOP)
    assert records[-1].errors == ["truncated frame: LEN 5 needs 10 bytes, stream ended after 7"]
    records = decode(h("EB 90"))
    assert records[-1].errors == [
        "truncated frame: stream ended 2 bytes in, before the length byte"
    ]


def test_live_feed_waits_for_the_rest_of_a_frame() -> None:
    dec = Eg2SerialDecoder()
    assert dec.feed(Chunk(CATCH[:6])) == []
    (r,) = dec.feed(Chunk(CATCH[6:]))
    assert r.ok and r.raw == CATCH
    assert dec.finish() == []


# -- properties ---------------------------------------------------------------------------

NOT_HEADER = st.binary(max_size=20).map(lambda b: bytes(x for x in b if x not in (0xEB, 0xEE)))
VALID_FRAME = st.builds(
    serial_frame,
    st.integers(0, 255),
    st.integers(0, 255),
    st.binary(max_size=24),
    st.booleans(),
)
CHUNK_SIZES = st.lists(st.integers(1, 40), min_size=1, max_size=8)


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.binary(max_size=600), sizes=CHUNK_SIZES)
def test_any_bytes_are_accounted_for(data: bytes, sizes: list[int]) -> None:
    records = decode(data, sizes)
    assert_accounting(records, data)
    assert signature(records) == signature(decode(data))
    for r in records:
        assert r.kind in (FRAME, GARBAGE, TRUNCATED)
        if r.kind == FRAME:
            assert r.raw[:2] in (b"\xeb\x90", b"\xee\x16")
            assert r.length == r.raw[3] + 5
        else:
            assert r.errors


@settings(max_examples=300, deadline=None)
@given(
    pieces=st.lists(st.tuples(NOT_HEADER, VALID_FRAME), max_size=12),
    tail=NOT_HEADER,
    sizes=CHUNK_SIZES,
)
def test_spliced_frames_are_all_found(
    pieces: list[tuple[bytes, bytes]], tail: bytes, sizes: list[int]
) -> None:
    data = b""
    want = []
    for junk, f in pieces:
        data += junk
        want.append((len(data), f))
        data += f
    data += tail
    records = decode(data, sizes)
    assert_accounting(records, data)
    found = [(r.offset, r.raw) for r in records if r.kind == FRAME]
    assert found == want
    assert all(r.kind == GARBAGE for r in records if r.kind != FRAME)
    assert not any(e.startswith("checksum") for r in records for e in r.errors)


@settings(max_examples=200, deadline=None)
@given(frames=st.lists(VALID_FRAME, max_size=10), sizes=CHUNK_SIZES)
def test_decoded_fields_survive_reencoding(frames: list[bytes], sizes: list[int]) -> None:
    data = b"".join(frames)
    records = decode(data, sizes)
    assert [r.raw for r in records] == frames
    dec = Eg2SerialDecoder()
    assert [dec.frame_at(bytearray(f), 0, False) for f in frames] == [len(f) for f in frames]
    for r in records:
        assert r.direction in (REQUEST, RESPONSE)
        assert r.code is not None and r.device is not None
        assert r.name is not None and r.summary
        rebuilt = serial_frame(r.device, r.code, r.raw[5:-1], r.direction == RESPONSE)
        assert rebuilt == r.raw
