"""What a batch run shows: a progress bar on stderr (captures done, bytes read, records, rate,
errors) while it runs, one line per capture that went wrong, and a summary at the end: a table
of the captures, then the records, grip cycles and bus health seconds written, and the tables."""

from __future__ import annotations

import sys
import threading
from typing import Any

from rich.console import Console
from rich.progress import (
    BarColumn,
    DownloadColumn,
    Progress,
    TextColumn,
    TimeElapsedColumn,
)
from rich.table import Table

from ..lifecycle import Running
from . import layout
from .capture_task import DAMAGED, DONE, FAILED, SKIPPED, UNREADABLE, CaptureResult
from .runner import Tally

_STYLE = {DAMAGED: "yellow", UNREADABLE: "red", FAILED: "red"}


class BatchProgress(Running):
    """The run's progress bar, over the bytes of every capture: ``capture_progress`` is told
    how far a capture being decoded has got (from this process or a Dask worker's events), so
    the bar moves within a capture; ``report`` is given each capture's result as it completes."""

    def __init__(self, sizes: dict[str, int], tally: Tally, show: bool) -> None:
        self.tally = tally
        self.sizes = sizes
        self.done_bytes = 0
        self.running: dict[str, tuple[int, int]] = {}  # path -> (bytes read, records)
        self.finished: set[str] = set()
        self.lock = threading.Lock()  # Dask's events come on its client's thread
        self.console = Console(stderr=True, highlight=False)
        self.progress = Progress(
            TextColumn("[bold]captures {task.fields[captures]}"),
            BarColumn(bar_width=20),  # the whole line fits 80 columns
            DownloadColumn(),
            TextColumn("{task.fields[records]:,} records {task.fields[rate]:,.0f}/s"),
            TextColumn("{task.fields[errors]:,} errors"),
            TimeElapsedColumn(),
            console=self.console,
            transient=True,
            disable=not show,
        )
        self.task = self.progress.add_task(
            "", total=sum(sizes.values()), captures=f"0/{len(sizes)}", records=0, rate=0.0, errors=0
        )

    def start(self) -> None:
        self.progress.start()

    def stop(self) -> None:
        self.progress.stop()

    def cluster_started(self, client: Any) -> None:
        """Say where the Dask dashboard is (once the cluster is up)."""
        link = getattr(client, "dashboard_link", None)
        workers = len(client.scheduler_info().get("workers", {}))
        where = f"; dashboard: {link}" if link else ""
        noun = "worker" if workers == 1 else "workers"
        self.console.print(f"eg2scope: Dask: {workers} {noun}{where}", highlight=False)

    def capture_progress(self, path: str, position: int, records: int) -> None:
        """A capture being decoded has read ``position`` bytes of its file into ``records``."""
        with self.lock:
            if path in self.sizes and path not in self.finished:  # (a worker's late event)
                self.running[path] = (min(position, self.sizes[path]), records)
                self._update()

    def report(self, result: CaptureResult) -> None:
        with self.lock:
            self.tally.add(result)
            self.finished.add(result.path)
            self.running.pop(result.path, None)
            self.done_bytes += self.sizes.get(result.path, 0)
            if result.hint:  # as decode says it
                self._say(f"eg2scope: {result.path}: {result.hint}", "yellow")
            if result.status in _STYLE:
                self._say(
                    f"eg2scope: {result.path}: {result.status}: {result.message}",
                    _STYLE[result.status],
                )
            elif result.status == DONE and result.message:
                self._say(f"eg2scope: {result.path}: {result.message}")
            self._update()

    def _say(self, line: str, style: str | None = None) -> None:
        self.console.print(line, style=style, soft_wrap=True, markup=False)

    def _update(self) -> None:
        tally = self.tally
        records = tally.records + sum(r for _, r in self.running.values())
        elapsed = tally.elapsed
        self.progress.update(
            self.task,
            completed=self.done_bytes + sum(p for p, _ in self.running.values()),
            captures=f"{len(tally.results)}/{len(self.sizes)}",
            records=records,
            rate=records / elapsed if elapsed > 0 else 0.0,
            errors=tally.errors,
        )


def print_summary(tally: Tally, root: str) -> None:
    """The summary table (stdout: it is what the command made)."""
    console = Console(highlight=False, width=None if sys.stdout.isatty() else 120)
    table = Table(title=f"eg2scope batch -> {root}", title_justify="left")
    for col in ("captures", "count"):
        table.add_column(col, justify="right" if col == "count" else "left")
    for status, meaning in (
        (DONE, "decoded"),
        (DAMAGED, "decoded, damaged"),
        (SKIPPED, "already in the dataset"),
        (UNREADABLE, "unreadable"),
        (FAILED, "failed"),
    ):
        table.add_row(meaning, f"{tally.count(status):,}")
    console.print(table)
    seconds = tally.elapsed
    rate = tally.records / seconds if seconds > 0 else 0.0
    console.print(
        f"{tally.records:,} records ({tally.frames:,} frames, {tally.errors:,} errors) "
        f"in {seconds:.1f} s: {rate:,.0f} records/s"
    )
    console.print(
        f"grip cycles: {tally.cycles:,}, bus health seconds: {tally.health_seconds:,}; "
        f"tables: {', '.join(f'{name}/' for name in layout.TABLES)}"
    )
