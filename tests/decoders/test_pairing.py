"""The pairing stage and the timing linter, on hand-built records."""

from __future__ import annotations

import pytest

from decoders.lint import TimingLinter
from decoders.model import EG2_CAN, EG2_SERIAL, FRAME, REQUEST, RESPONSE, Record
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
) -> Record:
    return Record(
        t=t,
        bus=bus,
        protocol=protocol,
        kind=FRAME,
        length=6,
        raw=b"",
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


def test_request_is_held_until_answered_and_order_is_kept() -> None:
    p = Pairer()
    req = rec(REQUEST, 1)
    assert p.push(req) == []  # held: its fate is not known yet
    other = Record(t=None, bus="serial", protocol=EG2_SERIAL, kind="garbage", length=2, raw=b"")
    assert p.push(other) == []  # waits behind the held request: order is kept
    resp = rec(RESPONSE, 1)
    assert p.push(resp) == [req, other, resp]


@pytest.mark.parametrize(
    ("records", "flagged", "why"),
    [
        # no answer before the next request on a one-question-at-a-time bus
        ([rec(REQUEST, 2), rec(REQUEST, 1), rec(RESPONSE, 1)], 0, "next request"),
        # end of capture
        ([rec(REQUEST, 1)], 0, "end of the capture"),
        # time-out by timestamps
        ([rec(REQUEST, 1, 0.0), rec(RESPONSE, 9, 0.7, code=1)], 0, "within 500 ms"),
    ],
)
def test_unanswered_request_is_flagged(records: list[Record], flagged: int, why: str) -> None:
    out = run(records)
    assert any(why in w for w in out[flagged].warnings), out[flagged].warnings
    assert out[flagged].pair is None


def test_save_gets_a_longer_timeout() -> None:
    save, resp = rec(REQUEST, 1, 0.0, code=1, save=True), rec(RESPONSE, 1, 0.86, code=1)
    out = run([save, resp])
    assert save.pair == resp.seq and not save.warnings
    assert out == [save, resp]


def test_broadcast_is_never_unanswered() -> None:
    out = run([rec(REQUEST, 255, expects=False), rec(REQUEST, 1), rec(RESPONSE, 1)])
    assert not out[0].warnings


def test_response_without_request() -> None:
    out = run([rec(RESPONSE, 1)])
    assert out[0].warnings == ["response without a request"]


def test_can_pairs_per_identifier_with_several_outstanding() -> None:
    a, b = (
        rec(REQUEST, 1, protocol=EG2_CAN, bus="can0"),
        rec(REQUEST, 2, protocol=EG2_CAN, bus="can0"),
    )
    rb, ra = (
        rec(RESPONSE, 2, protocol=EG2_CAN, bus="can0"),
        rec(RESPONSE, 1, protocol=EG2_CAN, bus="can0"),
    )
    out = run([a, b, rb, ra])
    assert out == [a, b, rb, ra]
    assert a.pair == ra.seq and b.pair == rb.seq
    assert not any(r.warnings for r in out)


def test_buses_are_paired_separately() -> None:
    a, b = rec(REQUEST, 1, bus="left"), rec(REQUEST, 1, bus="right")
    ra, rb = rec(RESPONSE, 1, bus="left"), rec(RESPONSE, 1, bus="right")
    run([a, b, ra, rb])
    assert a.pair == ra.seq and b.pair == rb.seq


def test_held_records_are_bounded() -> None:
    p = Pairer(max_held=100)
    out = p.push(rec(REQUEST, 1, code=1))
    assert out == []
    # a flood of CAN traffic behind a serial request that is never answered nor superseded
    for i in range(150):
        out += p.push(rec(RESPONSE, 5, protocol=EG2_CAN, bus="can0", code=i))
    assert len(out) >= 50  # released without waiting for the end of the stream
    assert "pairing window" in out[0].warnings[0]


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


def test_command_within_a_second_of_a_save_is_flagged() -> None:
    save, soon, later = rec(REQUEST, 1, 0.0, save=True), rec(REQUEST, 1, 0.5), rec(REQUEST, 1, 1.6)
    lint([save, soon, later])
    assert "500 ms after a parameter save" in soon.warnings[0]
    assert not later.warnings


def test_lint_ignores_untimed_records() -> None:
    a, b = rec(REQUEST, 1), rec(REQUEST, 1)
    lint([a, b])
    assert not a.warnings and not b.warnings


def test_corrupt_frames_are_not_paired() -> None:
    bad = rec(REQUEST, 1)
    bad.errors.append("checksum error: expected 0x0A, got 0x50")
    good, resp = rec(REQUEST, 1), rec(RESPONSE, 1)
    out = run([bad, good, resp])
    assert out == [bad, good, resp]
    assert not bad.warnings and bad.pair is None
    assert good.pair == resp.seq
