"""Hostile but ordinary use (issue 19): no silent wrong results, no lost data.

Each test names the issue's item it covers. A refused input gives exit status 2
and exactly one stderr line ``sitframe: error: FILE: KEY: ...`` with no
traceback, and whatever was finished before (a published log, a config, a
source log) is byte for byte as it was. Most cases call
:func:`sitframe.cli.app.main` in-process; concurrency, SIGTERM and closed pipes
need real processes.
"""

from __future__ import annotations

import errno
import fcntl
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest
from helpers import INTERRUPTED_TRIALS, KILLABLE, ROOM, small_config

from sitframe.cli.app import main
from sitframe.logs.compare import compare_logs
from sitframe.logs.reader import open_log

SMALL = small_config(trials=2, iterations=100, eval_iterations=50)
#: Starts the CLI with Python's SIGINT handler even under a shell that ignores it.
_CLI = ("import signal, sys; signal.signal(signal.SIGINT, signal.default_int_handler); "
        "from sitframe.cli.app import console_main; sys.exit(console_main(sys.argv[1:]))")



def refused(capsys, argv: list[str], *needles: str) -> str:
    """Run the CLI; assert exit 2 and one stderr line (no traceback) holding ``needles``."""
    capsys.readouterr()
    code = main([str(a) for a in argv])
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert code == 2, err
    assert len(lines) == 1 and lines[0].startswith("sitframe: error: "), err
    assert "Traceback" not in err
    for n in needles:
        assert n in lines[0], lines[0]
    return lines[0]


def ok(capsys, argv: list[str]) -> str:
    capsys.readouterr()
    code = main([str(a) for a in argv])
    cap = capsys.readouterr()
    assert code == 0, cap.err
    return cap.err


def _run(folder: Path, config: str, out: str, capsys, *argv: str) -> Path:
    cfg = folder / (out.rsplit(".", 1)[0] + ".toml")
    cfg.write_text(config)
    ok(capsys, ["run", cfg, "--out", folder / out, "--workers", "1", "--json", *argv])
    return folder / out


@pytest.fixture(scope="module")
def base(tmp_path_factory) -> Path:
    """A complete small log (2 trials) in its own folder."""
    from sitframe.cli.app import main as run_main

    d = tmp_path_factory.mktemp("hostile")
    (d / "base.toml").write_text(SMALL)
    assert run_main(["run", str(d / "base.toml"), "--out", str(d / "base.h5"), "--workers", "1",
                     "--json"]) == 0
    return d / "base.h5"


def _unfinished(src: Path, dst: Path) -> Path:
    """A copy of ``src`` as a killed run leaves it: trial 1 missing, status running."""
    if src != dst:
        shutil.copyfile(src, dst)
    with h5py.File(dst, "a") as f:
        del f["trials/0001"]
        f.attrs["status"] = "running"
    return dst


def _hold_lock(log: Path) -> int:
    """Hold the log's lock as another writing process would (returns the fd)."""
    fd = os.open(str(log) + ".lock", os.O_RDWR | os.O_CREAT)
    fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    return fd


# ----------------------------------------------------------------------------- 1. one writer


def test_1_second_writer_and_resume_during_a_run_are_refused(base, tmp_path, capsys):
    log = tmp_path / "same.h5"
    shutil.copyfile(base, log)
    cfg = base.with_suffix(".toml")
    before = log.read_bytes()
    fd = _hold_lock(log)
    try:
        refused(capsys, ["run", cfg, "--out", log, "--seed", "2", "--workers", "1"],
                "same.h5: --out:", "another sitframe process is writing this log")
        running = _unfinished(base, tmp_path / "running.h5")
        fd2 = _hold_lock(running)
        refused(capsys, ["run", "--resume", running, "--workers", "1"],
                "running.h5: --resume:", "another sitframe process")
        os.close(fd2)
    finally:
        os.close(fd)
    assert log.read_bytes() == before
    assert not list(tmp_path.glob("*.part"))


