"""The native decoding core against the Python engine: the same capture decoded by both must give
byte-identical JSONL, CSV and text, the same stderr and the same exit code.

Inputs: every capture in captures/ (also gzip compressed, and cut short), every frame of the
manual, the hostile inputs of the other tests (tests/native/native_corpus.py finds them), and
Hypothesis-generated streams: valid frames of each protocol with garbage, noise bytes, bit flips,
truncation and retransmissions; candump logs with bad lines, comments, CRLF and cut gzip.
Both engines run in this process through the command line (``eg2scope decode --engine python
--jobs 1`` and ``--engine native``), so the whole path is compared, option parsing and output
files included. Skipped when the extension is not built (no Rust toolchain).
"""

from __future__ import annotations

import functools
import gzip
import io
import random
import shutil
import tempfile
from collections.abc import Iterator, Sequence
from contextlib import redirect_stderr
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from native_core import skip_or_fail, why_not

from analyzer import cli
from decoders import build as b
from decoders.model import CanFrame

if why := why_not():
    skip_or_fail(why)

import native_corpus as corpus  # after the check (tests/native is on sys.path)

FORMATS = ("jsonl", "csv", "text")


# -- running both engines -------------------------------------------------------------------------


@pytest.fixture(scope="module")
def work() -> Iterator[Path]:
    """One directory for the whole module (Hypothesis examples cannot use tmp_path), in memory
    where there is a tmpfs (renaming the output into place costs ~10 ms on some disks); and the
    command line's parser built once (building it costs more than decoding a small file)."""
    shm = Path("/dev/shm")
    path = Path(tempfile.mkdtemp(prefix="eg2scope-native-", dir=shm if shm.is_dir() else None))
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(cli, "build_parser", functools.cache(cli.build_parser))
        yield path
    shutil.rmtree(path, ignore_errors=True)


def decode(engine: str, capture: Path, fmt: str, options: list[str]) -> tuple[int, bytes, str]:
    """(exit code, output bytes, stderr) of ``eg2scope decode`` with one engine."""
    out = capture.with_name(capture.name + f".{engine}.{fmt}.out")
    out.unlink(missing_ok=True)
    argv = ["decode", str(capture), "-f", fmt, "-o", str(out), "--no-progress", *options]
    argv += ["--engine", "python", "--jobs", "1"] if engine == "python" else ["--engine", "native"]
    err = io.StringIO()
    with redirect_stderr(err):
        try:
            code = cli.main(argv)
        except SystemExit as exc:  # a usage error
            code = exc.code if isinstance(exc.code, int) else 2
    data = out.read_bytes() if out.exists() else b""
    out.unlink(missing_ok=True)
    return code, data, err.getvalue()


def first_difference(a: bytes, b: bytes) -> str:
    la, lb = a.split(b"\n"), b.split(b"\n")
    for i, (x, y) in enumerate(zip(la, lb, strict=False)):
        if x != y:
            return f"line {i + 1}:\n  python: {x[:600]!r}\n  native: {y[:600]!r}"
    return f"python has {len(la)} lines, native {len(lb)}"


def assert_same(
    capture: Path, options: Sequence[str] = (), formats: Sequence[str] = FORMATS
) -> int:
    """Both engines on one capture in every format: identical output, stderr and exit code.
    Returns the number of output lines compared."""
    lines = 0
    for fmt in formats:
        py = decode("python", capture, fmt, list(options))
        nat = decode("native", capture, fmt, list(options))
        what = f"{capture.name} -f {fmt} {' '.join(options)}"
        assert py[0] == nat[0], f"{what}: exit code {py[0]} (python) != {nat[0]} (native)\n{py[2]}"
        assert py[2] == nat[2], f"{what}: stderr differs\npython: {py[2]!r}\nnative: {nat[2]!r}"
        if py[1] != nat[1]:
            pytest.fail(f"{what}: output differs at {first_difference(py[1], nat[1])}")
        lines += py[1].count(b"\n")
    return lines


def write(work: Path, name: str, data: bytes) -> Path:
    path = work / name
    path.write_bytes(data)
    return path


# -- the sample captures ------------------------------------------------------------------------

CAPTURES = sorted(p for p in corpus.CAPTURES.iterdir() if p.suffix in (".bin", ".log"))
BYTE_OPTIONS = [[], ["-p", "serial"], ["-p", "modbus"], ["--bus", "rs485"], ["-d", "1"], ["-e"],
                ["--bus", ""]]  # fmt: skip
