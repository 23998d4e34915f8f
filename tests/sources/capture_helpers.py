"""What the capture tests share: the sample CAN capture written in every layout candump writes
(as candump's own printf formats do: can-utils lib.c and candump.c), and ``eg2scope decode``
run in this process with either engine."""

from __future__ import annotations

import io
import json
import time
from contextlib import redirect_stderr
from pathlib import Path
from typing import Any

from analyzer import cli
from analyzer.session import engine as native
from analyzer.sources.can_files import open_can_file
from decoders.model import CanFrame

ROOT = Path(__file__).resolve().parents[2]
CAPTURES = ROOT / "captures"
CAN_LOG = CAPTURES / "can_pick_place.log"
ENGINES = ["python", "native"] if native.available() else ["python"]
TZ = "CET-1CEST,M3.5.0,M10.5.0/3"  # candump -tA stamps are local time: tests read them in CET


def sample_frames() -> list[CanFrame]:
    with open_can_file(CAN_LOG) as reader:
        return list(reader)


def _ident(frame: CanFrame) -> str:
    aid = frame.arbitration_id | (0x20000000 if frame.is_error else 0)
    return f"{aid:08X}" if frame.is_extended or frame.is_error else f"{aid:03X}"


def columns_line(frame: CanFrame) -> str:
    """candump's default layout (lib.c sprint_long_canframe)."""
    if frame.is_remote:
        return f"  {frame.channel}  {_ident(frame)}   [{frame.length}]  remote request"
    length = f"[{len(frame.data):02d}]" if frame.is_fd else f" [{len(frame.data)}]"
    data = "".join(f" {b:02X}" for b in frame.data)
    tail = " " * (3 * (8 - len(frame.data)) + 3) + "ERRORFRAME" if frame.is_error else ""
    return f"  {frame.channel}  {_ident(frame)}  {length} {data}{tail}"


def _micros(t: float | None) -> int:
    return round((t or 0.0) * 1_000_000)


def write_layout(path: Path, frames: list[CanFrame], stamps: str) -> Path:
    """The frames as ``candump [-t STAMPS]`` prints them: "" none, "a" absolute, "z" since the
    first, "d" since the previous, "A" local date and time."""
    lines = []
    first = previous = _micros(frames[0].t)
    for frame in frames:
        now = _micros(frame.t)
        if stamps == "a":
            stamp = f"({now // 1_000_000:010d}.{now % 1_000_000:06d}) "
        elif stamps in "zd" and stamps:
            since = now - (first if stamps == "z" else previous)
            stamp = f"({since // 1_000_000:03d}.{since % 1_000_000:06d}) "
        elif stamps == "A":
            local = time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(now // 1_000_000))
            stamp = f"({local}.{now % 1_000_000:06d}) "
        else:
            stamp = ""
        previous = now
        lines.append(stamp + columns_line(frame).lstrip() if stamp else columns_line(frame))
    path.write_text("\n".join(lines) + "\n")
    return path


def decode(capture: Path, engine: str, *options: str, fmt: str = "jsonl") -> tuple[int, str, str]:
    """(exit code, output, stderr) of ``eg2scope decode CAPTURE`` with one engine."""
    out = capture.with_name(f"{capture.name}.{engine}.out")
    out.unlink(missing_ok=True)
    argv = ["decode", str(capture), "-f", fmt, "-o", str(out), "--no-progress", *options]
    argv += ["--engine", engine] + (["--jobs", "1"] if engine == "python" else [])
    err = io.StringIO()
    with redirect_stderr(err):
        try:
            code = cli.main(argv)
        except SystemExit as exc:  # a usage error
            code = exc.code if isinstance(exc.code, int) else 2
    text = out.read_text() if out.exists() else ""
    out.unlink(missing_ok=True)
    return code, text, err.getvalue()


def decode_both(capture: Path, *options: str, fmt: str = "jsonl") -> tuple[int, str, str]:
    """``decode`` with every engine there is: they must agree to the byte; the result."""
    results = [decode(capture, engine, *options, fmt=fmt) for engine in ENGINES]
    for engine, result in zip(ENGINES, results, strict=True):
        assert result == results[0], f"{capture.name}: {engine} differs from python"
    return results[0]


def records(text: str) -> list[dict[str, Any]]:
    return [json.loads(line) for line in text.splitlines()]
