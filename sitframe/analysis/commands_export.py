"""Write a log's tables for other tools: ``sitframe export LOG [--format csv|parquet] [--out DIR]``.

Tidy tables (:mod:`sitframe.frames`): ``summary`` (one row per
trial), ``iterations`` (one row per iteration of every learning trial, with a
``trial`` column) and ``evaluations`` (one row per iteration of every
frozen-policy evaluation, with ``trial`` and ``world``). Needs pandas
(``pip install 'sitframe[pandas]'``); Parquet also needs pyarrow
(``'sitframe[parquet]'``).
"""

from __future__ import annotations

import argparse

# start-up time: this module is imported whenever the command line builds its parser
# (``sitframe --help`` and every command), so what only one command needs is imported
# inside the function that needs it.

HELP = "write a log's summary and per-iteration arrays as tidy CSV or Parquet tables"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the ``export`` options to ``parser``."""
    parser.add_argument("log", help="HDF5 log written by `sitframe run`")
    parser.add_argument("--format", choices=("csv", "parquet"), default="csv",
                        help="table format (default csv; parquet needs pyarrow)")
    parser.add_argument("--out", metavar="DIR",
                        help="output folder (default <log stem>-export next to the log)")


def main(args: argparse.Namespace) -> int:
    """Write the tables and print their paths."""
    from sitframe.analysis.export import export

    for path in export(args.log, args.out, args.format):
        print(path)
    return 0
