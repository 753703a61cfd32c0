"""Writing a log: :class:`LogWriter`, the one-writer lock, and the code fingerprint.

Every write is one short crash-safe transaction that publishes a complete, closed file by an
atomic rename; a finished trial goes to its own file until the run ends and packs them. The
layout and the reasons are in :mod:`sitframe.logs.layout`.

A small file is built in memory and written in one piece (:func:`_memory_file`); a large
one (a long trial's, the packed log) streams into its scratch file through
:class:`_ScratchFile`, which never reports a failed write to HDF5 (a full disk: the rest of
the file goes to memory and the error is raised once HDF5 has closed it), and arrays kept
in scratch files (:mod:`sitframe.scratch`) are handed to HDF5 a block of rows at a time: the
writer's memory does not grow with a trial's length (a 100,000-iteration trial's 110 MiB of
arrays, its 35 MiB file). Either way HDF5 never meets a failed write.

Why one module of this size: the transaction, the lock and the full-disk handling share
one boundary with the disk (:func:`write_bytes`); split, each half would need the other's
private state.
"""

from __future__ import annotations

import errno
import fcntl
import glob
import hashlib
import importlib.util
import itertools
import json
import os
import re
import shutil
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager, suppress
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from sitframe import scratch
from sitframe.contract.records import (
    RunInfo,
    TrialResult,
)
from sitframe.errors import DiskFullError, InputError
from sitframe.logs.interrupts import deferred_interrupt
from sitframe.logs.layout import (
    SCHEMA,
    SCHEMA_VERSION,
    SHARD_NAME,
    UNITS,
    shard_file,
    shard_folder,
)

_COMPRESS_MIN = 1024  # elements; smaller arrays are stored uncompressed

#: Bytes up to which a file is built in memory (HDF5's core driver) and written in one
#: piece: a stage, the run file (its trials in their own files), a trial of at most this
#: many bytes of arrays (a 5000-iteration trial has 6 MB, its file 1.4 MB). Larger ones,
#: and the packed log, stream into their scratch files (:class:`_ScratchFile`): HDF5 calls
#: Python for each of its reads and writes there, which costs a small file some 4% of its
#: writing time (1.5 ms of a 5000-iteration trial's 35).
_SMALL = 16 << 20

#: Bytes of a streamed file gathered in memory between two writes to the disk.
_BUFFER = 4 << 20


