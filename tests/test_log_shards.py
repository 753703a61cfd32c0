"""A log in parts: one file per trial while the run is written, one file when it ends.

A killed run leaves the run file and its ``LOG.trials`` folder; readers see
the same trials, arrays and summary as in the packed file, the summary kept
by appending equals the one rebuilt from every trial, and a log never makes
the reader open a file that is not one of its own trial files.
"""

from __future__ import annotations

import errno
import os
import shutil

import h5py
import numpy as np
import pytest

from sitframe.cli.app import main
from sitframe.contract.records import RunInfo, TrialResult
from sitframe.errors import InputError
from sitframe.logs.compare import compare_logs
from sitframe.logs.layout import shard_folder
from sitframe.logs.reader import open_log
from sitframe.logs.writer import LogWriter, _write_summary


def _trial(k: int, extra: bool = False) -> TrialResult:
    rng = np.random.default_rng(k)
    summary = {"converged": bool(k % 2), "collisions": k, "eval/novel-1/coverage": 0.5 * k}
    if extra:
        summary["late_key"] = 1.5
    return TrialResult(k, 1000 + k, "training", {"pose": rng.random((21, 3)),
                                                 "collision": rng.random(20) < 0.1},
                       {"avoid": {"heading/q": rng.random((4, 3))}}, summary)


def _writer(path) -> LogWriter:
    w = LogWriter(path)
    w.start(RunInfo("t", {}, "", "h", 0, str(path), 4, 20))
    w.stage("cluster", {"state/centers": np.ones((4, 2))})
    return w


@pytest.fixture
def unpacked(tmp_path):
    """A log with trials 0, 1, 3, 2 written (3 adds a summary column) and not packed."""
    path = tmp_path / "run.h5"
    w = _writer(path)
    for k in (0, 1):
        w.trial(_trial(k))
    w.trials([_trial(3, extra=True), _trial(2)])
    w.release()
    return path


def test_an_unpacked_log_reads_as_the_packed_one(unpacked, tmp_path, capsys):
    assert sorted(p.name for p in shard_folder(unpacked).iterdir()) == \
        ["0000.h5", "0001.h5", "0002.h5", "0003.h5"]
    log = open_log(unpacked)
    log.check()
    assert log.status == "running" and log.trial_indices() == [0, 1, 2, 3]
    assert np.array_equal(log.trial(3).arrays["pose"], _trial(3).arrays["pose"])
    assert log.trial(2).summary["eval/novel-1/coverage"] == 1.0
    with h5py.File(unpacked, "a") as f:  # appended rows = the table rebuilt from every trial
        kept = f["summary"][()]
        _write_summary(f)
        rebuilt = f["summary"][()]
        assert kept.dtype == rebuilt.dtype
        assert all(np.array_equal(kept[c], rebuilt[c], equal_nan=c != "trial")
                   for c in kept.dtype.names)
    assert list(kept["trial"]) == [0, 1, 2, 3] and np.isnan(kept["late_key"][:3]).all()

    copy = tmp_path / "moved" / "run.h5"  # the file and its folder move together
    shutil.copytree(unpacked.parent, copy.parent, ignore=shutil.ignore_patterns("moved"))
    assert main(["pack", str(copy)]) == 0
    assert "packed" in capsys.readouterr().out
    assert sorted(p.name for p in copy.parent.iterdir()) == ["run.h5"]
    assert open_log(copy).status == "running"  # still resumable
    assert compare_logs(unpacked, copy) == []


def test_the_end_of_the_run_packs_and_a_failed_commit_leaves_no_trial_file(unpacked,
                                                                           monkeypatch):
    import sitframe.logs.writer as L

    w = LogWriter(unpacked)

    real, calls = L.write_bytes, []

    def full(fd, data):  # the trial file is written, the run file is not
        calls.append(len(data))
        if len(calls) == 1:
            return real(fd, data)
        os.close(fd)
        raise OSError(errno.ENOSPC, "No space left on device")

    before = unpacked.read_bytes()
    with monkeypatch.context() as m:
        m.setattr(L, "write_bytes", full)
        with pytest.raises(InputError, match="the disk is full"):
            w.trial(_trial(4))
    assert unpacked.read_bytes() == before
    assert not (shard_folder(unpacked) / "0004.h5").exists()
    assert not list(shard_folder(unpacked).glob("*.part"))
    w.set_status("complete")
    w.release()
    assert not shard_folder(unpacked).exists()
    log = open_log(unpacked)
    log.check()
    assert log.complete and log.trial_indices() == [0, 1, 2, 3]


def _relink(path, name: str, target: str) -> None:
    with h5py.File(path, "a") as f:
        del f["trials"][name]
        f["trials"][name] = h5py.ExternalLink(target, "/")


@pytest.mark.parametrize("target, what", [
    ("/etc/hostname", "expected the trial's own file"),
    ("../run.h5.trials/0001.h5", "expected the trial's own file"),
    ("run.h5.trials/0002.h5", "expected the trial's own file"),  # another trial's file
    ("other.h5.trials/0001.h5", "missing"),
])
def test_a_trial_link_outside_the_logs_own_files_is_refused(unpacked, capsys, target, what):
    _relink(unpacked, "0001", target)
    before = unpacked.read_bytes()
    code = main(["pack", str(unpacked)])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "trials/0001" in err and what in err, err
    assert unpacked.read_bytes() == before


def test_a_missing_trial_folder_says_to_move_it_with_the_log(unpacked, tmp_path):
    (tmp_path / "elsewhere").mkdir()
    lone = tmp_path / "elsewhere" / "lone.h5"
    shutil.copyfile(unpacked, lone)
    with pytest.raises(InputError, match=r"run\.h5\.trials' beside it.*sitframe pack"):
        open_log(lone).trial(0)
    shutil.rmtree(shard_folder(unpacked))
    with pytest.raises(InputError, match="missing"):
        open_log(unpacked).check()
