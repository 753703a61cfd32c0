"""Faults without loss (issue 42): a full disk, a replaced log, a symlinked log, a killed
writer, a bad scheduler address, a churning Dask cluster.

Every case ends in one line on stderr with the right exit status (2 for a full disk or a bad
address, 3 for a plugin that fails), no traceback and no raw Python warning, and loses
nothing finished: every finished trial stays readable, a complete log is never destroyed
by a later command, and ``run --resume`` (or ``sweep --reuse``) in a place with space
finishes a run bit for bit as an uninterrupted run (``compare_logs``).

A full disk is made two ways: an ``OSError(ENOSPC)`` injected at the writer's one boundary
with the disk (:func:`sitframe.logs.writer.write_bytes`), which always runs, and a real
tmpfs of a few hundred kB (``mount -t tmpfs``), which needs root and a system that allows
mounting; where it does not, those tests skip and say why. Today's code (before this
module) crashed on a real full disk with SIGSEGV and HDF5's native output, replaced a
complete log before the new run had a trial, replaced a symlink by a regular file, and
printed a Client's traceback 10 s after a bad ``--scheduler`` address.
"""

from __future__ import annotations

import errno
import fcntl
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import textwrap
import time
import warnings
from pathlib import Path

import pytest
from helpers import KILLABLE, small_config, small_tmpfs

from sitframe.cli.app import main
from sitframe.logs.compare import compare_logs
from sitframe.logs.layout import shard_folder
from sitframe.logs.reader import open_log

TRIALS = 4
SMALL = small_config(trials=TRIALS, iterations=100, eval_iterations=50)
_CLI = ("import signal, sys; signal.signal(signal.SIGINT, signal.default_int_handler); "
        "from sitframe.cli.app import console_main; sys.exit(console_main(sys.argv[1:]))")
CLI = [sys.executable, "-c", _CLI]


def one_line(err: str, *needles: str) -> str:
    """``err`` is exactly one ``sitframe: error:`` line holding ``needles``; return it."""
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("sitframe: error: "), err
    assert "Traceback" not in err and "Warning" not in err, err
    for n in needles:
        assert n in lines[0], (n, lines[0])
    return lines[0]


def cli(capsys, *argv: object) -> tuple[int, str]:
    """``sitframe ARGV`` in this process: (exit status, stderr)."""
    capsys.readouterr()
    code = main([str(a) for a in argv])
    return code, capsys.readouterr().err


@pytest.fixture(scope="module")
def reference(tmp_path_factory) -> tuple[Path, Path]:
    """``(config, log)``: the uninterrupted run every interrupted one must reproduce."""
    d = tmp_path_factory.mktemp("reference")
    (d / "c.toml").write_text(SMALL)
    assert main(["run", str(d / "c.toml"), "--out", str(d / "ref.h5"), "--workers", "1",
                 "--json"]) == 0
    return d / "c.toml", d / "ref.h5"


@pytest.fixture(scope="module")
def swept(tmp_path_factory) -> tuple[Path, Path]:
    """``(sweep file, folder)``: an uninterrupted sweep of 2 points x 3 trials."""
    d = tmp_path_factory.mktemp("swept")
    _sweep_file(d)
    assert main(["sweep", str(d / "s.toml"), "--out", str(d / "ref"), "--workers", "1",
                 "--json"]) == 0
    return d / "s.toml", d / "ref"


def _sweep_file(d: Path) -> Path:
    (d / "base.toml").write_text(small_config(name="b", trials=3, iterations=100,
                                              eval_iterations=50))
    (d / "s.toml").write_text('[sweep]\nname = "s"\nbase = "base.toml"\ntrials = 3\n\n'
                              '[grid]\n"behaviours.avoid.p" = [4, 5]\n')
    return d / "s.toml"


class FullDisk:
    """The writer's boundary with the disk on a disk that fills up: the first ``after``
    writes pass, every later one fails with ENOSPC (as ``write`` does on a full disk)."""

    def __init__(self, monkeypatch: pytest.MonkeyPatch, after: int) -> None:
        import sitframe.logs.writer as writer

        self.real, self.after, self.n = writer.write_bytes, after, 0
        monkeypatch.setattr(writer, "write_bytes", self)

    def __call__(self, fd: int, data: bytes | memoryview) -> None:
        self.n += 1
        if self.n > self.after:
            os.close(fd)
            raise OSError(errno.ENOSPC, "No space left on device")
        self.real(fd, data)


