"""The pairing stage and the timing linter: hand-built records, and real frames built with
``decoders.build`` and decoded by the protocol decoders."""

from __future__ import annotations

import pytest

from decoders import build
from decoders.eg2_can import Eg2CanDecoder
from decoders.eg2_serial import Cmd, Eg2SerialDecoder
from decoders.flags import (
    CLOSER_THAN_5MS,
    DURING_SAVE,
    ORPHAN_RESPONSE,
    RETRANSMISSION,
    UNANSWERED,
)
from decoders.lint import TimingLinter
from decoders.modbus_rtu import ModbusRtuDecoder
from decoders.model import (
    EG2_CAN,
    EG2_SERIAL,
    FRAME,
    GARBAGE,
    MODBUS_RTU,
    REQUEST,
    RESPONSE,
    CanFrame,
    Chunk,
    Record,
)
from decoders.pairing import Pairer


def rec(
    direction: str,
    device: int,
    t: float | None = None,
    code: int = 0x10,
    protocol: str = EG2_SERIAL,
    bus: str = "serial",
    expects: bool = True,
    save: bool = False,
    data: bytes = b"",
) -> Record:
    """A record as a decoder makes it; the same arguments give the same bytes."""
    return Record(
        t=t,
        bus=bus,
        protocol=protocol,
        kind=FRAME,
        length=6,
        raw=bytes((direction == REQUEST, device & 0xFF, code & 0xFF)) + data,
        direction=direction,
        device=device,
        code=code,
        pair_key=(device, code),
        expects_response=expects and direction == REQUEST,
        is_save=save,
    )


def run(records: list[Record], **kw: float) -> list[Record]:
    p = Pairer(**kw)
    out = p.push_many(records)
    return out + p.flush()


def test_response_linked_to_request_with_latency() -> None:
    req, resp = rec(REQUEST, 1, 10.0), rec(RESPONSE, 1, 10.0004)
    out = run([req, resp])
    assert out == [req, resp]
    assert (req.seq, resp.seq) == (0, 1)
    assert req.pair == 1 and resp.pair == 0
    assert resp.latency_ms == pytest.approx(0.4)
    assert not req.warnings and not resp.warnings
    assert req.flags == resp.flags == []


def test_request_is_held_until_answered_and_order_is_kept() -> None:
    p = Pairer()
    req = rec(REQUEST, 1)
    assert p.push(req) == []  # held: its fate is not known yet
    other = Record(t=None, bus="serial", protocol=EG2_SERIAL, kind="garbage", length=2, raw=b"")
    assert p.push(other) == []  # waits behind the held request: order is kept
    resp = rec(RESPONSE, 1)
    assert p.push(resp) == [req, other, resp]


CAN = {"protocol": EG2_CAN, "bus": "can0"}


@pytest.mark.parametrize(
    ("records", "flagged", "why"),
    [
        # no answer before the next request on a one-question-at-a-time bus
        ([rec(REQUEST, 2), rec(REQUEST, 1), rec(RESPONSE, 1)], 0, "next request"),
        # end of capture
        ([rec(REQUEST, 1)], 0, "end of the capture"),
        # time-out by timestamps
        ([rec(REQUEST, 1, 0.0), rec(RESPONSE, 9, 0.7, code=1)], 0, "within 500 ms"),
        # CAN: another request on the same identifier
        (
            [rec(REQUEST, 1, data=b"\x01", **CAN), rec(REQUEST, 1, data=b"\x02", **CAN)],
            0,
            "next request with the same ID",
        ),
    ],
    ids=["next request", "end", "time-out", "same CAN ID"],
)
def test_unanswered_request_is_flagged(records: list[Record], flagged: int, why: str) -> None:
    out = run(records)
    assert any(why in w for w in out[flagged].warnings), out[flagged].warnings
    assert out[flagged].flags == [UNANSWERED]
    assert out[flagged].pair is None


def test_save_gets_a_longer_timeout() -> None:
    save, resp = rec(REQUEST, 1, 0.0, code=1, save=True), rec(RESPONSE, 1, 0.86, code=1)
    out = run([save, resp])
    assert save.pair == resp.seq and not save.warnings
    assert out == [save, resp]


def test_broadcast_is_never_unanswered() -> None:
    out = run([rec(REQUEST, 255, expects=False), rec(REQUEST, 1), rec(RESPONSE, 1)])
    assert not out[0].warnings and not out[0].flags


def test_response_without_request() -> None:
    out = run([rec(RESPONSE, 1)])
    assert out[0].warnings == ["response without a request"]
    assert out[0].flags == [ORPHAN_RESPONSE]


