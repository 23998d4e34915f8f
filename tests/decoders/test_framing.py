"""The byte-stream framing both line decoders share (``decoders/framing.py``), on the serial
and the Modbus RTU decoder alike: garbage runs stay bounded, a damaged frame right after garbage
keeps its own record, and times are estimated inside a chunk when the line's byte time is known.
Every stream is fed whole, in random chunks and one byte at a time."""

from __future__ import annotations

import random
from collections.abc import Callable
from typing import Any

import pytest

from decoders import build as b
from decoders import eg2_serial
from decoders import flags as F
from decoders.eg2_serial import Cmd, Eg2SerialDecoder
from decoders.framing import MAX_GARBAGE, ByteStreamDecoder
from decoders.modbus_rtu import ModbusRtuDecoder
from decoders.model import EG2_SERIAL, FRAME, GARBAGE, MODBUS_RTU, TRUNCATED, Chunk, Record
from decoders.registry import STREAM_DECODERS


def h(text: str) -> bytes:
    return bytes.fromhex(text)


BYTE_115200 = 10 / 115200  # seconds per byte at 115200 baud, 8N1
LONGEST_FRAME = 9 + 255  # a Modbus write-multiple request with a full byte count

DECODERS: dict[str, Callable[..., ByteStreamDecoder]] = {
    EG2_SERIAL: Eg2SerialDecoder,
    MODBUS_RTU: ModbusRtuDecoder,
}

# a request and its response, per protocol
PAIRS: dict[str, tuple[bytes, bytes]] = {
    EG2_SERIAL: (
        b.serial_frame(1, Cmd.READ_ACTPOS),
        b.serial_frame(1, Cmd.READ_ACTPOS, b.u16le(500), response=True),
    ),
    MODBUS_RTU: (b.modbus_read_request(1, 1061, 4), b.modbus_read_response(1, [500, 3, 36, 0])),
}


# -- feeding -----------------------------------------------------------------------------------


def whole(data: bytes) -> list[bytes]:
    return [data]


def bytewise(data: bytes) -> list[bytes]:
    return [data[i : i + 1] for i in range(len(data))]


def random_chunks(data: bytes, seed: int = 1) -> list[bytes]:
    rng = random.Random(seed)
    out, i = [], 0
    while i < len(data):
        n = rng.choice((1, 2, 3, 7, 13, 64, 300, 5000))
        out.append(data[i : i + n])
        i += n
    return out


FEEDS = [pytest.param(f, id=f.__name__) for f in (whole, random_chunks, bytewise)]


def decode(protocol: str, chunks: list[bytes], **kw: Any) -> list[Record]:
    dec = DECODERS[protocol](**kw)
    out: list[Record] = []
    for c in chunks:
        out += dec.feed(Chunk(c))
    return out + dec.finish()


def assert_accounting(records: list[Record], data: bytes) -> None:
    """Every input byte in exactly one record, in order."""
    pos = 0
    for r in records:
        assert r.offset == pos, (r.kind, r.offset, pos)
        assert r.raw == data[pos : pos + r.length] and r.length > 0
        pos += r.length
    assert pos == len(data)


def shape(records: list[Record]) -> list[tuple[Any, ...]]:
    return [(r.kind, r.offset, r.length, tuple(r.errors), tuple(r.flags)) for r in records]


# -- garbage stays bounded (issue 7 item 20) -----------------------------------------------------


@pytest.mark.parametrize(
    ("protocol", "size"),
    [(EG2_SERIAL, 3_000_000), (MODBUS_RTU, 600_000)],  # Modbus tries every byte: slower
)
def test_random_dump_garbage_records_and_held_bytes_stay_bounded(protocol: str, size: int) -> None:
    data = random.Random(20).randbytes(size)
    reads = [data[i : i + 65536] for i in range(0, size, 65536)]
    shapes = []
    for chunks in (whole(data), random_chunks(data, 3), reads):
        dec = DECODERS[protocol]()
        records: list[Record] = []
        for c in chunks:
            records += dec.feed(Chunk(c, t=0.0))
            # what is held between reads: an open garbage run and one undecided candidate
            assert len(dec._buf) < MAX_GARBAGE + 2 * LONGEST_FRAME
            assert len(dec._times) <= len(dec._buf) + 1
        records += dec.finish()
        assert_accounting(records, data)
        garbage = [r for r in records if r.kind == GARBAGE]
        assert len(garbage) > size // MAX_GARBAGE // 2
        assert max(r.length for r in garbage) <= MAX_GARBAGE
        shapes.append(shape(records))
    assert shapes[1] == shapes[0] and shapes[2] == shapes[0]


