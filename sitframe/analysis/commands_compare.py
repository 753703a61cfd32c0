"""Compare runs: ``sitframe compare LOG LOG [...] [-o DIR] [--json]``, or sweep folders.

Each metric (convergence, evaluation collisions and coverage per world, goal
metrics where present) per run: median over trials with a 95 % bootstrap
interval, and a rank test across runs (Mann-Whitney U for two, Kruskal-Wallis
for more; p also Holm-adjusted over the metrics). Prints the table and
writes ``index.html``, ``compare.md``, ``compare.csv`` and figures to DIR
(default ``compare-<run>-<run>...`` in the working folder; for a sweep folder
``<folder>/report``). A sweep folder (``sitframe sweep`` output) is compared
per setting, pooled over seeds, with each metric drawn against each grid axis;
two or more sweep folders are compared as one run each (all points pooled).
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

# start-up time: this module is imported whenever the command line builds its parser
# (``sitframe --help`` and every command), so what only one command needs is imported
# inside the function that needs it.

HELP = "compare runs (logs, or the settings of a sweep folder) with intervals and rank tests"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the ``compare`` options to ``parser``."""
    parser.add_argument("logs", nargs="+", metavar="LOG",
                        help="two or more HDF5 logs, one `sitframe sweep` output folder (its "
                             "settings compared), or several (one run each)")
    parser.add_argument("-o", "--output", metavar="DIR", help="output folder")
    parser.add_argument("--seed", type=int, default=0,
                        help="seed of the bootstrap resampling (default 0)")
    parser.add_argument("--json", action="store_true",
                        help="print the comparison as JSON instead of the table")


def main(args: argparse.Namespace) -> int:
    """Run ``compare``; print the table (or JSON) and the page's path."""
    from sitframe.analysis.compare import compare_logs, compare_sweep, compare_sweeps
    from sitframe.analysis.compare_report import write_comparison
    from sitframe.errors import InputError

    dirs = [p for p in args.logs if os.path.isdir(p)]
    if len(dirs) == 1 and len(args.logs) == 1:
        cmp = compare_sweep(args.logs[0], seed=args.seed)
        out = args.output or str(Path(args.logs[0]) / "report")
        title = f"Sweep {Path(args.logs[0]).resolve().name}: settings compared"
    elif dirs and len(dirs) == len(args.logs):
        cmp = compare_sweeps(args.logs, seed=args.seed)
        out = args.output or "compare-" + "-".join(cmp.names).replace(os.sep, "_")
        title = "Comparison of the sweeps " + ", ".join(cmp.names)
    else:
        if dirs:
            raise InputError("sweep folders and logs cannot be mixed (give logs only, one "
                             "sweep folder, or sweep folders only)", file=dirs[0], key="LOG")
        cmp = compare_logs(args.logs, seed=args.seed)
        out = args.output or "compare-" + "-".join(n.replace(os.sep, "_") for n in cmp.names)
        title = "Comparison of " + ", ".join(cmp.names)
    paths = write_comparison(cmp, out, title=title)
    if args.json:
        print(json.dumps({**cmp.to_json(), "files": paths}, indent=1))
    else:
        print(cmp.table().to_markdown())
        print(paths[0])
    return 0
