"""The log writer's memory does not grow with a trial's length, and a full disk still costs
nothing but one clean error.

A large file (a long trial's, the log being packed) is written by HDF5 straight into its
scratch file, through a file object that never reports a failure to HDF5
(:class:`sitframe.logs.writer._ScratchFile`): a write that fails (a full disk) switches it
to memory for the rest of the file, and the error is raised once HDF5 has closed the file.
Arrays kept in scratch files (:mod:`sitframe.scratch`) are written a block of rows at a
time, so a long trial's arrays are never all resident at once. Before this, every file was
built in memory (HDF5's core driver, as small files still are) and copied out as bytes: a
100,000-iteration trial added its arrays and its file twice to the process's peak memory.
"""

from __future__ import annotations

import errno
import io
import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import h5py
import numpy as np
import pytest
from helpers import small_tmpfs

import sitframe.logs.writer as L
from sitframe import scratch
from sitframe.contract.records import RunInfo, TrialResult
from sitframe.errors import DiskFullError
from sitframe.logs.compare import compare_logs
from sitframe.logs.layout import shard_folder
from sitframe.logs.reader import open_log
from sitframe.logs.writer import LogWriter


def _info(path: Path, trials: int = 3) -> RunInfo:
    return RunInfo("m", {}, "", "h", 0, str(path), trials, 10)


def _arrays(n: int, make=np.empty, more: int = 0) -> dict[str, np.ndarray]:
    """A trial's arrays of ``n`` rows (random: they compress little), made by ``make``;
    ``more`` columns of weights besides (80 make some 1.1 kB a row, as a real trial)."""
    rng = np.random.default_rng(n)
    out = {}
    for name, shape, dtype in (("pose", (n + 1, 3), np.float64),
                               ("memberships", (n, 48), np.float64),
                               ("reading", (n, 8), np.float32),
                               ("collision", (n,), np.bool_),
                               ("room", (n,), np.int16),
                               *((("weights", (n, more), np.float64),) if more else ())):
        arr = make(shape, dtype)
        for i in range(0, shape[0], 5_000):  # (filled a block at a time, as a trial does)
            j = min(i + 5_000, shape[0])
            arr[i:j] = rng.random((j - i, *shape[1:])) * 100 if dtype != np.bool_ \
                else rng.random(j - i) < 0.1
            scratch.release(arr)
        out[name] = arr
    return out


def _every_array_in_a_file(folder: Path) -> dict[str, str]:
    """The environment that puts every array :func:`scratch.empty` makes in a file there."""
    return {"SITFRAME_SCRATCH_ROWS": "0", "SITFRAME_SCRATCH_DIR": str(folder)}


def _trial(k: int, arrays: dict[str, np.ndarray]) -> TrialResult:
    return TrialResult(k, 7 + k, "w", arrays, {"avoid": {"heading/q": np.ones((4, 3))}},
                       {"collisions": k, "converged": True})


def _datasets(path: Path) -> dict[str, tuple]:
    """Every dataset of an HDF5 file (a log, a trial file) with how it is stored."""
    out = {}
    with h5py.File(path, "r") as f:
        def visit(name, obj):
            if isinstance(obj, h5py.Dataset):
                out[name] = (obj.shape, obj.dtype, obj.chunks, obj.compression,
                             obj.compression_opts, obj.shuffle, obj.fletcher32,
                             dict(obj.attrs))
        f.visititems(visit)
    return out


@pytest.fixture
def in_files(tmp_path, monkeypatch):
    """Every array made by :func:`scratch.empty` is a scratch file's (in ``tmp_path``)."""
    for k, v in _every_array_in_a_file(tmp_path / "scratch").items():
        monkeypatch.setenv(k, v)
    return lambda shape, dtype: scratch.empty(shape, dtype)


# ----------------------------------------------------------------------------- a full disk


class FailsFrom:
    """The writer's boundary with the disk, failing with ENOSPC from its ``n``-th call on."""

    def __init__(self, monkeypatch: pytest.MonkeyPatch, n: int) -> None:
        self.real, self.n, self.calls = L.write_bytes, n, 0
        monkeypatch.setattr(L, "write_bytes", self)

    def __call__(self, fd: int, data) -> None:
        self.calls += 1
        if self.calls >= self.n:
            os.close(fd)
            raise OSError(errno.ENOSPC, "No space left on device")
        self.real(fd, data)