@pytest.mark.parametrize("feed", FEEDS)
@pytest.mark.parametrize(
    ("protocol", "filler"),
    [(EG2_SERIAL, b"\x00"), (EG2_SERIAL, b"\x5a\xa5"), (MODBUS_RTU, b"\xff")],
)
def test_long_garbage_run_is_cut_at_the_same_places_however_fed(
    protocol: str, filler: bytes, feed: Callable[[bytes], list[bytes]]
) -> None:
    frame = PAIRS[protocol][0]
    run = (filler * 10_000)[:10_000]
    data = frame + run + frame
    records = decode(protocol, feed(data))
    assert_accounting(records, data)
    assert [(r.kind, r.offset, r.length) for r in records] == [
        (FRAME, 0, len(frame)),
        (GARBAGE, len(frame), MAX_GARBAGE),
        (GARBAGE, len(frame) + MAX_GARBAGE, MAX_GARBAGE),
        (GARBAGE, len(frame) + 2 * MAX_GARBAGE, 10_000 - 2 * MAX_GARBAGE),
        (FRAME, len(frame) + 10_000, len(frame)),
    ]
    assert all(r.flags == [F.GARBAGE] for r in records if r.kind == GARBAGE)


def test_noise_fed_byte_by_byte_is_looked_at_once(monkeypatch: pytest.MonkeyPatch) -> None:
    """A noisy live line read a byte at a time: the bytes of an open garbage run are decided
    once, not again on every read (the work stays linear in the input)."""
    calls = 0
    frame_at = ModbusRtuDecoder.frame_at

    def counted(self: ModbusRtuDecoder, buf: bytearray, pos: int, final: bool) -> int:
        nonlocal calls
        calls += 1
        return frame_at(self, buf, pos, final)

    monkeypatch.setattr(ModbusRtuDecoder, "frame_at", counted)
    noise = b"\x07\xff" * 5000  # no function 0xFF, no slave address 0xFF
    records = decode(MODBUS_RTU, bytewise(noise))
    assert_accounting(records, noise)
    assert [r.length for r in records] == [MAX_GARBAGE, MAX_GARBAGE, len(noise) - 2 * MAX_GARBAGE]
    assert calls <= 2 * len(noise)


# -- a damaged frame right after garbage (issue 7 item 19) ---------------------------------------

SERIAL_CATCH = b.serial_frame(1, Cmd.MOVE_CATCH_XG, b.u16le(500, 100))
MODBUS_RESPONSE = b.modbus_read_response(1, [1, 2, 3, 4])
# per protocol: a frame damaged in its last byte, and the error it gets (expected vs actual)
DAMAGED: dict[str, tuple[bytes, str]] = {
    EG2_SERIAL: (
        SERIAL_CATCH[:-1] + b"\x35",
        f"checksum error: expected 0x{SERIAL_CATCH[-1]:02X}, got 0x35",
    ),
    MODBUS_RTU: (
        MODBUS_RESPONSE[:-1] + b"\x00",
        f"CRC error: expected {MODBUS_RESPONSE[-2]:02X} {MODBUS_RESPONSE[-1]:02X}, "
        f"got {MODBUS_RESPONSE[-2]:02X} 00",
    ),
}
SERIAL_OK = b.serial_frame(1, Cmd.MOVE_STOPHERE, b"\x01", response=True)
MODBUS_READ = b.modbus_read_request(1, 1061, 4)

