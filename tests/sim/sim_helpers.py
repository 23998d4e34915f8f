"""Helpers of the simulator tests: the protocol vectors, reading a port with a deadline."""

from __future__ import annotations

import time

import serial
from protocol_vectors import params

vectors = params


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
