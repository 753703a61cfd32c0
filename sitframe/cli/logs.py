"""The log commands ``analyse``, ``replay``, ``compare`` and ``export``: one class each.

Each class is what :data:`sitframe.cli.app.EXTRA_COMMANDS` names: its docstring
is the command's description, ``HELP`` its one-line help, ``add_arguments``
adds its options and ``main`` runs it (returns the exit status).
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

from sitframe.errors import InputError, warn

# start-up time: this module is imported whenever the command line builds its parser
# (``sitframe --help`` and every command), so what only one command needs is imported
# inside the function that needs it (sitframe.errors is light and the CLI's own import).


class Analyse:
    """Write the figures and tables of a log: ``sitframe analyse LOG [-o DIR]``.

    Figures (PNG) and tables (Markdown + CSV) go to ``<log stem>-analysis/`` next
    to the log, or into DIR, with an ``index.md`` that links them with one-line
    captions and an ``index.html`` that shows them on one page with the run's
    metadata, config and plugins and an interactive replay of every trial. An
    incomplete log (aborted run, missing stages or trials) is analysed as far as
    it goes; what is missing is listed in both indexes and summarised in one line
    on stderr.
    """

    HELP = "a log's figures, tables and HTML report with a replay"

    @staticmethod
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

    @staticmethod
    def main(args: argparse.Namespace) -> int:
        """Run ``analyse``; print the index path (stdout) and any incompleteness (stderr)."""
        from sitframe.analysis.report import analyse
        from sitframe.logs.reader import open_log

        for name in ("window", "path_iterations", "dpi"):
            if getattr(args, name) < 1:
                raise InputError(f"must be at least 1, got {getattr(args, name)}",
                                 key="--" + name.replace("_", "-"))
        log = open_log(args.log)
        trials = "all" if args.all_trials else args.trial
        rep = analyse(log, args.output, trials=trials, window=args.window,
                      path_iterations=args.path_iterations, dpi=args.dpi)
        if rep.problems:
            warn(f"{log.path}: incomplete log, analysed what is there: "
                 + "; ".join(rep.problems))
        n_fig = sum(1 for _s, f, _c in rep.files if f.endswith(".png"))
        n_tab = len(rep.files) - n_fig
        print(f"{rep.html}  ({n_fig} figures, {n_tab} tables, replay, {rep.seconds:.1f} s; "
              f"also {os.path.basename(rep.index)})")
        return 0


class Replay:
    """Animate a logged trial: ``sitframe replay LOG --trial K [--eval W] [--from I --to J]
    -o FILE``.

    Without ``--eval`` the learning trial is shown; with ``--eval W`` the frozen
    rule base's evaluation run in world ``W`` (logs written since evaluations
    keep their sonar, memberships and commands).

    The robot (disc and heading) moves through its world with its sonar rays
    (drawn from the rim to the logged ranges; dashed = nothing within range), the
    path so far, collisions marked, and as text the dominant situation, the
    command and the reward. ``.gif`` is written with Pillow; ``.mp4`` needs
    ffmpeg on PATH.
    """

    HELP = "animate a logged trial as GIF or MP4"

    @staticmethod
    def add_arguments(parser: argparse.ArgumentParser) -> None:
        """Add the ``replay`` options to ``parser``."""
        parser.add_argument("log", help="HDF5 log written by `sitframe run`")
        parser.add_argument("--trial", type=int, default=0, metavar="K",
                            help="learning trial to animate (default 0)")
        parser.add_argument("--eval", dest="eval_world", default=None, metavar="W",
                            help="animate trial K's frozen-policy evaluation in world W instead")
        parser.add_argument("--from", dest="start", type=int, default=0, metavar="I",
                            help="first iteration (default 0)")
        parser.add_argument("--to", dest="stop", type=int, default=None, metavar="J",
                            help="stop before this iteration (default I + 300)")
        parser.add_argument("-o", "--output", required=True, metavar="FILE",
                            help="output animation, .gif or .mp4 (mp4 needs ffmpeg)")
        parser.add_argument("--fps", type=int, default=8,
                            help="iterations shown per second (default 8 = 12x real time)")
        parser.add_argument("--dpi", type=int, default=110, help="resolution (default 110)")

    @staticmethod
    def main(args: argparse.Namespace) -> int:
        """Write the animation and print its path."""
        from sitframe.analysis.replay import replay
        from sitframe.logs.reader import open_log

        if args.dpi < 1:
            raise InputError(f"must be at least 1, got {args.dpi}", key="--dpi")
        log = open_log(args.log)
        log.check()  # damaged contents: one line before any drawing
        print(replay(log, args.trial, args.output, start=args.start, stop=args.stop, fps=args.fps,
                     dpi=args.dpi, evaluation=args.eval_world))
        return 0


class Compare:
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

    HELP = "compare runs or a sweep's settings: intervals, rank tests"

    @staticmethod
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

    @staticmethod
    def main(args: argparse.Namespace) -> int:
        """Run ``compare``; print the table (or JSON) and the page's path."""
        from sitframe.analysis.compare import compare_logs, compare_sweep, compare_sweeps
        from sitframe.analysis.compare_report import write_comparison

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


class Export:
    """Write a log's tables for other tools: ``sitframe export LOG [--format csv|parquet]
    [--out DIR]``.

    Tidy tables (:mod:`sitframe.logs.frames`): ``summary`` (one row per
    trial), ``iterations`` (one row per iteration of every learning trial, with a
    ``trial`` column) and ``evaluations`` (one row per iteration of every
    frozen-policy evaluation, with ``trial`` and ``world``). Needs pandas
    (``pip install 'sitframe[pandas]'``); Parquet also needs pyarrow
    (``'sitframe[parquet]'``).
    """

    HELP = "a log's summary and arrays as tidy CSV or Parquet tables"

    @staticmethod
    def add_arguments(parser: argparse.ArgumentParser) -> None:
        """Add the ``export`` options to ``parser``."""
        parser.add_argument("log", help="HDF5 log written by `sitframe run`")
        parser.add_argument("--format", choices=("csv", "parquet"), default="csv",
                            help="table format (default csv; parquet needs pyarrow)")
        parser.add_argument("--out", metavar="DIR",
                            help="output folder (default <log stem>-export next to the log)")

    @staticmethod
    def main(args: argparse.Namespace) -> int:
        """Write the tables and print their paths."""
        from sitframe.analysis.export import export

        for path in export(args.log, args.out, args.format):
            print(path)
        return 0
