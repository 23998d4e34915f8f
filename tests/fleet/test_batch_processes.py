"""``eg2scope batch`` as a user runs it, as a process: on a Dask LocalCluster of two worker
processes (one killed mid-run), interrupted and resumed, bound to localhost, and without Dask."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path

import psutil
import pyarrow.dataset as ds
import pytest
from fleet_folder import make_fleet

from analyzer.fleet import layout
from analyzer.fleet.inputs import content_hash

# real processes, Dask clusters started and stopped, runs done twice: on a busy machine this
# takes longer than the unit tests' limit
pytestmark = pytest.mark.timeout(300)

ROOT = Path(__file__).resolve().parents[2]
ENV = {**os.environ, "PYTHONPATH": str(ROOT), "COLUMNS": "120"}
BATCH = [sys.executable, "-m", "analyzer", "batch"]


@pytest.fixture(scope="module")
def fleet(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    """Captures big enough that a run lasts a few seconds (no damaged or unreadable ones)."""
    paths = make_fleet(tmp_path_factory.mktemp("fleet"), frames=12_000, broken=False)
    return sorted(paths.values())


def start(*argv: str) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [*BATCH, *argv, "--no-progress"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=ENV,
        cwd=ROOT,
    )


def wait_for(predicate: object, timeout: float = 120.0) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():  # type: ignore[operator]
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.02)


def assert_complete_without_duplicates(root: Path, fleet: list[Path]) -> None:
    assert layout.done_hashes(root) == {content_hash(p) for p in fleet}
    records = ds.dataset(root / layout.RECORDS, partitioning="hive").to_table(
        columns=["capture_hash", "seq"]
    )
    keys = Counter(
        zip(records["capture_hash"].to_pylist(), records["seq"].to_pylist(), strict=True)
    )
    assert max(keys.values()) == 1  # no row twice
    per_capture = Counter(h for h, _ in keys)
    captures = ds.dataset(root / layout.CAPTURES, partitioning="hive").to_table()
    for row in captures.to_pylist():
        assert per_capture[row["capture_hash"]] == row["records"]  # and none missing
    assert not list(layout.stale_temporaries(root))


def summary_count(out: str, label: str) -> int:
    match = re.search(rf"{label}\s*│\s*(\d+)", out)
    assert match, out
    return int(match.group(1))


def test_a_worker_killed_mid_capture_leaves_the_dataset_whole(
    fleet: list[Path], tmp_path: Path
) -> None:
    root = tmp_path / "d"
    proc = start(*map(str, fleet), "-o", str(root), "--workers", "2", "--dashboard-address", "none")
    victims: list[psutil.Process] = []

    def writing_worker() -> bool:
        for child in psutil.Process(proc.pid).children(recursive=True):
            try:
                if any(layout._TEMP_MARK in f.path for f in child.open_files()):
                    victims.append(child)
                    return True
            except psutil.Error:
                continue
        assert proc.poll() is None, proc.communicate()
        return False

    wait_for(writing_worker)
    victims[0].kill()  # mid-capture: it holds a temporary partition file open
    out, err = proc.communicate(timeout=300)
    assert proc.returncode == 0, err
    assert summary_count(out, "decoded") == len(fleet)
    assert_complete_without_duplicates(root, fleet)


def writing(root: Path) -> bool:
    """A capture is being written: a temporary partition file is there."""
    return any(layout.stale_temporaries(root))


# Ctrl-C between captures (two done) and in the middle of one (its partitions being written),
# each a few times: a Ctrl-C that landed in pyarrow's conversion of a list was lost now and
# then (the batch went on and exited 0), so one try proves little
MOMENTS = {
    "after two captures": lambda root: len(layout.done_hashes(root)) >= 2,
    "mid-capture": writing,
}


@pytest.mark.parametrize(
    ("workers", "moment", "attempt"),
    [("1", moment, attempt) for moment in MOMENTS for attempt in range(3)]
    + [("2", moment, 0) for moment in MOMENTS],
)
def test_interrupted_then_resumed_redoes_nothing_and_duplicates_nothing(
    workers: str, moment: str, attempt: int, fleet: list[Path], tmp_path: Path
) -> None:
    root = tmp_path / "d"
    inputs = [str(p) for p in fleet]
    proc = start(*inputs, "-o", str(root), "--workers", workers, "--dashboard-address", "none")
    wait_for(lambda: MOMENTS[moment](root))
    proc.send_signal(signal.SIGINT)
    _out, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    assert "run the same command again to finish the rest" in err
    done = layout.done_hashes(root)
    assert len(done) < len(fleet)
    assert not list(layout.stale_temporaries(root))  # the capture cut short left nothing
    kept = {p: p.stat().st_mtime_ns for h in done for p in layout.capture_files(root, h)}

    again = subprocess.run(
        [*BATCH, *inputs, "-o", str(root), "--workers", workers, "--no-progress"],
        capture_output=True,
        text=True,
        env=ENV,
        cwd=ROOT,
        timeout=300,
    )
    assert again.returncode == 0, again.stderr
    assert summary_count(again.stdout, "already in the dataset") == len(done)
    assert summary_count(again.stdout, "decoded") == len(fleet) - len(done)
    assert {p: p.stat().st_mtime_ns for p in kept} == kept  # nothing redone
    assert_complete_without_duplicates(root, fleet)


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGHUP])
def test_sigterm_and_sighup_interrupt_it_too(
    signum: signal.Signals, fleet: list[Path], tmp_path: Path
) -> None:
    root = tmp_path / "d"
    proc = start(*map(str, fleet), "-o", str(root), "--workers", "1")
    wait_for(lambda: writing(root))
    proc.send_signal(signum)
    _out, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    assert "run the same command again to finish the rest" in err
    assert len(layout.done_hashes(root)) < len(fleet)
    assert not list(layout.stale_temporaries(root))


def test_the_local_cluster_listens_on_localhost_only(fleet: list[Path], tmp_path: Path) -> None:
    proc = start(
        *map(str, fleet),
        "-o",
        str(tmp_path / "d"),
        "--workers",
        "2",
        "--dashboard-address",
        "127.0.0.1:0",
    )
    listening: set[str] = set()

    def sockets_up() -> bool:
        family = psutil.Process(proc.pid)
        for p in [family, *family.children(recursive=True)]:
            try:
                for c in p.net_connections(kind="inet"):
                    if c.status == psutil.CONN_LISTEN:
                        listening.add(c.laddr.ip)
            except psutil.Error:
                continue
        return len(listening) > 0 and len(family.children()) >= 2

    wait_for(sockets_up)
    _out, err = proc.communicate(timeout=300)
    assert proc.returncode == 0, err
    assert listening == {"127.0.0.1"}
    assert re.search(r"dashboard: http://127\.0\.0\.1:\d+/status", err)


NO_DASK = (
    "import sys\n"
    "sys.modules['distributed'] = None; sys.modules['dask'] = None\n"
    "from analyzer.cli import main\n"
    "sys.exit(main(sys.argv[1:]))\n"
)


def test_without_dask_it_says_how_to_install_and_one_worker_still_works(
    fleet: list[Path], tmp_path: Path
) -> None:
    def run(*argv: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run(
            [sys.executable, "-c", NO_DASK, "batch", *argv, "-o", str(tmp_path / "d")],
            capture_output=True,
            text=True,
            env=ENV,
            cwd=ROOT,
            timeout=300,
        )

    refused = run(str(fleet[0]))
    assert refused.returncode == 2
    assert "pip install 'eg2scope[fleet]'" in refused.stderr
    assert "--workers 1" in refused.stderr
    assert not (tmp_path / "d").exists()
    done = run(str(fleet[0]), "--workers", "1")
    assert done.returncode == 0, done.stderr
    assert layout.done_hashes(tmp_path / "d") == {content_hash(fleet[0])}


def test_an_existing_cluster_named_by_its_scheduler(fleet: list[Path], tmp_path: Path) -> None:
    from dask.distributed import LocalCluster

    root = tmp_path / "d"
    with LocalCluster(
        n_workers=1, threads_per_worker=1, host="127.0.0.1", dashboard_address=None
    ) as cluster:
        done = subprocess.run(
            [
                *BATCH,
                *map(str, fleet[:3]),
                "-o",
                str(root),
                "--scheduler",
                cluster.scheduler_address,
                "--no-progress",
            ],
            capture_output=True,
            text=True,
            env=ENV,
            cwd=ROOT,
            timeout=300,
        )
    assert done.returncode == 0, done.stderr
    assert "Dask: 1 worker" in done.stderr
    assert summary_count(done.stdout, "decoded") == 3
    assert_complete_without_duplicates(root, fleet[:3])
