"""Whether numba is about to compile the kernels, and the one line that says so on a terminal.

The first run after an install (or after :mod:`sitframe.kernels_numba` changes) waits some
10-40 s while numba compiles the kernels; later runs load them from numba's cache in
some 0.3 s. An audit took that wait for a stalled worker pool. :mod:`sitframe.kernels_numba`
calls :func:`announce_compilation` before it compiles, so an interactive user knows why.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

__all__ = ["announce_compilation", "compile_pending"]


def compile_pending(source: Path) -> bool:
    """Whether numba will compile the kernels of ``source`` instead of loading them.

    numba caches a module's kernels in the ``__pycache__`` folder beside it (index files
    ``<module>.<kernel>-<line>.py<version>.nbi``) and compiles again when the source is
    newer than its index. So: no index there at least as new as ``source``. A cache
    elsewhere (``NUMBA_CACHE_DIR``, or numba's per-user folder when the package's folder
    is read-only) is not looked for: False (nothing is claimed).
    """
    if os.environ.get("NUMBA_CACHE_DIR") or not os.access(source.parent, os.W_OK):
        return False
    newest = source.stat().st_mtime
    return not any(p.stat().st_mtime >= newest
                   for p in (source.parent / "__pycache__").glob(f"{source.stem}.*.nbi"))


def announce_compilation(source: Path) -> None:
    """Say on a terminal why the first run after an install waits (numba compiling).

    Printed only when stderr is a terminal, so logs, pipes and tests never see it.
    """
    if sys.stderr is not None and sys.stderr.isatty() and compile_pending(source):
        print("sitframe: compiling the simulator's kernels with numba (once after an "
              "install or upgrade; some 10-40 s)", file=sys.stderr, flush=True)
