"""``eg2scope batch`` in a real pseudo-terminal (pexpect, the screen read back through pyte): the
progress bar moves within a capture (the bytes of it read), in one process and on Dask, on the
native route (a candump log) and in a session (a python-can log); and the workers' progress
reaches the client as Dask events."""

from __future__ import annotations

import re
import sys
import time
from pathlib import Path

import can
import pytest
from traffic import can_frames

from analyzer.fleet.runner import DaskOptions, plan, run_on_dask
from decoders.build import candump_line

pexpect = pytest.importorskip("pexpect")
pyte = pytest.importorskip("pyte")
pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[2]
T0 = 1_763_700_000.0
BAR = re.compile(r"captures (\d+)/(\d+) .*?([\d.]+)/([\d.]+) (k?B|MB|GB)")


@pytest.fixture(scope="module")
def big(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    """A candump log and an .asc log that take a few seconds each."""
    folder = tmp_path_factory.mktemp("big")
    log = folder / "cell.log"
    log.write_text("\n".join(candump_line(f) for f in can_frames(150_000, seed=1, t0=T0)) + "\n")
    asc = folder / "cell.asc"
    with can.ASCWriter(str(asc)) as writer:
        for f in can_frames(40_000, seed=2, t0=T0):
            writer.on_message_received(
                can.Message(
                    timestamp=f.t or T0,
                    arbitration_id=f.arbitration_id,
                    is_extended_id=f.is_extended,
                    data=f.data,
                )
            )
    return [log, asc]


def watch(
    argv: list[str], columns: int, lines: int, timeout: float = 300.0
) -> tuple[list[tuple[int, int, float, float]], int]:
    """Run ``argv`` in a pseudo-terminal of that size; every state of the bar seen (captures
    done, captures, bytes read, bytes in all) and the exit status."""
    screen = pyte.Screen(columns, lines)
    stream = pyte.ByteStream(screen)
    child = pexpect.spawn(
        argv[0],
        argv[1:],
        cwd=str(ROOT),
        dimensions=(lines, columns),
        env={"TERM": "xterm-256color", "PATH": "/usr/bin:/bin", "PYTHONPATH": str(ROOT)},
    )
    seen: list[tuple[int, int, float, float]] = []
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        try:
            stream.feed(child.read_nonblocking(65536, timeout=0.05))
        except pexpect.TIMEOUT:
            pass
        except pexpect.EOF:
            break
        for line in screen.display:
            m = BAR.search(line)
            if m:
                state = (int(m[1]), int(m[2]), float(m[3]), float(m[4]))
                if not seen or seen[-1] != state:
                    seen.append(state)
    child.close()
    return seen, child.exitstatus


def moved_within_a_capture(seen: list[tuple[int, int, float, float]]) -> bool:
    """A state with no capture done yet and part of the bytes read."""
    return any(done == 0 and 0 < read < total for done, _, read, total in seen)


@pytest.mark.parametrize(("workers", "size"), [("1", (80, 24)), ("2", (200, 50))])
def test_the_bar_moves_within_a_capture(
    workers: str, size: tuple[int, int], big: list[Path], tmp_path: Path
) -> None:
    argv = [sys.executable, "-m", "analyzer", "batch", *map(str, big), "-o", str(tmp_path / "d")]
    seen, status = watch([*argv, "--workers", workers, "--dashboard-address", "none"], *size)
    assert status == 0
    assert moved_within_a_capture(seen), seen
    assert len({read for _, _, read, _ in seen}) >= 3, seen  # it moved, more than once
    assert seen[-1][1] == 2


def test_dask_workers_tell_the_client_how_far_they_have_got(
    big: list[Path], tmp_path: Path
) -> None:
    told: list[tuple[str, int, int]] = []
    results = []
    jobs, _ = plan(big, tmp_path / "d", None, False)
    options = DaskOptions(2, dashboard=None)
    run_on_dask(jobs, options, results.append, progress=lambda *event: told.append(event))
    assert [r.status for r in results] == ["done", "done"]
    for path in big:
        mine = [(position, records) for p, position, records in told if p == str(path)]
        assert any(0 < position < path.stat().st_size for position, _ in mine), mine
        assert mine == sorted(mine)  # in order, never back
