"""Parallel trials: a process pool and a Dask cluster give the serial log bit for bit."""

from __future__ import annotations

import os
import platform
import sys
import time
from concurrent.futures.process import BrokenProcessPool

import pytest
from helpers import run_config, run_json, small_config

from sitframe.cli.app import main
from sitframe.errors import InputError
from sitframe.logs.compare import compare_logs
from sitframe.logs.reader import open_log
from sitframe.runs.parallel import ProcessExecutor, SerialExecutor, TaskCancelled, make_executor

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
                                  dashboard_address="127.0.0.1:0") as cluster:
        run_json(capsys, "run", str(cfg), "--out", str(out), "--scheduler",
             cluster.scheduler_address, "--json")
    assert open_log(out).status == "complete"
    assert compare_logs(ref, out) == []


def test_unreachable_scheduler_fails_fast_one_line(serial_log, tmp_path, capsys, monkeypatch):
    pytest.importorskip("distributed")
    monkeypatch.setattr("sitframe.runs.parallel.DASK_CONNECT_TIMEOUT", 0.5)  # (default 5 s)
    cfg, _ref = serial_log
    capsys.readouterr()
    out = tmp_path / "never.h5"
    code = main(["run", str(cfg), "--out", str(out), "--scheduler", "tcp://127.0.0.1:9"])
    err = capsys.readouterr().err
    assert code == 2
    assert err.count("\n") == 1 and "--scheduler: cannot reach the Dask scheduler" in err
    assert "within 0.5 s" in err
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


def test_arithmetic_names_numpy_and_its_simd_targets_and_follows_the_environment():
    import subprocess

    import numpy as np

    from sitframe.runs.arithmetic import arithmetic, numpy_simd

    here = numpy_simd()
    assert arithmetic().startswith(f"numpy {np.__version__}, SIMD {here}, BLAS ")
    used = here.partition("+")[2].split()
    if used == ["-"]:
        pytest.skip("numpy dispatches to no extra SIMD target on this CPU")
    env = {**os.environ, "NPY_DISABLE_CPU_FEATURES": " ".join(used)}
    off = subprocess.run([sys.executable, "-c", "from sitframe.runs.arithmetic import numpy_simd; "
                          "print(numpy_simd())"], env=env, capture_output=True, text=True,
                         check=True).stdout.strip()
    assert off == f"{here.partition('+')[0]}+ -"


def test_blas_names_the_kernel_openblas_picked_and_follows_the_environment():
    # OpenBLAS picks its kernels by the CPU at load time, and they change a run's log
    # (np.dot and @ go through them), so the kernel is part of the arithmetic.
    import subprocess

    from sitframe.runs.arithmetic import arithmetic, blas

    here = blas()
    assert here in arithmetic()
    if not here.startswith("openblas "):
        pytest.skip(f"numpy's BLAS here is not OpenBLAS ({here})")
    if platform.machine() not in ("x86_64", "AMD64"):
        pytest.skip("the kernel override below names an x86-64 kernel")
    env = {**os.environ, "OPENBLAS_CORETYPE": "Prescott"}  # (SSE3 kernels: every x86-64)
    other = subprocess.run([sys.executable, "-c", "from sitframe.runs.arithmetic import blas; "
                            "print(blas())"], env=env, capture_output=True, text=True,
                           check=True).stdout.strip()
    assert other.split()[:2] == here.split()[:2]  # same library and version,
    assert other != here  # another kernel (OpenBLAS calls Prescott's "Katmai")


def test_workers_of_another_arithmetic_are_refused_with_the_fix():
    from sitframe.runs.arithmetic import check_same_arithmetic

    avx2 = "numpy 2.4.6, SIMD X86_V2 + X86_V3"
    avx512 = "numpy 2.4.6, SIMD X86_V2 + X86_V3 X86_V4 AVX512_ICL"
    check_same_arithmetic(avx2, {"tcp://a:1": avx2, "tcp://b:1": avx2})
    with pytest.raises(InputError, match='there: NPY_DISABLE_CPU_FEATURES="AVX512_ICL X86_V4"'):
        check_same_arithmetic(avx2, {"tcp://a:1": avx2, "tcp://b:1": avx512})
    with pytest.raises(InputError, match="same SIMD targets"):
        check_same_arithmetic(avx512, {"tcp://a:1": avx2})
    haswell, skx = f"{avx2}, BLAS openblas 0.3.31 Haswell", f"{avx2}, BLAS openblas 0.3.31 SkylakeX"
    with pytest.raises(InputError, match=r"there: OPENBLAS_CORETYPE=Haswell set before numpy"):
        check_same_arithmetic(haswell, {"tcp://a:1": skx})
    with pytest.raises(InputError, match=r"there: numpy with the BLAS mkl 2024.1\)"):
        check_same_arithmetic(f"{avx2}, BLAS mkl 2024.1", {"tcp://a:1": skx})
    with pytest.raises(InputError, match=r'there: NPY_DISABLE_CPU_FEATURES="AVX512_ICL X86_V4" '
                                         r"set before numpy is imported and OPENBLAS_CORETYPE"):
        check_same_arithmetic(haswell, {"tcp://a:1": f"{avx512}, BLAS openblas 0.3.31 SkylakeX"})
    with pytest.raises(InputError, match=r"there: numpy 2.4.6\)") as err:
        check_same_arithmetic(avx2, {"tcp://a:1": "numpy 2.3.0, SIMD X86_V2 + X86_V3"})
    assert err.value.key == "--scheduler" and "worker tcp://a:1 computes with numpy 2.3.0" in \
        str(err.value)


def test_a_dask_task_on_a_worker_of_another_arithmetic_fails_the_run_in_one_line(
        serial_log, tmp_path, capsys, monkeypatch):
    """A worker that joined after the connection check is caught by its first task."""
    distributed = pytest.importorskip("distributed")
    import sitframe.runs.parallel as par

    cfg, _ref = serial_log
    real = par.DaskExecutor.__init__

    def init(self, *a, **k):  # as if the workers had been asked before this one joined
        real(self, *a, **k)
        self.arithmetic = "numpy 0.0, SIMD X86_V2 + -"

    monkeypatch.setattr(par.DaskExecutor, "__init__", init)
    out = tmp_path / "mixed.h5"
    capsys.readouterr()
    with distributed.LocalCluster(n_workers=1, threads_per_worker=2, processes=False,
                                  protocol="tcp", host="127.0.0.1",
                                  dashboard_address="127.0.0.1:0") as cluster:
        code = main(["run", str(cfg), "--out", str(out), "--scheduler",
                     cluster.scheduler_address])
    err = capsys.readouterr().err
    assert code == 2, err
    errors = [ln for ln in err.splitlines() if "error" in ln]
    assert len(errors) == 1 and errors[0].startswith("sitframe: error: --scheduler: worker tcp://")
    assert "this process with numpy 0.0" in errors[0] and "Traceback" not in err
    assert open_log(out).status != "complete"
