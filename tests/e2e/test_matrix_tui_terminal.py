"""``eg2scope tui CAPTURE`` on every input kind, and ``tui --demo`` live, as a user runs it: a
real process in a real pseudo-terminal (pexpect, the screen read back through pyte) at 80x24
and 200x50. Decoded frames appear with their manual names whole (a name cut short ends in
``…``, never as a bare ``CMD_`` or a shorter name that reads like a real one); each bus has its
health line (a load in percent, or for a raw dump, which has no times, "no timing"); ``c``
shows the grip cycles with their outcomes; and ``q`` exits 0. The terminals run a few at a
time (``Prefetch``)."""

from __future__ import annotations

import re
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest
from e2e_checks import CMD_WORD, Prefetch, Terminal, manual_names
from e2e_inputs import EG2SCOPE, IDS, KINDS, LIVE_DEMO

from analyzer.cycles.model import OUTCOMES
from analyzer.health.bus import NO_TIMING

pytest.importorskip("pexpect")
pytest.importorskip("pyte")

SIZES = {"80x24": (80, 24), "200x50": (200, 50)}
RAW_DUMPS = {k.id for k in KINDS if k.file.endswith(".bin")}  # no times at all
LOAD = re.compile(r"^ (\S+) +load +\d+\.\d%", re.MULTILINE)  # a bus's health line
OUTCOME = re.compile(rf"\b({'|'.join(OUTCOMES)})\b")


@dataclass(frozen=True)
class Seen:
    screen: str  # once decoded frames are shown and the screen has settled
    cycles: str  # after c: the cycles panel, once a cycle is shown
    status: int | None  # after q


def watch(argv: list[str], size: str, cwd: Path) -> Seen:
    term = Terminal(argv, *SIZES[size], cwd=cwd)
    try:
        screen = term.settle(ready=lambda text: CMD_WORD.search(text) is not None)
        term.child.send("c")
        cycles = term.settle(ready=lambda text: OUTCOME.search(_panel(text)) is not None)
        return Seen(screen, cycles, term.quit("q"))
    finally:
        term.close()


@pytest.fixture(scope="module")
def terminals(request, inputs, tmp_path_factory) -> Iterator[Prefetch[Seen]]:
    def start(kind: str, size: str) -> Callable[[], Seen]:
        source = ["--demo"] if kind == LIVE_DEMO else [str(inputs[kind])]
        cwd = tmp_path_factory.mktemp("tui")
        return lambda: watch([*EG2SCOPE, "tui", *source], size, cwd)

    with Prefetch(request, test_tui_in_a_terminal, start) as runs:
        yield runs


def _panel(screen: str) -> str:
    """The cycles panel's lines: under its header (``outcome``), above the footer."""
    lines = screen.splitlines()
    top = next((k for k, line in enumerate(lines) if "outcome" in line and "command" in line), None)
    return "" if top is None else "\n".join(lines[top + 1 : -1])


def health_problems(kind: str, screen: str) -> list[str]:
    """What is wrong with the health lines: a raw dump's must say it has no timing (and show no
    load); every other input's show a load in percent."""
    if kind in RAW_DUMPS:
        if NO_TIMING not in screen or LOAD.search(screen):
            return ["a raw dump's health line does not say it has no timing"]
        return []
    return [] if LOAD.search(screen) else ["no health line with a load in percent"]


def cut_names(screen: str, names: set[str]) -> list[str]:
    """The CMD_ words on the screen that are no name of the capture and carry no mark of a cut
    (or are cut down to the bare prefix)."""
    cut = []
    for word in CMD_WORD.findall(screen):
        marked = word.endswith("…") and len(word) > len("CMD_…")
        if word not in names and not marked:
            cut.append(word)
    return cut


@pytest.mark.parametrize("size", SIZES)
@pytest.mark.parametrize("kind", [*IDS, LIVE_DEMO])
def test_tui_in_a_terminal(kind: str, size: str, terminals, reference) -> None:
    names = manual_names() if kind == LIVE_DEMO else reference.decoded(kind).cmd_names()
    seen = terminals(kind=kind, size=size)
    problems = []
    if not set(CMD_WORD.findall(seen.screen)) & names:
        problems.append("no decoded frame's name is shown whole")
    if cut := cut_names(seen.screen, names):
        problems.append(f"names cut without a mark: {sorted(set(cut))}")
    problems += health_problems(kind, seen.screen)
    if not OUTCOME.search(_panel(seen.cycles)):
        problems.append("c shows no grip cycle with its outcome:\n" + seen.cycles)
    if seen.status != 0:
        problems.append(f"q exited {seen.status}")
    assert not problems, "; ".join(problems) + "; the screen:\n" + seen.screen
