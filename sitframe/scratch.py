"""Scratch arrays: a long trial's rows kept in a file on disk instead of in memory.

A trial records some 1.2 kB per iteration (the memberships, the learner's Q snapshots, the
reading, ...): 110 MiB for 100,000 iterations, all held until the trial's log is written.
The per-iteration arrays of a trial longer than :func:`limit` iterations are instead
:class:`numpy.memmap` arrays of scratch files (:func:`empty`), and :func:`release` drops
their pages from the process (the data stays in the file and comes back when read). The
trial loop releases every few thousand iterations and the writer after every block it
writes, so a long trial's resident memory does not grow with its length. A shorter trial
keeps its arrays in memory: a page of a file costs more to write than one of memory (some
10% of a 5000-iteration trial's time), and its arrays are small.

A scratch file has no name (it is unlinked as soon as it is mapped: a killed process leaves
nothing behind) and its blocks are reserved when it is made (``posix_fallocate``), so a full
disk is an ``OSError`` then, never a ``SIGBUS`` later. Where no file can be made the array
is an ordinary one in memory: a run never fails for its scratch.

Where: ``SITFRAME_SCRATCH_DIR``, else the ``scratch`` folder of ``SITFRAME_CACHE_DIR`` or of
the user's cache folder (``~/.cache/sitframe/scratch``), never ``/tmp``, which may be memory
itself. ``SITFRAME_SCRATCH_ROWS`` sets :func:`limit` (default 20,000; ``0`` puts every
array in a file, a number above any trial's length none). The values are the same bits
either way. Both variables are read and checked by :func:`sitframe.params.environment`.

It imports only the rest of the ground floor (errors, params): the learner, the loop and
the writer all use it.
"""

from __future__ import annotations

import atexit
import itertools
import mmap
import multiprocessing.util
import os
import tempfile
import threading
import weakref
from contextlib import suppress
from pathlib import Path
from typing import Any

import numpy as np

from sitframe.errors import warn
from sitframe.params import cache_folder, environment

__all__ = ["BLOCK", "copy", "copy_rows", "empty", "folder", "in_file", "limit", "release",
           "release_all", "share_by_name", "share_warning", "wanted"]

#: Bytes of rows :func:`copy_rows` copies between two releases.
BLOCK = 4 * 2**20

#: Every scratch mapping of this process still alive (:func:`release_all` drops their pages).
#: (Weak references without callbacks, pruned as new ones come: a callback may run inside a
#: signal handler's exception, which Python then prints as "Exception ignored".)
_live: dict[int, weakref.ref[np.memmap]] = {}
#: The files this process mapped from pickles (:func:`_open`), by name.
_opened: dict[str, weakref.ref[np.memmap]] = {}
#: The named files this process made and has not handed over: (mapping, its name record).
_made: list[tuple[weakref.ref[np.memmap], dict[str, Any]]] = []
#: Whether this process names its scratch files (:func:`share_by_name`).
_share = [False]
_names = itertools.count()
#: Whether this process (or, after :func:`share_warning`, its pool) said that no scratch
#: file could be made (:func:`_warn_once`): a flag with ``is_set`` and ``set``.
_said: list[Any] = [threading.Event()]


def limit() -> int:
    """Rows (iterations) above which :func:`empty` makes a scratch file
    (``SITFRAME_SCRATCH_ROWS``, default 20,000; checked by :func:`sitframe.params.environment`)."""
    return environment("SITFRAME_SCRATCH_ROWS")


def wanted(rows: int) -> bool:
    """Whether arrays of ``rows`` rows (a trial of as many iterations) go to scratch files."""
    return rows > limit()


def folder() -> Path:
    """The folder scratch files are made in (see the module's docstring); not created."""
    own = environment("SITFRAME_SCRATCH_DIR")
    return Path(own).expanduser() if own else cache_folder() / "scratch"