def test_a_full_disk_half_way_through_a_trial_file_is_one_error_and_hdf5_goes_on(
        tmp_path, monkeypatch):
    path = tmp_path / "run.h5"
    w = LogWriter(path)
    w.start(_info(path))
    w.trial(_trial(0, _arrays(1000)))
    before = {p: p.read_bytes() for p in [path, *shard_folder(path).iterdir()]}
    big = _trial(1, _arrays(60_000))  # some 27 MB: HDF5 writes it in many pieces
    finished = []  # (the file HDF5 finished in memory after the failure)
    done = L._ScratchFile.done

    def keep(box):
        if box.error is not None:
            finished.append(bytes(box.view[:box.size]))
        done(box)

    with monkeypatch.context() as m:
        disk = FailsFrom(m, 3)
        m.setattr(L._ScratchFile, "done", keep)
        with pytest.raises(DiskFullError) as e:
            w.trial(big)
    assert disk.calls == 3  # (the third piece failed; HDF5 then wrote on in memory)
    with h5py.File(io.BytesIO(finished[0]), "r") as f:  # HDF5 saw the file it wrote
        for name, arr in big.arrays.items():
            assert np.array_equal(f[name][()], arr), name
    assert "\n" not in e.value.message and "the disk is full" in e.value.message
    need = float(e.value.message.split("this write needs ")[1].split(" MB")[0])
    assert need > 20, e.value.message  # (the whole trial file HDF5 went on to write)
    assert {p: p.read_bytes() for p in [path, *shard_folder(path).iterdir()]} == before
    assert not list(tmp_path.rglob("*.part"))
    w.trial(big)  # HDF5 is not broken: the same process writes it once there is space
    w.set_status("complete")
    w.release()
    log = open_log(path)
    log.check()
    assert log.trial_indices() == [0, 1]
    for name, arr in big.arrays.items():
        assert np.array_equal(log.trial(1).arrays[name], arr), name


@pytest.fixture
def small_disk(tmp_path):
    with small_tmpfs(tmp_path / "disk", "8m") as disk:
        yield disk


def test_a_real_full_disk_half_way_through_a_trial_file(small_disk):
    path = small_disk.folder / "run.h5"
    w = LogWriter(path)
    w.start(_info(path))
    w.trial(_trial(0, _arrays(1000)))
    before = {p: p.read_bytes() for p in [path, *shard_folder(path).iterdir()]}
    big = _trial(1, _arrays(60_000))  # some 27 MB on a disk of 8 MB
    with pytest.raises(DiskFullError, match="the disk is full: ") as e:
        w.trial(big)
    assert "the log keeps its 1 finished trial" in e.value.message
    assert {p: p.read_bytes() for p in [path, *shard_folder(path).iterdir()]} == before
    assert not list(small_disk.folder.rglob("*.part"))
    small_disk.resize(64 << 20)  # space made: the same process writes on
    w.trial(big)
    w.set_status("complete")
    w.release()
    log = open_log(path)
    log.check()
    assert log.trial_indices() == [0, 1]
    assert np.array_equal(log.trial(1).arrays["memberships"], big.arrays["memberships"])


@pytest.mark.parametrize("after", [1, 2])
def test_a_full_disk_copying_a_large_run_file_fails_before_hdf5_opens_it(tmp_path, monkeypatch,
                                                                         after):
    monkeypatch.setattr(L, "_SMALL", 0)  # (every run file streamed, and larger than its
    monkeypatch.setattr(L, "_BUFFER", 64 << 10)  # window: copied before HDF5 opens it)
    path = tmp_path / "run.h5"
    w = LogWriter(path)
    w.start(_info(path))
    w.stage("collect", {"samples": np.random.default_rng(0).random((20_000, 8))})
    assert path.stat().st_size > 3 * L._BUFFER
    before = path.read_bytes()
    opened = []
    monkeypatch.setattr(L, "_h5file", lambda *a, h5file=L._h5file, **k: opened.append(1)
                        or h5file(*a, **k))
    with monkeypatch.context() as m:
        disk = FailsFrom(m, after)
        with pytest.raises(DiskFullError, match="the disk is full") as e:
            w.stage("cluster", {"centers": np.ones((4, 8))})
    assert disk.calls == after and not opened  # (the copy failed: HDF5 never saw it)
    assert f"this write needs {L.human_size(len(before))}" in e.value.message
    assert path.read_bytes() == before and not list(tmp_path.glob("*.part"))
    w.stage("cluster", {"centers": np.ones((4, 8))})
    w.release()
    log = open_log(path)
    log.check()
    assert np.array_equal(log.stage("cluster")["centers"], np.ones((4, 8)))


@pytest.mark.parametrize("window", [4 << 10, 64 << 10])
def test_the_window_does_not_change_the_log(tmp_path, monkeypatch, window):
    """Files written in many pieces (HDF5 reading back, writing out of order, growing and
    truncating the file on disk) hold what files written in one piece hold."""
    logs = {}
    for size in (None, window):  # (in memory; streamed through a window of that size)
        monkeypatch.setattr(L, "_SMALL", L._SMALL if size is None else 0)
        monkeypatch.setattr(L, "_BUFFER", size or L._BUFFER)
        logs[size] = path = tmp_path / f"{size or 'memory'}.h5"
        w = LogWriter(path)
        w.start(_info(path, 3))
        w.stage("collect", {"samples": np.arange(30_000.0).reshape(-1, 3)})
        w.trials([_trial(1, _arrays(3000)), _trial(0, _arrays(2000))])  # (the summary rebuilt)
        w.trial(_trial(2, _arrays(1000)))
        w.stage("collect", {"samples": np.arange(3.0)})  # (a stage replaced: space freed)
        w.set_status("complete")  # (packed into the run file)
        w.release()
        open_log(path).check()
    assert compare_logs(*logs.values()) == []