def test_can_pairs_per_identifier_with_several_outstanding() -> None:
    a, b = rec(REQUEST, 1, **CAN), rec(REQUEST, 2, **CAN)
    rb, ra = rec(RESPONSE, 2, **CAN), rec(RESPONSE, 1, **CAN)
    out = run([a, b, rb, ra])
    assert out == [a, b, rb, ra]
    assert a.pair == ra.seq and b.pair == rb.seq
    assert not any(r.warnings or r.flags for r in out)


def test_buses_are_paired_separately() -> None:
    a, b = rec(REQUEST, 1, bus="left"), rec(REQUEST, 1, bus="right")
    ra, rb = rec(RESPONSE, 1, bus="left"), rec(RESPONSE, 1, bus="right")
    run([a, b, ra, rb])
    assert a.pair == ra.seq and b.pair == rb.seq


def test_a_request_without_a_number_for_its_time_never_times_out() -> None:
    """A NaN time (a hand-edited log) never times a request out, and the requests timed
    around it still do: it takes no place among the time-outs (a NaN there would break their
    order, and another request's time-out would be missed after the clock went back)."""
    nan = rec(REQUEST, 2, float("nan"), **CAN)
    late = rec(REQUEST, 1, 10.0, **CAN)
    back = rec(REQUEST, 3, 0.1, **CAN)  # the clock went back: a second log appended
    answer = rec(RESPONSE, 3, 0.7, **CAN)  # 600 ms later: too late
    out = run([nan, late, back, answer, rec(RESPONSE, 2, 20.0, **CAN)])
    assert back.pair is None and back.flags == [UNANSWERED] and answer.flags == [ORPHAN_RESPONSE]
    assert nan.pair is not None and not nan.flags
    assert late.flags == [UNANSWERED] and out[0] is nan


def test_held_records_are_bounded() -> None:
    p = Pairer(max_held=100)
    out = p.push(rec(REQUEST, 1, code=1))
    assert out == []
    # a flood of CAN traffic behind a serial request that is never answered nor superseded
    for i in range(150):
        out += p.push(rec(RESPONSE, 5, protocol=EG2_CAN, bus="can0", code=i))
    assert len(out) >= 50  # released without waiting for the end of the stream
    assert "pairing window" in out[0].warnings[0]
    assert out[0].flags == [UNANSWERED]


def test_held_bytes_are_bounded_behind_a_request_lost_in_garbage() -> None:
    """A valid-looking request in a random dump, never answered nor followed by another: the
    garbage behind it is released once 64 KiB are held, not at the end of the capture."""
    p = Pairer()
    out = p.push(rec(REQUEST, 1, code=1))
    for i in range(100):
        g = Record(None, "serial", EG2_SERIAL, GARBAGE, 4096, bytes(4096), offset=i * 4096)
        out += p.push(g)
        assert sum(r.length for r in p._held) <= 64 * 1024 + 4096
    assert len(out) >= 80
    assert "pairing window" in out[0].warnings[0] and out[0].flags == [UNANSWERED]


def test_corrupt_frames_are_not_paired() -> None:
    bad = rec(REQUEST, 1)
    bad.errors.append("checksum error: expected 0x0A, got 0x50")
    good, resp = rec(REQUEST, 1), rec(RESPONSE, 1)
    out = run([bad, good, resp])
    assert out == [bad, good, resp]
    assert not bad.warnings and bad.pair is None
    assert good.pair == resp.seq


def test_waiting_before_a_position() -> None:
    """The parallel decoder asks whether a request before a part boundary is still open."""
    p = Pairer(positional=True)
    ask = rec(REQUEST, 1)
    ask.offset = 100
    p.push(ask)
    assert p.waiting_before(101) and not p.waiting_before(100)
    answer = rec(RESPONSE, 1)
    answer.offset = 106
    p.push(answer)
    assert not p.waiting_before(1000)


# -- retransmissions: the same request again before the first answer --------------------------

SERIAL = {"protocol": EG2_SERIAL, "bus": "rs232"}
MODBUS = {"protocol": MODBUS_RTU, "bus": "rs485"}
PROTOCOLS = [SERIAL, MODBUS, CAN]
PROTOCOL_IDS = ["serial", "modbus", "can"]


def _no_false_flags(*records: Record) -> None:
    for r in records:
        assert UNANSWERED not in r.flags and ORPHAN_RESPONSE not in r.flags, r.warnings