def test_1_two_simultaneous_runs_give_one_log_and_one_refusal(base, tmp_path):
    cfg = base.with_suffix(".toml")
    out = tmp_path / "same.h5"
    procs = [subprocess.Popen([sys.executable, "-c", _CLI, "run", str(cfg), "--out", str(out),
                               "--seed", str(seed), "--iterations", "2000", "--workers", "1",
                               "--json"], stdout=subprocess.PIPE, stderr=subprocess.PIPE)
             for seed in (1, 2)]
    results = [(p.wait(timeout=120), p.stdout.read(), p.stderr.read().decode()) for p in procs]
    codes = sorted(r[0] for r in results)
    assert codes == [0, 2], results
    winner = next(r for r in results if r[0] == 0)
    loser = next(r for r in results if r[0] == 2)
    assert loser[2].count("\n") == 1 and "another sitframe process" in loser[2]
    seed = json.loads(winner[1])["trials"][0]["seed"]
    log = open_log(out)
    log.check()
    assert log.status == "complete" and log.trial(0).seed == seed
    assert not list(tmp_path.glob("*.part")) and not list(tmp_path.glob("*.lock"))


# ----------------------------------------------------------------------------- 2. sweep names


@pytest.mark.parametrize("values", ['["rooms/a.toml", "rooms-a.toml"]', "[2, 2.0]",
                                    '["A.toml", "a.toml"]'])
def test_2_sweep_points_that_would_share_a_log_are_refused(tmp_path, capsys, values):
    (tmp_path / "s.toml").write_text(f'[sweep]\nbase = "obstacle-avoidance"\n\n[grid]\n'
                                     f'"experiment.world" = {values}\n')
    refused(capsys, ["sweep", tmp_path / "s.toml", "--out", tmp_path / "out"],
            "s.toml: grid:", "same log name")
    assert not (tmp_path / "out").exists()


def test_2_close_floats_get_distinct_reversible_names():
    from sitframe.runs.sweep import point_names

    names = [n for n, _ in point_names({"behaviours.avoid.alpha": [0.1, 0.1000001, 5.0]})]
    assert names == ["alpha=0.1", "alpha=0.1000001", "alpha=5"]


def test_15_sweep_refuses_experiment_name_and_out_outside_the_working_folder(tmp_path,
                                                                             capsys):
    (tmp_path / "s.toml").write_text('[sweep]\nbase = "obstacle-avoidance"\n\n[set]\n'
                                     '"experiment.name" = "x"\n\n[grid]\n"interpreter.c" = [6]\n')
    refused(capsys, ["sweep", tmp_path / "s.toml"], "s.toml: set.experiment.name:",
            "[sweep] name")
    (tmp_path / "s.toml").write_text(f'[sweep]\nbase = "obstacle-avoidance"\nout = '
                                     f'"{tmp_path}/elsewhere"\n\n[grid]\n"interpreter.c" = [6]\n')
    refused(capsys, ["sweep", tmp_path / "s.toml"], "s.toml: sweep.out:", "--out")


# ----------------------------------------------------------------------------- 3. resume inputs


def test_3_resume_refuses_a_changed_world(tmp_path, capsys):
    (tmp_path / "room.toml").write_text(ROOM)
    cfg = SMALL.replace("seed = 3", 'seed = 3\nworld = "room.toml"')
    log = _run(tmp_path, cfg, "r.h5", capsys)
    _unfinished(log, log)
    before = log.read_bytes()
    (tmp_path / "room.toml").write_text(ROOM.replace("[4, 2.5], [5, 2.5]", "[3, 2.5], [5, 2.5]"))
    refused(capsys, ["run", "--resume", log, "--workers", "1"], "r.h5: worlds:",
            "world 'room.toml' changed since the run started (its file differs from the "
            "copy in the log); resuming would run trials in two different rooms")
    assert log.read_bytes() == before


