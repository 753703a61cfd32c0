"""The ``sitframe`` command line.

What it holds
    :mod:`~sitframe.cli.app` (the parser, ``run``, ``evaluate``, ``world``, ``presets``,
    ``plugins`` and the error handling every command shares), :mod:`~sitframe.cli.logs`
    (``analyse``, ``replay``, ``compare``, ``export``), :mod:`~sitframe.cli.sweep`
    (``sweep``) and :mod:`~sitframe.cli.pack` (``pack``).

What it may import
    Everything below it: :mod:`sitframe.runs`, :mod:`sitframe.analysis`,
    :mod:`sitframe.logs` and the rest. Nothing imports the command line.

Entry points
    :func:`console_main` (the ``sitframe`` script; ``python -m sitframe.cli``), :func:`main`
    (returns the exit status), :func:`build_parser`.
"""

from __future__ import annotations

import importlib
from typing import Any

__all__ = ["add_parallel_arguments", "build_parser", "console_main", "main"]


def __getattr__(name: str) -> Any:  # (the parser is built only when a command runs)
    if name in __all__:
        return getattr(importlib.import_module("sitframe.cli.app"), name)
    raise AttributeError(f"module 'sitframe.cli' has no attribute {name!r}")
