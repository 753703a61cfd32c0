"""Crash safety: kill -9 leaves a readable log; --resume reproduces the uninterrupted run;
Ctrl-C marks the log aborted and exits 130."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from helpers import INTERRUPTED_ITERATIONS, INTERRUPTED_TRIALS, KILLABLE, run_json

from sitframe.cli.app import main
from sitframe.errors import InputError
from sitframe.logs.compare import compare_logs
from sitframe.logs.reader import open_log

N_TRIALS, ITERATIONS = INTERRUPTED_TRIALS, INTERRUPTED_ITERATIONS

#: Runs the CLI with Python's own SIGINT handler even if the test runner was
#: started with SIGINT ignored (as background jobs of a non-interactive shell are).
_CLI = ("import signal, sys; signal.signal(signal.SIGINT, signal.default_int_handler); "
        "from sitframe.cli.app import console_main; sys.exit(console_main(sys.argv[1:]))")


@pytest.fixture
def reference(interrupted_reference):
    return interrupted_reference


def _start(cfg, out, *extra):
    return subprocess.Popen([sys.executable, "-c", _CLI, "run", str(cfg), "--out", str(out),
                             "--json", *extra],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=KILLABLE)


def _wait_for_trials(proc, out, n=1, timeout=60.0):
    """Poll the log (as a reader would) until it holds ``n`` finished trials."""
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        if proc.poll() is not None:
            return
        if out.exists():
            try:
                if len(open_log(out).trial_indices()) >= n:
                    return
            except InputError:  # the file is being created
                pass
        time.sleep(0.02)
    pytest.fail("no trial written in time")


@pytest.mark.parametrize("workers", ["1", "2"])
def test_kill_9_then_resume_reproduces_uninterrupted_run(reference, tmp_path, capsys, workers):
    cfg, ref = reference
    capsys.readouterr()
    rng = np.random.default_rng(int(workers))
    out = tmp_path / "killed.h5"
    proc = _start(cfg, out, "--workers", workers)
    _wait_for_trials(proc, out)
    time.sleep(float(rng.uniform(0.0, 0.05)))  # (the whole run takes some 0.3 s)
    proc.kill()  # SIGKILL
    proc.communicate(timeout=30)  # (also closes the stderr pipe)
    log = open_log(out)  # always opens
    have = log.trial_indices()
    if log.status == "complete":  # (a resume of a complete log proves nothing)
        pytest.skip("the run finished before it was killed")
    assert log.status == "running"
    # in trial order; all of them when the kill came after the last trial but before the
    # log was marked complete
    assert 1 <= len(have) <= N_TRIALS and have == list(range(len(have)))
    for k in have:  # every finished trial is intact
        assert log.trial(k).arrays["pose"].shape == (ITERATIONS + 1, 3)

    doc = run_json(capsys, "run", "--resume", str(out), "--workers", workers, "--json")
    assert doc["resumed_trials"] == list(range(len(have), N_TRIALS))
    assert open_log(out).status == "complete"
    assert compare_logs(ref, out) == []
    assert sorted(p.name for p in tmp_path.iterdir()) == ["killed.h5"]  # packed: one file


def test_sigint_marks_aborted_exit_130_and_resume_completes(reference, tmp_path, capsys):
    cfg, ref = reference
    capsys.readouterr()
    out = tmp_path / "interrupted.h5"
    proc = _start(cfg, out, "--workers", "2")
    _wait_for_trials(proc, out)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=30)
    if proc.returncode == 0 or (out.exists() and open_log(out).status == "complete"):
        # (the run finished before the signal arrived; a signal just after the log
        # completed may still exit 130, the log stays complete)
        pytest.skip("the run finished before the signal arrived")
    assert proc.returncode == 130, err
    assert b"interrupted" in err
    log = open_log(out)
    assert log.status == "aborted"
    have = log.trial_indices()
    assert len(have) >= 1 and have == list(range(len(have)))

    doc = run_json(capsys, "run", "--resume", str(out), "--json")
    assert doc["resumed_trials"] == list(range(len(have), N_TRIALS))
    assert open_log(out).status == "complete"
    assert compare_logs(ref, out) == []


def test_resume_complete_log_is_a_no_op(reference, capsys):
    _cfg, ref = reference
    before = os.stat(ref).st_mtime_ns
    capsys.readouterr()
    assert main(["run", "--resume", str(ref)]) == 0
    assert "nothing to resume" in capsys.readouterr().out
    assert os.stat(ref).st_mtime_ns == before


@pytest.mark.parametrize(
    ("argv", "pattern"),
    [
        (["--trials", "3"], "--trials: cannot be combined with --resume"),
        (["--seed", "1"], "--seed: cannot be combined with --resume"),
    ],
)
def test_resume_rejects_overrides(reference, capsys, argv, pattern):
    _cfg, ref = reference
    capsys.readouterr()
    assert main(["run", "--resume", str(ref), *argv]) == 2
    assert pattern in capsys.readouterr().err


def test_resume_missing_log_and_missing_experiment(tmp_path, capsys):
    assert main(["run", "--resume", str(tmp_path / "nope.h5")]) == 2
    assert "log file not found" in capsys.readouterr().err
    assert main(["run"]) == 2
    assert "missing EXPERIMENT" in capsys.readouterr().err


def test_resume_warns_when_the_code_changed(reference, tmp_path, capsys):
    import h5py

    _cfg, ref = reference
    out = tmp_path / "changed.h5"
    out.write_bytes(ref.read_bytes())
    with h5py.File(out, "a") as f:
        assert len(f.attrs["code_hash"]) == 64
        f.attrs["code_hash"] = "0" * 64
        f.attrs["status"] = "aborted"
        del f["trials/0007"]
    capsys.readouterr()
    assert main(["run", "--resume", str(out)]) == 0
    captured = capsys.readouterr()
    assert "warning" in captured.err and "code of sitframe or its plugins changed" in captured.err
    assert f"resumed {out}: ran trial(s) [7]" in captured.out  # the plain report
    assert open_log(out).status == "complete"
    assert compare_logs(ref, out) == []  # (root attributes, such as code_hash, aside)


def _unfinished_copy(ref, out, drop=(5, 6, 7)):
    import h5py

    out.write_bytes(ref.read_bytes())
    with h5py.File(out, "a") as f:
        f.attrs["status"] = "aborted"
        for k in drop:
            del f[f"trials/{k:04d}"]


def test_resume_reports_and_runs_exactly_the_missing_trials(reference, tmp_path, capsys):
    _cfg, ref = reference
    out = tmp_path / "gaps.h5"
    _unfinished_copy(ref, out, drop=(2, 6))
    capsys.readouterr()
    doc = run_json(capsys, "run", "--resume", str(out), "--json")
    assert doc["resumed_trials"] == [2, 6]
    assert [t["trial"] for t in doc["trials"]] == [2, 6]
    assert compare_logs(ref, out) == []


@pytest.mark.parametrize(
    ("edit", "key"),
    [
        (lambda text: text.replace("iterations = 300", "iterations = 299"), "config_hash"),
        (lambda text: text.replace("seed = 5", "seed = 6"), "config_hash"),
    ],
    ids=["iterations", "seed"],
)
def test_resume_refuses_a_log_whose_config_changed(reference, tmp_path, capsys, edit, key):
    """Trials of two configurations must never end up in one log."""
    import h5py

    _cfg, ref = reference
    out = tmp_path / "edited.h5"
    _unfinished_copy(ref, out)
    with h5py.File(out, "a") as f:
        text = f.attrs["config"]
        assert edit(text) != text
        f.attrs["config"] = edit(text)
    before = out.read_bytes()
    capsys.readouterr()
    assert main(["run", "--resume", str(out), "--json"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"{out}: {key}:" in err
    assert re.search(r": this sitframe resolves the logged config differently \(config hash "
                     r"[0-9a-f]{12} != logged [0-9a-f]{12}: defaults changed since the run\); "
                     r"resuming would mix two configurations$", err.strip()), err
    assert out.read_bytes() == before


def test_resume_refuses_a_log_whose_plugins_changed(reference, tmp_path, capsys):
    """Trials of two plugin versions, or of a plugin no longer there, never share a log."""
    import json

    import h5py

    _cfg, ref = reference
    out = tmp_path / "plugins.h5"
    _unfinished_copy(ref, out)
    with h5py.File(out, "r") as f:
        logged = json.loads(f.attrs["plugins"])
    fq = next(d for d in logged if d["name"] == "fuzzy-q")
    cases = [
        ({**fq, "version": "0.0.1"},
         f"plugin 'fuzzy-q' is {fq['version']} now, 0.0.1 when the run started; resuming "
         "would mix results of two versions"),
        ({**fq, "distribution": "sitframe-fork"},
         f"plugin 'fuzzy-q' is {fq['version']} now, {fq['version']} when the run started"),
        ({"name": "ghost", "origin": "entry point", "distribution": "ghost-plugins",
          "version": "1.0"}, "plugin 'ghost' (ghost-plugins) that the run used is not "
                             "installed now"),
        ({"name": "ghost", "origin": "module"},
         "plugin 'ghost' (module) that the run used is not installed now"),
    ]
    for entry, message in cases:
        plugins = [d for d in logged if d["name"] != entry["name"]] + [entry]
        with h5py.File(out, "a") as f:
            f.attrs["plugins"] = json.dumps(plugins)
        before = out.read_bytes()
        capsys.readouterr()
        assert main(["run", "--resume", str(out), "--json"]) == 2
        err = capsys.readouterr().err
        assert err.startswith(f"sitframe: error: {out}: plugins: {message}"), entry
        assert err.count("\n") == 1
        assert out.read_bytes() == before


def test_resume_api_and_the_records_a_log_may_lack_or_add(reference, tmp_path, capsys):
    import h5py

    from sitframe.runs.prepare import prepare_resume

    _cfg, ref = reference
    out = tmp_path / "api.h5"
    _unfinished_copy(ref, out)
    exp, kwargs, missing = prepare_resume(out)
    assert missing == [5, 6, 7] and kwargs["skip"] == frozenset(range(5))
    assert exp.info.extra["progress"] is False and exp.info.extra["resume"] is True
    assert exp.info.extra["code_changed"] is False  # the same code
    with h5py.File(out, "a") as f:  # a log from before the code hash was recorded
        del f.attrs["code_hash"]
    assert prepare_resume(out)[0].info.extra["code_changed"] is False
    # a log from before inputs were recorded resumes; one recording an input this
    # config does not read is refused
    with h5py.File(out, "a") as f:
        del f.attrs["inputs"]
    assert prepare_resume(out)[2] == [5, 6, 7]
    with h5py.File(out, "a") as f:
        f.attrs["inputs"] = '{"clusters_from": "0123"}'
    with pytest.raises(InputError, match="what the run read for clusters_from changed"):
        prepare_resume(out)
    # a plugin the run loaded from a folder is checked through config.plugins.dirs, not
    # as an installed one
    with h5py.File(out, "a") as f:
        f.attrs["inputs"] = "{}"
        plugins = json.loads(f.attrs["plugins"])
        f.attrs["plugins"] = json.dumps(plugins + [{"name": "mine", "origin": "plugins-dir"}])
    assert prepare_resume(out)[2] == [5, 6, 7]
    # a logged config this sitframe refuses names the key inside the log's config
    with h5py.File(out, "a") as f:
        f.attrs["config"] = f.attrs["config"].replace("iterations = 300", "iterations = -3")
    with pytest.raises(InputError) as e:
        prepare_resume(out)
    assert e.value.file == str(out) and e.value.key == "config.experiment.iterations"
    assert e.value.message.startswith("the log's config is no longer valid: ")


def test_resume_refuses_another_arithmetic(reference, tmp_path, capsys):
    """Trials computed with other numpy SIMD loops (another CPU) never join a log: the last
    bits of sin/cos/exp differ, and a closed loop turns them into other trajectories."""
    import h5py

    from sitframe.runs.arithmetic import numpy_simd

    _cfg, ref = reference
    out = tmp_path / "simd.h5"
    _unfinished_copy(ref, out)
    with h5py.File(out, "a") as f:
        versions = json.loads(f.attrs["versions"])
        assert versions["numpy_simd"] == numpy_simd()  # recorded by the run
        f.attrs["versions"] = json.dumps({**versions, "numpy_simd": numpy_simd() + " FUTURE"})
    before = out.read_bytes()
    capsys.readouterr()
    assert main(["run", "--resume", str(out), "--json"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith(f"sitframe: error: {out}: versions: the run "
                                                   f"started with numpy {np.__version__}, SIMD")
    assert "FUTURE" in err and "would not be bit-identical" in err
    assert out.read_bytes() == before
    # another BLAS kernel (OpenBLAS picks one by the CPU) is another arithmetic too
    with h5py.File(out, "a") as f:
        f.attrs["versions"] = json.dumps({**versions, "blas": "openblas 0.3.31 SkylakeX"})
    assert main(["run", "--resume", str(out), "--json"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "BLAS openblas 0.3.31 SkylakeX, this process has" in err
    # logs written before a key existed resume on the keys they have (session-15 logs
    # record numpy_simd but not blas; older ones neither)
    from sitframe.runs.prepare import _check_arithmetic

    for drop in (("blas",), ("blas", "numpy_simd")):
        with h5py.File(out, "a") as f:
            f.attrs["versions"] = json.dumps({k: v for k, v in versions.items()
                                              if k not in drop})
        _check_arithmetic(open_log(out))  # (raises InputError if it would refuse)
        with h5py.File(out, "a") as f:  # ... and with another SIMD it still refuses
            f.attrs["versions"] = json.dumps({**{k: v for k, v in versions.items()
                                                 if k not in drop}, "numpy_simd": "OTHER"})
        with pytest.raises(InputError, match="SIMD OTHER"):
            _check_arithmetic(open_log(out))
    with h5py.File(out, "a") as f:
        f.attrs["versions"] = json.dumps({k: v for k, v in versions.items()
                                          if k not in ("blas", "numpy_simd")})
    assert main(["run", "--resume", str(out), "--json"]) == 0
    assert compare_logs(ref, out) == []
