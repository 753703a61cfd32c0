"""End to end through the CLI: run -> HDF5 log -> reader -> evaluate; errors exit 2."""

from __future__ import annotations

import h5py
import numpy as np
import pytest
from helpers import run_json, small_config

from sitframe.cli.app import main
from sitframe.logs.layout import SCHEMA_VERSION
from sitframe.logs.reader import open_log

SMALL = small_config()


@pytest.fixture(scope="module")
def small_run(tmp_path_factory):
    d = tmp_path_factory.mktemp("run")
    cfg = d / "small.toml"
    cfg.write_text(SMALL)
    out = d / "small.h5"
    return cfg, out


def test_run_json_contract_and_log(small_run, capsys):
    cfg, out = small_run
    doc = run_json(capsys, "run", str(cfg), "--out", str(out), "--json")
    assert doc["log"] == str(out)
    assert doc["wall_seconds"] > 0
    assert [t["trial"] for t in doc["trials"]] == [0, 1]
    for t in doc["trials"]:
        assert set(t) >= {"trial", "seed", "converged", "convergence_iteration",
                          "collisions_per_1000_after_convergence", "rule_base"}
        headings = t["rule_base"]["avoid.heading"]
        assert len(headings) == 6
        assert set(headings) <= {90.0, 60.0, 30.0, 0.0, -30.0, -60.0, -90.0}

    log = open_log(out)
    assert log.status == "complete"
    assert log.attrs["schema_version"] == SCHEMA_VERSION
    assert log.config["interpreter"]["c"] == 6
    assert {"sitframe", "numpy", "h5py", "hdf5", "python"} <= set(log.versions)
    assert any(p["name"] == "fuzzy-q" for p in log.plugins)
    assert "novel-1" in log.worlds and "collect-1" in log.worlds
    col = log.stage("collect")
    assert col["samples"].shape[1] == 8 and col["samples"].shape[0] == col["poses"].shape[0]
    cl = log.stage("cluster")
    assert cl["trial_centers"].shape == (4, 6, 8)
    assert 0 <= cl["chosen"] < 4
    tr = log.trial(1)
    assert tr.arrays["pose"].shape == (301, 3)
    assert tr.arrays["sonar"].shape == (300, 8)
    np.testing.assert_allclose(tr.arrays["memberships"].sum(axis=1), 1.0)
    assert tr.arrays["reward/avoid"].shape == (300,)
    beh = tr.behaviours["avoid"]
    assert beh["heading/q_snapshots"].shape[1:] == (6, 7)
    assert beh["heading/snapshot_iteration"][0] == 0
    assert tr.policy("avoid")["heading"].shape == (6,)
    summary = log.summary()
    assert list(summary["trial"]) == [0, 1]
    assert summary["collisions"][1] == tr.arrays["collision"].sum()
    # reward is -30 exactly on collision iterations
    r, c = tr.arrays["reward/avoid"], tr.arrays["collision"]
    assert np.all(r[c] == -30.0) and np.all(r[~c] > 0)


def test_evaluate_json_contract(small_run, capsys):
    cfg, out = small_run
    if not out.exists():
        main(["run", str(cfg), "--out", str(out), "--json"])
        capsys.readouterr()
    doc = run_json(capsys, "evaluate", str(out), "--world", "novel-2", "--trial", "1",
                    "--iterations", "120", "--json")
    assert set(doc) >= {"iterations", "collisions", "collisions_per_1000", "distance_m",
                        "mean_speed_m_s", "coverage"}
    assert doc["iterations"] == 120
    assert 0.0 < doc["coverage"] <= 1.0
    assert doc["mean_speed_m_s"] == pytest.approx(0.15)
    assert doc["collisions_per_1000"] == pytest.approx(doc["collisions"] * 1000 / 120)


