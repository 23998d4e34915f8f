"""The latency-timer hint, on synthetic read times: reads in bursts at multiples of 16 ms (an
FTDI adapter's default timer) get the setting that fixes it; at multiples of 1 ms (the timer at
its minimum, one read per USB frame) a note with nothing to set; reads at the line's own pace,
or too few reads, get nothing. And through a serial line's figures, from its reads."""

from __future__ import annotations

import random

from analyzer.health.latency_timer import ReadTimes
from analyzer.health.serial_line import SerialLine
from decoders.model import Chunk

T0 = 1_763_700_000.0


def read_times(times: list[float]) -> ReadTimes:
    reads = ReadTimes()
    for t in times:
        reads.add(t)
    return reads


def bursts(quantum_s: float, n: int, seed: int = 1, jitter_s: float = 0.0002) -> list[float]:
    """``n`` reads, each a whole number (1-4) of quanta after the last, with scheduling jitter;
    some bursts read in two (a second read 50 us after the first)."""
    rng = random.Random(seed)
    t, times = T0, []
    for i in range(n):
        t += rng.randint(1, 4) * quantum_s
        times.append(t + rng.uniform(0, jitter_s))
        if i % 5 == 0:
            times.append(times[-1] + 0.00005)
    return times


def test_reads_every_16_ms_get_the_fix() -> None:
    hint = read_times(bursts(0.016, 200)).hint("/dev/ttyUSB3")
    assert hint is not None and hint["quantum_ms"] == 16.0 and hint["share"] >= 0.8
    assert hint["fix"] == (
        "echo 1 > /sys/bus/usb-serial/devices/ttyUSB3/latency_timer "
        "(or setserial /dev/ttyUSB3 low_latency)"
    )
    assert "16 ms" in hint["message"]


def test_a_port_not_known_gets_an_example() -> None:
    hint = read_times(bursts(0.016, 200)).hint(None)
    assert hint is not None and "/ttyUSB0/latency_timer" in hint["fix"]


def test_reads_every_1_ms_are_the_timer_at_its_minimum() -> None:
    hint = read_times(bursts(0.001, 500, jitter_s=0.00005)).hint("/dev/ttyUSB0")
    assert hint is not None and hint["quantum_ms"] == 1.0 and hint["fix"] is None


def test_reads_at_the_lines_pace_get_no_hint() -> None:
    rng = random.Random(5)
    t, times = T0, []
    for _ in range(500):
        t += rng.uniform(0.0005, 0.030)  # frames and gaps as they come
        times.append(t)
    assert read_times(times).hint("/dev/ttyUSB0") is None


def test_too_few_reads_say_nothing() -> None:
    assert read_times(bursts(0.016, 10)).hint("/dev/ttyUSB0") is None


def test_a_line_says_it_from_its_reads() -> None:
    line = SerialLine(115_200, "/dev/ttyUSB1")
    for t in bursts(0.016, 100):
        line.add_read("", Chunk(bytes(14), t))
    hint = line.figures()["latency_timer"]
    assert hint is not None and "ttyUSB1" in hint["fix"]
