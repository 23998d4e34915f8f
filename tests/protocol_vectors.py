"""The manual's frames (``../shared/protocol/vectors.json``) for the tests, in one place."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

VECTORS_PATH = Path(__file__).resolve().parents[2] / "shared/protocol/vectors.json"
MISSING = f"protocol vectors not found at {VECTORS_PATH}"
needs_vectors = pytest.mark.skipif(not VECTORS_PATH.exists(), reason=MISSING)


def load(key: str) -> list[dict[str, Any]]:
    """The entries under ``key``, or [] when the shared folder is not beside the checkout."""
    if not VECTORS_PATH.exists():
        return []
    return list(json.loads(VECTORS_PATH.read_text())[key])


def params(key: str, indexed: bool = False) -> list[Any]:
    """Entries as pytest params (``(index, entry)`` when indexed), or one skipped param."""
    entries = load(key)
    if not entries:
        return [
            pytest.param(*([None, None] if indexed else [None]), marks=pytest.mark.skip(MISSING))
        ]
    if indexed:
        return [pytest.param(i, e, id=e["meaning"]) for i, e in enumerate(entries)]
    return [pytest.param(e, id=e["meaning"]) for e in entries]
