"""Writing a log: :class:`LogWriter`, the one-writer lock, and the code fingerprint.

Every write is one short crash-safe transaction that publishes a complete, closed file by an
atomic rename; a finished trial goes to its own file until the run ends and packs them. The
layout and the reasons are in :mod:`sitframe.logs.layout`.
"""

from __future__ import annotations

import errno
import fcntl
import glob
import hashlib
import importlib.util
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

from sitframe.contract.records import (
    RunInfo,
    TrialResult,
)
from sitframe.errors import InputError
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


def _write_value(group: h5py.Group, name: str, value: Any) -> None:
    """Write a scalar as an attribute, an array as a (compressed) dataset."""
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
    ds = group.create_dataset(name, data=arr, **kw)
    if name in UNITS:
        ds.attrs["units"] = UNITS[name]


#: Logs this process is the writer of: resolved log path -> (fd of its flocked
#: ``LOG.lock``, lock file path).
_held: dict[str, tuple[int, Path]] = {}


def lock_log(path: str | os.PathLike[str], key: str = "--out") -> None:
    """Become the only writer of the log at ``path`` (no-op if this process already is).

    Takes an exclusive, non-blocking :func:`fcntl.flock` on ``LOG.lock``
    (opened with ``O_NOFOLLOW``: a symlink planted there is refused), held
    until :func:`unlock_log` or the end of the process (the OS releases it
    when the process dies, even by SIGKILL).

    Raises
    ------
    InputError
        Another process holds the lock, or the lock file cannot be created.
    """
    real = os.path.realpath(path)
    if real in _held:
        return
    lock = Path(str(path) + ".lock")
    while True:
        try:
            lock.parent.mkdir(parents=True, exist_ok=True)
            fd = os.open(lock, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW, 0o644)
        except OSError as exc:
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
            _held[real] = (fd, lock)
            return
        os.close(fd)


def unlock_log(path: str | os.PathLike[str] | None = None) -> None:
    """Stop being the writer of the log at ``path`` (every log if ``path`` is None)."""
    keys = list(_held) if path is None else [os.path.realpath(path)]
    for key in keys:
        entry = _held.pop(key, None)
        if entry is not None:
            fd, lock = entry
            lock.unlink(missing_ok=True)  # while still held, so no one else holds this file
            os.close(fd)


def _write_error(exc: OSError, path: Path) -> InputError:
    why = "no space left on device" if exc.errno == errno.ENOSPC else (exc.strerror or str(exc))
    return InputError(f"cannot write the log ({why}); the log keeps its last complete "
                      "transaction", file=str(path), key="--out")


