"""``sitframe sweep SWEEP.toml``: an experiment over a grid of config values x seeds.

The sweep file's format and what a sweep writes are in :mod:`sitframe.runs.sweep`.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from functools import partial
from typing import Any

from sitframe.cli.app import add_parallel_arguments
from sitframe.errors import InputError, note
from sitframe.runs.summaries import markdown_table, pool_over_seeds, write_tables
from sitframe.runs.sweep import load_sweep, run_sweep

HELP = "run an experiment over a grid of config values and seeds"


def _finite(obj: Any) -> Any:
    """``obj`` with non-finite floats replaced by ``None`` (valid JSON)."""
    if isinstance(obj, dict):
        return {k: _finite(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_finite(v) for v in obj]
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("sweep", help="sweep definition (.toml)")
    parser.add_argument("--out", metavar="DIR",
                        help="folder for the logs and summary (default [sweep] out, else "
                        "logs/sweeps/<name>)")
    parser.add_argument("--json", action="store_true", help="print the summary as JSON")
    parser.add_argument("--reuse", action="store_true",
                        help="keep a point's log that is complete and was made by the same "
                        "config and the same code instead of running the point again (e.g. "
                        "after adding a value to the grid), and finish an unfinished one of the "
                        "same config and code (a sweep stopped by Ctrl-C, a kill or a full "
                        "disk) keeping its finished trials")
    add_parallel_arguments(parser)


def main(args: argparse.Namespace) -> int:
    from sitframe.runs.parallel import make_executor  # start-up time: the runs layer

    if args.workers is not None and args.workers < 1:
        raise InputError(f"must be at least 1, got {args.workers}", key="--workers")
    from sitframe.runs.prepare import make_prerequisites  # start-up time: the runs layer

    dirs = tuple(args.plugins_dir)
    executor_for = partial(make_executor, args.workers, args.scheduler)
    sweep = load_sweep(args.sweep, out=args.out, plugins_dirs=dirs, prerequisites=lambda c, b:
                       make_prerequisites(c, b, executor_for=executor_for, plugins_dirs=dirs,
                                          say=note))
    total = sum(pt.experiment.info.n_trials for pt in sweep.points)
    executor = make_executor(args.workers, args.scheduler, total)
    failed = True
    try:
        result = run_sweep(sweep, executor, progress=not args.json and sys.stderr.isatty(),
                           reuse=args.reuse)
        failed = False
    finally:
        executor.shutdown(cancel=failed)
    result["pooled"] = pool_over_seeds(result)
    csv_path, md_path = write_tables(result, sweep.out)
    if args.json:
        doc = _finite({**result, "csv": str(csv_path), "markdown": str(md_path)})
        print(json.dumps(doc, indent=2, default=str))
    else:
        print(markdown_table(result), end="")
        if result["pooled"]:
            print(f"\npooled over the seeds ({md_path.parent / 'summary-pooled.md'}):")
            print(markdown_table(result, pooled=True), end="")
        print(f"{len(sweep.points)} points, {total} trials in {result['wall_seconds']:.1f} s; "
              f"logs and summary in {sweep.out}")
    return 0
