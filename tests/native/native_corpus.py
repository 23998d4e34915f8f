"""Inputs for the differential tests of the two decode engines (tests/native/): the manual's
frames as capture files, and the hostile inputs the other tests already hold, found by walking
their modules (constants and ``parametrize`` tables) for byte strings, CAN frames and candump
lines, so that a case added there is compared here too."""

from __future__ import annotations

import importlib.util
import json
import re
import sys
from collections.abc import Iterator
from pathlib import Path
from types import ModuleType
from typing import Any

from decoders.model import CanFrame

TESTS = Path(__file__).resolve().parents[1]
ROOT = TESTS.parent
CAPTURES = ROOT / "captures"
MANUAL_FRAMES = TESTS / "data" / "manual_frames.json"

# the test modules whose tables hold hostile inputs (garbage, truncation, bad lines, odd frames)
MINED = [
    "decoders/test_eg2_serial.py",
    "decoders/test_modbus_rtu.py",
    "decoders/test_framing.py",
    "decoders/test_pairing.py",
    "decoders/test_eg2_can.py",
    "analyzer/test_can_files.py",
    "analyzer/test_cli_decode.py",
    "sources/test_capture_readers.py",
    "sources/test_candump_layouts.py",
]

CANDUMP_LINE = re.compile(r"^\s*\(")
HEX_TEXT = re.compile(r"^[0-9A-Fa-f]{2}( [0-9A-Fa-f]{2})+$")


def candump_line(frame: CanFrame, t: float, channel: str = "can0") -> str:
    """One candump -L line for any CanFrame (remote, error and FD frames too)."""
    aid = frame.arbitration_id
    if frame.is_error:
        ident = f"{aid | 0x20000000:08X}"
    elif frame.is_extended:
        ident = f"{aid:08X}"
    else:
        ident = f"{aid:03X}"
    if frame.is_remote:
        body = f"#R{frame.dlc}" if frame.dlc else "#R"
    elif frame.is_fd:
        body = f"##0{frame.data.hex().upper()}"
    else:
        body = f"#{frame.data.hex().upper()}"
    return f"({t:.6f}) {channel} {ident}{body}"


def _load(rel: str) -> ModuleType | None:
    path = TESTS / rel
    name = "_mined_" + rel.replace("/", "_").removesuffix(".py")
    if name in sys.modules:
        return sys.modules[name]
    spec = importlib.util.spec_from_file_location(name, path)
    if spec is None or spec.loader is None:
        return None
    module = importlib.util.module_from_spec(spec)
    sys.path.insert(0, str(path.parent))
    try:
        spec.loader.exec_module(module)
    except Exception:  # a test module that cannot be loaded on its own: nothing to mine
        return None
    finally:
        sys.path.remove(str(path.parent))
    sys.modules[name] = module
    return module


def _walk(value: Any, depth: int = 0) -> Iterator[Any]:
    if depth > 6:
        return
    if isinstance(value, bytes | bytearray | CanFrame):
        yield bytes(value) if not isinstance(value, CanFrame) else value
    elif isinstance(value, str):
        yield value
    elif isinstance(value, dict):
        for v in value.values():
            yield from _walk(v, depth + 1)
    elif isinstance(value, list | tuple | set | frozenset):
        for v in value:
            yield from _walk(v, depth + 1)
    elif type(value).__name__ == "ParameterSet":
        yield from _walk(value.values, depth + 1)


def _module_values(module: ModuleType) -> Iterator[tuple[str, Any]]:
    """(name of the table, value) for every value in the module's tables."""
    for name, value in vars(module).items():
        if name.startswith("__") or isinstance(value, ModuleType):
            continue
        if callable(value) and not isinstance(value, type):
            for mark in getattr(value, "pytestmark", []):
                if mark.name == "parametrize" and len(mark.args) > 1:
                    yield from ((name, v) for v in _walk(mark.args[1]))
            continue
        yield from ((name, v) for v in _walk(value))


def mined() -> tuple[list[bytes], list[CanFrame], list[str]]:
    """(byte strings, CAN frames, candump lines) of the hostile-input tables, each once, in a
    fixed order."""
    blobs: dict[bytes, None] = {}
    frames: dict[tuple[Any, ...], CanFrame] = {}
    lines: dict[str, None] = {}
    for rel in MINED:
        module = _load(rel)
        if module is None:
            continue
        for name, v in _module_values(module):
            if isinstance(v, bytes):
                if v:
                    blobs.setdefault(v)
            elif isinstance(v, CanFrame):
                if not isinstance(v.arbitration_id, int) or not isinstance(v.data, bytes):
                    continue  # a deliberately broken object, not a frame a log can hold
                key = (v.arbitration_id, v.data, v.is_extended, v.is_remote, v.is_error,
                       v.is_fd, v.dlc)  # fmt: skip
                frames.setdefault(key, v)
            elif isinstance(v, str):
                if "\n" in v:
                    continue
                if CANDUMP_LINE.match(v) or "LINES" in name:  # BAD_LINES: not all start "("
                    lines.setdefault(v)
                elif HEX_TEXT.match(v.strip()):
                    blobs.setdefault(bytes.fromhex(v))
    return list(blobs), list(frames.values()), list(lines)


def manual() -> dict[str, Any]:
    data: dict[str, Any] = json.loads(MANUAL_FRAMES.read_text(encoding="utf-8"))
    return data


def manual_byte_frames(protocol: str) -> list[bytes]:
    """Every frame of the manual for a byte-stream protocol, in the manual's order."""
    data = manual()
    out: list[bytes] = []
    if protocol == "eg2-serial":
        for v in data["eg2_serial"]:
            out += [bytes.fromhex(v["request"]), bytes.fromhex(v["response"])]
        out += [bytes.fromhex(v["bytes"]) for v in data["eg2_serial_bad"]]
    else:
        for v in data["modbus_rtu"]:
            out += [bytes.fromhex(v["wire"]), bytes.fromhex(v["manual_prints"])]
    return out


def manual_can_lines(t0: float = 1_700_000_000.0) -> list[str]:
    """Every CAN frame of the manual (request, then response) as candump lines."""
    lines = []
    t = t0
    for v in manual()["eg2_can"]:
        for part in (v, v.get("response")):
            if not part:
                continue
            lines.append(f"({t:.6f}) can0 {part['id']}#{part['data'].replace(' ', '')}")
            t += 0.001
    return lines
