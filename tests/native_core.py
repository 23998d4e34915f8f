"""Whether the tests of the native core (``analyzer._native``) run, skip or fail.

A machine without a Rust toolchain installs eg2scope in pure Python: its native tests skip,
saying why. Where ``cargo`` is on the PATH, ``make venv`` builds the core, so a core that is
missing (its build failed) or lacks part of what the tests call (an extension left over from an
older crate) fails those tests instead: skipping them would leave ``make test`` green with the
native engine untested.
"""

from __future__ import annotations

import shutil
from typing import NoReturn

import pytest

from analyzer.session import engine as native

#: what the product and the tests call on the core: a class or function, or "Class.method"
CORE_API = (
    "DecodeRun",
    "ArrowRun",
    "Unsupported",
    "ByteStage",
    "CandumpFrames",
    "CanStage",
    "CycleSegmenter",
    "Tracker",
    "RecordBatch.column",
    "RecordBatch.count_of",
    "RecordBatch.error_count",
    "RecordBatch.jsonl",
    "RecordBatch.messages",
    "RecordBatch.problems",
    "RecordBatch.rerun_log_rows",
    "RecordBatch.take",
    "SampleBatch.arrow",
    "SampleBatch.column",
    "SampleBatch.keys",
    "SampleBatch.messages",
    "SampleBatch.series",
    "can_raw_messages",
    "can_seconds",
    "detect_protocol",
)


def missing_api() -> list[str]:
    """The names of ``CORE_API`` the built core lacks (all of them where it is not built)."""
    if native._native is None:
        return list(CORE_API)
    gone = []
    for name in CORE_API:
        owner: object = native._native
        for part in name.split("."):
            owner = getattr(owner, part, None)
        if owner is None:
            gone.append(name)
    return gone


def why_not() -> str:
    """Why the native tests cannot run ("" when they can)."""
    if native._native is None:
        return f"the native core is {native.WHY_NOT}"
    gone = missing_api()
    if gone:
        return f"the native core lacks {', '.join(gone)} (built from an older crate?)"
    return ""


def skip_or_fail(why: str) -> NoReturn:
    """Skip (no cargo on the PATH: a pure-Python install) or fail (cargo is there, so the core
    should have been built). At module level (before importing the core) and in a test."""
    cargo = shutil.which("cargo")
    if cargo:
        pytest.fail(
            f"{why}, yet cargo is on the PATH ({cargo}): the core should have been built; "
            "`make native` rebuilds it and shows the build's errors",
            pytrace=False,
        )
    pytest.skip(f"{why}; no cargo on the PATH", allow_module_level=True)


def require_native() -> None:
    """Go on where the core is complete, else ``skip_or_fail``."""
    if why := why_not():
        skip_or_fail(why)


#: marks a test that needs the core, in a module whose other tests do not (the fixture
#: ``native_core`` of tests/conftest.py calls ``require_native``); a module that needs it
#: throughout starts ``if why := why_not(): skip_or_fail(why)``, before importing the core
needs_native = pytest.mark.usefixtures("native_core")
