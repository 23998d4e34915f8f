"""Every grip cycle ``eg2scope cycles`` finds, held against what the simulator says really
happened, for every scenario on all three buses and on both engines.

Each scenario is recorded by a real ``eg2scope record --demo --scenario NAME --truth FILE``
process (the simulated grippers on two pty lines and python-can's virtual bus, watched by the
real passive taps), once on all three buses (the Python engine: the native one decodes CAN only)
and once on CAN alone (both engines). A real ``eg2scope cycles REC.mcap --format jsonl`` process
cuts each recording into cycles, and each gripper's cycles, in the order they began, must be the
truth's cycles one for one: the same outcome, the width at contact within 0.2 mm, the slip
warned of, the stall's fault in words, the command's target. The one cycle the truth may lack is
the last one, cut off by the end of the recording while the host's script went on (``tour``
repeats): it must be ``unfinished``; and the truth's last cycle may be found ``unfinished``
where the taps stopped before the host's last readings.
"""

from __future__ import annotations

import json
import subprocess
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
from native_core import needs_native, why_not
from scenario_capture import BUS_OF, EG2SCOPE, ROOT, read_truth, record_scenarios

from analyzer.cycles.model import GRIPPED, SLIP, UNFINISHED
from analyzer.sim.scenarios import NAMES, SCRIPT_OUTCOMES
from decoders.registers import fault_text, opening_mm

WIDTH_TOLERANCE_MM = 0.2
EARLY_S = 0.05  # a command's capture time may lead the host's clock by this much, never more
TARGET_MM = {"catch": 0.0, "continuous catch": 0.0, "release": 70.0}  # a seek: its position
ALL_BUSES = ("rs232", "rs485", "can0")
CAN = BUS_OF["can"]
RUNS = [(bus, "python") for bus in ALL_BUSES] + [(CAN, "native")]
Cycle = dict[str, Any]


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


def pairs(found: Found, bus: str) -> list[tuple[Cycle, Cycle]]:
    """(truth, detected) for every cycle of the bus, each gripper's in the order they began;
    a gripper's last cycle, found unfinished (cut off by the recording's end), left out."""
    out = []
    for device in sorted({t["device"] for t in found.truth if t["bus"] == bus}):
        truth = sorted(
            (t for t in found.truth if (t["bus"], t["device"]) == (bus, device)),
            key=lambda t: t["start_t"],
        )
        seen = sorted(
            (c for c in found.cycles if (c["bus"], c["device"]) == (bus, device)),
            key=lambda c: c["start_seq"],
        )
        if seen and seen[-1]["outcome"] == UNFINISHED:  # cut off by the recording's end:
            seen = seen[:-1]  # the script's next cycle (the truth has none) ...
            if len(truth) == len(seen) + 1:  # ... or its last, ended after the taps stopped
                truth = truth[:-1]
        assert len(seen) == len(truth), _table(truth, seen)
        out += list(zip(truth, seen, strict=True))
    assert {c["bus"] for c in found.cycles} <= set(ALL_BUSES)
    return out


def _table(truth: list[Cycle], seen: list[Cycle]) -> str:
    told = [f"truth {t['start_t']:.3f} {t['command']} {t['outcome']}" for t in truth]
    return "\n".join(
        told + [f"found {c['start_t']:.3f} {c['command']} {c['outcome']}" for c in seen]
    )


def check(truth: Cycle, seen: Cycle) -> None:
    """One detected cycle against the truth of it."""
    what = f"{truth['scenario']} {truth['bus']} #{truth['index']} {truth['command']}: {seen}"
    assert truth["start_t"] - EARLY_S <= seen["start_t"] <= truth["end_t"], what
    assert seen["outcome"] == truth["outcome"], what
    if truth["outcome"] == GRIPPED:
        assert abs(seen["width_mm"] - truth["contact_mm"]) <= WIDTH_TOLERANCE_MM, what
    else:
        assert seen["width_mm"] is None, what
    assert (SLIP in seen["warnings"]) == (SLIP in truth["warnings"]), what
    assert seen["faults"] == fault_text(truth["faults"]), what
    target = TARGET_MM.get(truth["command"])
    expected = opening_mm(truth["position"]) if target is None else target
    assert seen["target_mm"] == pytest.approx(expected), what
    assert seen["retries"] >= (0 if truth["answered"] else 1), what  # the host resent it


@pytest.mark.parametrize(("bus", "engine"), RUNS)
@pytest.mark.parametrize("name", NAMES)
def test_every_cycle_is_found_with_its_true_outcome(
    found: dict[tuple[str, str], Found], name: str, bus: str, engine: str
) -> None:
    recording = found[name, engine]
    checked = pairs(recording, bus)
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
    outcomes = {t["outcome"] for t, _ in pairs(found["tour", engine], CAN)}
    assert outcomes == set(SCRIPT_OUTCOMES), engine
