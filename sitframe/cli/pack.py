"""``sitframe pack LOG``: make a log one self-contained HDF5 file.

A run writes each finished trial to its own file, ``LOG.trials/NNNN.h5``
beside the log, linked from the log, and packs them into the log when it
ends (see :mod:`sitframe.logs`). A run killed by ``kill -9`` (or a machine
that went down) leaves the log *and* that folder; ``run --resume LOG``
finishes the run and packs it. ``pack`` packs such a log as it is, without
resuming it: the trials are copied into the log in one crash-safe
transaction, then the folder is removed. The log's status is unchanged, so
it can still be resumed later. Packing a log that is already one file does
nothing. A log another process is writing is refused (one log has one
writer). A log behind a symbolic link is packed where the link points; a full
disk is one line (the log and its folder stay as they were).
"""

from __future__ import annotations

import argparse

from sitframe.errors import one_line

HELP = "pack an unfinished log's trial files into one file"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("log", help="the log (.h5) to pack")


def main(args: argparse.Namespace) -> int:
    from sitframe.logs.layout import shard_folder  # h5py: start-up time
    from sitframe.logs.reader import open_log  # h5py: start-up time
    from sitframe.logs.writer import LogWriter, lock_log  # h5py: start-up time

    log = open_log(args.log)
    lock_log(args.log, key="LOG")  # refused while a run writes it
    log.check()  # never rewrite a damaged log (every dataset's checksum is read)
    writer = LogWriter(args.log)
    had = shard_folder(args.log).is_dir()
    try:
        writer.remove_stale()
        writer.pack()
    finally:
        writer.release()
    what = "packed its trial files into it" if had else "already one file"
    print(one_line(f"{args.log}: {what} ({len(log.trial_indices())} trials, status "
                   f"{log.status})"))
    return 0