class _Mapped(np.memmap):
    """A scratch file's array (and its views). Pickled as its file's name where this process
    shares its scratch files (:func:`share_by_name`), else as its values."""

    def __array_wrap__(self, arr: Any, context: Any = None, return_scalar: bool = False) -> Any:
        out = super().__array_wrap__(arr, context, return_scalar)
        return out.view(np.ndarray) if isinstance(out, _Mapped) and out._mmap is None else out

    def __getitem__(self, index: Any) -> Any:
        out = super().__getitem__(index)
        return out.view(np.ndarray) if isinstance(out, _Mapped) and out._mmap is None else out

    def __reduce__(self) -> Any:
        base = _base(self)
        named = None if base is None else base.__dict__.get("named")
        if named is None or not Path(path := named["path"]).exists():
            return np.asarray(self).__reduce__()
        named["handed"] = True  # (the receiver unlinks it)
        at = self.__array_interface__["data"][0] - base.__array_interface__["data"][0]
        return _open, (path, base.nbytes, self.dtype.str, self.shape, self.strides, at)


def _open(path: str, size: int, dtype: str, shape: tuple[int, ...], strides: tuple[int, ...],
          at: int) -> np.ndarray:
    """An array pickled by :class:`_Mapped`: its file mapped here, and unlinked (this process
    now holds it; a second array of the same file maps it once)."""
    ref = _opened.get(path)
    base = None if ref is None else ref()
    if base is None:
        base = _Mapped(path, dtype=np.uint8, mode="r+", shape=(size,))
        _add(base)
        _opened[path] = weakref.ref(base)
        with suppress(OSError):
            os.unlink(path)
    return np.ndarray(shape, dtype, buffer=base, offset=at, strides=strides)


def share_by_name() -> None:
    """Name this process's scratch files from now on, so that an array pickled to another
    process of this machine travels as its file's name, not its values: a local pool's
    worker hands a long trial to the main process without either holding it
    (:mod:`sitframe.runs.parallel`). The process that unpickles it unlinks the file; this
    one unlinks those it never hands over (when their arrays are gone, or at exit), and the
    files of processes that died are removed here."""
    if not _share[0]:  # (a pool worker ends by os._exit: multiprocessing's own exit hook)
        atexit.register(_unlink_unhanded)
        multiprocessing.util.Finalize(None, _unlink_unhanded, exitpriority=0)
    _share[0] = True
    with suppress(OSError):
        for p in folder().glob("*.scratch"):
            pid = p.name.split("-", 1)[0]
            if pid.isdigit() and not _alive(int(pid)):
                p.unlink(missing_ok=True)


def _unlink_unhanded(gone_only: bool = False) -> None:
    """Unlink the named files this process made and never handed over (``gone_only``: of
    the arrays already gone; else all, at exit), and forget them."""
    keep = []
    for ref, named in _made:
        if gone_only and ref() is not None:
            keep.append((ref, named))
        elif not named["handed"]:
            with suppress(OSError):
                os.unlink(named["path"])
    _made[:] = keep


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:
        return True
    return True


def _base(arr: np.ndarray) -> np.memmap | None:
    """The live scratch mapping ``arr`` is (a view of), or ``None``."""
    base: Any = arr
    while base is not None:
        ref = _live.get(id(base)) if isinstance(base, np.memmap) else None
        if ref is not None and ref() is base:
            return base
        base = getattr(base, "base", None)
    return None


def _mapped(shape: tuple[int, ...], dtype: np.dtype) -> np.memmap | None:
    """A zero-filled array of a new scratch file, or ``None`` if none can be made. The file is
    unlinked at once (gone with the mapping) unless the process shares its files by name."""
    size = int(np.prod(shape)) * dtype.itemsize
    if size == 0:  # (nothing to keep: no file, and no warning that none could be made)
        return None
    path = None
    try:
        where = folder()
        where.mkdir(parents=True, exist_ok=True)
        if _share[0]:
            path = where / f"{os.getpid()}-{next(_names)}.scratch"
            fh = open(path, "x+b")  # noqa: SIM115 - closed below, the mapping kept
        else:
            fh = tempfile.TemporaryFile(dir=where)
        with fh:
            os.posix_fallocate(fh.fileno(), 0, size)
            arr = _Mapped(fh, dtype=dtype, mode="r+", shape=shape)
    except (OSError, ValueError) as exc:
        if path is not None:
            path.unlink(missing_ok=True)
        _warn_once(exc)
        return None
    if path is not None:  # (unlinked when the mapping is gone unless pickled: then the
        arr.__dict__["named"] = named = {"path": str(path), "handed": False}  # receiver does)
        _made.append((weakref.ref(arr), named))
    _add(arr)
    return arr