def test_3_resume_refuses_a_rewritten_policy_source(base, tmp_path, capsys):
    src, situations = tmp_path / "src.h5", tmp_path / "situations.h5"
    shutil.copyfile(base, src)
    shutil.copyfile(base, situations)
    cfg = SMALL.replace('p = 5', f'p = 5\npolicy_from = {{log = "{src}", trial = 0}}')
    log = _run(tmp_path, cfg, "p.h5", capsys, "--clusters-from", str(src))
    assert json.loads(open_log(log).attrs["inputs"]).keys() == {"clusters_from",
                                                                "policy_from/avoid"}
    _unfinished(log, log)
    before = log.read_bytes()
    # the source log is rewritten: same situations, other policies
    _run(tmp_path, SMALL, "src.h5", capsys, "--seed", "9", "--clusters-from", str(situations))
    refused(capsys, ["run", "--resume", log, "--workers", "1"], "p.h5: inputs.policy_from/avoid:",
            "what the run read for policy_from/avoid changed since it started (another log was "
            "rewritten); resuming would mix two inputs")
    assert log.read_bytes() == before


# ----------------------------------------------------------------------------- 4. config text


def test_4_odd_text_in_a_config_round_trips_through_the_log(tmp_path, capsys):
    cfg = SMALL.replace('name = "small"', 'name = "small"\ndescription = "a\\u0001b\\u007f\\ttab"')
    cfg = cfg.replace("[behaviours.avoid]", '[behaviours."évite"]')
    log = _run(tmp_path, cfg, "odd.h5", capsys)
    stored = open_log(log).config
    assert stored["experiment"]["description"] == "a\x01b\x7f\ttab"
    assert list(stored["behaviours"]) == ["évite"]
    assert open_log(log).trial(0).policy("évite")


@pytest.mark.parametrize("label", ['"a/b"', '""', '"."'])
def test_4_labels_that_cannot_name_an_hdf5_group_are_refused(tmp_path, capsys, label):
    (tmp_path / "c.toml").write_text(SMALL.replace("[behaviours.avoid]", f"[behaviours.{label}]"))
    refused(capsys, ["run", tmp_path / "c.toml", "--out", tmp_path / "x.h5"], "c.toml: behaviours.",
            "HDF5 group")
    assert not (tmp_path / "x.h5").exists()


# ----------------------------------------------------------------------------- 5, 14, 15 worlds


@pytest.mark.parametrize("edit, key, what", [
    ("[[trajectories]]\npoints = [[1, 1], [1, 3], [7, 3]]\n", "trajectories[0].points",
     "point 2"),
    ("[[trajectories]]\npoints = [[1, 1], [4.5, 2], [4.5, 3.5]]\n", "trajectories[0].points",
     "segment 1"),
    ("[[obstacles]]\npoints = [[10, 10], [11, 10], [11, 11]]\n", "obstacles[1].points",
     "outside the walls"),
    ("[goal]\nposition = [5, 1]\nradius = 1e300\n", "goal.radius", "(0.0, 10000.0]"),
])
def test_5_15_bad_world_geometry_is_refused(tmp_path, capsys, edit, key, what):
    (tmp_path / "w.toml").write_text(ROOM + edit)
    refused(capsys, ["world", "show", tmp_path / "w.toml", "-o", tmp_path / "w.png"],
            f"w.toml: {key}:", what)
    assert not (tmp_path / "w.png").exists()


@pytest.mark.parametrize("walls, key, what", [
    ("[[0, 0], [1e154, 0], [1e154, 4], [0, 4], [0, 0]]", "walls[0].points[1][0]",
     "[-10000.0, 10000.0]"),
    ("[[0, 0], [10000, 0], [10000, 10000], [0, 10000], [0, 0]]", "walls", "coverage grid"),
])
def test_14_extreme_worlds_are_refused_naming_the_limit(tmp_path, capsys, walls, key, what):
    (tmp_path / "w.toml").write_text(ROOM.replace(
        "[[0, 0], [6, 0], [6, 4], [0, 4], [0, 0]]", walls))
    # (refused before any grid is built: benchmarks/scale/bench_hostile.py times it, not this test)
    refused(capsys, ["world", "show", tmp_path / "w.toml"], f"w.toml: {key}:", what)


