"""The native tests skip without a Rust toolchain and fail with one when the core is missing or
lacks part of its API (tests/native_core.py): pytest run as a real process on real test modules,
with the core hidden or cut down in that process and cargo on its PATH or not."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
CARGO = shutil.which("cargo")
# a PATH without cargo: the interpreter's own folder (a venv's bin holds no cargo)
NO_CARGO_PATH = str(Path(sys.executable).parent)

HIDE_CORE = "sys.modules['analyzer._native'] = None"  # its import fails: as if never built
CUT_CORE = "import analyzer._native as core; del core.CanStage"  # as if built from an older crate

# one module that checks at its top, one test that checks in its fixture
MODULE = "tests/native/test_native_differential.py"
FIXTURE_TEST = "tests/native/test_native_engine.py::test_engine_native_refuses_what_it_cannot_do"


def pytest_run(core: str, path: str, target: str) -> subprocess.CompletedProcess[str]:
    """``pytest -rs TARGET`` in a fresh interpreter whose core was changed by ``core`` first."""
    args = ["-rs", "-p", "no:cacheprovider", target]
    code = f"import sys; {core}; import pytest; sys.exit(pytest.main({args!r}))"
    env = {**os.environ, "PATH": path, "PYTHONPATH": str(ROOT)}
    return subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, env=env, cwd=ROOT, timeout=90
    )


def with_cargo() -> str:
    if CARGO is None:
        pytest.skip("cargo is not installed here: the failing case needs it on the PATH")
    return f"{Path(CARGO).parent}{os.pathsep}{NO_CARGO_PATH}"


@pytest.mark.parametrize("target", [MODULE, FIXTURE_TEST])
def test_a_missing_core_fails_where_cargo_is(target: str) -> None:
    ran = pytest_run(HIDE_CORE, with_cargo(), target)
    assert ran.returncode not in (0, 5), ran.stdout  # 5: nothing ran
    assert "the native core is not built" in ran.stdout
    assert "yet cargo is on the PATH" in ran.stdout
    assert "make native" in ran.stdout


@pytest.mark.parametrize("target", [MODULE, FIXTURE_TEST])
def test_an_incomplete_core_fails_where_cargo_is(target: str) -> None:
    ran = pytest_run(CUT_CORE, with_cargo(), target)
    assert ran.returncode not in (0, 5), ran.stdout
    assert "the native core lacks CanStage (built from an older crate?)" in ran.stdout
    assert "yet cargo is on the PATH" in ran.stdout


@pytest.mark.parametrize("target", [MODULE, FIXTURE_TEST])
def test_without_cargo_the_native_tests_skip_saying_why(target: str) -> None:
    ran = pytest_run(HIDE_CORE, NO_CARGO_PATH, target)
    assert ran.returncode in (0, 5), ran.stdout  # 5: a skipped module leaves nothing to run
    assert ran.stdout.rstrip().splitlines()[-1].startswith("1 skipped in ")  # no fail, no error
    assert "the native core is not built" in ran.stdout
    assert "no cargo on the PATH" in ran.stdout


# native cases beside Python ones, outside tests/native: a module-wide mark, a test's own mark,
# a case parametrized engine="native"
OUTSIDE = [
    "tests/rerun/test_native_plot_path.py",
    "tests/analyzer/test_stop_semantics.py::test_both_engines_cut_off_alike",
    "tests/analyzer/test_stop_semantics.py::test_can_requests_waiting_at_a_stop_are_cut_off[native]",
]


@pytest.mark.parametrize("target", OUTSIDE)
def test_native_cases_elsewhere_fail_too_where_cargo_is(target: str) -> None:
    ran = pytest_run(HIDE_CORE, with_cargo(), target)
    assert ran.returncode not in (0, 5), ran.stdout
    assert "yet cargo is on the PATH" in ran.stdout
    assert " passed" not in ran.stdout.rstrip().splitlines()[-1]  # every case needs the core


@pytest.mark.parametrize("target", OUTSIDE)
def test_native_cases_elsewhere_skip_without_cargo(target: str) -> None:
    ran = pytest_run(HIDE_CORE, NO_CARGO_PATH, target)
    assert ran.returncode in (0, 5), ran.stdout
    last = ran.stdout.rstrip().splitlines()[-1]
    assert " skipped in " in last and "failed" not in last and "error" not in last, last
    assert "no cargo on the PATH" in ran.stdout
