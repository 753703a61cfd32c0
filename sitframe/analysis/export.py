"""``sitframe export``: a log's tables (:mod:`sitframe.logs.frames`) as CSV or Parquet files.

``summary`` (one row per trial), ``iterations`` (one row per iteration of
every learning trial, with a ``trial`` column) and ``evaluations`` (one row
per iteration of every frozen-policy evaluation, with ``trial`` and
``world``). What plugins logged is in them too: every per-trial scalar as a
``summary`` column, every per-iteration series as columns of ``iterations``
(or ``evaluations``), named ``plugins.<plugin>.<key>`` or
``behaviours.<label>.<key>``. Needs pandas (``pip install 'sitframe[pandas]'``); Parquet also
needs pyarrow (``'sitframe[parquet]'``).
"""

from __future__ import annotations

import os
from pathlib import Path

from sitframe.analysis.results import LogLike, as_log
from sitframe.errors import InputError
from sitframe.logs.frames import _pandas, evaluations_frame, iterations_frame, summary_frame

__all__ = ["export"]


def export(log: LogLike, out_dir: str | os.PathLike[str] | None = None,
           fmt: str = "csv") -> list[str]:
    """Write ``summary``, ``iterations`` and ``evaluations`` tables as CSV or Parquet.

    Parameters
    ----------
    log
        The log or its path.
    out_dir
        Output folder (default ``<log stem>-export`` beside the log); created.
    fmt
        ``"csv"`` or ``"parquet"`` (needs pyarrow).

    Returns
    -------
    list of str
        The written files (a table with no rows is not written).

    Raises
    ------
    InputError
        Unknown format, pandas or pyarrow missing (one line saying what to
        install), a damaged log, or an output folder that cannot be written.
    """
    if fmt not in ("csv", "parquet"):
        raise InputError(f"expected csv or parquet, got {fmt!r}", key="--format")
    try:
        _pandas()
    except ImportError as exc:
        raise InputError(str(exc), key="--format") from None
    if fmt == "parquet":
        try:
            import pyarrow  # noqa: F401
        except ImportError:
            raise InputError("parquet needs pyarrow, which is not installed; pip install "
                             "'sitframe[parquet]' or use --format csv", key="--format") from None
    lg = as_log(log)
    lg.check()
    out = Path(out_dir) if out_dir is not None else Path(lg.path).with_name(
        Path(lg.path).stem + "-export")
    tables = {"summary": summary_frame(lg), "iterations": iterations_frame(lg),
              "evaluations": evaluations_frame(lg)}
    written = []
    try:
        out.mkdir(parents=True, exist_ok=True)
        for name, frame in tables.items():
            if frame.empty:
                continue
            path = out / f"{name}.{fmt}"
            if fmt == "csv":
                frame.to_csv(path, index=False)
            else:
                frame.to_parquet(path, index=False)
            written.append(str(path))
    except OSError as exc:
        raise InputError(f"cannot write the export: {exc.strerror or exc}", file=str(out),
                         key="--out") from None
    return written