def test_14_free_cells_of_many_obstacles_are_those_of_the_direct_test():
    """The per-obstacle computation of free cells (time proportional to the room plus the
    obstacles; its speed is measured by benchmarks, not asserted here) gives the cells of
    the direct test, in a room of many obstacles and in shipped rooms."""
    from sitframe.sim.world import load_world, parse_world

    rows = ['name = "many"', "[robot]", "start = [0.5, 0.5, 0]", "[[walls]]",
            "points = [[0, 0], [16, 0], [16, 16], [0, 16], [0, 0]]"]
    for i in range(14):
        for j in range(14):
            x, y = 1.5 + i, 1.4 + j + 0.05 * i
            square = [[x, y], [x + 0.2, y], [x + 0.2, y + 0.2], [x, y + 0.2]]
            rows += ["[[obstacles]]", f"points = {square}"]
    many = parse_world("\n".join(rows))
    assert len(many.obstacles) == 196
    for w in (many, load_world("training"), load_world("novel-2")):
        x0, y0, x1, y1 = w.bounds
        gx, gy = np.meshgrid(np.arange(x0 + 0.25, x1, 0.5), np.arange(y0 + 0.25, y1, 0.5))
        c = np.stack([gx.ravel(), gy.ravel()], axis=1)
        assert w.free_cells().tobytes() == c[w.is_free(c)].tobytes()
    assert 0 < len(many.free_cells()) < 32 * 32


def test_15_world_path_that_is_a_folder_names_the_config_and_key(tmp_path, capsys):
    (tmp_path / "rooms").mkdir()
    (tmp_path / "c.toml").write_text(SMALL.replace("seed = 3", 'seed = 3\nworld = "rooms/"'))
    refused(capsys, ["run", tmp_path / "c.toml", "--out", tmp_path / "x.h5"],
            "c.toml: experiment.world:", "is a folder")
    (tmp_path / "c.toml").write_text(SMALL.replace("seed = 3", 'seed = 3\nworld = "/dev/null"'))
    refused(capsys, ["run", tmp_path / "c.toml", "--out", tmp_path / "x.h5"],
            "c.toml: experiment.world:", "not a regular file")


def test_15_world_paths_resolve_against_the_config_folder(tmp_path, capsys, monkeypatch):
    sub = tmp_path / "exp"
    sub.mkdir()
    (sub / "room.toml").write_text(ROOM)
    (sub / "c.toml").write_text(SMALL.replace("seed = 3", 'seed = 3\nworld = "room.toml"'))
    monkeypatch.chdir(tmp_path)  # not the config's folder
    ok(capsys, ["run", "exp/c.toml", "--out", "x.h5", "--workers", "1", "--json"])
    assert open_log(tmp_path / "x.h5").trial(0).world == "room"


# ----------------------------------------------------------------------------- 6. outputs


def test_6_out_may_not_be_an_input(base, tmp_path, capsys):
    cfg = tmp_path / "c.toml"
    cfg.write_text(SMALL)
    refused(capsys, ["run", cfg, "--out", cfg], "c.toml: --out:", "the run's config")
    assert cfg.read_text() == SMALL
    src = tmp_path / "src.h5"
    shutil.copyfile(base, src)
    before = src.read_bytes()
    refused(capsys, ["run", cfg, "--clusters-from", src, "--out", src], "src.h5: --out:",
            "experiment.clusters_from")
    (tmp_path / "p.toml").write_text(SMALL.replace('p = 5', f'p = 5\npolicy_from = {{log = '
                                                   f'"{src}"}}'))
    refused(capsys, ["run", tmp_path / "p.toml", "--out", src], "src.h5: --out:", "policy_from")
    assert src.read_bytes() == before
    (tmp_path / "notes.txt").write_text("mine")
    refused(capsys, ["run", cfg, "--out", tmp_path / "notes.txt"], "not an HDF5 log")
    assert (tmp_path / "notes.txt").read_text() == "mine"