@pytest.mark.parametrize("where", PROTOCOLS, ids=PROTOCOL_IDS)
def test_one_answer_to_a_retransmitted_request(where: dict[str, str]) -> None:
    """The host timed out and asked again; one answer came. It goes to the first copy; the
    second is a retransmission, not unanswered, and the answer is no orphan."""
    first, again = rec(REQUEST, 1, 0.000, **where), rec(REQUEST, 1, 0.030, **where)
    answer, nxt = rec(RESPONSE, 1, 0.032, **where), rec(REQUEST, 1, 0.060, code=0x41, **where)
    out = run([first, again, answer, nxt, rec(RESPONSE, 1, 0.061, code=0x41, **where)])
    assert out[:3] == [first, again, answer]
    assert (first.pair, answer.pair) == (answer.seq, first.seq)
    assert first.latency_ms == pytest.approx(32.0)
    assert again.pair is None
    assert again.flags == [RETRANSMISSION]
    assert any("retransmission" in w and "again" in w for w in again.warnings)
    assert first.flags == answer.flags == []
    _no_false_flags(*out)


@pytest.mark.parametrize("where", PROTOCOLS, ids=PROTOCOL_IDS)
def test_two_answers_to_a_retransmitted_request_pair_in_order(where: dict[str, str]) -> None:
    first, again = rec(REQUEST, 1, 0.000, **where), rec(REQUEST, 1, 0.030, **where)
    late, answer = rec(RESPONSE, 1, 0.031, **where), rec(RESPONSE, 1, 0.032, **where)
    out = run([first, again, late, answer])
    assert (first.pair, late.pair) == (late.seq, first.seq)
    assert (again.pair, answer.pair) == (answer.seq, again.seq)
    assert again.latency_ms == pytest.approx(2.0)
    assert [r.flags for r in out] == [[], [RETRANSMISSION], [], []]


@pytest.mark.parametrize("where", PROTOCOLS, ids=PROTOCOL_IDS)
def test_retransmissions_that_got_no_answer_are_unanswered(where: dict[str, str]) -> None:
    copies = [rec(REQUEST, 1, 0.03 * i, **where) for i in range(3)]
    out = run([*copies, rec(RESPONSE, 9, 0.1, code=1, **where)])
    assert [r.flags for r in out[:3]] == [
        [UNANSWERED],
        [RETRANSMISSION, UNANSWERED],
        [RETRANSMISSION, UNANSWERED],
    ]


@pytest.mark.parametrize("where", PROTOCOLS[:2], ids=PROTOCOL_IDS[:2])
def test_a_different_request_still_means_no_answer(where: dict[str, str]) -> None:
    """One question at a time: another request (another command, or the same command with
    other data) ends the wait, as before."""
    asked = rec(REQUEST, 1, 0.0, **where)
    other_data = rec(REQUEST, 1, 0.03, data=b"\x01", **where)
    other_command = rec(REQUEST, 1, 0.06, code=0x41, **where)
    run([asked, other_data, other_command, rec(RESPONSE, 1, 0.07, code=0x41, **where)])
    assert asked.flags == other_data.flags == [UNANSWERED]
    assert any("next request" in w for w in asked.warnings)
    assert other_command.flags == []


@pytest.mark.parametrize("where", PROTOCOLS, ids=PROTOCOL_IDS)
def test_after_an_answer_the_same_request_is_a_new_one(where: dict[str, str]) -> None:
    """A poll answered, then the next identical poll: no retransmission. Also when a copy of
    the answered request is still waiting (its own answer never came)."""
    records = [
        rec(REQUEST, 1, 0.000, **where),
        rec(REQUEST, 1, 0.030, **where),  # retransmission
        rec(RESPONSE, 1, 0.031, **where),  # answers the first
        rec(REQUEST, 1, 0.050, **where),  # the next poll
        rec(RESPONSE, 1, 0.051, **where),
    ]
    out = run(records)
    assert [r.flags for r in out] == [[], [RETRANSMISSION], [], [], []]
    assert out[3].pair == out[4].seq


def test_retransmission_after_the_first_timed_out() -> None:
    """The first copy waited longer than the time-out: it is unanswered, the answer goes to
    the copy still waiting."""
    first, again = rec(REQUEST, 1, 0.0), rec(REQUEST, 1, 0.4)
    answer = rec(RESPONSE, 1, 0.6)
    run([first, again, answer])
    assert first.flags == [UNANSWERED] and first.pair is None
    assert again.flags == [RETRANSMISSION] and again.pair == answer.seq
    assert answer.latency_ms == pytest.approx(200.0)


def test_retransmissions_stay_in_stream_order() -> None:
    p = Pairer()
    first, again, answer = rec(REQUEST, 1, 0.0), rec(REQUEST, 1, 0.03), rec(RESPONSE, 1, 0.031)
    assert p.push(first) == [] and p.push(again) == []
    assert p.push(answer) == [first]  # the copy may still get its own answer
    nxt = rec(REQUEST, 1, 0.05, code=0x41)
    assert p.push(nxt) == [again, answer]
    assert p.flush() == [nxt]


