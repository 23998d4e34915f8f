"""A Ctrl-C stops ``eg2scope batch`` even where Python code would lose it: CPython drops an
exception raised in a garbage-collector callback or a finalizer (it only prints it), and
pyarrow's conversion of a Python list lost some too (``batch --workers 1`` went on and exited
0). The batch notes the signal and stops at its next step instead, saying so, with exit 130
and nothing of the capture cut short in the dataset."""

from __future__ import annotations

import gc
import os
import signal
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from analyzer import cli
from analyzer.fleet import layout


@pytest.fixture(params=[signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def ctrl_c_in_the_collector(
    tmp_path: Path, request: pytest.FixtureRequest
) -> Iterator[list[float]]:
    """At the first garbage collection once the batch has started (its lock file is there),
    a Ctrl-C (or SIGTERM, which a session would raise as one) arrives while the collector runs
    a callback: a KeyboardInterrupt raised there is lost. The list gets the time it was sent."""
    signum = request.param
    sent: list[float] = []
    lock = tmp_path / "d" / layout.LOCK_NAME

    def callback(phase: str, info: dict[str, Any]) -> None:
        if phase == "start" and not sent and lock.exists():
            sent.append(time.monotonic())
            os.kill(os.getpid(), signum)
            time.sleep(0.01)  # Python runs the signal's handler here

    gc.callbacks.append(callback)
    try:
        yield sent
    finally:
        gc.callbacks.remove(callback)


def test_a_ctrl_c_lost_by_python_code_still_stops_the_batch(
    fleet: dict[str, Path],
    tmp_path: Path,
    ctrl_c_in_the_collector: list[float],
    capsys: pytest.CaptureFixture[str],
) -> None:
    root = tmp_path / "d"
    inputs = [str(fleet[k]) for k in ("candump", "asc", "blf", "serial", "modbus")]
    # the Python engine: objects to collect from the first capture on
    code = cli.main(["batch", *inputs, "-o", str(root), "--workers", "1", "--engine", "python"])
    assert ctrl_c_in_the_collector, "no garbage collection during the batch"
    assert code == 130
    assert "run the same command again to finish the rest" in capsys.readouterr().err
    assert len(layout.done_hashes(root)) < len(inputs)
    assert not list(layout.stale_temporaries(root))