def _write_value(group: h5py.Group, name: str, value: Any) -> None:
    """Write a scalar as an attribute, an array as a (compressed) dataset.

    An array in a scratch file (:func:`sitframe.scratch.in_file`) is written a block of
    whole chunks of rows at a time (some :data:`sitframe.scratch.BLOCK` bytes), its pages
    released after each, into a dataset made as ``data=`` would make it (the same shape,
    dtype, chunk shape guessed from them, filters): the same dataset, without the whole
    array resident at once."""
    if "/" in name:
        head, tail = name.split("/", 1)
        sub = group.require_group(head)
        _write_value(sub, tail, value)
        return
    if value is None:
        return
    if isinstance(value, bool | int | float | str | np.integer | np.floating | np.bool_):
        group.attrs[name] = value
        return
    if isinstance(value, list | tuple) and all(isinstance(v, str) for v in value):
        group.attrs[name] = json.dumps(list(value))
        return
    if isinstance(value, dict):
        sub = group.require_group(name)
        for k, v in value.items():
            _write_value(sub, str(k), v)
        return
    arr = np.asarray(value)
    # Every dataset carries a Fletcher-32 checksum per chunk, so a flipped byte in
    # the data makes reading it fail (InputError) instead of returning wrong numbers.
    kw: dict[str, Any] = {"chunks": True, "fletcher32": True}
    if arr.size >= _COMPRESS_MIN:
        kw.update(compression="gzip", compression_opts=1, shuffle=True)
    if name in group:
        del group[name]
    if arr.ndim and scratch.in_file(arr):  # (a block of whole chunks of rows at a time)
        ds = group.create_dataset(name, shape=arr.shape, dtype=arr.dtype, **kw)
        row = max(arr[:1].nbytes, 1)
        step = max(scratch.BLOCK // row // ds.chunks[0], 1) * ds.chunks[0]  # (whole chunks)
        for i in range(0, len(arr), step):
            ds[i:i + step] = arr[i:i + step]
            scratch.release(arr)
    else:
        ds = group.create_dataset(name, data=arr, **kw)
    if name in UNITS:
        ds.attrs["units"] = UNITS[name]


#: Logs this process is the writer of: real log path -> (fd of its flocked ``LOG.lock``, lock
#: file path, the option or key the log's path came from, for messages).
_held: dict[str, tuple[int, Path, str]] = {}

#: Runs that replace an existing log: real log path -> the scratch file holding the new
#: run's file until it has a trial of its own (:meth:`LogWriter.start`).
_staged: dict[str, Path] = {}

_names = itertools.count()


def real_path(path: str | os.PathLike[str]) -> Path:
    """The file a log path names, symbolic links followed: a log reached through a link
    (``logs/`` pointing into a store) is written, locked and packed where the link points."""
    return Path(os.path.realpath(path))


def lock_log(path: str | os.PathLike[str], key: str = "--out") -> None:
    """Become the only writer of the log at ``path`` (no-op if this process already is).

    Takes an exclusive, non-blocking :func:`fcntl.flock` on ``LOG.lock``
    beside the real log (symbolic links followed: two paths to one log share
    one lock; the lock file itself is opened with ``O_NOFOLLOW``, so a
    symlink planted there is refused), held until :func:`unlock_log` or the
    end of the process (the OS releases it when the process dies, even by
    SIGKILL). ``key`` is where the path came from (``--out``, ``--resume``,
    ``LOG``), named by the messages about this log.

    Raises
    ------
    InputError
        Another process holds the lock, or the lock file cannot be created.
    """
    real = str(real_path(path))
    if real in _held:
        return
    lock = Path(real + ".lock")
    while True:
        try:
            lock.parent.mkdir(parents=True, exist_ok=True)
            fd = os.open(lock, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW, 0o644)
        except OSError as exc:
            if exc.errno in _FULL:
                raise InputError(f"cannot create the log: the disk is full ({lock.parent} has "
                                 f"{human_size(_free(lock.parent))} free; its lock file "
                                 f"'{lock.name}' cannot be made)", file=str(path),
                                 key=key) from None
            raise InputError(f"cannot create the log: {exc.strerror or exc} (its lock file "
                             f"'{lock.name}')", file=str(path), key=key) from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            os.close(fd)
            raise InputError(f"another sitframe process is writing this log (it holds "
                             f"'{lock.name}'); one log has one writer: wait for that run to end "
                             "or choose another --out", file=str(path), key=key) from None
        try:  # the previous holder may have removed the file between our open and flock
            same = os.path.samestat(os.fstat(fd), os.stat(lock, follow_symlinks=False))
        except OSError:
            same = False
        if same:
            _held[real] = (fd, lock, key)
            return
        os.close(fd)


def unlock_log(path: str | os.PathLike[str] | None = None) -> None:
    """Stop being the writer of the log at ``path`` (every log if ``path`` is None).

    A new run that had not yet replaced the log it was to replace (no trial of its own)
    leaves that log as it was: its scratch run file is removed."""
    keys = list(_held) if path is None else [str(real_path(path))]
    for key in keys:
        staged = _staged.pop(key, None)
        if staged is not None:
            staged.unlink(missing_ok=True)
        entry = _held.pop(key, None)
        if entry is not None:
            fd, lock, _key = entry
            lock.unlink(missing_ok=True)  # while still held, so no one else holds this file
            os.close(fd)


#: ``errno`` values of a full disk (space, or the user's quota).
_FULL = (errno.ENOSPC, errno.EDQUOT)


def _free(folder: Path) -> int:
    """Bytes free for this user in ``folder``'s file system (0 if it cannot be told)."""
    try:
        return int(shutil.disk_usage(folder).free)
    except OSError:
        return 0


def human_size(n: float) -> str:
    """A byte count for people: ``512 B``, ``96 kB``, ``1.4 MB``, ``2.1 GB``."""
    for unit in ("B", "kB", "MB", "GB"):
        if n < 1000 or unit == "GB":
            return f"{n:.0f} {unit}" if unit in ("B", "kB") or n >= 100 else f"{n:.1f} {unit}"
        n /= 1000
    raise AssertionError  # pragma: no cover


def space_to_finish(logs: list[tuple[Path, int]]) -> int:
    """About how many bytes finishing the logs ``(path, trials the run has)`` needs on
    their disk (a sweep's points): every trial still to come, at the mean size of the
    trials written so far, and each log packed at its end (written while its trial files
    still exist). Complete logs need nothing; logs not begun count as the mean run file."""
    seen = []  # (run file bytes, trials in it, trial file sizes, complete)
    for path, _n in logs:
        try:
            with h5py.File(path, "r") as f:
                trials = f.get("trials")
                names = list(trials) if isinstance(trials, h5py.Group) else []
                done = f.attrs.get("status") == "complete"
            folder = shard_folder(path)
            sizes = [p.stat().st_size for p in folder.glob("*.h5")] if folder.is_dir() else []
            seen.append((Path(path).stat().st_size, len(names), sizes, done))
        except (OSError, ValueError, TypeError):
            seen.append(None)
    sizes = [x for s in seen if s for x in s[2]]
    packed = [s[0] / s[1] for s in seen if s and s[1] and not s[2]]
    mean = sum(sizes) / len(sizes) if sizes else (sum(packed) / len(packed) if packed else 0.0)
    runs = [s[0] - (s[1] - len(s[2])) * mean for s in seen if s and not s[3]]
    base = max(sum(runs) / len(runs), 0.0) if runs else 0.0
    need = 0.0
    for s, (_path, n) in zip(seen, logs, strict=True):
        if s is not None and s[3]:
            continue
        run, have = (s[0], s[1]) if s else (base, 0)
        to_come = max(n - have, 0)
        need += to_come * mean + run + (len(s[2]) if s else 0) * mean + to_come * mean
    return int(need)


def _memory_file(near: Path, image: bytes | None = None) -> h5py.File:
    """A writable HDF5 file held in memory only: new, or opened from the bytes ``image``
    (named beside ``near`` under a name no file has: HDF5's core driver refuses to open an
    image under the name of a file that exists)."""
    name = near.parent / f".{near.name}.{os.getpid()}-{next(_names)}.in-memory"
    fapl = h5py.h5p.create(h5py.h5p.FILE_ACCESS)
    fapl.set_fclose_degree(h5py.h5f.CLOSE_STRONG)
    fapl.set_fapl_core(block_size=1 << 20, backing_store=False)
    if image is None:
        fid = h5py.h5f.create(os.fsencode(name), h5py.h5f.ACC_EXCL, fapl=fapl)
    else:
        fapl.set_file_image(image)
        fid = h5py.h5f.open(os.fsencode(name), h5py.h5f.ACC_RDWR, fapl=fapl)
    return h5py.File(fid)


def _image(f: h5py.File) -> bytes:
    """The bytes of the in-memory file ``f``, everything flushed into them."""
    f.flush()
    return bytes(f.id.get_file_image())


def _nbytes(value: Any) -> int:
    """Bytes of the arrays in ``value`` (dicts, lists and tuples of them walked)."""
    if isinstance(value, np.ndarray):
        return value.nbytes
    if isinstance(value, dict):
        value = list(value.values())
    return sum(map(_nbytes, value)) if isinstance(value, list | tuple) else 0


def _h5file(name: Path, box: _ScratchFile, *, new: bool) -> h5py.File:
    """An HDF5 file (new, or opened for changes) read and written through ``box``.

    (Its file access list holds ``box`` and is dropped here: one left to the end of the
    process, in a traceback say, would be freed by HDF5 after Python is gone, SIGSEGV.)"""
    fapl = h5py.h5p.create(h5py.h5p.FILE_ACCESS)
    try:
        fapl.set_fclose_degree(h5py.h5f.CLOSE_STRONG)
        fapl.set_fileobj_driver(h5py.h5fd.fileobj_driver, box)
        if new:
            return h5py.File(h5py.h5f.create(os.fsencode(name), h5py.h5f.ACC_TRUNC, fapl=fapl))
        return h5py.File(h5py.h5f.open(os.fsencode(name), h5py.h5f.ACC_RDWR, fapl=fapl))
    finally:
        del fapl  # (not even in a traceback's frame)


def write_bytes(fd: int, data: bytes | memoryview) -> None:
    """The writer's one boundary with the disk: ``data`` written to the open file ``fd``
    at its offset (``fd`` closed here). Every byte of every file the writer makes goes
    through here (a file built in memory in one piece, a streamed one in pieces:
    :class:`_ScratchFile`); an ``OSError`` (a full disk: ``ENOSPC``) leaves nothing
    published."""
    try:
        view = memoryview(data).cast("B")
        while view:
            view = view[os.write(fd, view):]
    finally:
        os.close(fd)


class _ScratchFile:
    """The file object HDF5 writes a scratch file through (h5py's ``fileobj`` driver): it
    never reports a failure to HDF5.

    HDF5 whose own write to a file fails half-way (a full disk) leaves its library state
    broken: a later call crashed the process (SIGSEGV) with the log still ``running``. So
    every byte this object writes goes through :func:`write_bytes`, and the first write
    that fails is recorded instead of reported: the file as written so far is read back
    into memory and HDF5 goes on there, always seeing the file it wrote. :meth:`done`, once
    HDF5 has closed the file, raises the recorded error (the writer then removes the
    scratch file: nothing is published). Memory grows with the file only then, on the
    failing path.

    Writes gather in a window of :data:`_BUFFER` bytes in memory (from the file's first
    write on, anywhere beyond what the disk holds or adjoining it) and reach the disk in
    pieces of that size as HDF5 appends to the file, not in HDF5's thousands of small
    writes. ``source`` (an existing file to change: the run file) is read into the window,
    and copied into the scratch file first as far as it does not fit (plain I/O through
    :func:`write_bytes`: a full disk there raises before HDF5 sees the file).
    """

    __slots__ = ("buf", "disk", "error", "fd", "pos", "size", "start", "used", "view")

    def __init__(self, fd: int, source: Path | None = None) -> None:
        self.fd, self.pos, self.size = fd, 0, 0
        self.disk = 0  # (where the file's bytes on disk end)
        self.start, self.used = 0, 0  # (the window: the file's bytes start.. in buf[:used])
        self.buf = bytearray(_BUFFER)
        self.view = memoryview(self.buf)
        self.error: OSError | None = None
        if source is None:
            return
        with open(source, "rb", buffering=0) as src:
            while n := src.readinto(self.view[self.used:]):
                self.used += n
                if self.used == len(self.buf):  # (larger than the window: copied)
                    self._put(self.view, self.start)
                    self.start, self.used = self.start + self.used, 0
        self.size = self.start + self.used

    def _put(self, data: memoryview, offset: int) -> None:
        os.lseek(self.fd, offset, os.SEEK_SET)
        write_bytes(os.dup(self.fd), data)  # (a duplicate: write_bytes closes what it gets)
        self.disk = max(self.disk, offset + len(data))

    def _flush(self, at: int) -> None:
        """The window written to disk, and a new one begun at ``at`` (unless failed)."""
        if self.error is None:
            try:
                if self.used:
                    self._put(self.view[:self.used], self.start)
            except OSError as exc:
                self._fail(exc)
            else:
                self.start, self.used = at, 0

    def _fail(self, exc: OSError) -> None:
        """Go on in memory, the window the whole file as written so far (the first error
        kept)."""
        if self.error is not None:
            return
        self.error = exc.with_traceback(None)  # (its frames would keep HDF5's buffers)
        whole = bytearray(max(self.size, self.start + self.used))
        view, got = memoryview(whole), 0
        with suppress(OSError):  # (what cannot be read back reads as zeros)
            while got < len(whole) and (n := os.preadv(self.fd, [view[got:]], got)):
                got += n
        view[self.start:self.start + self.used] = self.view[:self.used]
        self.buf, self.view, self.start, self.used = whole, view, 0, len(whole)

    def _room(self, need: int) -> None:
        """A window of at least ``need`` bytes (a write larger than the window, or the
        file in memory after a failure)."""
        if need > len(self.buf):
            self.buf = bytearray(max(need, 2 * len(self.buf)))
            self.buf[:self.used] = self.view[:self.used]
            self.view = memoryview(self.buf)

    def write(self, data: memoryview) -> int:
        n, off = len(data), self.pos - self.start  # (data: h5py's view of HDF5's bytes)
        if self.error is None and (off < 0 or off + n > len(self.buf) or (
                off > self.used and self.start + self.used < self.disk)):
            self._flush(self.pos)
            off = self.pos - self.start
        self._room(off + n)
        if off > self.used:  # (nothing written there yet: zeros, as on disk)
            self.view[self.used:off] = bytes(off - self.used)
        self.view[off:off + n] = data
        self.used = max(self.used, off + n)
        self.pos += n
        self.size = max(self.size, self.pos)
        return n

    def readinto(self, buf: memoryview) -> int:
        view, n, got = memoryview(buf), len(buf), 0
        lo, hi = max(self.pos, self.start), min(self.pos + n, self.start + self.used)
        if self.error is None and (lo, hi) != (self.pos, self.pos + n):
            try:  # (from disk, unless the window holds it all)
                while got < n and (k := os.preadv(self.fd, [view[got:]], self.pos + got)):
                    got += k
            except OSError as exc:
                self._fail(exc)
                return self.readinto(buf)
        if got < n:  # (beyond the end of the file: zeros, as HDF5's own driver)
            view[got:] = bytes(n - got)
        if lo < hi:
            view[lo - self.pos:hi - self.pos] = self.view[lo - self.start:hi - self.start]
        self.pos += n
        return n

    def truncate(self, size: int) -> int:
        end = size - self.start
        whole = self.error is not None or (  # (the window holds the file's end)
            0 <= end <= len(self.buf) and self.disk <= min(size, self.start + self.used))
        if not whole:
            try:
                os.ftruncate(self.fd, size)
                self.disk = min(self.disk, size)
            except OSError as exc:
                self._fail(exc)
                whole, end = True, size
        if end < self.used:
            self.used = max(end, 0)
        elif whole:
            self._room(end)
            self.view[self.used:end] = bytes(end - self.used)
            self.used = end
        self.size = size
        return size

    def seek(self, pos: int, whence: int = os.SEEK_SET) -> int:
        self.pos = self.size + pos if whence == os.SEEK_END else pos
        return self.pos

    def tell(self) -> int:
        return self.pos

    def flush(self) -> None:
        """(Nothing: the rename protects against process death, not power loss; no fsync.)"""

    def done(self) -> None:
        """Once HDF5 has closed the file: all of it on disk, or the first error raised."""
        self._flush(self.size)
        if self.error is not None:
            self.buf, self.view = bytearray(), memoryview(b"")  # (not kept by a traceback)
            raise self.error


class LogWriter:
    """Writes one run's log by short crash-safe transactions (see the module docstring).

    Parameters
    ----------
    path
        The HDF5 run file. Created by :meth:`start`; its folder is created if needed.
        A symbolic link is followed: the log is written where it points.

    Notes
    -----
    Trials go to their own files in :func:`shard_folder`, linked from the run
    file; :meth:`set_status` with a final status packs them into it. Only the
    process holding the log's lock (:func:`lock_log`) replaces the published
    file, and only by a complete, closed one. A file is built in memory, or
    streamed through a :class:`_ScratchFile` that never reports a failure to HDF5;
    either way its bytes reach the disk only through :func:`write_bytes`, so a full
    disk is one :class:`InputError` that names the folder and the space needed.
    """

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.given = str(path)
        self.path = real_path(path)
        self.shards = shard_folder(self.path)
        self.part = self.path.with_name(self.path.name + ".part")  # the last scratch file used
        self._doing = "run"
        self._replacing = False  # (creating a new run's file beside an existing log)

    @property
    def key(self) -> str:
        """Where the log's path came from (as its lock was taken: ``--out``, ``--resume``)."""
        held = _held.get(str(self.path))
        return held[2] if held else "--out"

    @property
    def _pending(self) -> Path | None:
        """The new run's scratch run file while it has not yet replaced the existing log."""
        return _staged.get(str(self.path))

    def _mkstemp(self, folder: Path | None = None) -> tuple[int, Path]:
        """A new, empty scratch file in ``folder`` (default: beside the log; unique name,
        never a symlink), open."""
        lock_log(self.path)
        prefix = self.path.name if folder is None else ""
        fd, name = tempfile.mkstemp(prefix=prefix + ".", suffix=".part",
                                    dir=folder or self.path.parent)
        self.part = Path(name)
        return fd, self.part

    def _scratch(self, folder: Path | None = None) -> Path:
        """A new, empty scratch file in ``folder`` (default: beside the log), closed."""
        fd, path = self._mkstemp(folder)
        os.close(fd)
        return path

    @contextmanager
    def _file(self, dest: Path | None, source: Path | None = None,
              folder: Path | None = None, *, stream: bool = False) -> Iterator[h5py.File]:
        """An HDF5 file to write: new, or a copy of ``source`` to change. When the block
        ends it is closed, written to a new scratch file in ``folder`` (default: beside
        the log) and renamed over ``dest`` (left as :attr:`part` if ``dest`` is None); if
        anything failed (a full disk) the scratch file is removed instead.

        A small file (``source`` of at most :data:`_SMALL` bytes, unless ``stream``) is
        built in memory and written in one piece; any other streams into the scratch
        file through a :class:`_ScratchFile` (the first failed write raised once HDF5 has
        closed the file). Either way its bytes reach the disk only through
        :func:`write_bytes`, and HDF5 never sees a failed write."""
        fd, tmp = self._mkstemp(folder)
        try:
            self._want = source.stat().st_size if source else 0
            box = _ScratchFile(fd, source) if stream or self._want > _SMALL else None
            f = _h5file(tmp, box, new=source is None) if box else \
                _memory_file(tmp, source.read_bytes() if source else None)
            try:
                yield f
                image = b"" if box else _image(f)
            finally:
                f.close()
            if box is None:
                self._want = len(image)
                write_bytes(os.dup(fd), image)
            else:
                self._want = box.size
                box.done()
            if dest is not None:
                os.replace(tmp, dest)
        except BaseException:
            tmp.unlink(missing_ok=True)
            box = None  # (its memory not kept by the traceback)
            raise
        finally:
            os.close(fd)

    def remove_stale(self) -> None:
        """Remove what a killed writer left (call holding the lock): scratch files, and
        trial files the published log does not link (written, but never committed)."""
        lock_log(self.path)
        mine = re.compile(re.escape(self.path.name) + r"(\.[a-z0-9_]{8})?\.part")
        staged = self._pending
        for name in glob.glob(glob.escape(str(self.path)) + "*.part"):
            if mine.fullmatch(Path(name).name) and Path(name) != staged:
                Path(name).unlink(missing_ok=True)
        self._clear_shards(keep=self._linked())

    def _linked(self) -> set[str]:
        """Names of the trial files the published log links (empty if it cannot be read)."""
        try:
            with h5py.File(self.path, "r") as f:
                trials = f.get("trials")
                links = [trials.get(n, getlink=True) for n in trials] \
                    if isinstance(trials, h5py.Group) else []
        except (OSError, ValueError, KeyError):
            return set()
        return {Path(lk.filename).name for lk in links if isinstance(lk, h5py.ExternalLink)}

    def _clear_shards(self, keep: set[str] | frozenset[str] = frozenset()) -> None:
        """Remove the shard folder's trial and scratch files not in ``keep``; the folder too
        if that empties it (nothing else in it is touched)."""
        if self.shards.is_symlink() or not self.shards.is_dir():
            return
        for p in self.shards.iterdir():
            if (p.name.endswith(".part") or SHARD_NAME.fullmatch(p.name)) and p.name not in keep:
                p.unlink(missing_ok=True)
        with suppress(OSError):
            self.shards.rmdir()

    @contextmanager
    def _transaction(self) -> Iterator[None]:
        """Signals wait for the block's end; an OSError becomes a one-line InputError."""
        with deferred_interrupt():  # a Ctrl-C lands between transactions, never inside one
            try:
                yield
            except OSError as exc:
                raise self._write_error(exc) from None

    @contextmanager
    def _open(self, *, publish: bool = False, stream: bool = False) -> Iterator[h5py.File]:
        """The run file, a copy open for changes; published atomically on success
        (:meth:`_file`; ``stream``: it will grow large, the trials packed into it).

        A run replacing an existing log changes its scratch run file instead, until
        ``publish``: then the changed file replaces the log (the run has a trial of its
        own, or ended complete)."""
        with self._transaction():
            staged = self._pending
            with self._file(self.path if staged is None or publish else staged,
                            staged or self.path, stream=stream) as f:
                yield f
            if staged is not None and publish:
                _staged.pop(str(self.path), None)
                staged.unlink(missing_ok=True)

    def start(self, info: RunInfo, *, resume: bool = False) -> None:
        """Create the file with the run's attributes (``status = "running"``).

        Takes the log's lock first (:func:`lock_log`). With ``resume=True``
        the existing log is kept (what a killed writer left is removed,
        :meth:`remove_stale`) and only its status is set to ``running``.

        A file already at the path (a complete log, say) is not replaced yet: the
        new run's file is kept beside it (a scratch file) and replaces it only with
        the run's first trial (:meth:`trials`), or when the run ends complete
        without trials; a run that fails or is interrupted before leaves it as it
        was. An unfinished log there (its trials in ``LOG.trials``) is first packed
        into one file, so that it stays whole until then.
        """
        self.remove_stale()
        if resume:
            self.set_status("running")
            return
        if self.path.exists() and not self.path.is_file():
            why = os.strerror(errno.EISDIR) if self.path.is_dir() else "not a regular file"
            raise InputError(f"cannot create the log: {why}", file=self.given, key=self.key)
        if self.path.exists() and self._linked():
            self.pack()  # (the new run's trial files go where the old log's are)
        with self._transaction():
            self._create(info, replacing=self.path.exists())
        self._clear_shards()

    def _create(self, info: RunInfo, *, replacing: bool) -> None:
        """Write the new log's root attributes and publish them (beside an existing file,
        ``replacing`` it later)."""
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._replacing = replacing
        with self._file(None if replacing else self.path) as f:
            ex = info.extra
            f.attrs.update({
                "schema": SCHEMA, "schema_version": SCHEMA_VERSION, "status": "running",
                "name": info.name, "created": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
                "config": info.config_text, "config_hash": info.config_hash,
                "seed": info.seed, "n_trials": info.n_trials, "iterations": info.iterations,
                "source": str(ex.get("source", "")),
                "versions": json.dumps(ex.get("versions", {})),
                "plugins": json.dumps(info.plugins), "worlds": json.dumps(info.worlds),
                **({"evaluation": json.dumps(ex["evaluation"])} if ex.get("evaluation")
                   else {}),
                **({"sensor": json.dumps(ex["sensor"])} if ex.get("sensor") else {}),
                "inputs": json.dumps(ex.get("inputs", {})),
                **({"code_hash": str(ex["code_hash"])} if ex.get("code_hash") else {})})
            f.create_group("trials")
        if not replacing:
            return
        old = _staged.pop(str(self.path), None)
        if old is not None:
            old.unlink(missing_ok=True)
        _staged[str(self.path)] = self.part
        self._replacing = False

    def _write_error(self, exc: OSError) -> InputError:
        """The one line for a write that failed: a full disk names the folder, what is free
        and what the log needs; anything else says why."""
        if exc.errno not in _FULL:
            what = "create" if not self.path.exists() else "write"
            return InputError(f"cannot {what} the log ({exc.strerror or exc}); the log keeps its "
                              "last complete transaction", file=self.given, key=self.key)
        folder = self.path.parent
        want = getattr(self, "_want", 0)
        trials, total = self._space_needed(want)
        need = f"this write needs {human_size(want)}" if want else "it needs more space"
        if total > want:
            need += f" and finishing the run about {human_size(total)}"
        replacing = self._pending is not None or self._replacing
        if replacing or not self.path.exists() or not trials:
            kept = ("the existing log there is kept as it was" if replacing
                    else "nothing was written" if not self.path.exists()
                    else "the log holds no finished trial yet")
            how = "make space there and run the command again"
        else:
            kept = f"the log keeps its {trials} finished trial{'s' * (trials != 1)}"
            here = self.path.name + (f" and its folder {self.shards.name}"
                                     if self.shards.is_dir() else "")
            how = (f"make space there, or move {here} to a disk with space, then run "
                   + (f"`sitframe pack {self.given}`" if self._doing == "pack" else
                      f"`sitframe run --resume {self.given}`"))
        free = _free(folder)
        return DiskFullError(f"the disk is full: {folder} has {human_size(free)} free; "
                             f"{need}; {kept}: {how}", file=self.given, folder=str(folder),
                             free=free)

    def _space_needed(self, want: int) -> tuple[int, int]:
        """(trials in the log, bytes the rest of the run needs on its disk): the trials
        still to come at the mean size of those written, and the packed log at the end
        (written while the trial files still exist); at least ``want``, the write that
        failed (all that is known while the log holds no trial)."""
        if self._pending is not None or self._replacing:
            return 0, want
        try:
            with h5py.File(self.path, "r") as f:
                n_total = int(f.attrs.get("n_trials", 0))
                trials = f.get("trials")
                names = list(trials) if isinstance(trials, h5py.Group) else []
        except (OSError, ValueError, TypeError):
            return 0, want
        if not names:
            return 0, want
        sizes = [p.stat().st_size for p in self.shards.glob("*.h5") if p.is_file()] \
            if self.shards.is_dir() else []
        run = self.path.stat().st_size
        mean = sum(sizes) / len(sizes) if sizes else run / len(names)
        to_come = max(n_total - len(names), 0)
        packed = run + (len(sizes) + to_come) * mean  # (packed trials are in the run file)
        return len(names), int(max(want, to_come * mean + packed))

    def release(self) -> None:
        """Stop being the log's writer (:func:`unlock_log`)."""
        unlock_log(self.path)

    def stage(self, stage: str, data: dict[str, Any]) -> None:
        """Write a stage's data under ``/<stage>`` (replacing an earlier one)."""
        with self._open() as f:
            if stage in f:
                del f[stage]
            g = f.create_group(stage)
            for k, v in data.items():
                _write_value(g, k, v)

    def trial(self, trial: TrialResult, behaviour_labels: list[str] | None = None) -> None:
        """Write a finished trial and add its row to the root summary table."""
        self.trials([trial], behaviour_labels)

    def trials(self, trials: list[TrialResult], behaviour_labels: list[str] | None = None) -> None:
        """Write several finished trials: one file each, linked in one transaction (which
        also replaces the log a new run replaces: the run now has trials of its own)."""
        if not trials:
            return
        written: list[Path] = []
        with self._transaction():
            try:
                rows = []
                for trial in trials:
                    shard, row = self._write_shard(trial, behaviour_labels)
                    written.append(shard)
                    rows.append(row)
                with self._open(publish=True) as f:
                    links = f.require_group("trials")
                    for row, shard in zip(rows, written, strict=True):
                        name = f"{row['trial']:04d}"
                        if links.get(name, getlink=True) is not None:
                            del links[name]
                        links[name] = h5py.ExternalLink(f"{self.shards.name}/{shard.name}", "/")
                    _add_summary_rows(f, rows, self.path)
            except BaseException:
                linked = self._linked()  # a trial file the published log links stays
                for p in written:
                    if p.name not in linked:
                        p.unlink(missing_ok=True)
                raise

    def _write_shard(self, trial: TrialResult, behaviour_labels: list[str] | None
                     ) -> tuple[Path, dict[str, Any]]:
        """Write one trial to its own file (published by a rename); return the file and the
        trial's row of the summary table."""
        if self.shards.is_symlink():
            raise InputError(f"'{self.shards.name}' beside the log is a symlink; refusing to "
                             "write the log's trials through it", file=self.given,
                             key=self.key)
        self.shards.mkdir(exist_ok=True)
        shard = self.shards / f"{trial.index:04d}.h5"
        big = _nbytes([trial.arrays, trial.behaviours, trial.episodes, trial.plugin_data,
                       trial.situations]) > _SMALL
        with self._file(shard, folder=self.shards, stream=big) as f:
            _write_trial(f, trial, behaviour_labels)
            row = _summary_row(f)
        return shard, row

    def set_status(self, status: str, failure: str | None = None) -> None:
        """Set the root ``status`` (and ``failure``, the one-line reason a run failed).

        Any status but ``running`` ends the run: the trial files are packed
        into the run file in the same transaction (:meth:`pack`). A new run that
        ends ``failed`` or ``aborted`` before it replaced an existing log (no trial
        of its own) leaves that log as it was.
        """
        if self._pending is not None and status in ("failed", "aborted"):
            self._pending.unlink(missing_ok=True)
            _staged.pop(str(self.path), None)
            self._clear_shards(keep=self._linked())
            return
        self._commit(status, failure, pack=status != "running")

    def pack(self) -> None:
        """Copy every linked trial file into the run file (one transaction), then remove
        the trial files: the log becomes one self-contained HDF5 file."""
        self._doing = "pack"
        try:
            self._commit(None, None, pack=True)
        finally:
            self._doing = "run"

    def _commit(self, status: str | None, failure: str | None, *, pack: bool) -> None:
        packed: list[Path] = []
        with self._open(publish=pack, stream=pack) as f:
            if status is not None:
                f.attrs["status"] = status
            if failure:
                f.attrs["failure"] = failure
            if pack:
                packed = _pack_trials(f, str(self.path))
        for p in packed:
            p.unlink(missing_ok=True)
        for folder in {p.parent for p in packed} - {self.shards}:  # (a renamed log's)
            with suppress(OSError):
                folder.rmdir()
        if self.shards.is_dir():
            self._clear_shards(keep=self._linked())


def _pack_trials(f: h5py.File, path: str) -> list[Path]:
    """Replace every external trial link of ``f`` by a copy of the trial file's contents;
    return the files copied."""
    trials = f.get("trials")
    if not isinstance(trials, h5py.Group):
        return []
    done = []
    for name in list(trials):
        link = trials.get(name, getlink=True)
        if not isinstance(link, h5py.ExternalLink):
            continue
        src = shard_file(path, name, link)
        del trials[name]
        with h5py.File(src, "r") as s:
            f.copy(s["/"], trials, name=name)
        done.append(src)
    return done


def _write_trial(g: h5py.Group, trial: TrialResult, behaviour_labels: list[str] | None) -> None:
    """Write one trial's attributes, arrays and groups into ``g``."""
    g.attrs["index"] = trial.index
    g.attrs["seed"] = np.uint64(trial.seed)
    g.attrs["world"] = trial.world
    groups = {"summary": {k.replace("/", "."): v for k, v in trial.summary.items()},
              **trial.arrays, "behaviours": {lb: dict(d) for lb, d in trial.behaviours.items()}}
    for label, pol in trial.policies.items():
        box = groups["behaviours"].setdefault(label, {})
        for out, o in pol.outputs.items():
            box[f"policy/{out}"] = np.asarray(o.rules).astype(np.int16)
            box[f"actions/{out}"], box[f"units/{out}"] = o.actions, o.unit
            if o.q is not None:
                box[f"q/{out}"] = np.asarray(o.q, dtype=np.float64)
    groups |= {"episodes": trial.episodes, "plugins": trial.plugin_data,
               "situations": trial.situations}
    for k, v in groups.items():
        if not isinstance(v, dict) or v:  # (no empty groups)
            _write_value(g, k, v)
    if behaviour_labels:
        g["weights"].attrs["columns"] = json.dumps(behaviour_labels)


def _summary_row(g: h5py.Group) -> dict[str, Any]:
    """A trial group's row of the summary table: its index and numeric summary attributes
    (booleans included; in HDF5's attribute order, by name)."""
    row = {"trial": int(g.attrs["index"])}
    s = g["summary"].attrs if "summary" in g else {}
    for k in s:
        v = s[k]
        if isinstance(v, bool | int | float | np.integer | np.floating | np.bool_):
            row[k] = v
    return row


def _summary_table(cols: list[str], rows: list[dict[str, Any]]) -> np.ndarray:
    table = np.zeros(len(rows), dtype=[("trial", "i4")] + [(c, "f8") for c in cols[1:]])
    for i, row in enumerate(rows):
        table[i]["trial"] = row["trial"]
        for c in cols[1:]:
            table[i][c] = float(row.get(c, np.nan))
    return table


def _add_summary_rows(f: h5py.File, rows: list[dict[str, Any]], path: Path) -> None:
    """Append the rows of trials just linked to the root summary table.

    The table is what :func:`_write_summary` builds from every trial (rows in
    trial order, columns in order of first appearance), kept up to date by
    appending; only a trial that goes before a logged one or brings a new
    column (rare: a resumed gap, a plugin adding a summary key) rebuilds it
    (from the trials of the log at ``path``).
    """
    ds = f.get("summary")
    index = [r["trial"] for r in rows]
    if isinstance(ds, h5py.Dataset) and ds.maxshape == (None,) and ds.dtype.names:
        cols = list(ds.dtype.names)
        n = len(ds)
        last = int(ds[n - 1]["trial"]) if n else -1
        if index == sorted(set(index)) and index[0] > last and \
                all(set(r) <= set(cols) for r in rows):
            ds.resize((n + len(rows),))
            ds[n:] = _summary_table(cols, rows)
            return
    _write_summary(f, path)


def _write_summary(f: h5py.File, path: str | os.PathLike[str] | None = None) -> None:
    """(Re)build the root summary table from every trial's summary attributes.

    A trial in its own file is read from that file, opened by name (:func:`shard_file`
    beside the log at ``path``, default ``f``'s own name), never through the external
    link: HDF5 would open the link's target with ``f``'s file driver, which for the
    writer's file is its :class:`_ScratchFile`, the run file itself."""
    trials = f["trials"]
    rows = []
    for name in sorted(trials):
        link = trials.get(name, getlink=True)
        if not isinstance(link, h5py.ExternalLink):
            rows.append(_summary_row(trials[name]))
            continue
        with h5py.File(shard_file(str(path or f.filename), name, link), "r") as t:
            rows.append(_summary_row(t))
    keys = dict.fromkeys(k for row in rows for k in row)
    table = _summary_table(list(keys), rows)
    if "summary" in f:
        del f["summary"]
    ds = f.create_dataset("summary", data=table, chunks=True, maxshape=(None,),
                          fletcher32=True)
    ds.attrs["description"] = "one row per finished trial; booleans as 0/1, missing as NaN"


def code_fingerprint(plugins: list[dict[str, Any]] | None = None) -> str:
    """SHA-256 over the source of sitframe, its built-in plugins and loose plugin files.

    Written to the log (root attribute ``code_hash``) so that ``--resume`` can
    tell when the code changed since the run started (the resumed trials
    might then differ from the logged ones). Third-party plugin packages are
    covered by their distribution name and version in the ``plugins`` list.
    """
    h = hashlib.sha256()
    files: list[Path] = []
    for pkg in ("sitframe", "sitframe.plugins"):
        # (the package's own folder: in a source checkout sitframe's __path__ also holds
        # the checkout's root, which would hash every file below it, a venv's too)
        spec = importlib.util.find_spec(pkg)
        if spec is not None and spec.origin:
            files += sorted(Path(spec.origin).parent.rglob("*.py"))
    for info in plugins or []:
        if info.get("file"):
            files.append(Path(info["file"]))
        h.update(f"{info.get('name')}={info.get('distribution')}={info.get('version')};".encode())
    for f in files:
        try:
            h.update(f.read_bytes())
        except OSError:
            h.update(str(f).encode())
    return h.hexdigest()