def share_warning(flag: Any) -> None:
    """Say that no scratch file could be made at most once across the processes given the
    same ``flag`` (a :class:`multiprocessing.Event`: a run's main process and its pool's
    workers) instead of once in each."""
    _said[0] = flag


def _warn_once(exc: Exception) -> None:
    """Say once per process, in one line, that no scratch file could be made (the rows then
    stay in memory: a run never fails for it)."""
    if not _said[0].is_set():
        _said[0].set()
        why = getattr(exc, "strerror", None) or str(exc) or type(exc).__name__
        warn(f"scratch folder {folder()}: cannot make a file there ({why}); a long trial's "
             "rows stay in memory instead (set SITFRAME_SCRATCH_DIR to a folder with room)")


def _add(arr: np.memmap) -> None:
    """Count ``arr`` among the live mappings; forget the dead ones, and unlink the named files
    of those never handed to another process."""
    for key in [k for k, ref in _live.items() if ref() is None]:
        del _live[key]
    for key in [k for k, ref in _opened.items() if ref() is None]:
        del _opened[key]
    _unlink_unhanded(gone_only=True)
    _live[id(arr)] = weakref.ref(arr)


def empty(shape: int | tuple[int, ...], dtype: Any = np.float64, *, fill: Any = None,
          file: bool | None = None) -> np.ndarray:
    """A new array of ``shape``, a scratch file's when its rows are many.

    Parameters
    ----------
    shape, dtype
        As :func:`numpy.empty` takes them; ``shape[0]`` is the rows (iterations).
    fill
        A value to fill it with (``None``: uninitialised, or zeros in a file).
    file
        In a scratch file or not; ``None``: when :func:`wanted` says so of ``shape[0]``.
    """
    shape = (shape,) if isinstance(shape, int | np.integer) else tuple(shape)
    dt = np.dtype(dtype)
    arr: np.ndarray | None = None
    if file or (file is None and shape and wanted(shape[0])):
        arr = _mapped(shape, dt)
    if arr is None:
        arr = np.empty(shape, dtype=dt)
    if fill is not None:
        arr[...] = fill
        release(arr)
    return arr


def copy(arr: np.ndarray) -> np.ndarray:
    """A C-ordered copy of ``arr``, in a scratch file when ``arr`` is in one."""
    out = empty(arr.shape, arr.dtype, file=in_file(arr))
    copy_rows(out, arr)
    return out


def copy_rows(dst: np.ndarray, src: np.ndarray) -> None:
    """``dst[:len(src)] = src`` a block of rows at a time, releasing both after each block
    (a copy of a scratch array never holds either whole)."""
    if not (in_file(dst) or in_file(src)):
        dst[:len(src)] = src
        return
    step = max(1, BLOCK // max(1, src[:1].nbytes))
    for i in range(0, len(src), step):
        j = min(len(src), i + step)
        dst[i:j] = src[i:j]
        release(dst, src)


def _mapping(arr: np.ndarray) -> mmap.mmap | None:
    """The scratch mapping ``arr`` is (a view of), or ``None``."""
    base = _base(arr)
    return None if base is None else base._mmap


def in_file(arr: np.ndarray) -> bool:
    """Whether ``arr`` is (a view of) a scratch file's array."""
    return _mapping(arr) is not None


def release(*arrays: np.ndarray) -> None:
    """Drop the pages of the scratch arrays among ``arrays`` from this process's memory
    (their data stays in the file); other arrays are left alone."""
    for arr in arrays:
        mm = _mapping(arr)
        if mm is not None and not mm.closed:
            mm.madvise(mmap.MADV_DONTNEED)


def release_all() -> None:
    """:func:`release` every scratch array of this process."""
    release(*(arr for ref in list(_live.values()) if (arr := ref()) is not None))
