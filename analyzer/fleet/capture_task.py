"""One capture into the dataset: what a worker runs (in the batch's own process with
``--workers 1``, or on a Dask worker). It never raises for a bad capture: the outcome is the
``CaptureResult`` it returns, so one unreadable file never stops the others.

Safe to run again at any point (Dask retries a task whose worker died): it first removes what
an earlier attempt at the same content left, writes under temporary names, and commits with the
``captures/`` row last (``layout``).
"""

from __future__ import annotations

import datetime as dt
import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final

from .. import __version__
from ..commands.common import CaptureOptions, open_reader, run_capture
from ..sinks.stats import StatsListener
from . import layout
from .inputs import capture_suffix, content_hash
from .listeners import RecordPartitions, StatePartitions
from .partitions import PartitionFiles
from .tables import COUNTS, LATENCY, captures_table, utc_day

# outcomes
DONE: Final = "done"
DAMAGED: Final = "damaged"  # decoded as far as it goes, marked in captures/
SKIPPED: Final = "skipped"  # in the dataset already (same content)
UNREADABLE: Final = "unreadable"  # not in the dataset; the next run tries again
FAILED: Final = "failed"  # an output could not be written, or the worker kept dying


@dataclass(frozen=True)
class CaptureJob:
    path: str
    root: str
    protocol: str | None = None  # None: detected, as decode does
    force: bool = False  # decode it again even if the dataset holds it


@dataclass
class CaptureResult:
    path: str
    status: str
    content_hash: str | None = None
    records: int = 0
    frames: int = 0
    errors: int = 0
    message: str = ""
    seconds: float = 0.0


def decode_capture(job: CaptureJob) -> CaptureResult:
    """Decode one capture into the dataset under ``job.root``."""
    started = time.perf_counter()
    result = _decode(job)
    result.seconds = time.perf_counter() - started
    return result


def _decode(job: CaptureJob) -> CaptureResult:
    root, path = Path(job.root), Path(job.path)
    try:
        digest = content_hash(path)
        stat = path.stat()
    except OSError as exc:
        return CaptureResult(job.path, UNREADABLE, message=_reason(exc))
    if not job.force and layout.is_done(root, digest):
        return CaptureResult(job.path, SKIPPED, digest, message="same content is in the dataset")
    layout.remove_capture(root, digest)  # what an interrupted attempt or an older run left
    try:
        reader = open_reader(_options(job))
    except (OSError, ValueError) as exc:
        return CaptureResult(job.path, UNREADABLE, digest, message=_reason(exc))
    files = PartitionFiles(root, digest, utc_day(stat.st_mtime))
    stats = StatsListener()
    listeners = [RecordPartitions(files, job.path), StatePartitions(files, job.path), stats]
    try:
        session, reader = run_capture(_options(job), listeners, reader)
        damage = list(reader.errors)
        if session.counts.interrupted:
            raise KeyboardInterrupt
        if session.detached:
            files.discard()
            message = f"cannot write: {session.detached[0][1]}"
            return CaptureResult(job.path, FAILED, digest, message=message)
        if damage and not stats.stats.records:  # nothing of it could be read
            files.discard()
            return CaptureResult(job.path, UNREADABLE, digest, message="; ".join(damage))
        files.commit()
        row = _captures_row(job.path, digest, stat, damage, stats, files)
        _write_row(root, files.first_day or files.fallback_day, digest, row)
    except BaseException:
        files.discard()
        raise
    return CaptureResult(
        job.path,
        DAMAGED if damage else DONE,
        digest,
        records=row["records"],
        frames=row["frames"],
        errors=row["errors"] + row["truncated"],
        message="; ".join(damage),
    )


def _options(job: CaptureJob) -> CaptureOptions:
    return CaptureOptions(path=job.path, protocol=job.protocol, progress=False)


def _reason(exc: BaseException) -> str:
    return str(exc) or type(exc).__name__


def _captures_row(
    path: str,
    digest: str,
    stat: os.stat_result,
    damage: list[str],
    listener: StatsListener,
    files: PartitionFiles,
) -> dict[str, Any]:
    stats = listener.stats
    data = stats.as_dict()
    totals = stats.totals()
    latency = totals.latency.summary()
    return {
        "capture_path": path,
        "capture_hash": digest,
        "size": stat.st_size,
        "mtime": stat.st_mtime_ns // 1000,  # microseconds: what every reader takes
        "format": capture_suffix(Path(path)) or "raw",
        "protocols": sorted(data["protocols"]),
        "buses": files.buses,
        "devices": [{k: d[k] for k in ("bus", "protocol", "device")} for d in data["devices"]],
        "t_start": stats.first_t,
        "t_end": stats.last_t,
        **{name: data.get(name, getattr(totals, name, None)) for name in COUNTS},
        **dict(zip(LATENCY, latency.values(), strict=True)),
        "flags": list(data["flags"].items()),
        "damaged": bool(damage),
        "damage": damage,
        "engine": f"eg2scope {__version__}",
        "decoded_at": dt.datetime.now(dt.UTC),
    }


def _write_row(root: Path, day: str, digest: str, row: dict[str, Any]) -> None:
    """The commit: the capture's row, renamed into place last."""
    import pyarrow.parquet as pq

    folder = layout.partition_dir(root, layout.CAPTURES, day)
    folder.mkdir(parents=True, exist_ok=True)
    final = layout.data_file(folder, digest)
    temp = layout.temp_name(final)
    pq.write_table(captures_table(row), temp)
    temp.replace(final)