def _leftovers(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.rglob("*") if p.name.endswith((".part", ".lock")))


# ----------------------------------------------------------------------------- full disk


@pytest.mark.parametrize("workers", ["1", "2"])
def test_disk_full_mid_run_keeps_every_finished_trial_and_resume_finishes_it(
        reference, tmp_path, capsys, monkeypatch, workers):
    cfg, ref = reference
    out = tmp_path / "full.h5"
    with monkeypatch.context() as m:
        FullDisk(m, after=7)  # create, collect, cluster, trial 0 (file, link), trial 1 (...)
        code, err = cli(capsys, "run", cfg, "--out", out, "--workers", workers, "--json")
    assert code == 2
    line = one_line(err, f"{out}: the disk is full: {tmp_path} has ", "this write needs ",
                    "finishing the run about ", "the log keeps its 2 finished trials",
                    f"`sitframe run --resume {out}`", "full.h5.trials")
    assert re.search(r"needs \d+(\.\d)? kB", line), line
    log = open_log(out)
    log.check()
    assert log.trial_indices() == [0, 1] and log.status == "running"
    assert _leftovers(tmp_path) == []
    code, err = cli(capsys, "run", "--resume", out, "--workers", workers, "--json")
    assert code == 0, err
    assert compare_logs(ref, out) == [] and not shard_folder(out).exists()


def test_disk_full_at_start_writes_nothing(reference, tmp_path, capsys, monkeypatch):
    cfg, _ref = reference
    with monkeypatch.context() as m:
        FullDisk(m, after=0)
        code, err = cli(capsys, "run", cfg, "--out", tmp_path / "x.h5", "--workers", "1")
    assert code == 2
    one_line(err, "x.h5: the disk is full: ", "nothing was written",
             "make space there and run the command again")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("workers", ["1", "2"])
def test_disk_full_in_a_sweep_and_sweep_reuse_finishes_it(swept, tmp_path, capsys,
                                                          monkeypatch, workers):
    sweep, ref = swept
    out = tmp_path / "out"
    with monkeypatch.context() as m:
        disk = FullDisk(m, after=9)
        code, err = cli(capsys, "sweep", sweep, "--out", out, "--workers", workers, "--json")
    assert code == 2 and disk.n > 9
    one_line(err, "s.toml: the disk is full: ", f"{out} has ", "finishing the sweep needs "
             "about ", "every finished trial is kept",
             f"`sitframe sweep {sweep} --out {out} --reuse`")
    kept = {p.name: open_log(p).trial_indices() for p in sorted(out.glob("*.h5"))}
    assert sum(map(len, kept.values())) >= 1, kept
    code, err = cli(capsys, "sweep", sweep, "--out", out, "--workers", workers, "--json",
                    "--reuse")
    assert code == 0, err
    assert "finishing" in err and "unfinished logs" in err
    for name in ("p=4.h5", "p=5.h5"):
        assert compare_logs(ref / name, out / name) == [], name
    assert _leftovers(out) == []


def test_disk_full_while_packing_keeps_the_log_and_its_trial_files(reference, tmp_path,
                                                                   capsys, monkeypatch):
    cfg, ref = reference
    out = tmp_path / "p.h5"
    with monkeypatch.context() as m:
        FullDisk(m, after=7)
        assert cli(capsys, "run", cfg, "--out", out, "--workers", "1")[0] == 2
    before = {p: p.read_bytes() for p in [out, *shard_folder(out).iterdir()]}
    with monkeypatch.context() as m:
        FullDisk(m, after=0)
        code, err = cli(capsys, "pack", out)
    assert code == 2
    one_line(err, "p.h5: the disk is full", "the log keeps its 2 finished trials",
             f"`sitframe pack {out}`")
    assert {p: p.read_bytes() for p in before} == before
    assert cli(capsys, "pack", out)[0] == 0 and not shard_folder(out).exists()
    assert cli(capsys, "run", "--resume", out, "--workers", "1", "--json")[0] == 0
    assert compare_logs(ref, out) == []