CAN_OPTIONS = [[], ["--bus", "vcan7"], ["-d", "2"], ["-e"], ["-d", "1", "-e"], ["--bus", ""],
               ["-p", "serial"]]  # fmt: skip


@pytest.mark.parametrize("capture", CAPTURES, ids=lambda p: p.name)
def test_sample_captures(capture: Path, work: Path) -> None:
    options = CAN_OPTIONS if capture.suffix == ".log" else BYTE_OPTIONS
    for opts in options:
        assert_same(capture, opts)
    assert_same(capture, ["--absolute-time"], ("text",))
    assert_same(capture, ["--colour", "always"], ("text",))


@pytest.mark.parametrize("capture", CAPTURES, ids=lambda p: p.name)
def test_sample_captures_compressed_and_cut(capture: Path, work: Path) -> None:
    packed = gzip.compress(capture.read_bytes(), mtime=0)
    whole = write(work, capture.name + ".gz", packed)
    assert_same(whole)
    for keep in (0.5, 0.9):  # a cut .gz: decoded as far as it goes, exit 3, the damage said
        cut = write(
            work, f"cut{int(keep * 100)}-{capture.name}.gz", packed[: int(len(packed) * keep)]
        )
        assert_same(cut, formats=("jsonl",))
    # the capture cut in the middle (a frame or a line cut short)
    data = capture.read_bytes()
    assert_same(write(work, "half-" + capture.name, data[: len(data) // 2 + 3]))


def test_empty_and_tiny_files(work: Path) -> None:
    for name, data in [
        ("empty.bin", b""),
        ("empty.log", b""),
        ("one.bin", b"\xeb"),
        ("nl.log", b"\n"),
        ("cr.log", b"(1.0) can0 123#01\r(2.0) can0 123#02\r"),
        ("crlf.log", b"(1.0) can0 04FF0001#06\r\n(2.0) can0 04FF0001#06\r\n"),
        ("nonl.log", b"(1.0) can0 04FF0001#06"),
        ("empty.bin.gz", gzip.compress(b"")),
        ("zero.bin.gz", b""),
        ("zero.log.gz", b""),
        ("header-only.log.gz", gzip.compress(b"(1.0) can0 04FF0001#06\n")[:10]),
        ("notgz.bin.gz", b"\x1f\x8b not really"),
        ("plain.log.gz", b"(1.0) can0 04FF0001#06\n"),
        ("gz-inside.log", gzip.compress(b"(1.0) can0 04FF0001#06\n", mtime=0)),
        ("members.bin.gz", gzip.compress(b"\xeb\x90\x01\x01", mtime=0) * 2),
        ("padded.bin.gz", gzip.compress(b"\xeb\x90\x01\x01\x01\x03", mtime=0) + bytes(10)),
        ("trailing.bin.gz", gzip.compress(b"\xeb\x90\x01\x01\x01\x03", mtime=0) + b"junk"),
        ("trailing.log.gz", gzip.compress(b"(1.0) can0 04FF0001#06\n", mtime=0) + b"\x1f\x8bx"),
        ("zeros.bin", bytes(300)),
        # the protocol shows only after the first 4 KiB (detection reads further) or never
        ("late-modbus.bin", random.Random(1).randbytes(9000) + b.modbus_read_request(1, 1061, 5)),
        ("late-serial.bin", bytes(5000) + b.serial_frame(1, 0x41) * 3),
        ("both.bin", b.modbus_read_request(1, 1061, 5) + b.serial_frame(2, 0xD9) * 2),
        ("ff.bin", b"\xff" * 300),
    ]:
        assert_same(write(work, name, data))


# -- the manual's frames ------------------------------------------------------------------------


@pytest.mark.parametrize("protocol", ["eg2-serial", "modbus-rtu"])
def test_manual_frames(protocol: str, work: Path) -> None:
    frames = corpus.manual_byte_frames(protocol)
    short = "serial" if protocol == "eg2-serial" else "modbus"
    for i, frame in enumerate(frames):  # each frame on its own, detected and forced
        path = write(work, f"manual-{short}-{i}.bin", frame)
        assert_same(path, formats=("jsonl", "text"))
        assert_same(path, ["-p", short], ("jsonl",))
    stream = write(work, f"manual-{short}.bin", b"".join(frames))
    assert_same(stream)
    assert_same(stream, ["-p", short])


def test_manual_can_frames(work: Path) -> None:
    lines = corpus.manual_can_lines()
    for i, line in enumerate(lines):
        assert_same(write(work, f"manual-can-{i}.log", line.encode() + b"\n"), formats=("jsonl",))
    assert_same(write(work, "manual-can.log", "\n".join(lines).encode() + b"\n"))


# -- the hostile inputs of the other tests ------------------------------------------------------

BLOBS, CAN_FRAMES, CAN_LINES = corpus.mined()


def test_mined_inputs_found() -> None:
    assert len(BLOBS) > 100 and len(CAN_FRAMES) > 20 and len(CAN_LINES) > 30


@pytest.mark.parametrize("i", range(0, len(BLOBS), 8))
def test_mined_byte_strings(i: int, work: Path) -> None:
    for j, blob in enumerate(BLOBS[i : i + 8]):
        path = write(work, f"mined-{i + j}.bin", blob)
        assert_same(path, formats=("jsonl", "text"))


@pytest.mark.parametrize("protocol", ["serial", "modbus", "auto"])
def test_mined_byte_strings_as_one_stream(protocol: str, work: Path) -> None:
    path = write(work, "mined-all.bin", b"".join(BLOBS))
    assert_same(path, ["-p", protocol])


def test_mined_can_frames(work: Path) -> None:
    t = 1_700_000_000.0
    lines = [corpus.candump_line(f, t + i * 0.0005) for i, f in enumerate(CAN_FRAMES)]
    for i, line in enumerate(lines):
        assert_same(write(work, f"mined-can-{i}.log", line.encode() + b"\n"), formats=("jsonl",))
    assert_same(write(work, "mined-can.log", "\n".join(lines).encode() + b"\n"))
    # each twice (a retransmission), and far apart in time (pending requests expire)
    slow = [corpus.candump_line(f, t + i * 0.7) for i, f in enumerate(CAN_FRAMES * 2)]
    assert_same(write(work, "mined-can-slow.log", "\n".join(slow).encode() + b"\n"))


def test_mined_candump_lines(work: Path) -> None:
    good = b"(1.0) can0 04FF0001#0000F401F401\n"
    after = b"(2.0) can0 04FF0001#06\n"
    for i, line in enumerate(CAN_LINES):
        path = write(
            work, f"mined-line-{i}.log", good + line.encode("utf-8", "replace") + b"\n" + after
        )
        assert_same(path, formats=("jsonl",))
    body = "\n".join(CAN_LINES).encode("utf-8", "replace") + b"\n"
    assert_same(write(work, "mined-lines.log", body))
    assert_same(write(work, "mined-lines.log.gz", gzip.compress(body, mtime=0)))


def test_many_bad_lines_are_capped(work: Path) -> None:
    body = b"junk\n" * 300 + b"(1.0) can0 04FF0001#06\n" + b"(x) can0 1#1\n" * 50
    assert_same(write(work, "noise.log", body))


# -- Hypothesis: generated streams --------------------------------------------------------------

devices = st.sampled_from([0, 1, 2, 3, 5, 254, 255])
u16 = st.integers(0, 0xFFFF)
SERIAL_CMDS = [0x01, 0x04, 0x10, 0x11, 0x12, 0x13, 0x14, 0x15, 0x16, 0x17, 0x41, 0x5E, 0x5F,
               0x60, 0x61, 0x62, 0x63, 0x64, 0x65, 0x66, 0x67, 0x68, 0x69, 0x6A, 0x6B, 0x6C,
               0x6D, 0x6E, 0x6F, 0x70, 0xD9, 0x20, 0x7F]  # fmt: skip
REGISTERS = [1000, 1001, 1002, 1005, 1006, 1008, 1009, 1010, 1011, 1012, 1013, 1020, 1021, 1060,
             1061, 1062, 1063, 1064, 1065, 1066, 1100, 1120, 1128, 2000, 0, 4095]  # fmt: skip


@st.composite
def serial_frame(draw: st.DrawFn) -> bytes:
    cmd = draw(st.sampled_from(SERIAL_CMDS) | st.integers(0, 255))
    data = draw(st.binary(max_size=8))
    return b.serial_frame(draw(devices), cmd, data, response=draw(st.booleans()))


@st.composite
def modbus_frame(draw: st.DrawFn) -> bytes:
    slave = draw(devices)
    start = draw(st.sampled_from(REGISTERS) | u16)
    kind = draw(st.integers(0, 5))
    if kind == 0:
        return b.modbus_read_request(slave, start, draw(st.integers(0, 130)))
    if kind == 1:
        return b.modbus_read_response(slave, draw(st.lists(u16, max_size=12)))
    if kind == 2:
        return b.modbus_write_single(slave, start, draw(u16))
    if kind == 3:
        return b.modbus_write_multiple(slave, start, draw(st.lists(u16, min_size=1, max_size=6)))
    if kind == 4:
        return b.modbus_write_multiple_response(slave, start, draw(st.integers(0, 130)))
    return b.modbus_exception(slave, draw(st.sampled_from([3, 6, 16, 4])), draw(st.integers(0, 12)))


@st.composite
def byte_stream(draw: st.DrawFn) -> bytes:
    """Valid frames of one or both protocols, with garbage, noise, retransmissions, bit flips
    and a cut end."""
    frame = draw(st.sampled_from([serial_frame(), modbus_frame(), serial_frame() | modbus_frame()]))
    parts: list[bytes] = []
    for _ in range(draw(st.integers(1, 30))):
        what = draw(st.integers(0, 9))
        if what < 6 or not parts:
            parts.append(draw(frame))
        elif what == 6:
            parts.append(parts[-1])  # a retransmission
        elif what == 7:
            parts.append(draw(st.binary(min_size=1, max_size=12)))  # garbage
        elif what == 8:
            parts.append(
                draw(
                    st.sampled_from(
                        [b"\xeb", b"\xee", b"\xeb\x90", b"\xee\x16", b"\x01\x03", b"\x00"]
                    )
                )
            )
        else:
            parts.append(draw(frame)[: draw(st.integers(1, 6))])  # a frame cut short
    data = bytearray(b"".join(parts))
    for _ in range(draw(st.integers(0, 3))):  # bit flips
        if data:
            i = draw(st.integers(0, len(data) - 1))
            data[i] ^= 1 << draw(st.integers(0, 7))
    if draw(st.booleans()):
        data = data[: draw(st.integers(0, len(data)))]
    return bytes(data)


OPTIONS = st.sampled_from(
    [[], [], [], ["-e"], ["-d", "1"], ["-d", "0", "-e"], ["--bus", "b"], ["--colour", "always"],
     ["--absolute-time"]]
)  # fmt: skip
SLOW = settings(
    max_examples=150,
    suppress_health_check=[HealthCheck.too_slow],
)


@SLOW
@given(data=byte_stream(), protocol=st.sampled_from(["auto", "serial", "modbus"]),
       fmt=st.sampled_from(FORMATS), gz=st.booleans(), opts=OPTIONS)  # fmt: skip
def test_generated_byte_streams(
    work: Path, data: bytes, protocol: str, fmt: str, gz: bool, opts: list[str]
) -> None:
    path = write(work, "gen.bin.gz" if gz else "gen.bin", gzip.compress(data) if gz else data)
    assert_same(path, ["-p", protocol, *opts], (fmt,))


@st.composite
def can_frame(draw: st.DrawFn) -> CanFrame:
    dev = draw(st.sampled_from([0, 1, 2, 3, 0x3FFF, 77]))
    addr = draw(st.sampled_from(REGISTERS) | st.integers(0, 0xFFF))
    kind = draw(st.integers(0, 6))
    if kind == 0:
        return b.can_read_request(dev, addr, draw(st.integers(0, 9)), padded=draw(st.booleans()))
    if kind == 1:
        return b.can_read_response(dev, addr, draw(st.binary(max_size=8)))
    if kind == 2:
        return b.can_write_request(dev, addr, draw(st.binary(min_size=1, max_size=8)))
    if kind == 3:
        return b.can_write_response(dev, addr, draw(st.integers(0, 8)), padded=draw(st.booleans()))
    if kind == 4:  # operations 2 and 3, the reserved bit, anything
        return CanFrame(None, draw(st.integers(0, 0x1FFFFFFF)), draw(st.binary(max_size=8)))
    if kind == 5:  # a standard identifier
        return CanFrame(None, draw(st.integers(0, 0x7FF)), draw(st.binary(max_size=8)), False)
    return CanFrame(None, draw(st.integers(0, 0x1FFFFFFF)), b"", True, is_remote=True,
                    dlc=draw(st.integers(0, 8)))  # fmt: skip


BAD_LINE = st.sampled_from(corpus.mined()[2] or ["junk"])


@st.composite
def candump_log(draw: st.DrawFn) -> bytes:
    """A candump -L log: requests and their answers (some retransmitted, some lost), foreign
    frames, bad lines, comments, blank lines, CRLF, channels, time going backwards, a cut end."""
    t = draw(st.sampled_from([0.0, 1_700_000_000.0, 1.5]))
    lines: list[str] = []
    channels = draw(st.sampled_from([["can0"], ["can0", "can1"], ["vcan0", "can0", "x"]]))
    for _ in range(draw(st.integers(1, 40))):
        t += draw(st.sampled_from([0.0001, 0.001, 0.003, 0.05, 0.6, 2.5, -0.01]))
        what = draw(st.integers(0, 11))
        ch = draw(st.sampled_from(channels))
        if what < 7 or not lines:
            lines.append(corpus.candump_line(draw(can_frame()), t, ch))
        elif what == 7:
            lines.append(lines[-1])  # a retransmission (same time stamp)
        elif what == 8:
            lines.append(draw(BAD_LINE))
        elif what == 9:
            lines.append(draw(st.sampled_from(["", "# comment", "   "])))
        elif what == 10:  # a line damaged in one character
            line = corpus.candump_line(draw(can_frame()), t, ch)
            i = draw(st.integers(0, len(line) - 1))
            lines.append(line[:i] + draw(st.sampled_from(list("(#)GR _.-x9 "))) + line[i + 1 :])
        else:
            lines.append(
                corpus.candump_line(draw(can_frame()), t, ch)
                + draw(st.sampled_from([" R", " T", "\r", " X"]))
            )
    end = draw(st.sampled_from(["\n", "\r\n"]))
    body = end.join(lines).encode("utf-8", "replace") + end.encode()
    if draw(st.integers(0, 4)) == 0:
        body = body[: draw(st.integers(0, len(body)))]
    return body


@SLOW
@given(body=candump_log(), fmt=st.sampled_from(FORMATS), gz=st.integers(0, 5),
       opts=OPTIONS)  # fmt: skip
def test_generated_candump_logs(
    work: Path, body: bytes, fmt: str, gz: int, opts: list[str]
) -> None:
    if gz == 0:  # compressed
        path = write(work, "gen.log.gz", gzip.compress(body, mtime=0))
    elif gz == 1:  # compressed and cut
        packed = gzip.compress(body, mtime=0)
        path = write(work, "gen.log.gz", packed[: max(10, len(packed) * 2 // 3)])
    else:
        path = write(work, "gen.log", body)
    assert_same(path, opts, (fmt,))


# -- realistic traffic in bulk --------------------------------------------------------------------


@pytest.mark.parametrize("kind", ["serial", "modbus", "can"])
def test_realistic_traffic(kind: str, work: Path) -> None:
    """A few thousand frames of moving grippers (tests/benchmarks/traffic.py), with random
    damage: more state (pairing windows, the timing linter, the CAN direction table)."""
    import sys

    sys.path.insert(0, str(corpus.TESTS / "benchmarks"))
    try:
        import traffic
    finally:
        sys.path.pop(0)
    rng = random.Random(10)
    if kind == "can":
        lines = [corpus.candump_line(f, f.t or 0.0) for f in traffic.can_frames(6000)]
        for _ in range(20):
            lines.insert(rng.randrange(len(lines)), rng.choice(lines)[: rng.randrange(40)])
        path = write(work, "traffic.log", "\n".join(lines).encode() + b"\n")
    else:
        gen = traffic.serial_frames if kind == "serial" else traffic.modbus_frames
        data = bytearray(b"".join(gen(6000)))
        for _ in range(30):
            data[rng.randrange(len(data))] ^= 1 << rng.randrange(8)
        path = write(work, f"traffic-{kind}.bin", bytes(data))
    assert assert_same(path) > 5000


def test_thousands_of_requests_waiting_at_once(work: Path) -> None:
    """Requests to thousands of CAN identifiers, most never answered, some answered late or
    twice: the pairing's time-out order (a heap in Python) against the core's."""
    rng = random.Random(12)
    frames, t = [], 1_763_700_000.0
    for _ in range(6000):
        dev, reg = rng.randrange(1, 255), rng.randrange(1000, 1200)
        frames.append(b.can_read_request(dev, reg, 8, t=t))
        if rng.random() < 0.2:  # answered, sometimes after the time-out
            late = t + rng.choice((0.0004, 0.3, 0.6, 2.5))
            frames.append(b.can_read_response(dev, reg, bytes(8), t=late))
        t += rng.choice((0.00002, 0.0001, 0.01))
    frames.sort(key=lambda f: f.t or 0.0)
    lines = [corpus.candump_line(f, f.t or 0.0) for f in frames]
    assert assert_same(write(work, "pending.log", "\n".join(lines).encode() + b"\n")) > 6000
