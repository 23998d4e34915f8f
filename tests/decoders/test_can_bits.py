"""decoders.can_bits: a classic CAN frame's bits on the wire, checked by a second count.

The second count (tests/can_wire.py) shares no code with the module: it writes the frame as a
string of named fields, computes the CRC with ISO 11898-1's bit-serial shift register (no table,
no crcmod) and inserts the stuff bits into the string, where the module packs numbers, uses crcmod
and only counts. Constants are checked against the Linux kernel's include/linux/can/length.h
(can_frame_bits, CAN_FRAME_LEN_MAX) and can-utils canframelen.c (the closed forms of
CFL_NO_BITSTUFFING and CFL_WORSTCASE), read, not copied.
"""

from __future__ import annotations

import random

import pytest
from can_wire import (
    reference_bits,
    reference_crc,
    reference_stuff,
    reference_wire,
)
from hypothesis import given, settings
from hypothesis import strategies as st

from decoders.can_bits import (
    ERROR_FRAME_BITS,
    crc15,
    exact_bits,
    frame_bits,
    stuff_bit_count,
    unstuffed_bits,
    worst_case_bits,
)
from decoders.model import CanFrame


def test_reference_crc_is_crc15_can() -> None:
    # the CRC catalogue's check value of CRC-15/CAN (reveng): "123456789" -> 0x059E
    message = "".join(f"{byte:08b}" for byte in b"123456789")
    assert reference_crc(message) == 0x059E
    assert crc15(int.from_bytes(b"123456789", "big"), 72) == 0x059E


def test_reference_stuffing_counts_stuff_bits_in_runs() -> None:
    assert reference_stuff("0000011111") == "000001111101"  # the stuff 1 opens the run of 1s
    assert reference_stuff("00000") == "000001"  # a run the last bit completes is stuffed too
    assert stuff_bit_count("0000011111") == 2
    assert stuff_bit_count("00000") == 1
    assert stuff_bit_count("0000100001") == 0


# -- the module against it ----------------------------------------------------------------


@st.composite
def classic_frames(draw: st.DrawFn) -> tuple[int, bool, bool, int, bytes]:
    extended = draw(st.booleans())
    aid = draw(st.integers(0, (1 << (29 if extended else 11)) - 1))
    remote = draw(st.booleans())
    dlc = draw(st.integers(0, 15))
    # bytes of long runs as often as any: they are where stuffing happens
    byte = st.one_of(
        st.sampled_from([0x00, 0xFF, 0x0F, 0xF0, 0x1F, 0xF8, 0x55]), st.integers(0, 255)
    )
    size = 0 if remote else min(dlc, 8)
    data = bytes(draw(st.lists(byte, min_size=size, max_size=size)))
    return aid, extended, remote, dlc, data


@settings(max_examples=1500)
@given(classic_frames())
def test_exact_bits_matches_the_second_count(frame: tuple[int, bool, bool, int, bytes]) -> None:
    aid, extended, remote, dlc, data = frame
    got = exact_bits(aid, data, extended=extended, remote=remote, dlc=dlc)
    assert got == reference_bits(aid, extended, remote, dlc, data)


def test_exact_bits_matches_the_second_count_on_random_frames() -> None:
    rng = random.Random(20)
    for _ in range(5000):
        extended = rng.random() < 0.5
        aid = rng.getrandbits(29 if extended else 11)
        remote = rng.random() < 0.1
        dlc = rng.randrange(16)
        size = 0 if remote else min(dlc, 8)
        data = bytes(rng.choice((0, 255, rng.getrandbits(8))) for _ in range(size))
        frame = (aid, extended, remote, dlc, data)
        got = exact_bits(aid, data, extended=extended, remote=remote, dlc=dlc)
        assert got == reference_bits(*frame), frame


