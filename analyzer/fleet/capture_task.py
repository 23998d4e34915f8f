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
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Final

import pyarrow as pa

from decoders.model import EG2_SERIAL
from decoders.registry import detect_protocol, short_name

from .. import __version__
from ..health.rates import FROM_OPTION_BAUD, FROM_OPTION_BITRATE, RateOptions, rates_of_capture
from ..parquet import native as native_parquet
from ..session import engine as native
from ..session.capture import CaptureOptions, byte_protocol, open_reader, protocol_hint, run_capture
from ..session.stage import DETECT_BYTES
from ..sources import sniff
from ..sources.capture import CAPTURE_READERS, RAW_BYTES, CaptureReader, reader_for
from ..sources.naming import BUS_BY_PROTOCOL
from ..sources.source import CAPTURE_BATCH_ITEMS
from ..stats import CaptureStats
from . import layout
from .inputs import capture_suffix, content_hash
from .listeners import BusViews, CaptureTables, Checkpoint, Progress, SessionTables, Throttled
from .partitions import PartitionFiles
from .tables import COUNTS, LATENCY, STATE_COLUMNS, captures_table, utc_day

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
    engine: str = (
        "auto"  # "python": the Python decoders only; else the native core where it applies
    )
    # the rates given for its health rows (None: the capture's own, else the EG2's)
    rates: RateOptions = field(default_factory=RateOptions)

    @property
    def decode_options(self) -> str:
        """The options that change a capture's rows, as the command line says them: with its
        content hash, what identifies them (CAN captures ignore the protocol: ``-p can`` is
        the same as none; a rate given is said, the capture's own is not)."""
        protocol = byte_protocol(CaptureOptions(self.path, self.protocol))
        given = ((FROM_OPTION_BITRATE, self.rates.bitrate), (FROM_OPTION_BAUD, self.rates.baud))
        rates = "".join(f" {flag} {rate}" for flag, rate in given if rate is not None)
        return f"--protocol {'auto' if protocol is None else short_name(protocol)}{rates}"


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
    hint: str = ""  # decode's hint on a --protocol that finds fewer frames than detection
    cycles: int = 0  # rows written to cycles/
    health_seconds: int = 0  # rows written to health/ (one per bus and second)


class _WriteFailed(Exception):
    """The capture's tables could not be written (the message says why)."""


def _never() -> bool:
    return False


def decode_capture(
    job: CaptureJob,
    progress: Progress | None = None,
    interrupted: Callable[[], bool] = _never,
) -> CaptureResult:
    """Decode one capture into the dataset under ``job.root``. ``progress`` is told how far it
    has got now and then (bytes of the file read, records); ``interrupted`` is asked between
    batches, and True stops it with KeyboardInterrupt, nothing of it written."""
    started = time.perf_counter()
    result = _decode(job, progress, interrupted)
    result.seconds = time.perf_counter() - started
    return result


def _decode(
    job: CaptureJob, progress: Progress | None, interrupted: Callable[[], bool]
) -> CaptureResult:
    root, path = Path(job.root), Path(job.path)
    try:
        digest = content_hash(path)
        stat = path.stat()
    except OSError as exc:
        return CaptureResult(job.path, UNREADABLE, message=_reason(exc))
    held = None if job.force else layout.held_options(root, digest)
    if held == job.decode_options:
        return CaptureResult(job.path, SKIPPED, digest, message="same content is in the dataset")
    layout.remove_capture(root, digest)  # what an interrupted attempt or an older run left
    opts = _options(job)
    try:
        reader = open_reader(opts)
    except (OSError, ValueError) as exc:
        return CaptureResult(job.path, UNREADABLE, digest, message=_reason(exc))
    hint = protocol_hint(opts, reader)
    files = PartitionFiles(root, digest, utc_day(stat.st_mtime))
    tables = CaptureTables(files, job.path)
    rates = rates_of_capture(reader.metadata, job.rates.bitrate, job.rates.baud)
    views = BusViews(files, job.path, rates)
    try:
        damage = _fill(opts, job.engine, reader, (tables, views), progress, interrupted)
        if interrupted():
            raise KeyboardInterrupt
        views.write_health(final=True)
        stats = tables.summary.stats
        if damage and not stats.records:  # nothing of it could be read
            files.discard()
            return CaptureResult(job.path, UNREADABLE, digest, message="; ".join(damage))
        files.commit()
        row = _captures_row(job, digest, stat, damage, stats, files)
        _write_row(root, files.first_day or files.fallback_day, digest, row)
    except _WriteFailed as exc:
        files.discard()
        return CaptureResult(job.path, FAILED, digest, message=f"cannot write: {exc}")
    except BaseException:
        files.discard()
        raise
    replaced = [] if held is None else [f"decoded again (the dataset held it decoded with {held})"]
    return CaptureResult(
        job.path,
        DAMAGED if damage else DONE,
        digest,
        records=row["records"],
        frames=row["frames"],
        errors=row["errors"] + row["truncated"],
        message="; ".join(damage + replaced),
        hint=hint,
        cycles=views.cycles,
        health_seconds=views.seconds,
    )


#: what a capture's rows go to: its records and states, its cycles and health seconds
Outputs = tuple[CaptureTables, BusViews]