# (protocol, the garbage before the damaged frame, what follows it)
AFTER_GARBAGE: list[tuple[str, bytes, bytes]] = [
    # a header in the garbage claims more bytes than the stream holds before the good frame
    (EG2_SERIAL, h("F9 38 C6 04 72 EE 16 47 49"), SERIAL_OK),
    (EG2_SERIAL, h("4E EE 16 02 E5 EE"), SERIAL_OK),
    # ... or a span that ends inside the good frame
    (EG2_SERIAL, h("EB 90 01 0A"), SERIAL_OK),
    (EG2_SERIAL, h("EB 90 01 0C 00"), SERIAL_CATCH),
    # plain noise, and the end of the stream after the damaged frame
    (EG2_SERIAL, h("00 11 22"), SERIAL_OK),
    (EG2_SERIAL, h("00 11 EB EE"), b""),
    # Modbus: bytes that read as the start of a long frame (byte count 0x42, 0xFA, ...)
    (MODBUS_RTU, h("BC B1 42 B8 3A 02 C3 C7 61"), MODBUS_READ),
    (MODBUS_RTU, h("88 81 A4 C5 DC 4C EC 19 39 09 AE 01 AD 3D"), MODBUS_READ),
    (MODBUS_RTU, h("07 03 FA 00"), MODBUS_READ),
    (MODBUS_RTU, h("FF FF FF"), MODBUS_READ),
    (MODBUS_RTU, h("FF 07"), b""),
]


@pytest.mark.parametrize("feed", FEEDS)
@pytest.mark.parametrize(
    ("protocol", "junk", "after"),
    [pytest.param(*row, id=f"{row[0]}-{row[1].hex()}-{len(row[2])}") for row in AFTER_GARBAGE],
)
def test_damaged_frame_right_after_garbage_keeps_its_own_record(
    protocol: str, junk: bytes, after: bytes, feed: Callable[[bytes], list[bytes]]
) -> None:
    first = PAIRS[protocol][0]  # a good frame first, so the bus state is a usual one
    damaged, error = DAMAGED[protocol]
    data = first + junk + damaged + after
    records = decode(protocol, feed(data))
    assert_accounting(records, data)
    at = len(first)
    want = [(FRAME, 0), (GARBAGE, at), (FRAME, at + len(junk))]
    if after:
        want.append((FRAME, at + len(junk) + len(damaged)))
    assert [(r.kind, r.offset) for r in records] == want
    assert records[1].raw == junk
    bad = records[2]
    assert bad.raw == damaged
    assert bad.errors == [error]
    assert bad.flags == [F.BAD_CHECKSUM]
    assert all(r.ok for r in records[3:])


# -- times inside a chunk (issue 7 item 18) ------------------------------------------------------


@pytest.mark.parametrize("protocol", [EG2_SERIAL, MODBUS_RTU])
def test_request_and_response_in_one_read_get_times_counted_back(protocol: str) -> None:
    req, resp = PAIRS[protocol]
    bt = BYTE_115200
    dec = STREAM_DECODERS[protocol]("line", byte_time_s=bt)
    # the adapter returned both frames in one read at t = 100.0 (when the last byte came)
    a, z = dec.feed(Chunk(req + resp, t=100.0)) + dec.finish()
    assert a.t == pytest.approx(100.0 - (len(req) + len(resp)) * bt)
    assert z.t == pytest.approx(100.0 - len(resp) * bt)
    assert z.t - a.t == pytest.approx(len(req) * bt)
    assert a.flags == z.flags == [F.ESTIMATED_TIME]
    assert a.ok and z.ok
    # without a byte time both keep the read's time, as before
    plain = STREAM_DECODERS[protocol]("line")
    a, z = plain.feed(Chunk(req + resp, t=100.0)) + plain.finish()
    assert a.t == z.t == 100.0
    assert a.flags == z.flags == []


@pytest.mark.parametrize("protocol", [EG2_SERIAL, MODBUS_RTU])
def test_record_alone_in_its_read_is_not_flagged(protocol: str) -> None:
    req, resp = PAIRS[protocol]
    bt = BYTE_115200
    dec = DECODERS[protocol](byte_time_s=bt)
    a, z = dec.feed(Chunk(req, t=5.0)) + dec.feed(Chunk(resp, t=5.004)) + dec.finish()
    assert a.t == pytest.approx(5.0 - len(req) * bt)  # when its first byte came
    assert z.t == pytest.approx(5.004 - len(resp) * bt)
    assert a.flags == z.flags == []


