"""The fleet dataset on disk: five Parquet tables, Hive-partitioned, one file per capture and
partition, named by the capture's content hash.

```
fleet/records/day=2026-11-20/bus=can0/<hash>.parquet    every record (decode --format parquet)
fleet/states/day=2026-11-20/bus=can0/<hash>.parquet     every state sample
fleet/cycles/day=2026-11-20/bus=can0/<hash>.parquet     every grip cycle (cycles --format parquet)
fleet/health/day=2026-11-20/bus=can0/<hash>.parquet     each bus's health, one row per second
fleet/captures/day=2026-11-20/<hash>.parquet            one row per capture, written last
```

A capture's files are written under a hidden temporary name and renamed into place, and its
``captures/`` row comes last: it is the commit. A capture is done when its row exists; one whose
worker died before its row leaves no row, and the next attempt removes whatever it had renamed
into place before writing again, so no partition is ever duplicated or half written. Readers
(pyarrow, DuckDB, polars) skip hidden files, so temporary ones are never read.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
from collections.abc import Iterator
from pathlib import Path
from typing import Final
from urllib.parse import quote

from ..outfile import OutputError

RECORDS: Final = "records"
STATES: Final = "states"
CYCLES: Final = "cycles"
HEALTH: Final = "health"
CAPTURES: Final = "captures"
#: the tables partitioned by day and bus, then the one of the captures (the commit)
BUS_TABLES: Final = (RECORDS, STATES, CYCLES, HEALTH)
TABLES: Final = (*BUS_TABLES, CAPTURES)
OPTIONS: Final = "decode_options"  # in a captures/ row: with the content hash, its key
LOCK_NAME: Final = ".eg2scope-batch.lock"
_TEMP_MARK: Final = ".tmp-"


def partition_dir(root: Path, table: str, day: str, bus: str | None = None) -> Path:
    """The folder of one partition (the bus percent-encoded, as pyarrow writes Hive keys)."""
    folder = root / table / f"day={day}"
    return folder if bus is None else folder / f"bus={quote(bus, safe='')}"


def data_file(folder: Path, content_hash: str) -> Path:
    return folder / f"{content_hash}.parquet"


def temp_name(final: Path) -> Path:
    """Where ``final`` is written before it is renamed into place: hidden, unique to the
    process (two attempts at one capture never share a temporary file)."""
    return final.with_name(f".{final.name}{_TEMP_MARK}{os.getpid()}")


def done_hashes(root: Path) -> set[str]:
    """The content hashes of the captures the dataset holds (their ``captures/`` rows)."""
    return {p.stem for p in (root / CAPTURES).glob("day=*/*.parquet")}


def held_options(root: Path, content_hash: str) -> str | None:
    """The decode options of the capture the dataset holds with this content (its
    ``captures/`` row's ``decode_options``; "" for a row written before they were kept), or
    None when it holds none."""
    rows = sorted((root / CAPTURES).glob(f"day=*/{content_hash}.parquet"))
    if not rows:
        return None
    import pyarrow.parquet as pq

    table = pq.read_table(rows[0])
    if OPTIONS not in table.column_names:
        return ""
    return str(table.column(OPTIONS)[0].as_py() or "")


def capture_files(root: Path, content_hash: str) -> list[Path]:
    """Every file of one capture in the dataset, its ``captures/`` row last."""
    name = f"{content_hash}.parquet"
    found = [path for table in BUS_TABLES for path in (root / table).glob(f"day=*/bus=*/{name}")]
    found += (root / CAPTURES).glob(f"day=*/{name}")
    return found


def remove_capture(root: Path, content_hash: str) -> None:
    """Take a capture out of the dataset: its row first (it is no longer done), then its data."""
    for path in reversed(capture_files(root, content_hash)):
        path.unlink(missing_ok=True)


def stale_temporaries(root: Path) -> Iterator[Path]:
    """Temporary files left by a run that was killed (only safe to remove under the lock)."""
    for table in TABLES:
        yield from (root / table).rglob(f".*{_TEMP_MARK}*")


class DatasetLocked(RuntimeError):
    """Another ``eg2scope batch`` is writing this dataset."""


@contextlib.contextmanager
def run_lock(root: Path) -> Iterator[None]:
    """One batch run per dataset at a time (an advisory lock on a file in its folder); stale
    temporary files are removed once it is held, and again at the end."""
    try:
        root.mkdir(parents=True, exist_ok=True)
        lock = open(root / LOCK_NAME, "a+b")  # noqa: SIM115 (closed below)
    except OSError as exc:
        raise OutputError(
            f"cannot write the dataset folder {root}: {exc.strerror or exc}"
        ) from None
    with lock:
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise DatasetLocked(
                f"another 'eg2scope batch' is writing {root} (lock {root / LOCK_NAME})"
            ) from None
        _remove_temporaries(root)
        try:
            yield
        finally:
            _remove_temporaries(root)  # a worker that was killed mid-capture left its own
            fcntl.flock(lock, fcntl.LOCK_UN)


def _remove_temporaries(root: Path) -> None:
    for path in stale_temporaries(root):
        path.unlink(missing_ok=True)
