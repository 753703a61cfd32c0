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
import subprocess
import sys
import tempfile
import time
from pathlib import Path

__all__ = ["announce_compilation", "cache_dir", "compile_elsewhere", "compile_pending", "configure",
           "drop_stale"]

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


#: A background compile whose lock is older than this [s] is taken for dead (a reused pid).
STALE_S = 600.0
#: The background compiles this process started (polled, so none is left a zombie), and
#: their modules.
_STARTED: list[subprocess.Popen[bytes]] = []
_TRIED: set[str] = set()
#: What the background process runs: import the module (compiling its kernels into the
#: cache), then remove the lock; on a failure, write ``failed`` in it instead.
_CHILD = """import importlib, os, sys
getattr(os, "nice", int)(10)  # (background work: the run's own processes first)
try:
    importlib.import_module(sys.argv[2])
except BaseException:
    with open(sys.argv[1], "w") as f:
        f.write("failed")
    raise
os.unlink(sys.argv[1])
"""


def _running(lock: Path) -> bool | None:
    """Whether the background compile of ``lock`` still runs (``None``: it failed)."""
    try:
        text, age = lock.read_text().strip(), time.time() - lock.stat().st_mtime
    except OSError:
        return False  # (it finished meanwhile)
    if text == "failed":
        return None
    if not text.isdigit():  # (its starter has yet to write the pid)
        return age < 5.0
    for p in _STARTED:
        p.poll()  # (reaps ours)
    try:
        os.kill(int(text), 0)
    except ProcessLookupError:
        return False
    except OSError:  # (alive, another user's)
        pass
    return age < STALE_S


def compile_elsewhere(module: str, source: Path) -> str | None:
    """Have a process of its own compile ``module``'s kernels into the cache, unless one is
    at it already; the caller goes on without them meanwhile.

    Parameters
    ----------
    module
        The module to import (its kernels compile, and are cached, at import).
    source
        Its file (:func:`compile_pending` tells from it whether the cache has them).

    Returns
    -------
    str or None
        What is happening while a background compile runs (``"... compiling in the
        background ..."``). ``None`` when the caller is to import ``module`` itself: there is
        no cache (every process compiles for itself), the kernels are cached, the background
        compile failed, or one this process started stopped before it finished (a kill, a
        full disk). Importing it then shows the error, and nothing is started again and
        again. The lock is ``<cache folder>/<module>.compiling``, holding the pid: one
        background compile per cache folder, however many processes ask.
    """
    folder = _CONFIGURED[0] if _CONFIGURED else None
    if folder is None or not sys.executable:  # (an embedded Python: no interpreter to start)
        return None
    lock = folder / f"{module}.compiling"
    if lock.exists():  # (first: the kernels it has cached so far are not all of them)
        state = _running(lock)
        if state:
            return f"its kernels are compiling in the background ({lock.name})"
        lock.unlink(missing_ok=True)
        # (stopped before it finished: try again, once per process; failed, or stopped
        # again: compile here, which says why)
        again = state is False and module not in _TRIED
        return compile_elsewhere(module, source) if again else None
    if not compile_pending(source, folder):
        return None
    try:
        fd = os.open(lock, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
    except FileExistsError:  # (another process started one just now)
        return compile_elsewhere(module, source)
    except OSError:
        return None
    try:
        path = os.pathsep.join(p or os.getcwd() for p in sys.path)
        child = subprocess.Popen(
            [sys.executable, "-c", _CHILD, str(lock), module], stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True,
            env=dict(os.environ, NUMBA_CACHE_DIR=str(folder), PYTHONPATH=path))
        os.write(fd, str(child.pid).encode())
    except OSError:
        lock.unlink(missing_ok=True)
        return None
    finally:
        os.close(fd)
    _STARTED.append(child)
    _TRIED.add(module)
    return f"its kernels are compiling in the background (pid {child.pid})"


def announce_compilation(source: Path | None = None, background: bool = False) -> None:
    """Say on a terminal why the first run after an install waits (numba compiling), or,
    with ``background``, that the learning trial's kernel (``source``) compiles in a process
    of its own (:func:`compile_elsewhere`) while the trials run the Python loop.

    ``source``: the kernels' module (default :mod:`sitframe.sim.kernels_numba`). Printed
    only when stderr is a terminal and the kernels are cached, so logs, pipes and tests
    never see it (without a cache every process compiles, as its warning said); with
    ``background`` whatever the cache holds so far (the caller knows a compile is running:
    the one in the background may have cached some of the kernels already).
    """
    if source is None:
        source = Path(__file__).with_name("kernels_numba.py")
    if (sys.stderr is not None and sys.stderr.isatty() and _CONFIGURED
            and _CONFIGURED[0] is not None
            and (background or compile_pending(source, _CONFIGURED[0]))):
        print("sitframe: compiling the learning trial's kernel in the background (once after "
              "an install or upgrade); trials run the Python loop, with the same results, "
              "until it is ready" if background else
              "sitframe: compiling the simulator's kernels with numba (once after an "
              "install or upgrade; some 10-40 s)", file=sys.stderr, flush=True)


configure()