@pytest.mark.parametrize("protocol", [EG2_SERIAL, MODBUS_RTU])
def test_times_counted_back_over_any_chunking_of_a_steady_line(protocol: str) -> None:
    """Bytes arriving back to back at line speed: whatever reads they come in, each record's
    time is when its first byte arrived."""
    req, resp = PAIRS[protocol]
    data = (req + resp + b"\xff\xff") * 20 + req[:5]
    bt, t0 = BYTE_115200, 50.0
    for chunks in (whole(data), random_chunks(data, 7), bytewise(data)):
        dec = DECODERS[protocol](byte_time_s=bt)
        records: list[Record] = []
        end = 0
        for c in chunks:
            end += len(c)
            records += dec.feed(Chunk(c, t=t0 + end * bt))
        records += dec.finish()
        assert_accounting(records, data)
        assert records[-1].kind == TRUNCATED
        for r in records:
            assert r.t == pytest.approx(t0 + (r.offset or 0) * bt)


def test_continuous_line_gives_no_false_silence() -> None:
    """A chunk that arrives 64 byte-times after the previous one came without a pause: with the
    byte time known, no silence is seen before it, so a bad frame followed by noise stays
    garbage as in the bare bytes (the silence hint would make it a frame)."""
    bad = bytearray(b.modbus_read_response(1, [1, 2, 3]))
    bad[-1] ^= 0xFF
    req = b.modbus_read_request(1, 1061, 3)
    noise = b"\xff" * 64
    bare = decode(MODBUS_RTU, [req + bytes(bad) + noise])
    assert [(r.kind, r.length) for r in bare] == [(FRAME, 8), (GARBAGE, len(bad) + 64)]
    bt, t1 = BYTE_115200, 1.0
    reads = [Chunk(req + bytes(bad), t=t1), Chunk(noise, t=t1 + len(noise) * bt)]
    dec = ModbusRtuDecoder(byte_time_s=bt)
    records = dec.feed(reads[0]) + dec.feed(reads[1]) + dec.finish()
    assert [(r.kind, r.length) for r in records] == [(FRAME, 8), (GARBAGE, len(bad) + 64)]
    # read as arrival times of first bytes, the same reads show a 5.6 ms silence
    dec = ModbusRtuDecoder()
    records = dec.feed(reads[0]) + dec.feed(reads[1]) + dec.finish()
    assert [(r.kind, r.length) for r in records] == [(FRAME, 8), (FRAME, len(bad)), (GARBAGE, 64)]
    # a real silence before the noise (5 ms after the bad frame's last byte) makes it a frame
    dec = ModbusRtuDecoder(byte_time_s=bt)
    records = dec.feed(Chunk(req + bytes(bad), t=t1))
    records += dec.feed(Chunk(noise, t=t1 + 0.005 + len(noise) * bt))
    records += dec.finish()
    assert [(r.kind, r.length) for r in records] == [(FRAME, 8), (FRAME, len(bad)), (GARBAGE, 64)]


@pytest.mark.parametrize("protocol", [EG2_SERIAL, MODBUS_RTU])
def test_byte_time_must_be_positive(protocol: str) -> None:
    for bad in (0.0, -1e-4):
        with pytest.raises(ValueError, match="byte_time_s"):
            STREAM_DECODERS[protocol]("line", byte_time_s=bad)


# -- one home for each thing (issue 6 item 6) ----------------------------------------------------


def test_frames_are_encoded_in_build_only_and_no_unread_limit_is_left() -> None:
    """The decoders check frames; decoders.build makes them (the tests use it)."""
    assert not hasattr(eg2_serial, "build_frame")
    for cls in (ByteStreamDecoder, Eg2SerialDecoder, ModbusRtuDecoder):
        assert not hasattr(cls, "max_frame")
    frame = b.serial_frame(1, Cmd.MOVE_CATCH_XG, b.u16le(500, 100))
    (r,) = decode(EG2_SERIAL, [frame])
    assert r.ok and r.name == "CMD_MC_MOVE_CATCH_XG"
    assert eg2_serial.checksum(frame[2:-1]) == frame[-1]
