"""Shared test set-up: helpers (``protocol_vectors``) importable from every test folder, one
Hypothesis profile, and the fixture of the tests that need the native core.

Property tests assert behaviour, not speed (speed lives in tests/benchmarks/): no per-example
deadline, so a loaded CI machine cannot turn a slow example into a failure.
"""

import sys
from pathlib import Path

import pytest
from hypothesis import settings

# the helpers importable from every folder, and the project itself ahead of them: tests/analyzer
# (a folder without __init__) would otherwise pass for the analyzer package when a folder's
# tests run alone, ahead of the editable install's finder
sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from native_core import require_native

settings.register_profile("eg2scope", deadline=None, print_blob=True)
settings.load_profile("eg2scope")


@pytest.fixture
def native_core() -> None:
    """The native core, complete: else the test skips or fails (``native_core.require_native``)."""
    require_native()


@pytest.fixture(autouse=True)
def native_engine_case(request: pytest.FixtureRequest) -> None:
    """A case parametrized ``engine="native"`` needs the core like ``native_core`` (a param
    cannot carry that fixture's mark)."""
    callspec = getattr(request.node, "callspec", None)
    if callspec is not None and callspec.params.get("engine") == "native":
        require_native()
