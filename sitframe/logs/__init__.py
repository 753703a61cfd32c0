"""Logs: HDF5 run logs, written crash-safe and read back as arrays, records and tables.

What it holds
    :mod:`~sitframe.logs.layout` (the layout of a log, and why it survives a kill),
    :mod:`~sitframe.logs.writer` (:class:`~sitframe.logs.writer.LogWriter`: one short
    crash-safe transaction per stage and trial; one writer per log),
    :mod:`~sitframe.logs.reader` (:func:`~sitframe.logs.reader.open_log`,
    :class:`~sitframe.logs.reader.Log`, :class:`~sitframe.logs.reader.TrialLog`),
    :mod:`~sitframe.logs.frames` (a log's tables as pandas DataFrames),
    :mod:`~sitframe.logs.policies` (which trial's learned policy a config reuses, read back),
    :mod:`~sitframe.logs.compare` (two logs compared dataset by dataset) and
    :mod:`~sitframe.logs.interrupts` (Ctrl-C and SIGTERM held back around HDF5 I/O).

What it may import
    :mod:`sitframe.contract` (records, the plugin registry), :mod:`sitframe.situations`,
    :mod:`sitframe.sim` and the ground floor; never runs, analysis, gym or the command line.

Entry points
    ``open_log``, ``Log``, ``TrialLog``, ``LogWriter``, ``lock_log``, ``unlock_log``,
    ``shard_folder``, ``code_fingerprint``, ``SCHEMA_VERSION``: importable from here.
"""

from __future__ import annotations

import importlib
from typing import Any

_EXPORTS = {
    **dict.fromkeys(("open_log", "Log", "TrialLog"), "reader"),
    **dict.fromkeys(("LogWriter", "lock_log", "unlock_log", "code_fingerprint"), "writer"),
    **dict.fromkeys(("SCHEMA", "SCHEMA_VERSION", "READING", "UNITS", "shard_folder"), "layout"),
    **dict.fromkeys(("log_contents", "compare_logs"), "compare"),
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> Any:
    if name in _EXPORTS:
        return getattr(importlib.import_module(f"sitframe.logs.{_EXPORTS[name]}"), name)
    raise AttributeError(f"module 'sitframe.logs' has no attribute {name!r}")
