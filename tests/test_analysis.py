"""Analysis API, figures, tables, `analyse` and `replay` on a tiny real log."""

from __future__ import annotations

import math
import os
import shutil

import h5py
import numpy as np
import pytest
from helpers import run_config, small_config
from matplotlib.figure import Figure

from sitframe import analysis as A
from sitframe.cli.app import main
from sitframe.errors import InputError
from sitframe.plugins.sonar import PIONEER_ANGLES_DEG as PIONEER
from sitframe.sim.world import parse_world

TINY = small_config(name="tiny", seed=5, sweep=(3, 6))


@pytest.fixture(scope="module")
def tiny_log(tmp_path_factory):
    return run_config(tmp_path_factory.mktemp("analysis"), TINY, "tiny.h5")[1]


@pytest.fixture(scope="module")
def log(tiny_log):
    return A.as_log(tiny_log)


@pytest.fixture(scope="module")
def trial(log):
    return log.trial(0)


# ------------------------------------------------------------------------ arrays


def test_exploration_counts_sum_to_iterations(trial):
    counts = A.exploration_counts(trial)
    assert counts.shape == (6, 7)
    assert counts.sum() == 300
    # each row's total = iterations in which that situation was dominant
    dom = trial.arrays["memberships"].argmax(axis=1)
    np.testing.assert_array_equal(counts.sum(axis=1), np.bincount(dom, minlength=6))
    assert A.exploration_counts(trial, start=100, stop=150).sum() == 50


def test_reward_per_window_length_and_values():
    r = np.arange(120, dtype=float)
    m = A.reward_per_window(r, 50)
    assert m.shape == (math.ceil(120 / 50),)
    np.testing.assert_allclose(m, [24.5, 74.5, 109.5])  # last window is 20 long
    with pytest.raises(ValueError):
        A.reward_per_window(r, 0)


def test_reward_per_window_on_log(trial):
    assert A.reward_per_window(trial.arrays["reward/avoid"]).shape == (math.ceil(300 / 50),)


def test_collision_intervals():
    c = np.zeros(20, bool)
    c[[3, 4, 10]] = True
    ci = A.collision_intervals(c)
    np.testing.assert_array_equal(ci.iterations, [3, 4, 10])
    np.testing.assert_array_equal(ci.intervals, [4, 1, 6])
    assert ci.n_iterations == 20
    assert A.collision_intervals(np.zeros(5, bool)).intervals.size == 0


def test_situation_labels_and_config_readers(log):
    labels = A.situation_labels(log)
    assert len(labels) == 6 and labels[0].startswith("S1: ") and labels[-1].startswith("S6: ")
    assert A.sensor_angles(log).tolist() == [90, 50, 30, 10, -10, -30, -50, -90]
    assert A.robot_radius(log) == pytest.approx(0.15)


def test_clustering_from_log(log):
    ct = A.clustering_trials(log)
    assert ct.n_trials == 4 and ct.c == 6
    assert ct.chosen == log.stage("cluster")["chosen"]
    sw = A.sweep_result(log)
    assert sw is not None and sw.cs.tolist() == [3, 6]


# ------------------------------------------------------------------------ tables


def test_lookup_and_rule_base_tables_one_row_per_situation(log, trial):
    lt = A.lookup_table(log, trial)
    assert len(lt.rows) == 6
    assert lt.columns[2:9] == ["+90°", "+60°", "+30°", "0°", "-30°", "-60°", "-90°"]
    q = trial.behaviours["avoid"]["heading/q"]
    np.testing.assert_allclose([r[2:9] for r in lt.rows], q)
    rb = A.rule_base_table(log, 0)
    assert [r[0] for r in rb.rows] == list(range(1, 7))  # situations numbered from 1
    singles = trial.behaviours["avoid"]["actions/heading"]
    assert rb.column("Action [deg]") == [int(singles[i]) for i in trial.policy("avoid")["heading"]]
    assert sum(rb.column("Dominant [%]")) == pytest.approx(100.0)
    md, csv = rb.to_markdown(), rb.to_csv()
    assert md.count("\n| ") == 1 + 6  # header + rows
    assert csv.splitlines()[0] == "Situation,Description,Action [deg],Max Q,Dominant [%]"
    assert len(csv.splitlines()) == 7


def test_convergence_and_rule_base_tables(log):
    t = A.convergence_table(log)
    assert [r[0] for r in t.rows] == [0, 1, "mean"]
    assert "novel-1 collisions [/1000 it.]" in t.columns
    s = log.summary()
    assert t.column("Collisions [/1000 it.]")[:2] == pytest.approx(s["collisions_per_1000"])
    rb = A.rule_bases_across_trials(log)
    assert len(rb.rows) == 6 and {"T0", "T1"} <= {c.rstrip("*") for c in rb.columns}


