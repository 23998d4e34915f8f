"""Shared test set-up: helpers (``protocol_vectors``) importable from every test folder, one
Hypothesis profile, and the fixture of the tests that need the native core.

Property tests assert behaviour, not speed (speed lives in tests/benchmarks/): no per-example
deadline, so a loaded CI machine cannot turn a slow example into a failure.
"""

import sys
from pathlib import Path

import pytest
from hypothesis import settings

sys.path.insert(0, str(Path(__file__).resolve().parent))

from native_core import require_native

settings.register_profile("eg2scope", deadline=None, print_blob=True)
settings.load_profile("eg2scope")


@pytest.fixture
def native_core() -> None:
    """The native core, complete: else the test skips or fails (``native_core.require_native``)."""
    require_native()
