"""The layout of a sitframe HDF5 log, and how it is kept crash-safe.

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
                          proposals/<label> (L, 2), reward/<label> (L,);
                          a trial over rooms (experiment.rooms) also room (L,),
                          each iteration's index into episodes/learn attr rooms
    /trials/NNNN/behaviours/<label>/   what the behaviour's trial_data() returned
                          (e.g. heading/q_snapshots (K, c, A),
                          heading/snapshot_iteration (K,)), and its learned
                          policy (LearnedPolicy), for every output:
                          policy/<out> (c,) action index per situation,
                          actions/<out> (A,) action values, units/<out> attr,
                          q/<out> (c, A) if the learner keeps Q; a learning
                          arbiter's under the label "arbiter"
    /trials/NNNN/episodes/...          evaluation / goal-episode arrays; a trial in
                          episodes: learn/first_iteration (E,) and, over rooms,
                          learn/room (E,) and attr learn/rooms (JSON names); a
                          trial of candidates: select/first_iteration, select/
                          collisions_per_1000, select/coverage, select/score (K,)
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

* A file reaches the disk only through one function
  (:func:`sitframe.logs.writer.write_bytes`, the writer's one boundary with
  the disk), and HDF5 itself never meets a failing write (it used to, and
  left its library state broken: the next call crashed the process,
  SIGSEGV, with the log still ``running``). A small file (a stage, the run
  file during the run, a trial of up to 16 MiB of arrays) is built in memory
  (HDF5's core driver) and written to the scratch file by one ordinary
  ``write``. A large one (a long trial's, the log being packed) is written
  by HDF5 straight into its scratch file, through a Python file object
  (h5py's ``fileobj`` driver) that gathers its writes into pieces of a few
  MiB and never reports a failure to HDF5: the first write that fails is
  recorded, the file as written so far is read back into memory and HDF5
  finishes it there; once HDF5 has closed the file the error is raised.
  Either way a full disk removes the scratch file, leaves the published log
  as it was and is one :class:`~sitframe.errors.DiskFullError` line naming
  the folder, what is free and what the log needs. Memory does not grow
  with a trial's length: a large file is never whole in memory (but on
  that failing path), and a trial's arrays kept in scratch files
  (:mod:`sitframe.scratch`) are handed to HDF5 a block of rows at a time.
* A finished trial is written to its own file, ``LOG.trials/NNNN.h5`` (the
  trial group's contents at the file's root), and then linked from the run
  file as ``/trials/NNNN`` by an HDF5 external link; its row is appended to
  ``/summary``. The run file (root attributes, stages, links, summary) is
  changed copy-on-write: read into memory (a large one: copied to the
  scratch file by plain I/O through the same boundary, so a full disk there
  fails before HDF5 opens the copy), changed, and written to a scratch file
  renamed over the log. It holds no trial data, so a trial costs the same to write
  whether it is the first or the thousandth (see
  ``benchmarks/logs/bench_log.py``).
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
as it was: every finished trial stays, and ``run --resume`` finishes the run
once there is space (in place, or after moving the log with its folder).
Readers never block the writer (it never opens a published file
for writing; a reader that opened the log just before packing published it
may find a trial file gone, and reading again sees the packed log). The
rename protects against process death, not against power loss (no fsync).

A new run whose ``--out`` holds a log already (complete, say) does not
replace it at once: its run file is a scratch file beside the log until the
transaction that links its first trial (or, without trials, the one that
marks it complete) publishes it over the old log. A run that fails, is
stopped or is killed before that leaves the old log as it was (a killed
one's scratch file is removed by the next writer). An unfinished old log
(trial files in ``LOG.trials``) is packed first, so that it stays whole
and the new run's trial files do not meet its own.

A log reached through a symbolic link is written where the link points: the
writer, its scratch and trial files and the lock work beside the real file
(:func:`~sitframe.logs.writer.real_path`), and readers follow a trial's link
beside it; the link itself is never replaced.

One log has one writer: the writing process holds an exclusive
:func:`fcntl.flock` on ``LOG.lock`` (beside the real log) from its first
transaction to the end of the run (:func:`lock_log`). A second run, or a
``run --resume``, on the same log while it is held is refused with an
:class:`InputError`. The operating system releases the lock when the
process dies, so a killed writer never leaves it stuck.

Writing: :mod:`sitframe.logs.writer` (:class:`~sitframe.logs.writer.LogWriter`, the
lock); reading: :mod:`sitframe.logs.reader` (:func:`~sitframe.logs.reader.open_log`).
"""

from __future__ import annotations

import os
import re
import stat
from pathlib import Path

import h5py

from sitframe.errors import InputError

#: Per-iteration sensor readings (``sonar`` in logs from before contract v2).
READING = "reading"


#: Groups of a trial that are not per-iteration arrays.
TRIAL_GROUPS = ("summary", "behaviours", "episodes", "plugins", "situations")


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


def shard_folder(path: str | os.PathLike[str]) -> Path:
    """The folder beside the log ``LOG`` holding its unpacked trial files (``LOG.trials``)."""
    return Path(str(path) + ".trials")


#: A trial file: ``NNNN.h5`` in the shard folder; a scratch file in it ends ``.part``.
SHARD_NAME = re.compile(r"\d{4,}\.h5")


#: What the external link of an unpacked trial names: ``<log name>.trials/NNNN.h5``.
SHARD_LINK = re.compile(r"([^/\\]+)\.trials/(\d{4,})\.h5")


def shard_file(path: str, name: str, link: h5py.ExternalLink) -> Path:
    """The trial file an unpacked trial links to, checked: ``LOG.trials/NNNN.h5`` beside
    the log for trial NNNN, an existing regular file, linked at its root."""
    m = SHARD_LINK.fullmatch(link.filename)
    if m is None or link.path != "/" or not name.isdigit() or int(m.group(2)) != int(name):
        raise InputError(f"links to '{link.filename}:{link.path}'; expected the trial's own "
                         f"file <log>.trials/{name}.h5 beside the log", file=path,
                         key=f"trials/{name}")
    target = Path(os.path.realpath(path)).parent / link.filename  # (beside the real log)
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