# ----------------------------------------------------------------------- figures


def test_figures_are_figures(log, trial):
    conv = A.convergence_iteration(trial)
    world = parse_world(log.worlds[trial.world])
    figs = [
        A.plot_prototypes(log.interpreter_state()["centers"], PIONEER),
        A.plot_measures_by_trial(A.clustering_trials(log)),
        A.plot_measures_by_c(A.sweep_result(log)),
        A.plot_exploration(A.exploration_counts(trial), A.situation_labels(log),
                           trial.behaviours["avoid"]["actions/heading"]),
        A.plot_collision_intervals(A.collision_intervals(trial.arrays["collision"]), conv),
        A.plot_reward_per_window(trial.arrays["reward/avoid"], 50, conv),
        A.plot_learning_curves({0: trial.arrays["reward/avoid"]}, {0: conv}),
        A.plot_trajectory(world, trial.arrays["pose"], collision=trial.arrays["collision"],
                          contact=trial.arrays["contact"], start=10, stop=200),
        A.plot_evaluation_paths({"novel-1": parse_world(log.worlds["novel-1"])},
                                A.evaluation_episodes(trial)),
    ]
    assert all(isinstance(f, Figure) for f in figs)
    # exploration annotates every cell with its count
    texts = [t.get_text() for t in figs[3].axes[0].texts]
    assert sum(int(t) for t in texts) == 300


# ---------------------------------------------------------------------- commands


def test_analyse_command_writes_index(tiny_log, tmp_path, capsys):
    out = tmp_path / "rep"
    assert main(["analyse", str(tiny_log), "-o", str(out)]) == 0
    captured = capsys.readouterr()
    assert captured.err == ""
    index = (out / "index.md").read_text()
    for name in ("prototypes.png", "measures_by_trial.png", "measures_by_c.png",
                 "learning_curves.png", "convergence.md", "rule_bases.md"):
        assert (out / name).exists() and f"]({name})" in index
    k = A.representative_trial(tiny_log)
    for name in (f"exploration_trial{k}.png", f"reward_trial{k}.png",
                 f"collision_intervals_trial{k}.png", f"trajectory_trial{k}.png",
                 f"evaluation_trial{k}.png", f"lookup_table_trial{k}.csv",
                 f"rule_base_trial{k}.md"):
        assert (out / name).exists(), name
    assert "Incomplete" not in index
    page = (out / "index.html").read_text()  # the page shows every figure and table
    assert captured.out.startswith(str(out / "index.html"))
    for png in out.glob("*.png"):
        assert f'<img src="{png.name}"' in page
    assert page.count("<table") >= 5 and 'id="replay-data"' in page
    assert "http://" not in page and "https://" not in page  # nothing from the network


def test_analyse_aborted_log_reports_what_is_missing(tiny_log, tmp_path, capsys):
    bad = tmp_path / "aborted.h5"
    shutil.copy(tiny_log, bad)
    with h5py.File(bad, "a") as f:
        del f["trials/0001"]
        del f["trials/0000/episodes"]
        f.attrs["status"] = "aborted"
    assert main(["analyse", str(bad)]) == 0
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "incomplete" in err and "aborted" in err
    index = (tmp_path / "aborted-analysis" / "index.md").read_text()
    assert "## Incomplete log" in index
    assert "'aborted'" in index
    assert "1 of 2 learning trials missing: 1" in index
    assert "evaluation in 'novel-1' missing for trial(s) 0" in index
    assert (tmp_path / "aborted-analysis" / "exploration_trial0.png").exists()


