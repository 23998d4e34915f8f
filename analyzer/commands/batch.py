"""``eg2scope batch CAPTURES... -o DATASET``: decode many captures into one Parquet dataset, on
this machine's cores or a Dask cluster (analyzer/fleet)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from ..errors import EXIT_DAMAGED, EXIT_ERROR, EXIT_INTERRUPTED, EXIT_OK, UsageError
from ..interrupts import noted_interrupts
from ..session import engine
from .common import add_protocol_argument, add_rate_arguments, positive_int, rate_options
from .helptext import BATCH_EXIT_STATUS, HelpFormatter

INSTALL_HINT = "pip install 'eg2scope[fleet]'"


def add_subparser(sub: Any) -> None:
    parser = sub.add_parser(
        "batch",
        help="decode many captures into one Parquet dataset (Dask for many cores or machines)",
        description=(
            "Decode a fleet's captures (eg2scope .mcap recordings, candump logs, python-can "
            "logs, raw serial dumps) into one Parquet dataset that pandas, polars and DuckDB "
            "read directly: records/ (every record, the columns of 'decode --format parquet' "
            "plus capture_path and capture_hash), states/ (every state sample), cycles/ (every "
            "grip cycle, as 'eg2scope cycles' finds them), health/ (each bus's frames, bits, "
            "load, errors and controller state, one row per second; at --bitrate and --baud, "
            "else the rate a recording gives, else the EG2's) and captures/ (one row per "
            "capture: counts, latency, damage), partitioned by day and bus. A capture the "
            "dataset holds already (same sha256, decoded with the same --protocol, --bitrate "
            "and --baud) is skipped, so a run that was interrupted finishes the rest when run "
            "again; --force decodes everything again. "
            "See docs/fleet.md."
        ),
        epilog=(
            "examples:\n"
            "  eg2scope batch 'site-a/**/*.mcap' 'site-b/**/*.log' -o fleet/\n"
            "  eg2scope batch captures/ -o fleet/ --scheduler tcp://dask-scheduler:8786\n"
            "  eg2scope batch captures/ -o fleet/ --workers 1\n\n"
            "Dask is an optional extra: "
            + INSTALL_HINT
            + " (--workers 1 needs no Dask).\n\n"
            + BATCH_EXIT_STATUS
        ),
        formatter_class=HelpFormatter,
    )
    parser.add_argument(
        "inputs",
        nargs="+",
        metavar="CAPTURES",
        help="capture files, folders (searched recursively for captures, by suffix: .mcap, "
        ".log, .log.gz, .asc, .blf, .trc, .csv, .mf4, .bin, .raw, .dump, or by content: a "
        "candump log saved as .txt; the files passed over are counted) or glob patterns in "
        "quotes ('site-a/**/*.mcap')",
    )
    parser.add_argument("--output", "-o", required=True, metavar="DIR", help="the dataset folder")
    parser.add_argument(
        "--workers",
        type=positive_int,
        metavar="N",
        help="Dask worker processes on this machine (default: one per core); 1: decode in "
        "this process, one capture after the other, without Dask",
    )
    parser.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="run on an existing Dask cluster (tcp://host:8786); its workers must see the "
        "captures and the dataset folder at the same paths",
    )
    parser.add_argument(
        "--force", action="store_true", help="decode every capture again, even those in the dataset"
    )
    add_protocol_argument(parser)
    add_rate_arguments(parser)
    parser.add_argument(
        "--engine",
        choices=engine.ENGINES,
        default="auto",
        help="auto: the native core wherever 'decode' uses it (candump logs and raw dumps, "
        "their state samples too; CAN sessions), else Python (default); python: the Python "
        "decoders only; native: as auto, but a usage error when the native core is not built. "
        "The dataset is the same either way",
    )
    parser.add_argument(
        "--host",
        default="127.0.0.1",
        help="where the local Dask scheduler and workers listen (default 127.0.0.1: this "
        "machine only)",
    )
    parser.add_argument(
        "--dashboard-address",
        default="127.0.0.1:8787",
        metavar="HOST:PORT",
        help="the local Dask dashboard (default 127.0.0.1:8787, another port if taken; "
        "'none': no dashboard)",
    )
    parser.add_argument("--no-progress", action="store_true", help="never show a progress bar")
    parser.set_defaults(func=run)


def _dask_installed() -> bool:
    try:
        import distributed  # noqa: F401
    except ImportError:
        return False
    return True


def _check(args: argparse.Namespace) -> None:
    if args.scheduler and args.workers:
        raise UsageError("--workers is for a local cluster; a --scheduler's cluster has its own")
    uses_dask = args.scheduler is not None or args.workers != 1
    if uses_dask and not _dask_installed():
        raise UsageError(
            f"batch on several workers needs Dask, which is not installed: {INSTALL_HINT}, "
            "or run it in one process with --workers 1"
        )
    if args.engine == "native" and not engine.available():
        raise UsageError(
            f"--engine native: the native core is {engine.WHY_NOT}; use --engine auto or python"
        )
    out = Path(args.output)
    if out.exists() and not out.is_dir():
        raise UsageError(f"the output {args.output} is a file; batch writes a dataset folder")


def run(args: argparse.Namespace) -> int:
    import sys

    from ..fleet import layout
    from ..fleet.inputs import check_protocol, expand, passed_over_note
    from ..fleet.progress import BatchProgress, print_summary
    from ..fleet.runner import DaskOptions, Tally, default_workers, plan, run_in_loop, run_on_dask

    _check(args)
    root = Path(args.output).resolve()
    inputs = expand(args.inputs, exclude=root)
    paths = inputs.paths
    if inputs.passed_over:
        print(f"eg2scope: {passed_over_note(inputs.passed_over)}", file=sys.stderr)
    if not paths:
        raise UsageError(f"no captures in {', '.join(args.inputs)}")
    check_protocol(paths, args.protocol)
    rates = rate_options(args)
    tally = Tally()
    dashboard = None if args.dashboard_address.lower() == "none" else args.dashboard_address
    options = DaskOptions(args.workers or default_workers(), args.scheduler, args.host, dashboard)
    show = not args.no_progress and sys.stderr.isatty()
    # Ctrl-C, SIGTERM and SIGHUP are noted and acted on between batches and captures: raised
    # where they land, library code could lose them (analyzer/interrupts.py)
    with noted_interrupts() as noted:

        def interrupted() -> bool:
            return bool(noted)

        try:
            with layout.run_lock(root):
                jobs, skipped = plan(paths, root, args.protocol, args.force, args.engine, rates)
                sizes = {str(p): p.stat().st_size for p in paths}
                with BatchProgress(sizes, tally, show) as progress:
                    for result in skipped:
                        progress.report(result)
                    told = progress.capture_progress
                    if options.scheduler is None and options.workers == 1:
                        run_in_loop(jobs, progress.report, told, interrupted)
                    elif jobs:
                        run_on_dask(
                            jobs,
                            options,
                            progress.report,
                            progress.cluster_started,
                            told,
                            interrupted,
                        )
                    if interrupted():  # after the last capture: the run was cut short all the same
                        raise KeyboardInterrupt
        except layout.DatasetLocked as exc:
            raise UsageError(str(exc)) from None
        except KeyboardInterrupt:
            held = len(layout.done_hashes(root))  # the last results may not have been reported
            print(
                f"eg2scope: interrupted: {root} holds {held} complete captures; run the same "
                "command again to finish the rest",
                file=sys.stderr,
            )
            return EXIT_INTERRUPTED
    print_summary(tally, str(root))
    if tally.count("unreadable", "failed"):
        return EXIT_ERROR
    return EXIT_DAMAGED if tally.count("damaged") else EXIT_OK