def test_disk_full_before_a_new_run_has_a_trial_keeps_the_log_it_was_to_replace(
        reference, tmp_path, capsys, monkeypatch):
    cfg, ref = reference
    out = tmp_path / "old.h5"
    shutil.copyfile(ref, out)
    before = out.read_bytes()
    with monkeypatch.context() as m:
        FullDisk(m, after=2)  # the new run's file and its collect stage, beside the old log
        code, err = cli(capsys, "run", cfg, "--out", out, "--seed", "9", "--workers", "1")
    assert code == 2
    one_line(err.splitlines()[-1], "the existing log there is kept as it was")
    assert out.read_bytes() == before and sorted(p.name for p in tmp_path.iterdir()) == \
        ["old.h5"]


# ----------------------------------------------------------------------------- a real tmpfs


@pytest.fixture
def small_disk(tmp_path):
    with small_tmpfs(tmp_path / "disk", "4m") as disk:
        yield disk


@pytest.mark.parametrize("workers", ["1", "2"])
def test_a_real_full_disk_mid_run_is_one_line_and_the_log_resumes_elsewhere(
        reference, small_disk, tmp_path, workers):
    cfg, ref = reference
    small_disk.resize(int(0.6 * ref.stat().st_size))  # room for the first trial or two
    out = small_disk.folder / "r.h5"
    res = subprocess.run([*CLI, "run", str(cfg), "--out", str(out), "--workers", workers,
                          "--json"], capture_output=True, text=True, timeout=300)
    assert res.returncode == 2, (res.returncode, res.stderr[-2000:])  # (was -11, SIGSEGV)
    one_line(res.stderr, f"{out}: the disk is full: {small_disk.folder} has ",
             "finishing the run about ", "`sitframe run --resume ")
    have = open_log(out).trial_indices()
    assert 1 <= len(have) < TRIALS, have
    moved = tmp_path / "space"  # a place with space: the log and its trial folder, moved
    moved.mkdir()
    shutil.copyfile(out, moved / "r.h5")
    shutil.copytree(shard_folder(out), shard_folder(moved / "r.h5"))
    res = subprocess.run([*CLI, "run", "--resume", str(moved / "r.h5"), "--workers", workers,
                          "--json"], capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    assert json.loads(res.stdout)["resumed_trials"] == list(range(len(have), TRIALS))
    assert compare_logs(ref, moved / "r.h5") == []


def test_a_real_full_disk_in_a_sweep_then_space_and_reuse(swept, small_disk):
    sweep, ref = swept
    small_disk.resize(int(0.8 * ref.joinpath("p=4.h5").stat().st_size))
    out = small_disk.folder / "out"
    run = [*CLI, "sweep", str(sweep), "--out", str(out), "--workers", "2", "--json"]
    res = subprocess.run(run, capture_output=True, text=True, timeout=300)
    assert res.returncode == 2, (res.returncode, res.stderr[-2000:])
    one_line(res.stderr, "the disk is full: ", "finishing the sweep needs about ", "--reuse`")
    small_disk.resize(8 << 20)  # space made
    res = subprocess.run([*run, "--reuse"], capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    for name in ("p=4.h5", "p=5.h5"):
        assert compare_logs(ref / name, out / name) == [], name


def test_a_real_full_disk_at_start(reference, small_disk):
    cfg, _ref = reference
    small_disk.resize(4 << 10)  # one page: not even the new log's first file fits
    out = small_disk.folder / "x.h5"
    res = subprocess.run([*CLI, "run", str(cfg), "--out", str(out), "--workers", "1"],
                         capture_output=True, text=True, timeout=300)
    assert res.returncode == 2, (res.returncode, res.stderr[-2000:])
    one_line(res.stderr, "x.h5: the disk is full: ", "nothing was written")
    assert list(small_disk.folder.iterdir()) == []


# ----------------------------------------------------------------------------- replacing a log

EXPLODES = textwrap.dedent('''
    from sitframe import hookimpl
    from sitframe.plugins.rewards import ObstacleAvoidanceReward

    class Explodes(ObstacleAvoidanceReward):
        name = "explodes"

        def __call__(self, tr):
            raise RuntimeError("boom")

    @hookimpl
    def sitframe_rewards():
        return [Explodes]
''')


def _failing(folder: Path, config: str) -> tuple[Path, Path]:
    """A plugin folder with a reward that raises, and ``config`` using it."""
    (folder / "plug").mkdir()
    (folder / "plug" / "explodes.py").write_text(EXPLODES)
    cfg = folder / "fails.toml"
    cfg.write_text(config.replace('reward = "obstacle-avoidance"', 'reward = "explodes"'))
    return folder / "plug", cfg


def test_a_run_that_fails_in_its_first_trial_keeps_the_complete_log_it_was_to_replace(
        reference, tmp_path, capsys):
    _cfg, ref = reference
    out = tmp_path / "keep.h5"
    shutil.copyfile(ref, out)
    before = out.read_bytes()
    plug, cfg = _failing(tmp_path, SMALL)
    code, err = cli(capsys, "--plugins-dir", plug, "run", cfg, "--out", out, "--workers", "1")
    assert code == 3, err
    lines = err.strip().splitlines()
    assert lines[0] == (f"sitframe: note: {out}: replacing the existing log (status complete) "
                        "once this run has finished a trial of its own; until then it is kept "
                        "as it is")
    one_line(lines[1], "explodes", "RuntimeError: boom")
    assert out.read_bytes() == before  # (was: replaced by the failed run's empty log)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fails.toml", "keep.h5", "plug"]


def test_a_new_run_replaces_the_log_with_its_first_trial(reference, tmp_path, capsys):
    cfg, ref = reference
    out = tmp_path / "again.h5"
    shutil.copyfile(ref, out)
    assert cli(capsys, "run", cfg, "--out", out, "--seed", "9", "--workers", "1",
               "--json")[0] == 0
    log = open_log(out)
    assert log.complete and log.attrs["seed"] == 9 and compare_logs(ref, out) != []
    assert sorted(p.name for p in tmp_path.iterdir()) == ["again.h5"]


def test_a_killed_run_before_its_first_trial_leaves_the_old_log_whole(reference, tmp_path):
    cfg, ref = reference
    out = tmp_path / "old.h5"
    shutil.copyfile(ref, out)
    before = out.read_bytes()
    proc = subprocess.Popen([*CLI, "run", str(cfg), "--out", str(out), "--seed", "9",
                             "--iterations", "3000", "--workers", "1"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    t0 = time.monotonic()  # the new run's own file exists beside the old log: kill it now
    while not list(tmp_path.glob("old.h5.*.part")) and time.monotonic() - t0 < 60:
        time.sleep(0.01)
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=60)
    assert out.read_bytes() == before and open_log(out).complete
    res = subprocess.run([*CLI, "run", "--resume", str(out)], capture_output=True, text=True)
    assert res.returncode == 0 and "already complete" in res.stdout, res.stderr
    res = subprocess.run([*CLI, "pack", str(out)], capture_output=True, text=True)
    assert res.returncode == 0 and "already one file" in res.stdout, res.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["old.h5"]  # (the next writer tidied)
    assert out.read_bytes() == before


def test_an_unfinished_log_at_out_is_packed_and_kept_until_the_new_run_has_a_trial(
        reference, tmp_path, capsys, monkeypatch):
    cfg, ref = reference
    out = tmp_path / "u.h5"
    with monkeypatch.context() as m:  # an unfinished log: 2 trials in their own files
        FullDisk(m, after=7)
        assert cli(capsys, "run", cfg, "--out", out, "--workers", "1")[0] == 2
    assert shard_folder(out).is_dir()
    plug, failing = _failing(tmp_path, SMALL)
    code, err = cli(capsys, "--plugins-dir", plug, "run", failing, "--out", out, "--workers",
                    "1")
    assert code == 3, err
    log = open_log(out)  # the old log, whole, in one file, as unfinished as it was
    assert log.trial_indices() == [0, 1] and log.status == "running"
    assert not shard_folder(out).exists()
    assert cli(capsys, "run", "--resume", out, "--workers", "1", "--json")[0] == 0
    assert compare_logs(ref, out) == []


def test_a_sweep_that_fails_keeps_the_complete_point_logs(swept, tmp_path, capsys):
    _sweep, ref = swept
    out = tmp_path / "out"
    shutil.copytree(ref, out)
    before = {p.name: p.read_bytes() for p in out.glob("*.h5")}
    plug, _cfg = _failing(tmp_path, SMALL)
    (tmp_path / "base.toml").write_text(small_config(name="b", trials=3, iterations=100,
                                                     eval_iterations=50).replace(
        'reward = "obstacle-avoidance"', 'reward = "explodes"'))
    (tmp_path / "s.toml").write_text('[sweep]\nname = "s"\nbase = "base.toml"\ntrials = 3\n\n'
                                     '[grid]\n"behaviours.avoid.p" = [4, 5]\n')
    code, err = cli(capsys, "--plugins-dir", plug, "sweep", tmp_path / "s.toml", "--out", out,
                    "--workers", "1")
    assert code == 3, err
    assert {p.name: p.read_bytes() for p in out.glob("*.h5")} == before
    assert _leftovers(out) == []


# ----------------------------------------------------------------------------- links, kills


def _links(tmp_path: Path) -> tuple[Path, Path]:
    """``logs/`` holds a link ``x.h5`` into ``store/`` (the target does not exist yet)."""
    (tmp_path / "logs").mkdir()
    (tmp_path / "store").mkdir()
    os.symlink(tmp_path / "store" / "x.h5", tmp_path / "logs" / "x.h5")
    return tmp_path / "logs" / "x.h5", tmp_path / "store" / "x.h5"


@pytest.mark.parametrize("workers", ["1", "2"])
def test_a_killed_run_behind_a_symlink_resumes_where_the_link_points(reference, tmp_path,
                                                                     workers):
    cfg, ref = reference
    link, real = _links(tmp_path)
    proc = subprocess.Popen([*CLI, "run", str(cfg), "--out", str(link), "--workers", workers,
                             "--json"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            env=KILLABLE)
    t0 = time.monotonic()
    while proc.poll() is None and time.monotonic() - t0 < 120:
        try:
            if open_log(real).trial_indices():
                break
        except Exception:  # noqa: BLE001 - not written yet
            pass
        time.sleep(0.01)
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=60)
    assert link.is_symlink() and real.is_file()
    assert sorted(p.name for p in link.parent.iterdir()) == ["x.h5"]  # (no lock beside it)
    if open_log(real).complete:
        pytest.skip("the run finished before it was killed")
    res = subprocess.run([*CLI, "run", "--resume", str(link), "--workers", workers, "--json"],
                         capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    assert link.is_symlink() and os.readlink(link) == str(real)  # (was: replaced by a file)
    assert compare_logs(ref, real) == [] and compare_logs(ref, link) == []
    assert sorted(p.name for p in real.parent.iterdir()) == ["x.h5"]


def test_the_lock_follows_the_real_file(reference, tmp_path, capsys):
    cfg, _ref = reference
    link, real = _links(tmp_path)
    fd = os.open(str(real) + ".lock", os.O_RDWR | os.O_CREAT)
    fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)  # another process writes store/x.h5
    try:
        code, err = cli(capsys, "run", cfg, "--out", link, "--workers", "1")
    finally:
        os.close(fd)
    assert code == 2
    one_line(err, "x.h5: --out: another sitframe process is writing this log")
    assert not real.exists() and link.is_symlink()


def test_pack_writes_through_a_link(reference, tmp_path, capsys, monkeypatch):
    cfg, ref = reference
    link, real = _links(tmp_path)
    with monkeypatch.context() as m:
        FullDisk(m, after=7)
        assert cli(capsys, "run", cfg, "--out", link, "--workers", "1")[0] == 2
    assert cli(capsys, "pack", link)[0] == 0
    assert link.is_symlink() and not shard_folder(real).exists()
    assert open_log(link).trial_indices() == [0, 1]


# ----------------------------------------------------------------------------- bad addresses


@pytest.mark.parametrize("address, needle", [
    ("", "(it is empty)"),
    ("tcp://localhost", "(no port number)"),
    ("tcp://:8786", "(no host)"),
    ("tls://localhost:8786", "no TLS certificates"),
])
def test_a_bad_scheduler_address_is_one_line_and_nothing_after(reference, tmp_path, address,
                                                              needle):
    pytest.importorskip("distributed")
    cfg, _ref = reference
    t0 = time.monotonic()
    res = subprocess.run([*CLI, "run", str(cfg), "--out", str(tmp_path / "x.h5"),
                          "--scheduler", address], capture_output=True, text=True, timeout=120)
    assert res.returncode == 2
    one_line(res.stderr, "--scheduler: ", needle)  # (was: a TimeoutError traceback, 10 s later)
    assert time.monotonic() - t0 < 30 and list(tmp_path.iterdir()) == []


# ----------------------------------------------------------------------------- sources


def test_a_command_line_value_is_blamed_on_its_option(reference, capsys, tmp_path):
    cfg, _ref = reference
    for opt, value in (("--seed", "99999999999999999999999"), ("--trials", "100000000"),
                       ("--iterations", "100000000000")):
        code, err = cli(capsys, "run", cfg, opt, value, "--out", tmp_path / "x.h5")
        assert code == 2
        one_line(err, f"sitframe: error: {opt}: expected an integer <= ")  # (was c.toml's key)
    code, err = cli(capsys, "run", cfg, "--clusters-from", tmp_path / "no.h5", "--out",
                    tmp_path / "x.h5")
    one_line(err, "no.h5: --clusters-from: log file not found")


def test_a_sweep_out_that_is_a_file_is_blamed_on_where_it_was_given(swept, tmp_path, capsys,
                                                                     monkeypatch):
    sweep, _ref = swept
    monkeypatch.chdir(tmp_path)  # (a sweep's out is relative to the working folder)
    (tmp_path / "o").write_text("mine")
    shutil.copyfile(sweep.parent / "base.toml", tmp_path / "base.toml")
    (tmp_path / "s.toml").write_text(sweep.read_text().replace(
        'trials = 3', 'trials = 3\nout = "o"'))
    code, err = cli(capsys, "sweep", tmp_path / "s.toml")
    assert code == 2
    one_line(err, "s.toml: sweep.out: 'o' is a file; expected the folder")  # (was: --out)
    code, err = cli(capsys, "sweep", tmp_path / "s.toml", "--out", tmp_path / "o")
    one_line(err, "sitframe: error: --out: ", "is a file")
    assert (tmp_path / "o").read_text() == "mine"


def test_text_from_a_log_is_printed_escaped_on_one_line(reference, tmp_path, capsys):
    import h5py

    cfg, ref = reference
    out = tmp_path / "odd.h5"
    shutil.copyfile(ref, out)
    with h5py.File(out, "a") as f:
        f.attrs["status"] = "done\nsitframe: error: fake\x1b[31m"
    capsys.readouterr()
    assert main(["pack", str(out)]) == 0
    printed = capsys.readouterr().out
    assert printed.count("\n") == 1 and "\\nsitframe: error: fake\\x1b[31m" in printed
    code, err = cli(capsys, "run", cfg, "--out", out, "--workers", "1", "--json")
    assert code == 0 and err.count("\n") == 1, err
    assert "(status done\\nsitframe: error: fake\\x1b[31m)" in err


def test_situations_the_data_cannot_fill_are_one_warning_naming_the_key(tmp_path, capsys):
    cfg = tmp_path / "c.toml"
    cfg.write_text(small_config(trials=1, iterations=50, c=600, eval_iterations=20).replace(
        "[collect]", "[collect]\nwander_samples = 20"))
    code, err = cli(capsys, "run", cfg, "--out", tmp_path / "c.h5", "--workers", "1", "--json")
    assert code == 0, err
    assert err.strip().splitlines() == [
        f"sitframe: warning: {cfg}: interpreter.c: every clustering trial left one of the 600 "
        "situations empty (more situations than the collected samples fill); the best-ranked "
        "trial is used anyway: lower c, or collect more samples"]


def test_a_tiny_softmax_temperature_raises_no_python_warning():
    import numpy as np

    from sitframe.learning.fuzzy_q import QLearningParams, softmax_choice

    q = np.array([[0.0, 1.0, 2.0], [np.inf, 1.0, -np.inf]])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for mode in ("relative", "absolute"):
            params = QLearningParams(temperature=1e-320, temperature_mode=mode)
            a = softmax_choice(q, params, np.random.default_rng(0))
            assert a[0] == 2  # (the greedy limit, exactly)


def test_the_stderr_scan_finds_tracebacks_and_raw_warnings():
    """The scan every corpus test's stderr goes through (conftest.stderr_problems) can fail."""
    from conftest import stderr_problems

    assert stderr_problems("sitframe: error: x.toml: a: expected b\n") == []
    assert stderr_problems("sitframe: warning: c.toml: interpreter.c: ...\n") == []
    assert stderr_problems("Traceback (most recent call last):\n  File ...\n")
    assert stderr_problems("/x/fuzzy_q.py:189: RuntimeWarning: invalid value\n  logits = ...\n")
    assert stderr_problems("sitframe: warning: RuntimeWarning in fcm.py:126: c = 600\n")
    assert stderr_problems("Exception ignored in: <function Client.__del__>\n")


# ----------------------------------------------------------------------------- churn


def test_a_sweep_on_a_churning_dask_cluster_finishes_every_point_identically(tmp_path,
                                                                           capsys):
    """40 settings x 2 seeds on a real cluster of 2 worker processes, one killed (SIGKILL)
    and replaced every 1.5 s: every point's log complete and bit-identical to a calm run's.
    Throughput with and without churn: ``benchmarks/scale/bench_churn.py``."""
    if not os.environ.get("CI"):
        pytest.importorskip("distributed")
    from churn import Churn, Cluster, write_sweep

    sweep = write_sweep(tmp_path, settings=40, seeds=2, iterations=30)
    assert main(["sweep", str(sweep), "--out", str(tmp_path / "calm"), "--workers", "1",
                 "--json"]) == 0
    capsys.readouterr()
    with Cluster(2) as cluster, Churn(cluster, interval=1.5) as churn:
        res = subprocess.run([*CLI, "sweep", str(sweep), "--out", str(tmp_path / "churn"),
                              "--scheduler", cluster.address, "--json"],
                             capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stderr[-3000:]
    assert res.stderr.strip().splitlines() == [  # the one warning a plain tcp:// address gets
        f"sitframe: warning: --scheduler {cluster.address}: plain tcp; Dask unpickles what it "
        "receives, so whoever can reach the scheduler can run code here and on the workers: "
        "use tls:// on a shared network (see docs/how-to/dask.md)"]
    assert churn.kills >= 2, churn.kills
    calm = sorted(p.name for p in (tmp_path / "calm").glob("*.h5"))
    assert len(calm) == 80
    for name in calm:
        log = tmp_path / "churn" / name
        assert open_log(log).complete, name
        assert compare_logs(tmp_path / "calm" / name, log) == [], name


def test_a_task_lost_with_its_worker_more_often_than_dask_retries_is_submitted_again():
    """With no retries left to the scheduler (allowed-failures 0), a task whose worker is
    killed fails with KilledWorker; the executor submits it again (to the replacement)."""
    if not os.environ.get("CI"):
        pytest.importorskip("distributed")
    import random

    from churn import Cluster

    from sitframe.runs.parallel import DaskExecutor

    with Cluster(1, allowed_failures=0) as cluster:
        ex = DaskExecutor(cluster.address)
        try:
            task = ex.submit(time.sleep, 3.0)
            t0 = time.monotonic()
            while task.remote.status == "pending" and time.monotonic() - t0 < 30:
                if cluster.cluster.scheduler.tasks.get(task.remote.key) is not None and \
                        cluster.cluster.scheduler.tasks[task.remote.key].state == "processing":
                    break
                time.sleep(0.05)
            time.sleep(0.5)
            cluster.kill_one(random.Random(0))
            assert task.result() is None and task.lost == 1
        finally:
            ex.shutdown()