def test_6_replacing_a_complete_log_is_said_in_one_line(base, tmp_path, capsys):
    out = tmp_path / "again.h5"
    shutil.copyfile(base, out)
    err = ok(capsys, ["run", base.with_suffix(".toml"), "--out", out, "--workers", "1", "--json"])
    said = [f"sitframe: note: {out}: replacing the existing log (status complete) once this "
            "run has finished a trial of its own; until then it is kept as it is"]
    assert err.strip().splitlines() == said
    # a note is said once per command, and every command says its own
    err = ok(capsys, ["run", base.with_suffix(".toml"), "--out", out, "--workers", "1", "--json"])
    assert err.strip().splitlines() == said


def test_6_a_note_is_said_once_per_command(capsys):
    from sitframe.errors import forget_notes, note
    forget_notes()
    for _ in range(3):  # (a sweep's points making the same choice)
        note("policy_from: trial 3 of x.h5")
    note("another choice")
    assert capsys.readouterr().err.splitlines() == ["sitframe: note: policy_from: trial 3 of x.h5",
                                                    "sitframe: note: another choice"]
    forget_notes()
    note("another choice")
    assert capsys.readouterr().err == "sitframe: note: another choice\n"


# ----------------------------------------------------------------------------- 7, 8, 9 security


def test_7_resume_does_not_load_plugin_folders_named_by_the_log(base, tmp_path, capsys):
    evil = tmp_path / "evil"
    evil.mkdir()
    marker = tmp_path / "ran"
    (evil / "boom.py").write_text(f"open({str(marker)!r}, 'w').close()\n")
    log = _unfinished(base, tmp_path / "crafted.h5")
    with h5py.File(log, "a") as f:
        f.attrs["config"] = f.attrs["config"].replace("dirs = []", 'dirs = ["evil"]')
        f.attrs["source"] = str(tmp_path / "anything.toml")
    refused(capsys, ["run", "--resume", log, "--workers", "1"],
            "crafted.h5: config.plugins.dirs:", "resuming never runs code that only a log "
            "names: pass --plugins-dir DIR for each folder you trust")
    assert not marker.exists()


def test_8_planted_symlinks_are_never_written_through(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "c.toml").write_text(SMALL)
    victim = tmp_path / "victim.txt"
    victim.write_text("precious")
    (tmp_path / "logs").mkdir()
    os.symlink(victim, tmp_path / "logs" / "small.h5.part")
    ok(capsys, ["run", "c.toml", "--workers", "1", "--json"])
    assert victim.read_text() == "precious"
    assert open_log("logs/small.h5").complete
    os.symlink(victim, tmp_path / "logs" / "other.h5.lock")
    refused(capsys, ["run", "c.toml", "--out", "logs/other.h5"], "other.h5: --out:",
            "cannot create the log", "lock file")
    assert victim.read_text() == "precious"


def test_9_scheduler_address_checks_and_plain_tcp_warning(tmp_path, capsys, monkeypatch):
    pytest.importorskip("distributed")
    import distributed

    from sitframe.runs.parallel import DaskExecutor

    refused(capsys, ["run", "obstacle-avoidance", "--scheduler", "tcp://::::", "--out",
                     tmp_path / "x.h5"], "--scheduler:", "malformed")

    class FakeClient:
        workers: dict[str, str] = {}
        closed = 0

        def __init__(self, *a, **k):
            pass

        def run(self, fn, **_kw):  # what each connected worker's fn() returns
            return dict(self.workers)

        def close(self):
            FakeClient.closed += 1

    monkeypatch.setattr(distributed, "Client", FakeClient)
    from distributed.security import Security  # (as if the Dask config held certificates)

    monkeypatch.setattr(Security, "get_connection_args", lambda self, role: {"ssl_context": 1})
    DaskExecutor("tcp://10.0.0.5:8786")
    assert "Dask unpickles" in capsys.readouterr().err
    DaskExecutor("tls://10.0.0.5:8786")
    assert capsys.readouterr().err == ""
    # a worker whose numpy computes otherwise (another CPU) is refused, with the fix
    from sitframe.errors import InputError
    from sitframe.runs.arithmetic import arithmetic

    FakeClient.workers = {"tcp://10.0.0.6:1": arithmetic(), "tcp://10.0.0.7:1": "numpy 0.0"}
    with pytest.raises(InputError, match=r"worker tcp://10.0.0.7:1 computes with numpy 0.0"):
        DaskExecutor("tls://10.0.0.5:8786")
    assert FakeClient.closed == 1  # the connection is not left open


