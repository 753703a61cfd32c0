"""Write the figures and tables of a log: ``sitframe analyse LOG [-o DIR]``.

Figures (PNG) and tables (Markdown + CSV) go to ``<log stem>-analysis/`` next
to the log, or into DIR, with an ``index.md`` that links them with one-line
captions and an ``index.html`` that shows them on one page with the run's
metadata, config and plugins and an interactive replay of every trial. An
incomplete log (aborted run, missing stages or trials) is analysed as far as
it goes; what is missing is listed in both indexes and summarised in one line
on stderr.
"""

from __future__ import annotations

import argparse
import os
import sys

# start-up time: this module is imported whenever the command line builds its parser
# (``sitframe --help`` and every command), so what only one command needs is imported
# inside the function that needs it.

HELP = "write the figures and tables of a log (PNG, Markdown, CSV), index.html with a replay"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the ``analyse`` options to ``parser``."""
    parser.add_argument("log", help="HDF5 log written by `sitframe run`")
    parser.add_argument("-o", "--output", metavar="DIR",
                        help="output folder (default: <log stem>-analysis next to the log)")
    g = parser.add_mutually_exclusive_group()
    g.add_argument("--trial", type=int, action="append", metavar="K",
                   help="make the per-trial figures for trial K (repeatable; default: the "
                   "converged trial with the median convergence iteration)")
    g.add_argument("--all-trials", action="store_true",
                   help="make the per-trial figures for every trial")
    parser.add_argument("--window", type=int, default=50,
                        help="iterations per reward window (default 50, as in the thesis)")
    parser.add_argument("--path-iterations", type=int, default=400, metavar="N",
                        help="iterations of each drawn path (default 400)")
    parser.add_argument("--dpi", type=int, default=200, help="PNG resolution (default 200)")


def main(args: argparse.Namespace) -> int:
    """Run ``analyse``; print the index path (stdout) and any incompleteness (stderr)."""
    from sitframe.analysis.report import analyse
    from sitframe.errors import InputError
    from sitframe.logs import open_log

    for name in ("window", "path_iterations", "dpi"):
        if getattr(args, name) < 1:
            raise InputError(f"must be at least 1, got {getattr(args, name)}",
                             key="--" + name.replace("_", "-"))
    log = open_log(args.log)
    trials = "all" if args.all_trials else args.trial
    rep = analyse(log, args.output, trials=trials, window=args.window,
                  path_iterations=args.path_iterations, dpi=args.dpi)
    if rep.problems:
        print(f"sitframe: warning: {log.path}: incomplete log, analysed what is there: "
              + "; ".join(rep.problems), file=sys.stderr)
    n_fig = sum(1 for _s, f, _c in rep.files if f.endswith(".png"))
    n_tab = len(rep.files) - n_fig
    print(f"{rep.html}  ({n_fig} figures, {n_tab} tables, replay, {rep.seconds:.1f} s; "
          f"also {os.path.basename(rep.index)})")
    return 0