def _fill(
    opts: CaptureOptions,
    engine: str,
    reader: CaptureReader,
    outputs: Outputs,
    progress: Progress | None,
    interrupted: Callable[[], bool],
) -> list[str]:
    """Decode the capture into ``outputs``: on the native core where ``decode`` uses it (the
    Python ``reader``, opened for the same checks and messages, is then closed; a candump
    log's frames are read again, natively, for the bus health), else in a session. The damage
    found in the input."""
    run = None if engine == "python" else _native_run(opts, reader)
    if run is None:
        return _in_session(opts, reader, outputs, progress, interrupted)
    frames = native.candump_frames(reader) if reader.kind == "can" else None
    reader.close()
    damage = _natively(run, outputs, progress, interrupted)
    if frames is not None:  # a raw dump has no times: no health seconds
        _frame_health(frames, outputs[1], interrupted)
    return damage


def _native_run(opts: CaptureOptions, reader: CaptureReader) -> Any:
    """The native core's run of a capture, records and state samples as columns, or None:
    the core does not read this capture (as ``decode`` decides, analyzer/session/engine.py)."""
    if native.ineligible(reader, "parquet", None, None):
        return None
    try:
        return native_parquet.open_run(
            native._native,
            opts.path,
            states=STATE_COLUMNS,
            protocol=byte_protocol(opts),
            bus=opts.bus,
        )
    except (native._native.Unsupported, OSError):  # type: ignore[union-attr]
        return None  # the core's word: the session decodes it, or says why it cannot


def _natively(
    run: Any, outputs: Outputs, progress: Progress | None, interrupted: Callable[[], bool]
) -> list[str]:
    """A native run's batches into the tables (records and samples: no object per row), and
    its grip cycles from the same columns."""
    tables, views = outputs
    report = None if progress is None else Throttled(progress)
    try:
        for _rows, parts, states in run:
            records = native_parquet.batch_table(parts)
            tables.write_parsed(records)
            samples = None
            if states is not None:
                samples = native_parquet.batch_table(states[1], STATE_COLUMNS)
                tables.add_states(samples)
            views.add_columns(records, samples)
            if interrupted():
                raise KeyboardInterrupt
            if report is not None:
                report(run.position, run.records_written)
        tables.close()
        views.close_cycles()
    except (OSError, ValueError, pa.ArrowException) as exc:  # an output, or a sample
        raise _WriteFailed(str(exc)) from None
    finally:
        run.close()
    return list(run.errors)


def _frame_health(frames: Any, views: BusViews, interrupted: Callable[[], bool]) -> None:
    """A candump log's frames, as the native core reads them, into the bus health."""
    while (batch := frames.read(CAPTURE_BATCH_ITEMS)) is not None:
        views.add_raw(batch)
        if interrupted():
            raise KeyboardInterrupt


def _in_session(
    opts: CaptureOptions,
    reader: CaptureReader,
    outputs: Outputs,
    progress: Progress | None,
    interrupted: Callable[[], bool],
) -> list[str]:
    """The capture through a session (the Python decoders, or the native core's CAN decoding
    and Tracker, as any session on CAN input), its listeners filling the tables."""
    tables, views = outputs
    output = SessionTables(tables)
    checkpoint = Checkpoint(lambda: reader.position, progress or _ignore, interrupted)
    whole = views.listeners
    session, reader = run_capture(opts, [output, checkpoint], reader, whole=whole)
    if session.counts.interrupted:
        raise KeyboardInterrupt
    ours = [output, *whole]
    failed = [exc for listener, exc in session.detached if listener in ours]
    if failed:
        raise _WriteFailed(str(failed[0]))
    return list(reader.errors)


def _ignore(position: int, records: int) -> None:
    pass


def _options(job: CaptureJob) -> CaptureOptions:
    engine = "python" if job.engine == "python" else "auto"
    bus = dump_bus(job.path, byte_protocol(CaptureOptions(job.path, job.protocol)))
    return CaptureOptions(job.path, job.protocol, bus, progress=False, engine=engine)


#: the readers of raw serial dumps (a file no format claims), plain and gzipped
_DUMP_READERS: Final = frozenset({RAW_BYTES, CAPTURE_READERS[".gz"]})


def dump_bus(path: str, protocol: str | None) -> str | None:
    """A raw dump's bus, named by its protocol as a live serial line is (``rs232`` for the
    regular serial protocol, ``rs485`` for Modbus RTU): the one given, else the one the
    decoding detects in its first bytes. None for any other capture (its buses are its own)."""
    try:
        if reader_for(path) not in _DUMP_READERS:
            return None
    except ValueError:
        return None  # the reader says why when it is opened
    if protocol is None:
        protocol = detect_protocol(sniff.head(path)[:DETECT_BYTES]) or EG2_SERIAL
    return BUS_BY_PROTOCOL[protocol]


def _reason(exc: BaseException) -> str:
    return str(exc) or type(exc).__name__


def _captures_row(
    job: CaptureJob,
    digest: str,
    stat: os.stat_result,
    damage: list[str],
    stats: CaptureStats,
    files: PartitionFiles,
) -> dict[str, Any]:
    data = stats.as_dict()
    totals = stats.totals()
    latency = totals.latency.summary()
    return {
        "capture_path": job.path,
        "capture_hash": digest,
        "decode_options": job.decode_options,
        "size": stat.st_size,
        "mtime": stat.st_mtime_ns // 1000,  # microseconds: what every reader takes
        "format": capture_suffix(Path(job.path)) or "raw",
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