class LogWriter:
    """Writes one run's log by short crash-safe transactions (see the module docstring).

    Parameters
    ----------
    path
        The HDF5 run file. Created by :meth:`start`; its folder is created if needed.

    Notes
    -----
    Trials go to their own files in :func:`shard_folder`, linked from the run
    file; :meth:`set_status` with a final status packs them into it. Only the
    process holding the log's lock (:func:`lock_log`) replaces the published
    file, and only by a complete, closed one.
    """

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.path = Path(path)
        self.shards = shard_folder(self.path)
        self.part = self.path.with_name(self.path.name + ".part")  # the last scratch file used

    def _scratch(self, folder: Path | None = None) -> Path:
        """A new, empty scratch file in ``folder`` (default: beside the log; unique name,
        never a symlink)."""
        lock_log(self.path)
        prefix = self.path.name if folder is None else ""
        fd, name = tempfile.mkstemp(prefix=prefix + ".", suffix=".part",
                                    dir=folder or self.path.parent)
        os.close(fd)
        self.part = Path(name)
        return self.part

    def remove_stale(self) -> None:
        """Remove what a killed writer left (call holding the lock): scratch files, and
        trial files the published log does not link (written, but never committed)."""
        lock_log(self.path)
        mine = re.compile(re.escape(self.path.name) + r"(\.[a-z0-9_]{8})?\.part")
        for name in glob.glob(glob.escape(str(self.path)) + "*.part"):
            if mine.fullmatch(Path(name).name):
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
                raise _write_error(exc, self.path) from None

    @contextmanager
    def _open(self) -> Iterator[h5py.File]:
        """Copy the run file, open the copy for appending, publish it atomically on success."""
        with self._transaction():
            tmp: Path | None = None
            try:
                tmp = self._scratch()
                shutil.copyfile(self.path, tmp)
                with h5py.File(tmp, "a") as f:
                    yield f
                    f.flush()
                os.replace(tmp, self.path)
            except BaseException:
                if tmp is not None:
                    tmp.unlink(missing_ok=True)
                raise

    def start(self, info: RunInfo, *, resume: bool = False) -> None:
        """Create the file with the run's attributes (``status = "running"``).

        Takes the log's lock first (:func:`lock_log`). With ``resume=True``
        the existing log is kept (what a killed writer left is removed,
        :meth:`remove_stale`) and only its status is set to ``running``.
        Otherwise the trial files of a log this one replaces are removed once
        the new log is published.
        """
        self.remove_stale()
        if not resume:
            with deferred_interrupt():
                self._create(info)
            self._clear_shards()
        else:
            self.set_status("running")

    def _create(self, info: RunInfo) -> None:
        """Write the new log's root attributes to a scratch file and publish it."""
        tmp: Path | None = None
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            tmp = self._scratch()
            with h5py.File(tmp, "w") as f:
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
            os.replace(tmp, self.path)
        except BaseException as exc:
            if tmp is not None:
                tmp.unlink(missing_ok=True)
            if isinstance(exc, OSError):
                raise InputError(f"cannot create the log: {exc.strerror or exc}",
                                 file=str(self.path), key="--out") from None
            raise

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
        """Write several finished trials: one file each, linked in one transaction."""
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
                with self._open() as f:
                    links = f.require_group("trials")
                    for row, shard in zip(rows, written, strict=True):
                        name = f"{row['trial']:04d}"
                        if links.get(name, getlink=True) is not None:
                            del links[name]
                        links[name] = h5py.ExternalLink(f"{self.shards.name}/{shard.name}", "/")
                    _add_summary_rows(f, rows)
            except BaseException:
                linked = self._linked()  # a trial file the published log links stays
                for p in written:
                    if p.name not in linked:
                        p.unlink(missing_ok=True)
                raise

    def _write_shard(self, trial: TrialResult, behaviour_labels: list[str] | None
                     ) -> tuple[Path, dict[str, Any]]:
        """Write one trial to its own file (scratch name, renamed when closed); return the
        file and the trial's row of the summary table."""
        if self.shards.is_symlink():
            raise InputError(f"'{self.shards.name}' beside the log is a symlink; refusing to "
                             "write the log's trials through it", file=str(self.path),
                             key="--out")
        self.shards.mkdir(exist_ok=True)
        tmp = self._scratch(self.shards)
        try:
            with h5py.File(tmp, "w") as f:
                _write_trial(f, trial, behaviour_labels)
                row = _summary_row(f)
            shard = self.shards / f"{trial.index:04d}.h5"
            os.replace(tmp, shard)
        except BaseException:
            tmp.unlink(missing_ok=True)
            raise
        return shard, row

    def set_status(self, status: str, failure: str | None = None) -> None:
        """Set the root ``status`` (and ``failure``, the one-line reason a run failed).

        Any status but ``running`` ends the run: the trial files are packed
        into the run file in the same transaction (:meth:`pack`).
        """
        self._commit(status, failure, pack=status != "running")

    def pack(self) -> None:
        """Copy every linked trial file into the run file (one transaction), then remove
        the trial files: the log becomes one self-contained HDF5 file."""
        self._commit(None, None, pack=True)

    def _commit(self, status: str | None, failure: str | None, *, pack: bool) -> None:
        packed: list[Path] = []
        with self._open() as f:
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


def _add_summary_rows(f: h5py.File, rows: list[dict[str, Any]]) -> None:
    """Append the rows of trials just linked to the root summary table.

    The table is what :func:`_write_summary` builds from every trial (rows in
    trial order, columns in order of first appearance), kept up to date by
    appending; only a trial that goes before a logged one or brings a new
    column (rare: a resumed gap, a plugin adding a summary key) rebuilds it.
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
    _write_summary(f)


def _write_summary(f: h5py.File) -> None:
    """(Re)build the root summary table from every trial's summary attributes."""
    trials = f["trials"]
    rows = [_summary_row(trials[name]) for name in sorted(trials)]
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
        spec = importlib.util.find_spec(pkg)
        for folder in (spec.submodule_search_locations or []) if spec else []:
            files += sorted(Path(folder).rglob("*.py"))
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
