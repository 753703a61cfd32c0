"""Where numba caches the compiled kernels, and the one line that says a compile is coming.

Nothing is ever written into the installed package. numba's default puts a module's cache in
the ``__pycache__`` folder beside it, inside site-packages: a later ``pip install -e`` over
that install left the folder behind, without an ``__init__.py``, and Python then imported it
as a namespace package ahead of the editable install (``cannot import name '__version__'``).
So :func:`configure` points numba at a folder of the user's, chosen in this order:

1. ``NUMBA_CACHE_DIR``, numba's own variable, when it is set;
2. ``SITFRAME_CACHE_DIR``, then its ``numba`` subfolder;
3. the user's cache folder (:func:`platformdirs.user_cache_dir`), its ``numba`` subfolder
   (``~/.cache/sitframe/numba`` on Linux).

When that folder cannot be created or written (a read-only home, a full disk), the kernels
are compiled in every process instead of cached, and one ``sitframe: warning:`` line on
stderr says so; a run never fails for it.

The first run after an install (or after :mod:`sitframe.sim.kernels_numba` changes) waits some
10-40 s while numba compiles; later runs load the kernels from the cache in some 0.3 s. An
audit took that wait for a stalled worker pool, so :func:`announce_compilation` says why on
a terminal.

It imports nothing of sitframe and prints its two lines itself: a worker pool's forkserver
loads it first, before the kernels, and it stays at the foot of the house.
"""

from __future__ import annotations

import os
import sys
import tempfile
from pathlib import Path

__all__ = ["announce_compilation", "cache_dir", "compile_pending", "configure", "drop_stale"]

#: Set once by :func:`configure`: the folder numba caches in, or ``None`` (no cache).
_CONFIGURED: list[Path | None] = []


def cache_dir() -> Path:
    """The folder the kernels are to be cached in (``NUMBA_CACHE_DIR``, ``SITFRAME_CACHE_DIR``
    or the user's cache folder; see the module's docstring). Nothing is created."""
    numba_dir = os.environ.get("NUMBA_CACHE_DIR", "").strip()
    if numba_dir:
        return Path(numba_dir).expanduser()
    own = os.environ.get("SITFRAME_CACHE_DIR", "").strip()
    if own:
        return Path(own).expanduser() / "numba"
    import platformdirs

    return Path(platformdirs.user_cache_dir("sitframe", appauthor=False)) / "numba"


def _writable(folder: Path) -> str | None:
    """``None`` when files can be written in ``folder`` (made if missing), else why not."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
        tempfile.TemporaryFile(dir=folder).close()
    except OSError as exc:
        return exc.strerror or type(exc).__name__
    return None


def configure() -> bool:
    """Point numba's cache at :func:`cache_dir`; whether kernels are to be cached at all.

    Called once per process when this module is imported, which the kernels' loader
    (:func:`sitframe.sim.kernels.load`) and a worker pool's forkserver do before
    :mod:`sitframe.sim.kernels_numba` defines its kernels (they are cached only if it
    succeeded: ``numba.core.config.CACHE_DIR`` is set).
    ``False`` (compile without a cache, one warning line on stderr) when the folder cannot be
    written: numba would otherwise fall back to the ``__pycache__`` folder inside the package.
    """
    if not _CONFIGURED:
        from numba.core import config

        folder = cache_dir()
        problem = _writable(folder)
        if problem is None:
            config.CACHE_DIR = str(folder)
            _CONFIGURED.append(folder)
        else:
            config.CACHE_DIR = ""  # (numba's own NUMBA_CACHE_DIR, if that was the one)
            _CONFIGURED.append(None)
            shown = str(folder) if str(folder).isprintable() else repr(str(folder))  # one line
            print(f"sitframe: warning: kernel cache folder {shown}: cannot write there "
                  f"({problem}); the kernels are compiled in every process instead (set "
                  "SITFRAME_CACHE_DIR to a writable folder to cache them)", file=sys.stderr)
    return _CONFIGURED[0] is not None


def compile_pending(source: Path, folder: Path | None = None) -> bool:
    """Whether numba will compile the kernels of ``source`` instead of loading them.

    numba keeps one index file per kernel (``<module>.<kernel>-<line>.py<version>.nbi``) in a
    subfolder of the cache folder named after the source's folder, and compiles again when
    the source changed. So: no index there at least as new as ``source``. ``folder`` is the
    cache folder (default :func:`cache_dir`).
    """
    from numba.core.caching import UserProvidedCacheLocator

    folder = cache_dir() if folder is None else folder
    sub = folder / UserProvidedCacheLocator.get_suitable_cache_subpath(str(source))
    newest = source.stat().st_mtime
    return not any(p.stat().st_mtime >= newest for p in sub.glob(f"{source.stem}.*.nbi"))


def drop_stale(source: Path, *depends: Path, folder: Path | None = None) -> int:
    """Remove the cache index of every kernel of ``source`` older than one of ``depends``;
    returns how many were removed.

    numba compiles a cached kernel again only when its *own* source file changed; a kernel
    that calls kernels of another module (``depends``) would keep their old compiled code.
    Without its index, numba compiles it anew. Only the user's cache folder is touched.
    """
    from numba.core.caching import UserProvidedCacheLocator

    folder = cache_dir() if folder is None else folder
    sub = folder / UserProvidedCacheLocator.get_suitable_cache_subpath(str(source))
    newest = max(p.stat().st_mtime for p in depends)
    gone = 0
    for p in sub.glob(f"{source.stem}.*.nbi"):
        try:
            if p.stat().st_mtime < newest:
                p.unlink()
                gone += 1
        except OSError:  # (another process removed it first)
            continue
    return gone


def announce_compilation(source: Path | None = None) -> None:
    """Say on a terminal why the first run after an install waits (numba compiling).

    ``source``: the kernels' module (default :mod:`sitframe.sim.kernels_numba`). Printed
    only when stderr is a terminal and the kernels are cached, so logs, pipes and tests
    never see it (without a cache every process compiles, as its warning said).
    """
    if source is None:
        source = Path(__file__).with_name("kernels_numba.py")
    if (sys.stderr is not None and sys.stderr.isatty() and _CONFIGURED
            and _CONFIGURED[0] is not None and compile_pending(source, _CONFIGURED[0])):
        print("sitframe: compiling the simulator's kernels with numba (once after an "
              "install or upgrade; some 10-40 s)", file=sys.stderr, flush=True)


configure()