@settings(max_examples=500)
@given(classic_frames())
def test_the_kernels_bounds_hold(frame: tuple[int, bool, bool, int, bytes]) -> None:
    aid, extended, remote, dlc, data = frame
    got = exact_bits(aid, data, extended=extended, remote=remote, dlc=dlc)
    assert unstuffed_bits(extended, len(data)) <= got <= worst_case_bits(extended, len(data))
    wire = reference_wire(aid, extended, remote, dlc, data)
    assert "000000" not in wire and "111111" not in wire


# -- known values -------------------------------------------------------------------------------


@pytest.mark.parametrize("data_len", range(9))
def test_kernel_and_canframelen_figures(data_len: int) -> None:
    # canframelen.c: CFL_NO_BITSTUFFING (eff ? 67 : 47) + 8*len, CFL_WORSTCASE (eff ? 80 : 55)
    # + 10*len; the kernel's can_frame_bits() gives the same for classic frames
    assert unstuffed_bits(False, data_len) == 47 + 8 * data_len
    assert unstuffed_bits(True, data_len) == 67 + 8 * data_len
    assert worst_case_bits(False, data_len) == 55 + 10 * data_len
    assert worst_case_bits(True, data_len) == 80 + 10 * data_len


def test_kernel_frame_len_max() -> None:
    # length.h: CAN_FRAME_LEN_MAX = can_frame_bytes(false, true, false, CAN_MAX_DLEN): an
    # extended 8-byte frame without stuff bits, intermission included, in whole bytes = 17
    assert -(-unstuffed_bits(True, 8) // 8) == 17


def test_all_zero_standard_frame_without_data() -> None:
    # Identifier 0, DLC 0: SOF, 11 id bits, RTR, IDE, r0 and the DLC are 19 zeros, and the CRC of
    # zeros is zero: 15 more. 34 equal bits get a stuff bit after each 5 (each stuff bit opens a
    # run of its own, so the zeros start counting again): after bits 5, 10, ..., 30, 6 stuff
    # bits. 34 + 6 + 13 = 53.
    assert exact_bits(0, b"", extended=False) == 53
    assert reference_bits(0, False, False, 0, b"") == 53


def test_all_zero_standard_frame_with_eight_zero_bytes() -> None:
    # Identifier 0, DLC 8, data 00 x 8. Unstuffed: 15 zeros (SOF, id, RTR, IDE, r0), DLC 1000,
    # 64 zeros: 98 bits with the CRC. The message is x^67, so the CRC is x^82 mod g(x) = 0x145B
    # = 001010001011011 (checked below). Stuffing:
    # - the 15 zeros: stuff bits after zeros 5, 10, 15 (3); the last is a 1,
    # - which with DLC's 1 makes a run of two 1s, no stuff bit,
    # - DLC's 000 and the 64 data zeros are one run of 67 zeros: stuff bits after zeros 5, 10,
    #   ..., 65 (13), leaving 2 zeros,
    # - the CRC's leading 00 makes that run 4, then 1: no run of 5 in the CRC, no stuff bit.
    # 98 + 3 + 13 stuff bits + 13 = 127.
    assert reference_crc("0" * 15 + "1000" + "0" * 64) == 0x145B
    assert crc15(1 << 67, 83) == 0x145B
    assert exact_bits(0, bytes(8), extended=False) == 127
    assert reference_bits(0, False, False, 8, bytes(8)) == 127


def test_example_frames() -> None:
    assert exact_bits(0x123, bytes(range(8)), extended=False) == 120
    assert exact_bits(0x0C81F401, bytes(4), extended=True) == 109
    assert exact_bits(0x7FF, extended=False, remote=True, dlc=0) == 50


# -- remote frames -----------------------------------------------------------------------------


@pytest.mark.parametrize("dlc", [0, 1, 4, 8, 15])
@pytest.mark.parametrize("extended", [False, True])
def test_remote_frame_has_no_data_field(dlc: int, extended: bool) -> None:
    # the DLC names the length asked for; no data follows (the kernel: data_len 0 for RTR)
    got = exact_bits(0x155, extended=extended, remote=True, dlc=dlc)
    assert got == reference_bits(0x155, extended, True, dlc, b"")
    assert unstuffed_bits(extended, 0) <= got <= worst_case_bits(extended, 0)


def test_remote_std_0x7ff() -> None:
    # SOF 0, id and RTR twelve 1s, IDE r0 DLC six 0s, then the CRC 0x54EA = 101010011101010.
    # Stuff bits: a 0 after ones 5 and 10 (the stuff 0 ends each run), a 1 after the fifth of
    # the six 0s; the CRC alternates too fast for any. 34 + 3 + 13 = 50.
    assert reference_crc("0" + "1" * 12 + "0" * 6) == 0x54EA
    wire = "0" + "11111" + "0" + "11111" + "0" + "11" + "00000" + "1" + "0" + "101010011101010"
    assert reference_wire(0x7FF, False, True, 0, b"") == wire
    assert exact_bits(0x7FF, extended=False, remote=True) == len(wire) + 13 == 50


def test_remote_frame_from_can_frame() -> None:
    frame = CanFrame(None, 0x7FF, b"", is_extended=False, is_remote=True, dlc=4)
    assert frame_bits(frame) == reference_bits(0x7FF, False, True, 4, b"")


def test_remote_frame_with_data_is_refused() -> None:
    with pytest.raises(ValueError, match="remote frame carries no data"):
        exact_bits(0x10, b"\x01", extended=False, remote=True)


# -- error frames, CAN FD, bad input ------------------------------------------------------------


def test_error_frame_counts_no_bits() -> None:
    # canbusload never receives error frames (no CAN_RAW_ERR_FILTER) and the kernel counts no
    # rx statistics for them: an error frame is the controller's report, not a frame's bits
    error = CanFrame(None, 0x008, bytes(8), is_error=True)  # as analyzer/sim sends one
    assert ERROR_FRAME_BITS == 0
    assert frame_bits(error) == 0


def test_can_fd_is_refused() -> None:
    fd = CanFrame(None, 0x123, bytes(12), is_extended=False, is_fd=True)
    with pytest.raises(ValueError, match="CAN FD"):
        frame_bits(fd)
    with pytest.raises(ValueError, match="CAN FD"):
        exact_bits(0x123, bytes(12), extended=False)
    with pytest.raises(ValueError, match="not a classic CAN frame"):
        worst_case_bits(False, 12)


def test_frame_bits_of_data_frames() -> None:
    std = CanFrame(None, 0x123, bytes(range(8)), is_extended=False)
    ext = CanFrame(None, 0x0C81F401, bytes(4))
    assert frame_bits(std) == exact_bits(0x123, bytes(range(8)), extended=False)
    assert frame_bits(ext) == exact_bits(0x0C81F401, bytes(4), extended=True)


def test_dlc_above_eight_sends_eight_bytes() -> None:
    # ISO 11898-1: a classic DLC of 9-15 means 8 data bytes; the DLC field carries the raw value
    frame = CanFrame(None, 0x123, bytes(8), is_extended=False, dlc=13)
    assert frame_bits(frame) == reference_bits(0x123, False, False, 13, bytes(8))


@pytest.mark.parametrize(
    ("aid", "data", "extended", "dlc", "message"),
    [
        (0x800, b"", False, None, "does not fit in 11 bits"),
        (1 << 29, b"", True, None, "does not fit in 29 bits"),
        (0x1, b"\x00", False, 2, "DLC 2 but 1 data bytes"),
        (0x1, bytes(8), False, 16, "4-bit DLC field"),
    ],
)
def test_impossible_frames_are_refused(
    aid: int, data: bytes, extended: bool, dlc: int | None, message: str
) -> None:
    with pytest.raises(ValueError, match=message):
        exact_bits(aid, data, extended=extended, dlc=dlc)