# -- real frames through the decoders ---------------------------------------------------------


def _decode_bytes(
    decoder: Eg2SerialDecoder | ModbusRtuDecoder, frames: list[bytes]
) -> list[Record]:
    chunks = [Chunk(f, 0.03 * i) for i, f in enumerate(frames)]
    records: list[Record] = []
    for chunk in chunks:
        records += decoder.feed(chunk)
    return run(records + decoder.finish())


SERIAL_POLL = build.serial_frame(1, Cmd.READ_ACTPOS)
SERIAL_ANSWER = build.serial_frame(1, Cmd.READ_ACTPOS, build.u16le(497), response=True)
MODBUS_POLL = build.modbus_read_request(1, 1061, 2)
MODBUS_ANSWER = build.modbus_read_response(1, [497, 12])


@pytest.mark.parametrize(
    ("decoder", "poll", "answer"),
    [
        (Eg2SerialDecoder, SERIAL_POLL, SERIAL_ANSWER),
        (ModbusRtuDecoder, MODBUS_POLL, MODBUS_ANSWER),
    ],
    ids=["serial", "modbus"],
)
@pytest.mark.parametrize("answers", [1, 2])
def test_retransmission_on_a_decoded_line(
    decoder: type[Eg2SerialDecoder | ModbusRtuDecoder], poll: bytes, answer: bytes, answers: int
) -> None:
    out = _decode_bytes(decoder("line"), [poll, poll] + [answer] * answers)
    assert [(r.direction, r.flags) for r in out] == [
        (REQUEST, []),
        (REQUEST, [RETRANSMISSION]),
        *[(RESPONSE, [])] * answers,
    ]
    assert out[0].pair == out[2].seq
    assert out[1].pair == (out[3].seq if answers == 2 else None)


@pytest.mark.parametrize("answers", [1, 2])
@pytest.mark.parametrize(
    ("ask", "answer"),
    [
        (build.can_read_request(1, 1128, 4), build.can_read_response(1, 1128, build.u16le(0, 1))),
        (build.can_write_request(1, 1020, build.u16le(500)), build.can_write_response(1, 1020, 2)),
    ],
    ids=["read", "write"],
)
def test_retransmission_on_a_decoded_can_bus(ask: CanFrame, answer: CanFrame, answers: int) -> None:
    dec = Eg2CanDecoder()
    frames = [ask, ask] + [answer] * answers
    out = run([dec.decode(f, i) for i, f in enumerate(frames)])
    assert [(r.direction, r.flags) for r in out] == [
        (REQUEST, []),
        (REQUEST, [RETRANSMISSION]),
        *[(RESPONSE, [])] * answers,
    ]
    assert out[0].pair == out[2].seq
    assert out[1].pair == (out[3].seq if answers == 2 else None)


# -- the timing linter ------------------------------------------------------------------------


def lint(records: list[Record]) -> list[Record]:
    linter = TimingLinter()
    for r in records:
        linter.check(r)
    return records


def test_commands_closer_than_5_ms_are_flagged() -> None:
    a, b, c = rec(REQUEST, 1, 0.0), rec(REQUEST, 1, 0.002), rec(REQUEST, 1, 0.010)
    other = rec(REQUEST, 2, 0.0105)
    lint([a, b, c, other])
    assert not a.warnings and not c.warnings and not other.warnings
    assert "2.00 ms after the previous one" in b.warnings[0]
    assert b.flags == [CLOSER_THAN_5MS]
    assert a.flags == c.flags == other.flags == []


def test_command_within_a_second_of_a_save_is_flagged() -> None:
    save, soon, later = rec(REQUEST, 1, 0.0, save=True), rec(REQUEST, 1, 0.5), rec(REQUEST, 1, 1.6)
    lint([save, soon, later])
    assert "500 ms after a parameter save" in soon.warnings[0]
    assert soon.flags == [DURING_SAVE]
    assert not later.warnings and not later.flags


def test_a_command_can_break_both_rules() -> None:
    save, soon = rec(REQUEST, 1, 0.0, save=True), rec(REQUEST, 1, 0.001)
    lint([save, soon])
    assert soon.flags == [DURING_SAVE, CLOSER_THAN_5MS]
    assert len(soon.warnings) == 2


def test_lint_ignores_untimed_records() -> None:
    a, b = rec(REQUEST, 1), rec(REQUEST, 1)
    lint([a, b])
    assert not a.warnings and not b.warnings