@pytest.mark.parametrize("content", [None, b"not hdf5", "h5-not-sitframe"])
def test_analyse_bad_input_is_one_line_error(tmp_path, capsys, content):
    p = tmp_path / "x.h5"
    if content == "h5-not-sitframe":
        with h5py.File(p, "w") as f:
            f.attrs["schema"] = "other"
    elif content is not None:
        p.write_bytes(content)
    assert main(["analyse", str(p)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("sitframe: error: ") and err.count("\n") == 1
    with pytest.raises(InputError):
        A.analyse(p)


def test_replay_gif_and_errors(tiny_log, tmp_path, capsys):
    gif = tmp_path / "t.gif"
    assert main(["replay", str(tiny_log), "--trial", "1", "--from", "20", "--to", "32",
                 "-o", str(gif)]) == 0
    from PIL import Image

    with Image.open(gif) as im:
        assert im.n_frames == 12
    capsys.readouterr()
    assert main(["replay", str(tiny_log), "--trial", "7", "-o", str(gif)]) == 2
    assert "no trial 7" in capsys.readouterr().err
    assert main(["replay", str(tiny_log), "-o", str(tmp_path / "t.avi")]) == 2
    capsys.readouterr()
    # a frozen-policy evaluation replays too; an unknown world names the ones there are
    world = A.as_log(tiny_log).config["evaluate"]["worlds"][0]
    assert main(["replay", str(tiny_log), "--trial", "0", "--eval", world, "--to", "5",
                 "-o", str(gif)]) == 0
    with Image.open(gif) as im:
        assert im.n_frames == 5
    capsys.readouterr()
    assert main(["replay", str(tiny_log), "--eval", "atlantis", "-o", str(gif)]) == 2
    err = capsys.readouterr().err
    assert "--eval" in err and world in err
    if shutil.which("ffmpeg") is None:
        assert main(["replay", str(tiny_log), "-o", str(tmp_path / "t.mp4")]) == 2
        assert "ffmpeg" in capsys.readouterr().err


def test_replay_refuses_a_window_outside_the_trial(tiny_log, tmp_path, capsys):
    gif = str(tmp_path / "w.gif")
    L = A.as_log(tiny_log).trial(0).arrays["collision"].size
    assert main(["replay", str(tiny_log), "--from", str(L), "-o", gif]) == 2
    err = capsys.readouterr().err
    assert err == (f"sitframe: error: --from: --from must be in [0, {L - 1}] (trial 0 has {L} "
                   f"iterations), got {L}\n")
    assert main(["replay", str(tiny_log), "--from", "5", "--to", "5", "-o", gif]) == 2
    assert capsys.readouterr().err == \
        "sitframe: error: --to: --to must be greater than --from (5), got 5\n"
    assert main(["replay", str(tiny_log), "--fps", "0", "-o", gif]) == 2
    assert capsys.readouterr().err == "sitframe: error: --fps: must be at least 1, got 0\n"
    assert not (tmp_path / "w.gif").exists()


FAKE_FFMPEG = """#!/bin/sh
# stands in for ffmpeg: keeps its arguments and the raw frames it is sent, or fails as an
# ffmpeg built without libx264 does
for last; do :; done
printf '%s\\n' "$@" > "$(dirname "$0")/args"
if [ -n "$FAIL" ]; then cat > /dev/null; echo "Unknown encoder 'libx264'" >&2; exit 1; fi
cat > "$last"
"""


def test_replay_mp4_pipes_every_frame_to_ffmpeg(tiny_log, tmp_path, capsys, monkeypatch):
    bindir = tmp_path / "bin"
    bindir.mkdir()
    (bindir / "ffmpeg").write_text(FAKE_FFMPEG)
    (bindir / "ffmpeg").chmod(0o755)
    monkeypatch.setenv("PATH", f"{bindir}:{os.environ['PATH']}")
    mp4 = tmp_path / "t.mp4"
    assert main(["replay", str(tiny_log), "--from", "3", "--to", "7", "--fps", "5",
                 "-o", str(mp4)]) == 0
    args = (bindir / "args").read_text().split("\n")
    w, h = map(int, args[args.index("-s") + 1].split("x"))
    assert args[args.index("-r") + 1] == "5" and "libx264" in args
    # 4 frames of w x h RGB, renamed into place from the scratch file ffmpeg wrote
    assert mp4.stat().st_size == 4 * w * h * 3
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bin", "t.mp4"]
    capsys.readouterr()
    monkeypatch.setenv("FAIL", "1")
    bad = tmp_path / "bad.mp4"
    assert main(["replay", str(tiny_log), "--to", "3", "-o", str(bad)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("sitframe: error: ") and err.count("\n") == 1
    assert f"{bad}: -o: ffmpeg failed: Unknown encoder 'libx264'" in err  # the user's path
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bin", "t.mp4"]  # no half file


def test_replay_refuses_an_unwritable_output_and_an_incomplete_log(tiny_log, tmp_path, capsys):
    (tmp_path / "afile").write_text("")
    assert main(["replay", str(tiny_log), "--to", "3", "-o",
                 str(tmp_path / "afile" / "r.gif")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("sitframe: error: ") and "r.gif: -o: cannot write the animation" in err
    broken = tmp_path / "broken.h5"
    shutil.copy(tiny_log, broken)
    with h5py.File(broken, "r+") as f:
        del f["trials/0000/memberships"]
        f["trials/0001"].attrs["world"] = "atlantis"
    assert main(["replay", str(broken), "--trial", "0", "-o", str(tmp_path / "r.gif")]) == 2
    assert capsys.readouterr().err == (
        f"sitframe: error: {broken}: trials/0000: trial 0 lacks the arrays ['memberships']\n")
    assert main(["replay", str(broken), "--trial", "1", "-o", str(tmp_path / "r.gif")]) == 2
    assert capsys.readouterr().err == (
        f"sitframe: error: {broken}: worlds: the log does not hold the world 'atlantis'\n")
    assert not (tmp_path / "r.gif").exists()
