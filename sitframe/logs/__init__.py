"""Logs: HDF5 run logs, written crash-safe and read back as arrays, records and tables.

placeholder docstring (split pending)
"""

from __future__ import annotations

import importlib
from typing import Any


def __getattr__(name: str) -> Any:
    _log = importlib.import_module("sitframe.logs._log")

    if not name.startswith("_") and hasattr(_log, name):
        return getattr(_log, name)
    raise AttributeError(f"module 'sitframe.logs' has no attribute {name!r}")