# ----------------------------------------------------------------------------- the same log


@pytest.mark.parametrize("streamed", [False, True])
def test_arrays_in_scratch_files_give_the_same_log_as_arrays_in_memory(tmp_path, in_files,
                                                                       monkeypatch, streamed):
    monkeypatch.setattr(scratch, "BLOCK", 100_000)  # many blocks, not aligned with the rows
    if streamed:
        monkeypatch.setattr(L, "_SMALL", 0)
    logs, trial_files = {}, {}
    for how, make in (("memory", np.empty), ("files", in_files)):
        arrays = _arrays(20_000, make)
        assert all(scratch.in_file(a) == (how == "files") for a in arrays.values())
        arrays["nearest"] = arrays["memberships"][:, 3]  # (a strided view of one)
        trial = _trial(0, arrays)
        snapshots = make((200, 48, 5), np.float64)
        snapshots[...] = np.arange(5)
        trial.behaviours["avoid"]["heading/q_snapshots"] = snapshots
        logs[how] = path = tmp_path / f"{how}.h5"
        w = LogWriter(path)
        w.start(_info(path, 1))
        w.trial(trial)
        trial_files[how] = _datasets(shard_folder(path) / "0000.h5")
        w.set_status("complete")
        w.release()
    assert trial_files["memory"] == trial_files["files"]
    assert compare_logs(logs["memory"], logs["files"]) == []
    assert _datasets(logs["memory"]) == _datasets(logs["files"])
    stored = trial_files["files"]["memberships"]
    assert stored[0] == (20_000, 48) and stored[3:7] == ("gzip", 1, True, True)
    assert len(trial_files["files"]) == 8


# ----------------------------------------------------------------------------- memory

PEAK = textwrap.dedent("""
    import json, sys
    from pathlib import Path
    import numpy as np
    from sitframe import scratch
    from sitframe.contract.records import RunInfo, TrialResult
    from sitframe.logs.writer import LogWriter

    sys.path.insert(0, sys.argv[2])
    from test_writer_memory import _arrays, _info, _trial

    def kib(key):  # (this process's, in kB: VmRSS now, VmHWM its peak)
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith(key + ":"):
                return int(line.split()[1])

    path = Path(sys.argv[1])
    arrays = _arrays(int(sys.argv[3]), lambda shape, dtype: scratch.empty(shape, dtype), 80)
    assert all(scratch.in_file(a) for a in arrays.values())
    w = LogWriter(path)
    w.start(_info(path, 1))
    w.trial(_trial(0, {"pose": np.zeros((11, 3))}))  # (everything imported and used once)
    Path("/proc/self/clear_refs").write_text("5")  # (the peak from here on)
    before = kib("VmRSS")
    w.trial(_trial(1, arrays))
    w.set_status("complete")
    grew = kib("VmHWM") - before
    w.release()
    print(json.dumps({"grew": grew * 1024, "arrays": sum(a.nbytes for a in arrays.values())}))
""")


@pytest.mark.skipif(not Path("/proc/self/clear_refs").exists(), reason="needs Linux's /proc")
def test_writing_a_long_trial_of_scratch_arrays_does_not_hold_them_in_memory(tmp_path):
    """The peak resident memory of a fresh process while it writes (and packs) a
    100,000-iteration trial whose arrays are in scratch files. (Read from /proc: the peak
    ``getrusage`` gives a child process starts at its parent's size, here pytest's.)"""
    env = os.environ | _every_array_in_a_file(tmp_path)
    res = subprocess.run([sys.executable, "-c", PEAK, str(tmp_path / "long.h5"),
                          str(Path(__file__).parent), "100000"], capture_output=True,
                         text=True, env=env, timeout=600)
    assert res.returncode == 0, res.stderr[-3000:]
    seen = json.loads(res.stdout)
    arrays, grew = seen["arrays"], seen["grew"]
    assert arrays > 100 << 20  # (some 103 MiB: 100,000 rows of 1.1 kB, as a long trial's)
    # (some 18 MiB, as at 200,000 rows: the writer's window and block, HDF5's chunk caches;
    # 114 MiB when the written blocks' pages are not released, 298 MiB when the files were
    # built in memory: the arrays, the file and its copy)
    assert grew < arrays / 3, f"peak memory grew {grew / 2**20:.0f} MiB writing " \
        f"{arrays / 2**20:.0f} MiB of arrays"
    log = open_log(tmp_path / "long.h5")
    assert log.trial(1).arrays["memberships"].shape == (100_000, 48)
