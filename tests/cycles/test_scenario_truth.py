"""Every grip cycle ``eg2scope cycles`` finds, held against what the simulator says really
happened, for every scenario on all three buses and on both engines.

Each scenario is recorded by a real ``eg2scope record --demo --scenario NAME --truth FILE``
process (the simulated grippers on two pty lines and python-can's virtual bus, watched by the
real passive taps), once on all three buses (the Python engine: the native one decodes CAN only)
and once on CAN alone (both engines). A real ``eg2scope cycles REC.mcap --format jsonl`` process
cuts each recording into cycles, and each gripper's cycles, in the order they began, must be the
truth's cycles one for one, by the rule of tests/scenario_truth.py: the same outcome, the width
at contact within 0.2 mm, the slip warned of, the stall's fault in words, the command's target
(``tour`` repeats: its last cycle may be cut off by the recording's end).
"""

from __future__ import annotations

import json
import subprocess
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest
from native_core import needs_native, why_not
from scenario_capture import BUS_OF, EG2SCOPE, ROOT, read_truth, record_scenarios
from scenario_truth import ALL_BUSES, Cycle, check, pairs

from analyzer.sim.scenarios import NAMES, SCRIPT_OUTCOMES

CAN = BUS_OF["can"]
RUNS = [(bus, "python") for bus in ALL_BUSES] + [(CAN, "native")]


@dataclass(frozen=True)
class Found:
    """One scenario's recording: what ``cycles`` found in it and the truth of it."""

    cycles: list[Cycle]
    truth: list[Cycle]
    stdout: bytes  # the jsonl as written, for comparing the engines


@pytest.fixture(scope="module")
def found(tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict[tuple[str, str], Found]]:
    """(scenario, engine) -> the cycles of its recording: the Python engine's of the recording
    of all three buses, the native engine's (and the Python one's, as ``can-python``) of the
    recording of CAN alone."""
    mixed, can_only = tmp_path_factory.mktemp("mixed"), tmp_path_factory.mktemp("can")
    native = not why_not()  # without the core its cases skip (or fail: native_core.py)
    record_scenarios(list(NAMES), mixed)
    if native:
        record_scenarios(list(NAMES), can_only, buses="can")
    runs = {(n, "python"): (mixed, "python") for n in NAMES}
    runs |= {
        (n, e): (can_only, e.removeprefix("can-"))
        for n in NAMES
        for e in (("native", "can-python") if native else ())
    }
    procs = {
        key: _cycles(folder / f"{key[0]}.mcap", engine) for key, (folder, engine) in runs.items()
    }
    out = {}
    for key, proc in procs.items():
        stdout, stderr = proc.communicate(timeout=120)
        assert proc.returncode == 0, f"cycles {key}: exit {proc.returncode}\n{stderr.decode()}"
        cycles = [json.loads(line) for line in stdout.splitlines()]
        out[key] = Found(cycles, read_truth(runs[key][0], key[0]), stdout)
    yield out


def _cycles(mcap: Path, engine: str) -> subprocess.Popen[bytes]:
    argv = [*EG2SCOPE, "cycles", str(mcap), "--format", "jsonl", "--engine", engine]
    return subprocess.Popen(argv, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE)


@pytest.mark.parametrize(("bus", "engine"), RUNS)
@pytest.mark.parametrize("name", NAMES)
def test_every_cycle_is_found_with_its_true_outcome(
    found: dict[tuple[str, str], Found], name: str, bus: str, engine: str
) -> None:
    recording = found[name, engine]
    checked = pairs(recording.cycles, recording.truth, bus)
    assert checked, f"no truth on {bus}"
    for truth, seen in checked:
        check(truth, seen)


@needs_native
@pytest.mark.parametrize("name", NAMES)
def test_both_engines_find_the_same_cycles(found: dict[tuple[str, str], Found], name: str) -> None:
    assert found[name, "native"].stdout == found[name, "can-python"].stdout
    assert found[name, "native"].cycles  # not two empty outputs


@pytest.mark.parametrize("engine", ["python", "native"])
def test_the_tour_checks_every_outcome_a_script_plays(
    found: dict[tuple[str, str], Found], engine: str
) -> None:
    outcomes = {
        t["outcome"]
        for t, _ in pairs(found["tour", engine].cycles, found["tour", engine].truth, CAN)
    }
    assert outcomes == set(SCRIPT_OUTCOMES), engine