# ----------------------------------------------------------------------------- 10, 13 full disk


def test_10_disk_full_mid_run_keeps_the_published_log(tmp_path, capsys, monkeypatch):
    import sitframe.logs.writer as L

    (tmp_path / "c.toml").write_text(SMALL)
    out = tmp_path / "full.h5"
    real = L.write_bytes
    calls = {"n": 0}

    def write(fd, image):
        calls["n"] += 1
        if calls["n"] >= 3:  # after the collect stage is in the log
            os.close(fd)
            raise OSError(errno.ENOSPC, "No space left on device")
        return real(fd, image)

    monkeypatch.setattr(L, "write_bytes", write)
    refused(capsys, ["run", tmp_path / "c.toml", "--out", out, "--workers", "1"],
            "full.h5: the disk is full: ", f"{tmp_path} has ", "no finished trial yet")
    log = open_log(out)
    log.check()
    assert log.has("collect") and not log.trial_indices()
    assert not list(tmp_path.glob("*.part")) and not list(tmp_path.glob("*.lock"))


def test_13_disk_full_at_start_leaves_nothing(tmp_path, capsys, monkeypatch):
    import sitframe.logs.writer as L

    (tmp_path / "c.toml").write_text(SMALL)

    def full(fd, image):
        os.close(fd)
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(L, "write_bytes", full)
    refused(capsys, ["run", tmp_path / "c.toml", "--out", tmp_path / "x.h5", "--workers", "1"],
            "x.h5: the disk is full:", "nothing was written")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.toml"]


def test_13_failed_analyse_leaves_no_half_written_folder(base, tmp_path, capsys, monkeypatch):
    import sitframe.analysis.report as report

    figure = report._Writer.figure

    def disk_full_after_the_first_file(self, *args, **kwargs):
        if os.listdir(self.r.out_dir):  # the folder is half-written when the disk fills up
            raise OSError(errno.ENOSPC, "No space left on device")
        figure(self, *args, **kwargs)

    monkeypatch.setattr(report._Writer, "figure", disk_full_after_the_first_file)
    refused(capsys, ["analyse", base, "-o", tmp_path / "an"], "an: -o:", "No space left")
    assert not (tmp_path / "an").exists()
    (tmp_path / "keep").mkdir()
    (tmp_path / "keep" / "mine.txt").write_text("x")
    refused(capsys, ["analyse", base, "-o", tmp_path / "keep"], "keep: -o:")
    assert [p.name for p in (tmp_path / "keep").iterdir()] == ["mine.txt"]


# ----------------------------------------------------------------------------- 11 damaged logs


def _damaged(base: Path, dst: Path, fn) -> Path:
    shutil.copyfile(base, dst)
    with h5py.File(dst, "a") as f:
        fn(f)
    return dst


def _trials_as_dataset(f: h5py.File) -> None:
    del f["trials"]
    f["trials"] = np.arange(3)


def _policy_out_of_range(f: h5py.File) -> None:
    for name in ("trials/0000/behaviours/avoid/policy/heading",
                 "trials/0001/behaviours/avoid/policy/heading"):
        data = f[name][()]
        del f[name]
        f.create_dataset(name, data=np.full_like(data, 99))


def _centres(value: float | None, shape: tuple[int, ...] | None = None):
    def fn(f: h5py.File) -> None:
        c = f["cluster/state/centers"][()]
        new = np.full(shape or c.shape, 1.0)
        if value is not None:
            new = c.copy()
            new[0, 0] = value
        del f["cluster/state/centers"]
        f["cluster/state/centers"] = new
    return fn


