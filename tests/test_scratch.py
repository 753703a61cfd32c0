"""A long trial's rows in scratch files (:mod:`sitframe.scratch`, issue 41's flat memory).

What a user relies on: a run logs the same bits whether its arrays live in memory or in
scratch files, in this process or in a pool's workers (which hand them over by the files'
names); the files go away by themselves; a disk with no room for them costs memory, not
the run; and the pages of a released array really leave the process.
"""

from __future__ import annotations

import concurrent.futures as cf
import errno
import multiprocessing as mp
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from helpers import small_config

from sitframe import scratch
from sitframe.learning.fuzzy_q import RowStack
from sitframe.logs.compare import compare_logs


@pytest.fixture()
def folder(tmp_path, monkeypatch) -> Path:
    """Scratch files in a folder of the test's own, every array in one."""
    where = tmp_path / "scratch"
    monkeypatch.setenv("SITFRAME_SCRATCH_DIR", str(where))
    monkeypatch.setenv("SITFRAME_SCRATCH_ROWS", "0")
    return where


def _resident_mib() -> float:
    return int(Path("/proc/self/statm").read_text().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20


@pytest.mark.parametrize("workers", [1, 2])
def test_a_run_with_its_arrays_in_scratch_files_logs_the_same_bits(tmp_path, workers):
    """Every array in a file (and, with two workers, handed to the main process by name)
    against every array in memory: the same log, and no scratch file left behind. With a
    scratch folder where no file can be made: the same log too, and one warning line for the
    whole run (not one per worker)."""
    cfg = tmp_path / "c.toml"
    cfg.write_text(small_config(trials=3, iterations=400))
    where, blocked = tmp_path / "scratch", tmp_path / "a-file"
    blocked.write_text("not a folder")
    logs, errs = {}, {}
    for rows, folder in (("1000000", where), ("0", blocked), ("0", where)):  # (files last:
        logs[rows, folder] = out = tmp_path / f"rows-{rows}-{folder.name}.h5"  # a later pool
        env = dict(os.environ, SITFRAME_SCRATCH_ROWS=rows,  # would sweep what it left)
                   SITFRAME_SCRATCH_DIR=str(folder))
        errs[rows, folder] = subprocess.run(
            [sys.executable, "-m", "sitframe", "run", str(cfg), "--out", str(out), "--workers",
             str(workers)], env=env, check=True, capture_output=True, text=True).stderr
    memory = logs["1000000", where]
    assert compare_logs(logs["0", where], memory) == []
    assert compare_logs(logs["0", blocked], memory) == []
    assert where.is_dir() and not list(where.iterdir())
    said = [line for line in errs["0", blocked].splitlines() if "scratch folder" in line]
    assert len(said) == 1, said  # (e.g. "(File exists)": what the OS said)
    assert said[0].startswith(f"sitframe: warning: scratch folder {blocked}: cannot make a "
                              "file there (")
    assert said[0].endswith("); a long trial's rows stay in memory instead (set "
                            "SITFRAME_SCRATCH_DIR to a folder with room)")
    assert "scratch" not in errs["0", where] + errs["1000000", where]


def test_a_long_trials_rows_go_to_files_and_a_short_ones_stay_in_memory(monkeypatch, tmp_path):
    from sitframe.runs.loop import Recorder

    monkeypatch.setenv("SITFRAME_SCRATCH_DIR", str(tmp_path))
    monkeypatch.setenv("SITFRAME_SCRATCH_ROWS", "1000")
    long, short = Recorder(1001, 8, 4, ["a"], ["a"]), Recorder(1000, 8, 4, ["a"], ["a"])
    assert all(scratch.in_file(x) for x in (long.pose, long.memberships, long.collision))
    assert not any(scratch.in_file(x) for x in (short.pose, short.memberships))
    assert not long.collision.any() and np.isnan(long.contact).all()  # (filled as in memory)
    assert not list(tmp_path.iterdir())  # (unnamed: nothing to clean up)


def test_arrays_cross_to_a_pool_by_name_and_their_files_go(folder):
    ctx = mp.get_context("spawn")  # (its own environment: the scratch folder above)
    with cf.ProcessPoolExecutor(1, mp_context=ctx, initializer=scratch.share_by_name) as ex:
        got = ex.submit(_made_in_a_worker, 50_000).result()
    rows = np.arange(50_000 * 8, dtype=np.float64).reshape(50_000, 8)
    assert scratch.in_file(got["head"]) and not isinstance(got["head"], scratch._Mapped)
    np.testing.assert_array_equal(got["head"], rows[:40_000])
    np.testing.assert_array_equal(got["columns"], rows[10:20, 2:5])  # (a strided view)
    np.testing.assert_array_equal(got["flags"], np.ones(50_000, dtype=bool))
    assert not list(folder.iterdir())  # (the receiver unlinked them; the worker the rest)


def _made_in_a_worker(n: int) -> dict[str, np.ndarray]:
    a = scratch.empty((n, 8))
    a[:] = np.arange(n * 8, dtype=np.float64).reshape(n, 8)
    scratch.empty(n, fill=1.0)  # (never handed over: its file goes when the next one is made)
    return {"head": a[:40_000], "columns": a[10:20, 2:5],
            "flags": scratch.empty(n, bool, fill=True)}


def test_no_room_for_a_scratch_file_keeps_the_array_in_memory(folder, monkeypatch):
    def full(fd, offset, size):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(os, "posix_fallocate", full)
    a = scratch.empty((100, 3), fill=2.5)
    assert not scratch.in_file(a) and (a == 2.5).all()
    assert not list(folder.iterdir())


def test_released_pages_leave_the_process_and_the_data_stays(folder):
    a = scratch.empty((8 * 2**20,))  # 64 MiB
    a[:] = 1.25
    before = _resident_mib()
    scratch.release_all()
    assert before - _resident_mib() > 48
    assert float(a[::4096].sum()) == 1.25 * 2048
    b = scratch.copy(a[:2**20])
    assert scratch.in_file(b) and (b == 1.25).all()


def test_a_rowstack_in_a_file_gives_what_numpy_stack_gives(folder):
    rng = np.random.default_rng(5)
    rows = rng.integers(-40_000, 40_000, (3000, 48, 7)).astype(np.float64)
    st = RowStack(rows[0], file=True)
    for r in rows[1:1000]:
        st.append(r)
    early = st.array()
    st.extend(rows[1000:])
    assert scratch.in_file(st.array())
    np.testing.assert_array_equal(st.array(), rows)
    np.testing.assert_array_equal(early, rows[:1000])  # (a view handed out stays valid)
