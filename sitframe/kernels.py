"""Compiled kernels for the control loop, when numba is there: :func:`kernels`.

The hot paths of the simulator and the situation controller -- ray casting,
the robot's swept disc, memberships and the fuzzy controller's output -- have
two implementations: numpy code (the reference) and scalar loops compiled by
numba (:mod:`sitframe.kernels_numba`), some ten times faster on the small
arrays of one iteration. Both give bit-identical results: a kernel performs
the same IEEE operations in the same order as the numpy code it shadows, and
leaves every ``sin``, ``cos``, ``log``, ``exp`` and power to numpy (see
:mod:`sitframe.kernels_numba`).

numba is an ordinary dependency. The numpy path runs when numba cannot be
imported (a platform without wheels) or when the environment variable
``SITFRAME_NUMBA`` is ``0``; the tests compare the two.

Costs: importing numba and loading the kernels from numba's on-disk cache
(all of them, when :mod:`sitframe.kernels_numba` is imported) takes some
0.3-0.5 s once per process; a worker pool's forkserver preloads them, so its
workers start with them loaded. Compiling them, the first time after an
install, takes some 10 s (``benchmarks/bench_sim.py --first-call`` measures both).
"""

from __future__ import annotations

import os
from types import ModuleType

__all__ = ["kernels", "wanted"]

_LOADED: list[ModuleType | None] = []


def wanted() -> bool:
    """Whether the kernels are to be used (``SITFRAME_NUMBA`` is not ``0``)."""
    return os.environ.get("SITFRAME_NUMBA", "1").strip() != "0"


def kernels() -> ModuleType | None:
    """The compiled kernels (:mod:`sitframe.kernels_numba`), or ``None`` for the numpy path.

    Imported at the first call (``SITFRAME_NUMBA`` is read then, once).
    """
    if not _LOADED:
        k = None
        if wanted():
            try:  # imported here, not at the top: numba's import costs ~0.3 s of start-up,
                from sitframe import kernels_numba as k  # paid only by commands that simulate
            except ImportError:
                k = None
        _LOADED.append(k)
    return _LOADED[0]
