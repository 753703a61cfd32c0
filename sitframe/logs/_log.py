"""HDF5 run logs: crash-safe writing and a reader API.

Layout (schema ``sitframe-log``, version :data:`SCHEMA_VERSION`)::

    /                     attrs: schema, schema_version, status (running|complete|
                          aborted|failed), name, created, config (TOML text),
                          config_hash, seed, source, versions (JSON), plugins
                          (JSON list), worlds (JSON name -> TOML text), sensor
                          (JSON: name, angles_deg, max_range, unit, dim),
                          failure (one line, when plugin code failed), inputs
                          (JSON: SHA-256 of what the run read from other logs,
                          e.g. ``policy_from/<label>``; ``run --resume`` refuses
                          when any of these, the worlds or the plugins changed),
                          evaluation (JSON: the evaluation protocol and its worlds,
                          e.g. {"protocol": "goal-episodes", "worlds": [...]};
                          absent in logs written before it was recorded)
    /collect/             samples (n, d) [m], poses (n, 3) [m, m, rad],
                          source (n,) world index; attrs worlds (JSON)
    /cluster/             trial_centers (T, c, d), trial_measures (T, k) with
                          attr columns, trial_n_iter, trial_converged,
                          attrs chosen, rule; optional sweep_c, sweep_measures
    /cluster/state/       the interpreter's fitted state (e.g. centers, m)
    /trials/NNNN/         one group per learning trial; attrs: index, seed,
                          world, every summary scalar; per-iteration datasets
                          pose (L+1, 3), reading (L, d) (beams: root attr
                          sensor; called sonar before contract v2), memberships (L, c),
                          command (L, 2) [deg, m/s], collision (L,),
                          contact (L, 2), nearest (L,), weights (L, k),
                          proposals/<label> (L, 2), reward/<label> (L,)
    /trials/NNNN/behaviours/<label>/   what the behaviour's trial_data() returned
                          (e.g. heading/q_snapshots (K, c, A),
                          heading/snapshot_iteration (K,)), and its learned
                          policy (LearnedPolicy), for every output:
                          policy/<out> (c,) action index per situation,
                          actions/<out> (A,) action values, units/<out> attr,
                          q/<out> (c, A) if the learner keeps Q; a learning
                          arbiter's under the label "arbiter"
    /trials/NNNN/episodes/...          evaluation / goal-episode arrays
    /trials/NNNN/plugins/<plugin>/...  per-trial data handed by a plugin's
                          components (trial_end) or observers
                          (sitframe_trial_data); an evaluation's under eval/<world>/
    /summary              structured table, one row per finished trial
                          (resizable: rows are appended as trials finish)

Every dataset has a ``units`` or ``description`` attribute where it helps,
and every dataset is stored with a Fletcher-32 checksum per chunk: damaged
data fails to read (an :class:`InputError` naming the log) instead of being
returned as wrong numbers; :meth:`Log.check` reads everything.

Crash safety and cost: an HDF5 file left open by a process that dies can
be unreadable, so the writer never holds a published file open. Each stage
and each finished trial is one short transaction, and a transaction only
ever publishes a complete, closed file by an atomic rename
(:func:`os.replace`) of a scratch file written beside it (``*.part``,
created with :func:`tempfile.mkstemp`, so a pre-existing file or symlink is
never written through):

* A finished trial is written to its own file, ``LOG.trials/NNNN.h5`` (the
  trial group's contents at the file's root), and then linked from the run
  file as ``/trials/NNNN`` by an HDF5 external link; its row is appended to
  ``/summary``. The run file (root attributes, stages, links, summary) is
  changed copy-on-write: copied to a scratch file, opened, changed, closed
  and renamed over the log. It holds no trial data, so a trial costs the
  same to write whether it is the first or the thousandth (see
  ``benchmarks/bench_log.py``).
* The run's end (any status but ``running``: ``complete``, ``aborted``,
  ``failed``) *packs* the log: one transaction copies every linked trial
  file into the run file and publishes it, then the trial files and the
  folder are removed. A finished log is one self-contained HDF5 file, laid
  out as above. ``sitframe pack LOG`` does the same for a log a killed run
  left (without resuming it).

A process killed at *any* moment (even inside a write) therefore leaves the
last published run file and the trial files it links (at most a stale
scratch file, or a trial file not yet linked, removed by the next writer of
the log), so a ``kill -9`` costs at most the trial in progress, the log
always opens, and ``status = "running"`` tells the reader it did not
complete. Until it is packed, such a log is the file *and* its
``LOG.trials`` folder: move or archive them together (or pack first). The
reader follows a trial's link only to ``<log>.trials/NNNN.h5`` beside the
log, for trial NNNN, and only if it is a regular file. A write that fails
(e.g. a full disk) removes its scratch files and leaves the published log
as it was. Readers never block the writer (it never opens a published file
for writing; a reader that opened the log just before packing published it
may find a trial file gone, and reading again sees the packed log). The
rename protects against process death, not against power loss (no fsync).

One log has one writer: the writing process holds an exclusive
:func:`fcntl.flock` on ``LOG.lock`` (beside the log) from its first
transaction to the end of the run (:func:`lock_log`). A second run, or a
``run --resume``, on the same log while it is held is refused with an
:class:`InputError`. The operating system releases the lock when the
process dies, so a killed writer never leaves it stuck.
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
import stat
import tempfile
import time
import tomllib
from collections.abc import Iterator
from contextlib import contextmanager, suppress
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from sitframe.contract.pluginmanager import Registry, get_plugin_manager
from sitframe.contract.records import (
    LearnedPolicy,
    PolicyOutput,
    RunInfo,
    SensorSpec,
    TrialResult,
)
from sitframe.errors import InputError
from sitframe.logs.interrupts import deferred_interrupt

#: Per-iteration sensor readings (``sonar`` in logs from before contract v2).
READING = "reading"
#: Groups of a trial that are not per-iteration arrays.
_TRIAL_GROUPS = ("summary", "behaviours", "episodes", "plugins", "situations")

SCHEMA = "sitframe-log"
SCHEMA_VERSION = 1

UNITS = {
    "pose": "x [m], y [m], theta [rad]; row L is the pose after the last iteration",
    "reading": "sensor reading [m] (range from the robot's rim for the built-in sensors), "
               "columns = the beams of attribute angles_deg",
    "memberships": "membership of each situation [0-1], rows sum to 1",
    "command": "heading change [deg, + = left], speed [m/s]",
    "collision": "true if the iteration ended in a collision",
    "contact": "contact point x, y [m] (NaN without collision)",
    "nearest": "smallest sensor range at the start of the iteration [m]",
    "weights": "arbiter weight of each behaviour (columns = behaviour labels)",
    "samples": "sensor readings [m]",
    "poses": "x [m], y [m], theta [rad]",
}

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


def shard_folder(path: str | os.PathLike[str]) -> Path:
    """The folder beside the log ``LOG`` holding its unpacked trial files (``LOG.trials``)."""
    return Path(str(path) + ".trials")


#: A trial file: ``NNNN.h5`` in the shard folder; a scratch file in it ends ``.part``.
_SHARD_NAME = re.compile(r"\d{4,}\.h5")
#: What the external link of an unpacked trial names: ``<log name>.trials/NNNN.h5``.
_SHARD_LINK = re.compile(r"([^/\\]+)\.trials/(\d{4,})\.h5")


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
            if (p.name.endswith(".part") or _SHARD_NAME.fullmatch(p.name)) and p.name not in keep:
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
        src = _shard_file(path, name, link)
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


# ---------------------------------------------------------------------------
# Reader
# ---------------------------------------------------------------------------


def _read_group(g: h5py.Group) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for k, v in g.attrs.items():
        out[k] = _attr(v)
    for k, item in g.items():
        if isinstance(item, h5py.Group):
            for kk, vv in _read_group(item).items():
                out[f"{k}/{kk}"] = vv
        else:
            out[k] = item[()]
    return out


def _attr(v: Any) -> Any:
    if isinstance(v, bytes):
        v = v.decode()
    if isinstance(v, np.generic):
        return v.item()
    return v


@dataclass
class TrialLog:
    """One trial read back from a log.

    Attributes
    ----------
    index, seed, world
        Trial number, 64-bit seed, world name.
    summary
        Summary scalars (``converged``, ``convergence_iteration``, ...).
    arrays
        Per-iteration arrays (see the module docstring for names and units).
    behaviours
        Behaviour label -> flattened dict of its logged data.
    episodes
        Evaluation / goal-episode arrays.
    plugins
        Plugin name -> flattened dict of the data it handed for the trial.
    situations
        With an evolving interpreter: flattened ``state/...``, ``events/...`` and
        ``count`` of the trial's situations (empty otherwise).
    """

    index: int
    seed: int
    world: str
    summary: dict[str, Any]
    arrays: dict[str, np.ndarray]
    behaviours: dict[str, dict[str, Any]]
    episodes: dict[str, Any] = field(default_factory=dict)
    plugins: dict[str, dict[str, Any]] = field(default_factory=dict)
    situations: dict[str, Any] = field(default_factory=dict)

    def situations_part(self, part: str) -> dict[str, Any]:
        """``"state"`` (the trial's final interpreter state) or ``"events"`` of
        :attr:`situations`, unflattened one level; empty for a fixed interpreter."""
        head = f"{part}/"
        return {k[len(head):]: v for k, v in self.situations.items() if k.startswith(head)}

    def policy(self, label: str) -> dict[str, np.ndarray]:
        """The learned rule bases (``output -> (c,) action indices``) of behaviour ``label``.

        Raises
        ------
        ValueError
            The trial has no behaviour ``label`` (the message lists those it has).
        """
        if label not in self.behaviours:
            raise ValueError(f"trial {self.index} has no behaviour '{label}'; it has: "
                             f"{', '.join(self.behaviours) or 'none'}")
        data = self.behaviours[label]
        return {k.split("/", 1)[1]: np.asarray(v) for k, v in data.items()
                if k.startswith("policy/")}

    def learned_policy(self, label: str) -> LearnedPolicy | None:
        """The :class:`LearnedPolicy` of behaviour ``label`` (``None`` if it learned none).

        Logs written before contract v2 kept the action values under
        ``singletons/<output>``; they are read the same way. A label the trial
        does not have is a ``ValueError`` (:meth:`policy`), not ``None``.
        """
        data = self.behaviours.get(label, {})
        outs = {}
        for out, rules in self.policy(label).items():
            actions = data.get(f"actions/{out}", data.get(f"singletons/{out}"))
            if actions is None:
                continue
            q = data.get(f"q/{out}", data.get(f"{out}/q"))
            unit = data.get(f"units/{out}", _OLD_UNITS.get(out, ""))
            try:
                outs[out] = PolicyOutput(np.asarray(actions), np.asarray(rules), str(unit),
                                         None if q is None else np.asarray(q))
            except (TypeError, ValueError) as exc:
                raise InputError(f"the logged policy of trial {self.index} is damaged: {exc}",
                                 key=f"trials/{self.index:04d}/behaviours/{label}/policy/{out}"
                                 ) from None
        return LearnedPolicy(outs) if outs else None

    @cached_property
    def policies(self) -> dict[str, LearnedPolicy]:
        """Label -> :class:`LearnedPolicy` of every behaviour that learned one."""
        out = {}
        for label in self.behaviours:
            pol = self.learned_policy(label)
            if pol is not None:
                out[label] = pol
        return out


#: Units of the built-in outputs in logs written before units were logged.
_OLD_UNITS = {"heading": "deg", "speed": "m/s"}


@dataclass
class Log:
    """A sitframe HDF5 log opened for reading (the file is not kept open).

    Use :func:`open_log`. Attributes mirror the root attributes; methods read
    stages and trials on demand.
    """

    path: str
    attrs: dict[str, Any]

    @property
    def status(self) -> str:
        return str(self.attrs.get("status", "unknown"))

    @property
    def complete(self) -> bool:
        return self.status == "complete"

    @property
    def learned(self) -> bool:
        """Whether the logged run had a ``learn`` stage (True when its config does not say)."""
        return "learn" in self.config.get("experiment", {}).get("stages", ["learn"])

    @property
    def config(self) -> dict[str, Any]:
        text = self.attrs.get("config")
        if not isinstance(text, str):
            raise InputError("the log has no config (expected the run's TOML in the root "
                             "attribute 'config')", file=self.path, key="config")
        try:
            return tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise InputError(f"the log's config is not valid TOML: {exc}", file=self.path,
                             key="config") from None

    def _json_attr(self, name: str, default: str, kind: type) -> Any:
        try:
            value = json.loads(self.attrs.get(name, default))
        except (TypeError, ValueError) as exc:
            raise InputError(f"root attribute is not valid JSON: {exc}", file=self.path,
                             key=name) from None
        if not isinstance(value, kind):
            raise InputError(f"root attribute should hold a JSON {kind.__name__}, got "
                             f"{type(value).__name__}", file=self.path, key=name)
        return value

    @property
    def worlds(self) -> dict[str, str]:
        return self._json_attr("worlds", "{}", dict)

    @property
    def plugins(self) -> list[dict[str, Any]]:
        return self._json_attr("plugins", "[]", list)

    @property
    def versions(self) -> dict[str, str]:
        return self._json_attr("versions", "{}", dict)

    @property
    def failure(self) -> str | None:
        """The one-line reason the run failed (plugin code), if it did."""
        v = self.attrs.get("failure")
        return str(v) if v else None

    @cached_property  # (read once: an old log's asks the plugin registry)
    def sensor(self) -> SensorSpec:
        """The run sensor's geometry (name, beam angles, max range).

        Logs written before the spec was logged: the spec of the sensor plugin
        the ``[sensor]`` table names, created with the table's parameters.
        """
        d = self._json_attr("sensor", "{}", dict) or self._sensor_from_config()
        try:
            return SensorSpec(str(d["name"]), np.asarray(d["angles_deg"], dtype=np.float64),
                              float(d["max_range"]), str(d.get("unit", "m")))
        except (KeyError, TypeError, ValueError) as exc:
            raise InputError(f"root attribute is not a sensor spec: {exc}", file=self.path,
                             key="sensor") from None

    def _sensor_from_config(self) -> dict[str, Any]:
        table = dict(self.config.get("sensor", {}))
        name = str(table.pop("component", "pioneer-sonar"))
        registry = Registry.collect(get_plugin_manager())
        sensor = registry.create("sensor", name, table, file=self.path, key="sensor")
        return {"name": name, "angles_deg": np.asarray(sensor.angles_deg).tolist(),
                "max_range": sensor.max_range}

    @contextmanager
    def _file(self) -> Iterator[h5py.File]:
        """Open the log read-only; a damaged file or a missing item becomes an InputError."""
        try:
            with deferred_interrupt(), h5py.File(self.path, "r") as f:
                yield f
        except InputError:
            raise
        except (OSError, KeyError, RuntimeError, ValueError, TypeError) as exc:
            msg = " ".join(str(exc.args[0] if exc.args else exc).split())
            raise InputError(f"cannot read the log (truncated or corrupted?): {msg}",
                             file=self.path) from None

    def check(self) -> None:
        """Read the whole log: every header, attribute and dataset, and the root JSON.

        Also checks the layout every reader relies on (:func:`_check_layout`).
        Raises an :class:`InputError` naming the log if any part is damaged, so
        a command can fail before it writes anything. Datasets carry Fletcher-32
        checksums (logs written since they were added), so damaged *data* is
        caught here too, not only damaged structure.
        """
        _ = self.worlds, self.plugins, self.versions
        def read(_name: str, obj: Any) -> None:  # (returning a value would stop the visit)
            dict(obj.attrs)
            if isinstance(obj, h5py.Dataset):
                obj[()]

        with self._file() as f:
            f.visititems(read)  # hard links only: the trials in their own files are read below
            _check_layout(f, self.path)
            for name in _trial_names(f, self.path):
                g = _trial_group(f, name, self.path)
                if g is not None and g.file != f:
                    dict(g.attrs)
                    g.visititems(read)

    def has(self, group: str) -> bool:
        with self._file() as f:
            return group in f

    def trial_indices(self) -> list[int]:
        with self._file() as f:
            out = []
            for name in _trial_names(f, self.path):
                link = f["trials"].get(name, getlink=True)
                if isinstance(link, h5py.ExternalLink):  # checked: NNNN.h5 for trial NNNN
                    _shard_file(self.path, name, link)
                    out.append(int(name))
                else:
                    out.append(int(f["trials"][name].attrs["index"]))
            return sorted(out)

    def stage(self, name: str) -> dict[str, Any]:
        """Flattened dict of a stage group (``collect`` or ``cluster``)."""
        with self._file() as f:
            if name not in f:
                raise InputError(f"the log has no '{name}' stage (status: {self.status})",
                                 file=self.path, key=name)
            return _read_group(f[name])

    def interpreter_state(self) -> dict[str, Any]:
        """The fitted interpreter state written by the cluster stage."""
        with self._file() as f:
            if "cluster/state" not in f:
                raise InputError("the log has no fitted situations (no /cluster/state); "
                                 "was the cluster stage run?", file=self.path, key="cluster")
            return _read_group(f["cluster/state"])

    def trial(self, index: int) -> TrialLog:
        """Read trial ``index`` (an InputError lists the trials present if it is missing)."""
        with self._file() as f:
            _trial_names(f, self.path)
            g = _trial_group(f, f"{index:04d}", self.path)
            if g is None:
                have = self.trial_indices()
                raise InputError(f"the log has no trial {index}; it has "
                                 f"{have if have else 'no finished trials'}",
                                 file=self.path, key="trials")
            arrays = {}
            for k, item in g.items():
                if k in _TRIAL_GROUPS:
                    continue
                if isinstance(item, h5py.Group):
                    arrays.update({f"{k}/{kk}": v for kk, v in _read_group(item).items()
                                   if isinstance(v, np.ndarray)})
                else:
                    arrays[k] = item[()]
            if READING not in arrays and "sonar" in arrays:  # a log from before contract v2
                arrays[READING] = arrays["sonar"]
            if READING in arrays:  # the name the README showed before contract v2
                arrays.setdefault("sonar", arrays[READING])
            behaviours = ({lb: _read_group(bg) for lb, bg in g["behaviours"].items()}
                          if "behaviours" in g else {})
            episodes = _read_group(g["episodes"]) if "episodes" in g else {}
            plugins = ({p: _read_group(pg) for p, pg in g["plugins"].items()}
                       if "plugins" in g else {})
            summary = dict(_read_group(g["summary"])) if "summary" in g else {}
            summary = {k.replace(".", "/"): v for k, v in summary.items()}
            situations = _read_group(g["situations"]) if "situations" in g else {}
            return TrialLog(int(g.attrs["index"]), int(g.attrs["seed"]), str(g.attrs["world"]),
                            summary, arrays, behaviours, episodes, plugins, situations)

    def summary(self) -> np.ndarray:
        """The root summary table (structured array, one row per finished trial)."""
        with self._file() as f:
            if "summary" not in f:
                return np.zeros(0, dtype=[("trial", "i4")])
            return f["summary"][()]

    def summary_frame(self) -> Any:
        """The summary table as a pandas DataFrame (needs pandas; see
        :func:`sitframe.logs.frames.summary_frame`)."""
        from sitframe.logs.frames import summary_frame  # pandas is optional: loaded on use

        return summary_frame(self)

    def iterations_frame(self, trials: list[int] | None = None) -> Any:
        """Per-iteration arrays of the learning trials as one pandas DataFrame (needs pandas;
        see :func:`sitframe.logs.frames.iterations_frame`)."""
        from sitframe.logs.frames import iterations_frame  # pandas is optional: loaded on use

        return iterations_frame(self, trials)


def _trial_names(f: h5py.File, path: str) -> list[str]:
    """The names in ``/trials`` (none if absent; an InputError if it is not a group)."""
    trials = f.get("trials")
    if trials is None:
        return []
    if not isinstance(trials, h5py.Group):
        raise InputError("expected a group of trial groups, got a dataset", file=path,
                         key="trials")
    return list(trials)


def _trial_group(f: h5py.File, name: str, path: str) -> h5py.Group | h5py.Dataset | None:
    """``/trials/<name>`` (None if absent), following its link only if it is a trial file of
    the log (:func:`_shard_file`): a log never makes the reader open another file."""
    trials = f["trials"]
    link = trials.get(name, getlink=True)
    if link is None:
        return None
    if isinstance(link, h5py.SoftLink):
        raise InputError(f"is a soft link to '{link.path}'; expected a trial group",
                         file=path, key=f"trials/{name}")
    if isinstance(link, h5py.ExternalLink):
        _shard_file(path, name, link)
    return trials[name]


def _shard_file(path: str, name: str, link: h5py.ExternalLink) -> Path:
    """The trial file an unpacked trial links to, checked: ``LOG.trials/NNNN.h5`` beside
    the log for trial NNNN, an existing regular file, linked at its root."""
    m = _SHARD_LINK.fullmatch(link.filename)
    if m is None or link.path != "/" or not name.isdigit() or int(m.group(2)) != int(name):
        raise InputError(f"links to '{link.filename}:{link.path}'; expected the trial's own "
                         f"file <log>.trials/{name}.h5 beside the log", file=path,
                         key=f"trials/{name}")
    target = Path(path).parent / link.filename
    try:
        mode = os.stat(target, follow_symlinks=False).st_mode
    except OSError:
        raise InputError(f"trial {int(name)} is in '{link.filename}', which is missing: a log "
                         f"still being written (or killed) is its .h5 file and the folder "
                         f"'{m.group(1)}.trials' beside it; move them together, or pack the log "
                         "into one file first (sitframe pack LOG)", file=path,
                         key=f"trials/{name}") from None
    if not stat.S_ISREG(mode):
        raise InputError(f"'{link.filename}' is not a regular file (expected the trial's own "
                         "HDF5 file)", file=path, key=f"trials/{name}")
    return target


def _check_layout(f: h5py.File, path: str) -> None:
    """The parts of the layout that readers index with, checked so that a valid HDF5 file
    with damaged contents is one clear :class:`InputError` (naming the item), not a wrong
    figure or a traceback: ``/trials`` holds trial groups, fitted centres are a finite
    (c, d) array matching the trials' memberships (c) and readings (d), and every learned
    policy indexes an existing action."""
    def fail(key: str, what: str) -> None:
        raise InputError(what, file=path, key=key)

    trials = f.get("trials")
    if trials is not None and not isinstance(trials, h5py.Group):
        fail("trials", "expected a group of trial groups, got a dataset")
    centers = f.get("cluster/state/centers")
    shape = None
    if centers is not None:
        c = np.asarray(centers[()])
        if c.ndim != 2 or c.dtype.kind not in "fiu" or not np.isfinite(c).all():
            fail("cluster/state/centers", f"expected a finite (c, d) array of centres, got "
                 f"shape {c.shape}, dtype {c.dtype}")
        shape = c.shape
        capacity = f["cluster/state"].attrs.get("capacity")  # evolving situations: id slots
        if capacity is not None:
            shape = (int(capacity), shape[1])
    for name in _trial_names(f, path):
        _check_trial_layout(f, name, shape, path)


def _check_trial_layout(f: h5py.File, name: str, shape: tuple[int, int] | None,
                        path: str) -> None:
    """One trial of :func:`_check_layout`: its group, the shapes of its readings and
    memberships against the centres' ``shape``, and its policies' action indices."""
    def fail(key: str, what: str) -> None:
        raise InputError(what, file=path, key=key)

    g = _trial_group(f, name, path)
    if not isinstance(g, h5py.Group):
        fail(f"trials/{name}", "expected a trial group, got a dataset")
    if g.file != f and g.attrs.get("index") != int(name):
        fail(f"trials/{name}", f"its file holds trial {_attr(g.attrs.get('index'))!r}, expected "
             f"{int(name)}")
    for ds, axis in (("memberships", 0), (READING, 1), ("sonar", 1)):
        if shape is not None and isinstance(g.get(ds), h5py.Dataset) and \
                g[ds].shape[1:] != (shape[axis],):
            fail(f"trials/{name}/{ds}", f"has shape {g[ds].shape}, which does not fit the "
                 f"fitted centres' shape {shape}")
    for label, bg in (g["behaviours"].items() if isinstance(g.get("behaviours"), h5py.Group)
                      else ()):
        policy = bg.get("policy")
        singles = bg.get("actions", bg.get("singletons"))  # (named singletons before v2)
        if not isinstance(policy, h5py.Group) or not isinstance(singles, h5py.Group):
            continue
        for out, ds in policy.items():
            if out not in singles:
                continue
            idx, n = np.asarray(ds[()]), len(singles[out])
            if idx.dtype.kind not in "iu" or (idx.size and not (0 <= idx.min() <= idx.max()
                                                                 < n)):
                fail(f"trials/{name}/behaviours/{label}/policy/{out}", f"expected action "
                     f"indices in 0..{n - 1}, got {idx.tolist()}")


def open_log(path: str | os.PathLike[str]) -> Log:
    """Open a sitframe log for reading.

    Raises
    ------
    InputError
        The file does not exist, is not HDF5, is not a sitframe log, or has a
        schema version this sitframe does not know.
    """
    p = str(path)
    if not os.path.exists(p):
        raise InputError("log file not found", file=p)
    if not h5py.is_hdf5(p):
        raise InputError("not an HDF5 file (expected a sitframe .h5 log)", file=p)
    try:
        with deferred_interrupt(), h5py.File(p, "r") as f:
            attrs = {k: _attr(v) for k, v in f.attrs.items()}
    except OSError as exc:
        raise InputError(f"cannot open HDF5 log (truncated or corrupted?): {exc}", file=p) from None
    if attrs.get("schema") != SCHEMA:
        raise InputError(f"not a sitframe log (root attribute schema is "
                         f"{attrs.get('schema')!r}, expected {SCHEMA!r})", file=p)
    version = attrs.get("schema_version")
    if not isinstance(version, int) or isinstance(version, bool) or version != SCHEMA_VERSION:
        raise InputError(f"unknown log schema version {version!r}; this sitframe reads version "
                         f"{SCHEMA_VERSION}", file=p, key="schema_version")
    return Log(p, attrs)


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
