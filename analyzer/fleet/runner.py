"""Running a batch: which captures need decoding, then each one through ``decode_capture``, in
this process (``--workers 1``) or on Dask (a LocalCluster of this machine's cores, or a cluster
the user names), with a progress bar and a summary.

Dask gets one task per capture. A task that dies with its worker is retried by the scheduler
(that is safe: ``capture_task``); one that keeps killing workers ends as FAILED, and the rest go
on.
"""

from __future__ import annotations

import contextlib
import functools
import logging
import os
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final

from ..health.rates import RateOptions
from . import layout
from .capture_task import (
    DAMAGED,
    FAILED,
    SKIPPED,
    UNREADABLE,
    CaptureJob,
    CaptureResult,
    decode_capture,
)
from .listeners import Throttled
from .tables import CAPTURES_SCHEMA, HASH, PATH

Report = Callable[[CaptureResult], None]

#: Dask settings for the workers of the LocalCluster batch starts: Dask's statistical profiler
#: walks the running task's stack every 10 ms, which cost the decoding about 8% (measured with
#: tests/benchmarks/bench_batch.py; the dashboard loses its Profile page)
WORKER_CONFIG: Final = {"distributed.worker.profile.enabled": False}


@dataclass(frozen=True)
class DaskOptions:
    workers: int  # for a LocalCluster
    scheduler: str | None = None  # an existing cluster: its scheduler's address
    host: str = "127.0.0.1"  # where a LocalCluster's scheduler and workers listen
    dashboard: str | None = "127.0.0.1:8787"  # None: no dashboard


