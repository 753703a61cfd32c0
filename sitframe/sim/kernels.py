"""Compiled kernels for the control loop, when numba is there: :func:`kernels`.

The hot paths of the simulator and the situation controller -- ray casting,
the robot's swept disc, memberships and the fuzzy controller's output -- have
two implementations: numpy code (the reference) and scalar loops compiled by
numba (:mod:`sitframe.sim.kernels_numba`), some ten times faster on the small
arrays of one iteration. Both give bit-identical results: a kernel performs
the same IEEE operations in the same order as the numpy code it shadows, and
leaves every ``sin``, ``cos``, ``log``, ``exp`` and power to numpy (see
:mod:`sitframe.sim.kernels_numba`).

numba is an ordinary dependency. The numpy path runs when numba cannot be
imported (a platform without wheels), when the environment variable
``SITFRAME_NUMBA`` is ``0``, and for a process's first :data:`WARMUP_CALLS`
calls (so a short job never pays numba's start-up); the tests compare the two.

Costs: importing numba and loading the kernels from numba's on-disk cache
(all of them, when :mod:`sitframe.sim.kernels_numba` is imported) takes some
0.3-0.5 s once per process; a worker pool's forkserver preloads them, so its
workers start with them loaded. Compiling them, the first time after an
install, takes some 10 s (``benchmarks/sim/bench_sim.py --first-call`` measures both).
"""

from __future__ import annotations

import math
import os
import sys
from types import ModuleType

import numpy as np

__all__ = ["WARMUP_CALLS", "contact", "fused", "kernels", "load", "wanted"]

#: Calls of :func:`kernels` answered with the numpy path before numba is loaded:
#: a process that simulates only a few hundred iterations (a check of a config, a
#: short test) never pays numba's start-up, one that simulates more pays it after
#: some 30 ms of numpy work. Results are the same either way.
WARMUP_CALLS = 2000

_LOADED: list[ModuleType | None] = []
_CALLS = [0]


def wanted() -> bool:
    """Whether the kernels are to be used (``SITFRAME_NUMBA`` is not ``0``; read here as it
    is, at the foot of the house: its value is checked where a command, a run or an env
    starts, :func:`sitframe.params.check_environment`)."""
    return os.environ.get("SITFRAME_NUMBA", "1").strip() != "0"


def load() -> ModuleType | None:
    """Load the compiled kernels now; ``None`` when numba is missing or not :func:`wanted`."""
    if not _LOADED:
        k = None
        if wanted():
            try:  # imported here, not at the top: numba's import costs ~0.3 s of start-up,
                from sitframe.sim import numba_cache  # paid only by processes that simulate;
                # (importing it points numba's cache at the user's folder, first)
                numba_cache.announce_compilation()
                from sitframe.sim import kernels_numba as k  # (compiles or loads: seconds)
            except ImportError:
                k = None
        _LOADED.append(k)
    return _LOADED[0]


def kernels() -> ModuleType | None:
    """The compiled kernels (:mod:`sitframe.sim.kernels_numba`), or ``None`` for the numpy path.

    ``None`` for the first :data:`WARMUP_CALLS` calls of a process, unless the
    kernels are loaded already (a worker forked from a forkserver that preloaded
    them); then :func:`load`.
    """
    if _LOADED:
        return _LOADED[0]
    if "sitframe.sim.kernels_numba" in sys.modules or _CALLS[0] >= WARMUP_CALLS:
        return load()
    _CALLS[0] += 1
    return None


_TRIG_AGREES: list[bool] = []


def fused() -> ModuleType | None:
    """The compiled kernels for the fused steps, which compute sines and cosines themselves
    (the C library's) instead of between kernels in numpy: :func:`kernels`, or ``None`` where
    they differ from numpy's.

    numpy computes float64 ``sin`` and ``cos`` with the C library where measured (numpy 2.4
    on an AVX-512 CPU, with and without its AVX-512 loops), so the two agree to the bit
    there; a numpy built with vector versions of its own would not. Checked once per
    process on 4,100 angles (uniform in [-8, 8] rad, and zeros, multiples of pi/2, tiny
    and large ones): one difference and the fused steps are not used, the unfused kernels
    are (the same results, slower).
    """
    k = kernels()
    if k is None:
        return None
    if not _TRIG_AGREES:
        x = np.concatenate([np.random.default_rng(0).uniform(-8.0, 8.0, 4000),
                            np.pi / 2 * np.arange(-40, 41), [0.0, -0.0, 1e-300, 5e-324,
                                                              1e3, -1e5, 3e7, 1e22]])
        out = np.empty((2, x.size))
        k.trig(x, out)
        _TRIG_AGREES.append(bool(np.array_equal(out[0], np.sin(x))
                                 and np.array_equal(out[1], np.cos(x))))
    return k if _TRIG_AGREES[0] else None


_HYPOT_AGREES: list[bool] = []


def contact() -> ModuleType | None:
    """The compiled kernels for a whole step of ``step_robot``, contact, back-off and turn
    included (:func:`~sitframe.sim.kernels_numba.step_contact`): :func:`fused`, where the
    kernel's ``hypot`` is Python's ``math.hypot`` (its own algorithm, not the C library's;
    checked once per process on 2,000 pairs of lengths from 1e-300 to 1e300, zeros among
    them), and so is its ``wrap`` Python's ``math.remainder(x, 2 pi)`` (on 2,000 angles,
    multiples of pi among them); else ``None`` and the contact is stepped in Python (the same
    results, slower).
    """
    k = fused()
    if k is None:
        return None
    if not _HYPOT_AGREES:
        rng = np.random.default_rng(1)
        ab = rng.normal(size=(2, 2000)) * 10.0 ** rng.uniform(-300, 300, (2, 2000))
        ab[:, :50] = rng.normal(size=(2, 50))
        ab[0, 50:60] = 0.0
        got = np.array([k.hypot(a, b) for a, b in ab.T])
        want = np.array([math.hypot(a, b) for a, b in ab.T])
        th = np.concatenate([rng.uniform(-50.0, 50.0, 1900), np.pi * np.arange(-50, 50)])
        wrapped = np.array([k.wrap(x) for x in th])
        exact = np.array([math.remainder(x, 2.0 * math.pi) for x in th])
        _HYPOT_AGREES.append(bool(np.array_equal(got, want))
                             and wrapped.tobytes() == exact.tobytes())
    return k if _HYPOT_AGREES[0] else None
