"""``eg2scope tui CAPTURE`` on every input kind as a user runs it: a real process in a real
pseudo-terminal (pexpect, the screen read back through pyte) at 80x24 and 200x50. Decoded
frames appear with their manual names whole (a name cut short ends in ``…``, never as a bare
``CMD_`` or a shorter name that reads like a real one), and ``q`` exits 0."""

from __future__ import annotations

from pathlib import Path

import pytest
from e2e_checks import CMD_WORD, Terminal, manual_names
from e2e_inputs import EG2SCOPE, IDS, LIVE_DEMO

pytest.importorskip("pexpect")
pytest.importorskip("pyte")

SIZES = {"80x24": (80, 24), "200x50": (200, 50)}


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
def test_tui_in_a_terminal(kind: str, size: str, inputs, reference, tmp_path: Path) -> None:
    columns, lines = SIZES[size]
    if kind == LIVE_DEMO:
        source, names = ["--demo"], manual_names()
    else:
        source, names = [str(inputs[kind])], reference.decoded(kind).cmd_names()
    term = Terminal([*EG2SCOPE, "tui", *source], columns, lines, cwd=tmp_path)
    try:
        screen = term.settle(ready=lambda text: CMD_WORD.search(text) is not None)
        status = term.quit("q")
    finally:
        term.close()
    problems = []
    if not set(CMD_WORD.findall(screen)) & names:
        problems.append("no decoded frame's name is shown whole")
    if cut := cut_names(screen, names):
        problems.append(f"names cut without a mark: {sorted(set(cut))}")
    if status != 0:
        problems.append(f"q exited {status}")
    assert not problems, "; ".join(problems) + "; the screen:\n" + screen
