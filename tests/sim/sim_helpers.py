"""Helpers of the simulator tests: the protocol vectors, reading a port with a deadline."""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

import pytest
import serial

VECTORS_PATH = Path(__file__).parents[2].parent / "shared/protocol/vectors.json"


def vectors(key: str) -> list[Any]:
    """vectors.json entries as pytest params, or one skipped param when the file is absent."""
    if not VECTORS_PATH.exists():
        reason = f"protocol vectors not found at {VECTORS_PATH}"
        return [pytest.param(None, marks=pytest.mark.skip(reason=reason))]
    entries = json.loads(VECTORS_PATH.read_text())[key]
    return [pytest.param(e, id=e["meaning"]) for e in entries]


def h(text: str) -> bytes:
    return bytes.fromhex(text)


def read_exactly(port: serial.Serial, n: int, timeout: float = 2.0) -> bytes:
    """n bytes from port, or fewer if the deadline passes."""
    deadline = time.monotonic() + timeout
    out = b""
    while len(out) < n and time.monotonic() < deadline:
        port.timeout = max(0.001, deadline - time.monotonic())
        out += port.read(n - len(out))
    return out


def read_quiet(port: serial.Serial, quiet: float = 0.05) -> bytes:
    """Everything that arrives until the line has been quiet for `quiet` seconds."""
    out = b""
    port.timeout = quiet
    while True:
        chunk = port.read(4096)
        if not chunk:
            return out
        out += chunk