@pytest.mark.parametrize(
    ("argv", "pattern"),
    [
        (["run", "obstacle-avoid"], r"unknown experiment 'obstacle-avoid' .*available presets"),
        (["run", "nope.toml"], r"nope.toml: config file not found"),
        (["run", "obstacle-avoidance", "--trials", "0"],
         r"--trials: expected an integer in \[1, inf\), got 0"),
        (["run", "obstacle-avoidance", "--world", "narnia"], r"error: --world: unknown world"),
        (["evaluate", "missing.h5", "--world", "training"], r"missing.h5: log file not found"),
        (["world", "show", "narnia"], r"unknown world 'narnia'"),
    ],
)
def test_bad_input_one_line_exit_2(argv, pattern, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    code = main(argv)
    err = capsys.readouterr().err
    assert code == 2
    assert err.count("\n") == 1 and err.startswith("sitframe: error: ")
    assert __import__("re").search(pattern, err), err
    assert not (tmp_path / "logs").exists()  # nothing written


def test_not_hdf5_and_wrong_schema(tmp_path, capsys):
    bogus = tmp_path / "bogus.h5"
    bogus.write_text("hello")
    assert main(["evaluate", str(bogus), "--world", "training"]) == 2
    assert "not an HDF5 file" in capsys.readouterr().err
    other = tmp_path / "other.h5"
    with h5py.File(other, "w") as f:
        f.attrs["schema"] = "sitframe-log"
        f.attrs["schema_version"] = 99
    assert main(["evaluate", str(other), "--world", "training"]) == 2
    assert "unknown log schema version 99" in capsys.readouterr().err


def test_a_missing_log_without_prerequisite_is_one_line(tmp_path, capsys, monkeypatch):
    """A config that reads a log it names no prerequisite for: one line, nothing run.
    (The shipped presets name theirs: tests/test_prerequisites.py.)"""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "c.toml").write_text(SMALL.replace('seed = 3', 'seed = 3\nclusters_from = '
                                                   '"logs/obstacle-avoidance.h5"'))
    assert main(["run", "c.toml"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "logs/obstacle-avoidance.h5: log file not found" in err
    assert not (tmp_path / "logs").exists() or not any((tmp_path / "logs").iterdir())


def test_reused_situations_are_recorded_and_sensor_must_match(small_run, tmp_path, capsys):
    cfg, out = small_run
    if not out.exists():
        main(["run", str(cfg), "--out", str(out), "--json"])
        capsys.readouterr()
    reuse = tmp_path / "reuse.toml"
    reuse.write_text(SMALL.replace('seed = 3', f'seed = 3\nclusters_from = "{out}"')
                     .replace("trials = 2", "trials = 1"))
    log2 = tmp_path / "reuse.h5"
    run_json(capsys, "run", str(reuse), "--out", str(log2), "--json")
    reused = open_log(log2)
    np.testing.assert_array_equal(reused.interpreter_state()["centers"],
                                  open_log(out).interpreter_state()["centers"])
    assert reused.stage("cluster")["reused_from"] == str(out)
    doc = run_json(capsys, "evaluate", str(log2), "--world", "novel-1", "--iterations", "50",
                    "--json")
    assert doc["iterations"] == 50
    cone = tmp_path / "cone.toml"
    cone.write_text(reuse.read_text() + '\n[sensor]\nbeam_width_deg = 20\nrays_per_beam = 3\n')
    assert main(["run", str(cone), "--out", str(tmp_path / "cone.h5")]) == 2
    assert "situations were fitted on readings of sensor" in capsys.readouterr().err


def test_same_seed_is_bit_identical_across_processes_and_another_seed_is_not(tmp_path, capsys):
    """A `sitframe run` process (its own hash seed) and this one write the same log bit for
    bit; another seed changes the trials."""
    import os
    import subprocess
    import sys

    from sitframe.logs.compare import compare_logs

    cfg = tmp_path / "small.toml"
    cfg.write_text(small_config(trials=2, iterations=200))
    a, b, c = tmp_path / "a.h5", tmp_path / "b.h5", tmp_path / "c.h5"
    env = {**os.environ, "PYTHONHASHSEED": "1"}
    subprocess.run([sys.executable, "-m", "sitframe.cli", "run", str(cfg), "--out", str(a),
                    "--workers", "1", "--json"], check=True, env=env, capture_output=True)
    run_json(capsys, "run", str(cfg), "--out", str(b), "--workers", "1", "--json")
    assert compare_logs(a, b) == []
    run_json(capsys, "run", str(cfg), "--out", str(c), "--workers", "1", "--seed", "4", "--json")
    diff = compare_logs(a, c)
    assert {"trials/0000/pose", "trials/0001/pose"} <= set(diff)


def test_best_of_weighs_collisions_and_coverage():
    from sitframe.logs.policies import best_of

    idx = [0, 1, 2, 3]
    # trial 1 never collides but hardly moves (a looper); trial 2 is nearly as
    # safe and covers the room: the rank sums are 6, 5, 3, 6
    assert best_of(idx, [3.0, 0.0, 1.0, 2.0], [0.30, 0.05, 0.40, 0.10], [0, 0, 0, 0]) == 2
    # equal rank sums: fewer collisions after convergence, then the lower index
    assert best_of([0, 1], [1.0, 2.0], [0.1, 0.2], [5.0, 1.0]) == 1
    assert best_of([0, 1], [1.0, 2.0], [0.1, 0.2], [1.0, 1.0]) == 0
    # a trial without an evaluation (NaN) ranks last
    assert best_of([0, 1], [np.nan, 9.0], [np.nan, 0.1], [0, 0]) == 1


def test_best_trial_uses_only_the_learning_world(tmp_path, capsys):
    from sitframe.errors import InputError
    from sitframe.logs.policies import best_trial

    cfg = tmp_path / "best.toml"
    cfg.write_text(small_config(trials=3, iterations=200, eval_worlds=("training", "novel-1")))
    out = tmp_path / "best.h5"
    run_json(capsys, "run", str(cfg), "--out", str(out), "--workers", "1", "--json")
    log = open_log(out)
    table = log.summary()
    coll = table["eval.training.collisions_per_1000"]
    cov = table["eval.training.coverage"]
    best = best_trial(log)
    # no other trial is at least as good on both counts and better on one
    assert not any((coll[k] <= coll[best] and cov[k] >= cov[best]) and
                   (coll[k] < coll[best] or cov[k] > cov[best]) for k in range(len(table)))
    # a log evaluated only in other rooms cannot be ranked without peeking at them
    other = tmp_path / "other.toml"
    other.write_text(small_config(trials=1, iterations=100))
    out2 = tmp_path / "other.h5"
    run_json(capsys, "run", str(other), "--out", str(out2), "--workers", "1", "--json")
    with pytest.raises(InputError, match="no evaluation in its learning world 'training'"):
        best_trial(open_log(out2))