DAMAGE = {
    "schema-version-string": lambda f: f.attrs.__setitem__("schema_version", "1"),
    "schema-version-array": lambda f: f.attrs.__setitem__("schema_version", [1, 1]),
    "trials-dataset": _trials_as_dataset,
    "policy-out-of-range": _policy_out_of_range,
    "centres-nan": _centres(float("nan")),
    "centres-wrong-shape": _centres(None, (3, 2)),
}


@pytest.mark.parametrize("damage", sorted(DAMAGE))
@pytest.mark.parametrize("command", ["evaluate {log} --world novel-1 --iterations 20",
                                     "analyse {log} -o {d}/an",
                                     "replay {log} --to 5 -o {d}/r.gif"])
def test_11_damaged_log_contents_give_one_line(base, tmp_path, capsys, damage, command):
    log = _damaged(base, tmp_path / f"{damage}.h5", DAMAGE[damage])
    argv = command.format(log=log, d=tmp_path).split()
    line = refused(capsys, argv, f"{damage}.h5")
    assert "Traceback" not in line
    assert not (tmp_path / "an").exists() and not (tmp_path / "r.gif").exists()


def test_11_read_only_folder_on_resume_and_replay(base, tmp_path, capsys, monkeypatch):
    import tempfile

    import sitframe.logs.writer as L

    ro = tmp_path / "ro"
    ro.mkdir()
    log = _unfinished(base, ro / "r.h5")
    before = log.read_bytes()
    ro.chmod(0o555)
    if os.geteuid() == 0:  # root writes anyway: make the folder refuse new files as it would
        real_open, real_mkstemp = os.open, tempfile.mkstemp

        def no_open(path, flags, *a, **k):
            if str(path).startswith(str(ro)) and flags & os.O_CREAT:
                raise PermissionError(errno.EACCES, "Permission denied")
            return real_open(path, flags, *a, **k)

        def no_mkstemp(*a, dir=None, **k):
            if str(dir).startswith(str(ro)):
                raise PermissionError(errno.EACCES, "Permission denied")
            return real_mkstemp(*a, dir=dir, **k)

        monkeypatch.setattr(L.os, "open", no_open)
        monkeypatch.setattr(tempfile, "mkstemp", no_mkstemp)
    try:
        refused(capsys, ["run", "--resume", log, "--workers", "1"], "r.h5: --resume:",
                "Permission denied")
        refused(capsys, ["replay", log, "--to", "5", "-o", ro / "r.gif"], "r.gif: -o:",
                "Permission denied")
    finally:
        ro.chmod(0o755)
    assert log.read_bytes() == before
    assert sorted(p.name for p in ro.iterdir()) == ["r.h5"]


def test_11_huge_fcm_trials_is_refused_with_a_limit(tmp_path, capsys):
    (tmp_path / "c.toml").write_text(SMALL.replace("trials = 4", "trials = 100000000"))
    refused(capsys, ["run", tmp_path / "c.toml", "--out", tmp_path / "x.h5"],
            "c.toml: interpreter.trials:", "10000")


