"""The manual's frames (``tests/data/manual_frames.json``) for the tests, in one place.

The file holds every frame the EG2-4XX manual prints, grouped by protocol (``eg2_serial``,
``eg2_serial_bad``, ``modbus_rtu``, ``eg2_can``), with what a correct decoder reports for each;
docs/protocol.md explains them.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

VECTORS_PATH = Path(__file__).resolve().parent / "data" / "manual_frames.json"


def load(key: str) -> list[dict[str, Any]]:
    """The entries under ``key``, freshly read (a test may change its copy); KeyError for a
    group the file does not have."""
    groups: dict[str, Any] = json.loads(VECTORS_PATH.read_text(encoding="utf-8"))
    return list(groups[key])


def params(key: str, indexed: bool = False) -> list[Any]:
    """The entries under ``key`` as pytest params named by their ``meaning``
    (``(index, entry)`` when indexed)."""
    entries = load(key)
    if indexed:
        return [pytest.param(i, e, id=e["meaning"]) for i, e in enumerate(entries)]
    return [pytest.param(e, id=e["meaning"]) for e in entries]
