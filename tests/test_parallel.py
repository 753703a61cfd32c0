"""Parallel trials: a process pool and a Dask cluster give the serial log bit for bit."""

from __future__ import annotations

import sys
import time
from concurrent.futures.process import BrokenProcessPool

import pytest
from helpers import run_config, run_json, small_config

from sitframe.cli import main
from sitframe.logs import open_log
from sitframe.parallel import (
    ProcessExecutor,
    SerialExecutor,
    TaskCancelled,
    compare_logs,
    make_executor,
)

SMALL = small_config(trials=5, seed=11, eval_worlds=("novel-1", "training"))


@pytest.fixture(scope="module")
def serial_log(tmp_path_factory):
    return run_config(tmp_path_factory.mktemp("parallel"), SMALL, "serial.h5", "--workers", "1")


def test_process_pool_log_identical_to_serial(serial_log, tmp_path, capsys):
    cfg, ref = serial_log
    capsys.readouterr()
    out = tmp_path / "pool.h5"
    doc = run_json(capsys, "run", str(cfg), "--out", str(out), "--workers", "2", "--json")
    assert [t["trial"] for t in doc["trials"]] == [0, 1, 2, 3, 4]
    assert open_log(out).status == "complete"
    assert compare_logs(ref, out) == []
    with_eval = open_log(out).trial(3)
    assert "eval/novel-1/pose" in with_eval.episodes
    assert with_eval.summary["eval/training/collisions_per_1000"] >= 0


def test_dask_cluster_log_identical_to_serial(serial_log, tmp_path, capsys):
    distributed = pytest.importorskip("distributed")
    cfg, ref = serial_log
    capsys.readouterr()
    out = tmp_path / "dask.h5"
    with distributed.LocalCluster(n_workers=1, threads_per_worker=2, processes=False,
                                  protocol="tcp", host="127.0.0.1",
                                  dashboard_address=None) as cluster:
        run_json(capsys, "run", str(cfg), "--out", str(out), "--scheduler",
             cluster.scheduler_address, "--json")
    assert open_log(out).status == "complete"
    assert compare_logs(ref, out) == []


def test_unreachable_scheduler_fails_fast_one_line(serial_log, tmp_path, capsys):
    pytest.importorskip("distributed")
    cfg, _ref = serial_log
    capsys.readouterr()
    out = tmp_path / "never.h5"
    t0 = time.perf_counter()
    code = main(["run", str(cfg), "--out", str(out), "--scheduler", "tcp://127.0.0.1:9"])
    elapsed = time.perf_counter() - t0
    err = capsys.readouterr().err
    assert code == 2
    assert elapsed < 15
    assert err.count("\n") == 1 and "--scheduler: cannot reach the Dask scheduler" in err
    assert not out.exists()


def test_dask_missing_is_a_clear_input_error(serial_log, tmp_path, capsys, monkeypatch):
    cfg, _ref = serial_log
    capsys.readouterr()
    monkeypatch.setitem(sys.modules, "distributed", None)  # import raises ImportError
    out = tmp_path / "never.h5"
    assert main(["run", str(cfg), "--out", str(out), "--scheduler", "tcp://127.0.0.1:8786"]) == 2
    err = capsys.readouterr().err
    assert "needs Dask distributed" in err and "sitframe[dask]" in err
    assert not out.exists()


@pytest.mark.parametrize(
    ("argv", "pattern"),
    [
        (["--workers", "0"], "--workers: must be at least 1"),
        (["--workers", "2", "--scheduler", "tcp://127.0.0.1:8786"], "not both"),
    ],
)
def test_bad_parallel_options_exit_2(serial_log, tmp_path, capsys, argv, pattern):
    cfg, _ref = serial_log
    capsys.readouterr()
    out = tmp_path / "never.h5"
    assert main(["run", str(cfg), "--out", str(out), *argv]) == 2
    err = capsys.readouterr().err
    assert pattern in err and err.count("\n") == 1
    assert not out.exists()


def test_make_executor_choices():
    assert isinstance(make_executor(1, None, 10), SerialExecutor)
    assert isinstance(make_executor(4, None, 1), SerialExecutor)  # one trial: no pool
    ex = make_executor(3, None, 10)
    assert isinstance(ex, ProcessExecutor) and ex.workers == 3
    ex = make_executor(8, None, 2)
    assert isinstance(ex, ProcessExecutor) and ex.workers == 2


def test_cancel_stops_running_tasks_promptly_and_workers_exit():
    """Ctrl-C must not wait for running trials, nor hang on a worker killed mid-write."""
    ex = ProcessExecutor(2)
    futures = [ex.submit(time.sleep, 60) for _ in range(4)]  # two run, two queued
    t0 = time.monotonic()
    while sum(f.running() for f in futures) < 2:
        assert time.monotonic() - t0 < 60, "workers did not start"
        time.sleep(0.01)
    procs = list(ex.pool._processes.values())
    t0 = time.monotonic()
    ex.shutdown(cancel=True)
    assert time.monotonic() - t0 < 20
    assert all(not p.is_alive() for p in procs)
    for f in futures:  # (a worker still starting up is simply killed: BrokenProcessPool)
        assert f.cancelled() or isinstance(f.exception(), TaskCancelled | BrokenProcessPool)