def test_11_closed_stdout_and_non_utf8_names(base, tmp_path):
    proc = subprocess.Popen([sys.executable, "-m", "sitframe.cli", "evaluate", str(base),
                             "--world", "novel-1", "--iterations", "10", "--json"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    proc.stdout.close()  # as `| head -c 1` does once it has its byte
    err = proc.stderr.read()
    assert proc.wait(timeout=60) == 141 and err == b""
    name = os.fsencode(tmp_path) + b"/\xff.toml"
    shutil.copyfile(base.with_suffix(".toml"), name)
    res = subprocess.run([sys.executable, "-m", "sitframe.cli", "run", name, "--out",
                          os.fsencode(tmp_path) + b"/u.h5"], capture_output=True)
    assert res.returncode == 2 and res.stderr.count(b"\n") == 1 and b"not UTF-8" in res.stderr


# ----------------------------------------------------------------------------- 12 SIGTERM


@pytest.mark.parametrize("workers", ["1", "2"])
def test_12_sigterm_aborts_like_ctrl_c_and_resumes_identically(interrupted_reference, tmp_path,
                                                               workers):
    cfg, ref = interrupted_reference
    out = tmp_path / "t.h5"
    proc = subprocess.Popen([sys.executable, "-c", _CLI, "run", str(cfg), "--out", str(out),
                             "--workers", workers, "--json"], stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, env=KILLABLE)
    t0 = time.monotonic()
    while time.monotonic() - t0 < 60 and proc.poll() is None:
        try:
            if open_log(out).trial_indices():
                break
        except Exception:  # noqa: BLE001 - not created yet
            pass
        time.sleep(0.02)
    proc.send_signal(signal.SIGTERM)
    err = proc.communicate(timeout=60)[1].decode()
    log = open_log(out)
    assert "Traceback" not in err and "leaked" not in err
    if (proc.returncode, log.status) == (0, "complete"):  # (a resume would prove nothing)
        pytest.skip("the run finished before SIGTERM arrived")
    assert (proc.returncode, log.status) == (143, "aborted"), err
    assert err.strip().splitlines() == ["sitframe: terminated"]
    have = log.trial_indices()
    assert 1 <= len(have) < INTERRUPTED_TRIALS and have == list(range(len(have)))
    res = subprocess.run([sys.executable, "-m", "sitframe.cli", "run", "--resume", str(out),
                          "--workers", workers, "--json"], check=True, capture_output=True)
    assert json.loads(res.stdout)["resumed_trials"] == list(range(len(have), INTERRUPTED_TRIALS))
    assert compare_logs(ref, out) == []


def _sweep_file(folder: Path, trials: int = 2, iterations: int = 100) -> Path:
    (folder / "base.toml").write_text(small_config(name="b", trials=trials, iterations=iterations,
                                                   eval_iterations=50))
    (folder / "s.toml").write_text(f'[sweep]\nname = "s"\nbase = "base.toml"\ntrials = {trials}\n'
                                   '\n[grid]\n"behaviours.avoid.p" = [4, 5]\n')
    return folder / "s.toml"


def test_1_sweep_refuses_a_point_log_another_process_writes(tmp_path, capsys):
    sweep = _sweep_file(tmp_path)
    out = tmp_path / "out"
    out.mkdir()
    fd = _hold_lock(out / "p=5.h5")
    try:
        refused(capsys, ["sweep", sweep, "--out", out, "--workers", "1"], "p=5.h5: --out:",
                "another sitframe process")
    finally:
        os.close(fd)
    assert sorted(p.name for p in out.iterdir()) == ["p=5.h5.lock"]  # (the test's own lock)


def test_12_sigterm_aborts_a_sweep(tmp_path):
    sweep = _sweep_file(tmp_path, trials=6, iterations=300)
    out = tmp_path / "out"
    proc = subprocess.Popen([sys.executable, "-c", _CLI, "sweep", str(sweep), "--out", str(out),
                             "--workers", "2", "--json"], stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, env=KILLABLE)
    t0 = time.monotonic()
    while time.monotonic() - t0 < 60 and proc.poll() is None:
        try:
            if any(open_log(p).trial_indices() for p in out.glob("*.h5")):
                break
        except Exception:  # noqa: BLE001 - not created yet
            pass
        time.sleep(0.02)
    proc.send_signal(signal.SIGTERM)
    err = proc.communicate(timeout=60)[1].decode()
    statuses = [open_log(p).status for p in sorted(out.glob("*.h5"))]
    assert proc.returncode in (143, 0) and "Traceback" not in err, err
    assert not list(out.glob("*.part")) and not list(out.glob("*.lock"))
    if proc.returncode == 0:  # (nothing was left to abort)
        pytest.skip("the sweep finished before SIGTERM arrived")
    assert err.strip().splitlines() == ["sitframe: terminated"]
    assert "aborted" in statuses and set(statuses) <= {"aborted", "complete"}