def plan(
    paths: Iterable[Path],
    root: Path,
    protocol: str | None,
    force: bool,
    engine: str = "auto",
    rates: RateOptions | None = None,
) -> tuple[list[CaptureJob], list[CaptureResult]]:
    """The jobs to run, and the captures skipped without reading them: a path whose size and
    modification time match its row in ``captures/``, decoded with the same options, has the
    same rows (as make and rsync assume); anything else is hashed by its task."""
    known = {} if force else _known(root)
    jobs, skipped = [], []
    for path in paths:
        stat = path.stat()
        job = CaptureJob(str(path), str(root), protocol, force, engine, rates or RateOptions())
        key = (str(path), stat.st_size, stat.st_mtime_ns // 1000, job.decode_options)
        digest = known.get(key)
        if digest is not None:
            skipped.append(CaptureResult(str(path), SKIPPED, digest, message="unchanged"))
        else:
            jobs.append(job)
    return jobs, skipped


def _known(root: Path) -> dict[tuple[str, int, int, str], str]:
    """(path, size, mtime, decode options) -> content hash, of the captures the dataset
    holds."""
    files = sorted((root / layout.CAPTURES).glob("day=*/*.parquet"))
    if not files:
        return {}
    import pyarrow.dataset as ds  # 0.1 s to import: only for a dataset that holds captures

    columns = [PATH, HASH, "size", "mtime", layout.OPTIONS]
    # the schema of today's rows: one written before the options were kept reads as null
    dataset = ds.dataset([str(f) for f in files], schema=CAPTURES_SCHEMA, format="parquet")
    table = dataset.to_table(columns=columns)
    table = table.set_column(3, "mtime", table.column("mtime").cast("int64"))
    rows = table.to_pydict()
    keys = zip(rows[PATH], rows["size"], rows["mtime"], rows[layout.OPTIONS], strict=True)
    return dict(zip(keys, rows[HASH], strict=True))


#: how far a capture has got, for the progress bar: (path, bytes of it read, records)
CaptureProgress = Callable[[str, int, int], None]
#: the Dask topic the workers tell it on (Worker.log_event, Client.subscribe_topic)
PROGRESS_TOPIC: Final = "eg2scope-batch-progress"
#: seconds between two looks at a Ctrl-C while waiting for Dask's results
POLL_S: Final = 0.05
#: seconds between two progress events of a Dask worker
WORKER_PROGRESS_S: Final = 0.5


def run_in_loop(
    jobs: list[CaptureJob],
    report: Report,
    progress: CaptureProgress | None = None,
    interrupted: Callable[[], bool] = lambda: False,
) -> None:
    """Every capture in this process, one after the other (no Dask needed); ``interrupted``
    is asked before each capture and between its batches (KeyboardInterrupt when it says so)."""
    for job in jobs:
        if interrupted():
            raise KeyboardInterrupt
        told = None if progress is None else functools.partial(progress, job.path)
        report(decode_capture(job, told, interrupted))


def decode_on_worker(job: CaptureJob) -> CaptureResult:
    """``decode_capture`` as a Dask task: its progress goes to the client as events."""
    from distributed import get_worker

    worker = get_worker()

    def progress(position: int, records: int) -> None:
        worker.log_event(PROGRESS_TOPIC, [job.path, position, records])

    # through the scheduler: twice a second per worker is enough for a bar
    return decode_capture(job, Throttled(progress, WORKER_PROGRESS_S))


def run_on_dask(
    jobs: list[CaptureJob],
    options: DaskOptions,
    report: Report,
    started: Callable[[Any], None] | None = None,
    progress: CaptureProgress | None = None,
    interrupted: Callable[[], bool] = lambda: False,
) -> None:
    """Every capture as a Dask task, results reported as they complete (``started``: given the
    client once the cluster is up; ``progress``: told how far the workers have got with each
    capture; ``interrupted``: asked while waiting, KeyboardInterrupt when it says so)."""
    from dask.distributed import as_completed

    with _client(options) as client:
        if started is not None:
            started(client)
        if progress is not None:
            client.subscribe_topic(PROGRESS_TOPIC, lambda event: progress(*event[1]))
        futures = client.map(decode_on_worker, jobs, pure=False)
        by_key = {f.key: job for f, job in zip(futures, jobs, strict=True)}
        waiting = as_completed(futures)
        while not waiting.is_empty():
            for future in waiting.next_batch(block=False):
                report(_result(future, by_key[future.key]))
            if interrupted():
                raise KeyboardInterrupt
            time.sleep(POLL_S)


def _result(future: Any, job: CaptureJob) -> CaptureResult:
    try:
        return future.result()
    except Exception as exc:  # the task kept killing its workers, or the cluster went away
        return CaptureResult(job.path, FAILED, message=f"{type(exc).__name__}: {exc}")


@contextlib.contextmanager
def _client(options: DaskOptions) -> Iterator[Any]:
    import dask
    from dask.distributed import Client, LocalCluster

    if options.scheduler is not None:
        with Client(options.scheduler) as client:
            yield client
        return
    with (
        dask.config.set(WORKER_CONFIG),  # the worker processes take the config they start with
        LocalCluster(
            n_workers=options.workers,
            threads_per_worker=1,  # the decoders hold the GIL: processes, not threads
            processes=True,
            host=options.host,
            dashboard_address=options.dashboard,
            worker_dashboard_address=None,
            silence_logs=logging.ERROR,  # not a warning per task cancelled by Ctrl-C
        ) as cluster,
        Client(cluster) as client,
    ):
        yield client


def default_workers() -> int:
    """The cores this process may use."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1


class Tally:
    """Counts for the progress bar and the summary."""

    def __init__(self) -> None:
        self.started = time.perf_counter()
        self.results: list[CaptureResult] = []
        self.records = 0
        self.frames = 0
        self.errors = 0
        self.cycles = 0
        self.health_seconds = 0

    def add(self, result: CaptureResult) -> None:
        self.results.append(result)
        self.records += result.records
        self.frames += result.frames
        self.errors += result.errors
        self.cycles += result.cycles
        self.health_seconds += result.health_seconds

    def count(self, *statuses: str) -> int:
        return sum(r.status in statuses for r in self.results)

    @property
    def elapsed(self) -> float:
        return time.perf_counter() - self.started

    def problems(self) -> list[CaptureResult]:
        return [r for r in self.results if r.status in (DAMAGED, UNREADABLE, FAILED)]
