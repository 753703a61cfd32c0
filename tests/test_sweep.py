"""`sitframe sweep`: one log per grid point (identical to `sitframe run`), summary tables,
one-line errors for bad keys, empty grids and unreachable schedulers."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest
from helpers import small_config

from sitframe.cli.app import main
from sitframe.logs.compare import compare_logs
from sitframe.logs.reader import open_log
from sitframe.runs.sweep import point_names

BASE = small_config(name="base", iterations=200, seed=7, c=4, fcm_trials=3,
                    eval_iterations=60)

SWEEP = """
[sweep]
name = "mini"
base = "base.toml"
trials = 2

[grid]
"behaviours.avoid.update" = ["thesis", "standard"]
"interpreter.c" = [4, 5]
"""


@pytest.fixture(scope="module")
def swept(tmp_path_factory):
    d = tmp_path_factory.mktemp("sweep")
    (d / "base.toml").write_text(BASE)
    (d / "mini.toml").write_text(SWEEP)
    out = d / "out"
    assert main(["sweep", str(d / "mini.toml"), "--out", str(out), "--workers", "2",
                 "--json"]) == 0
    return d, out


def test_sweep_writes_a_log_per_point_and_tables(swept, capsys):
    _d, out = swept
    names = ["update=thesis_c=4", "update=thesis_c=5", "update=standard_c=4",
             "update=standard_c=5"]
    for name in names:
        log = open_log(out / f"{name}.h5")
        assert log.status == "complete"
        assert log.trial_indices() == [0, 1]
    assert open_log(out / "update=standard_c=5.h5").config["interpreter"]["c"] == 5
    assert open_log(out / "update=standard_c=5.h5").config["behaviours"]["avoid"]["update"] \
        == "standard"
    with open(out / "summary.csv", encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    assert [r["point"] for r in rows] == names
    assert {"convergence_rate", "conv_iter_median", "conv_iter_q25", "post_coll_median",
            "eval_novel-1_coll_median", "eval_novel-1_coverage_median"} <= set(rows[0])
    md = (out / "summary.md").read_text()
    assert md.count("\n") == 2 + len(names) and "novel-1: coverage" in md


def test_sweep_point_equals_plain_run(swept, tmp_path, capsys):
    d, out = swept
    cfg = tmp_path / "point.toml"
    text = BASE.replace("c = 4", "c = 5").replace('p = 5', 'p = 5\nupdate = "standard"')
    text = text.replace('name = "base"', 'name = "mini/update=standard_c=5"')
    cfg.write_text(text)
    ref = tmp_path / "ref.h5"
    assert main(["run", str(cfg), "--out", str(ref), "--workers", "1", "--json"]) == 0
    capsys.readouterr()
    assert compare_logs(ref, out / "update=standard_c=5.h5") == []


def test_sweep_json_and_one_worker(swept, tmp_path, capsys):
    d, out = swept
    capsys.readouterr()
    out1 = tmp_path / "one"
    assert main(["sweep", str(d / "mini.toml"), "--out", str(out1), "--workers", "1",
                 "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert [p["point"] for p in doc["points"]][0] == "update=thesis_c=4"
    assert doc["points"][0]["trials"] == 2
    for name in ("update=thesis_c=4", "update=standard_c=5"):
        assert compare_logs(out / f"{name}.h5", out1 / f"{name}.h5") == []


def test_reuse_keeps_complete_logs_of_the_same_config_and_runs_the_rest(swept, tmp_path,
                                                                         capsys):
    """Adding a grid value with --reuse runs only the new point, and says which logs it
    kept; a log of another config (here: another trial count) is run again."""
    import shutil

    d, out = swept
    out2 = tmp_path / "reuse"
    shutil.copytree(out, out2)
    before = {p.name: p.stat().st_mtime_ns for p in out2.glob("*.h5")}
    (d / "more.toml").write_text(SWEEP.replace('"interpreter.c" = [4, 5]',
                                               '"interpreter.c" = [4, 5, 6]'))
    capsys.readouterr()
    assert main(["sweep", str(d / "more.toml"), "--out", str(out2), "--workers", "2",
                 "--json", "--reuse"]) == 0
    cap = capsys.readouterr()
    doc = json.loads(cap.out)
    assert len(doc["points"]) == 6 and "reusing 0 of" not in cap.err
    assert sorted(doc["reused"]) == sorted(n.removesuffix(".h5") for n in before)
    assert "reusing 4 of 6 points' logs" in cap.err  # (said, not silent)
    for name, t in before.items():
        assert (out2 / name).stat().st_mtime_ns == t, f"{name} was rewritten"
    new = open_log(out2 / "update=thesis_c=6.h5")
    assert new.status == "complete" and new.config["interpreter"]["c"] == 6
    # the same file, another trial count: nothing is reused
    (d / "more3.toml").write_text(SWEEP.replace("trials = 2", "trials = 3"))
    assert main(["sweep", str(d / "more3.toml"), "--out", str(out2), "--workers", "2",
                 "--json", "--reuse"]) == 0
    cap = capsys.readouterr()
    assert json.loads(cap.out)["reused"] == [] and "reusing" not in cap.err
    assert open_log(out2 / "update=thesis_c=4.h5").trial_indices() == [0, 1, 2]
    # the same config made by other code (a plugin edited since): run again, and said
    import h5py

    with h5py.File(out2 / "update=thesis_c=4.h5", "r+") as f:
        f.attrs["code_hash"] = "0" * 64
    assert main(["sweep", str(d / "more3.toml"), "--out", str(out2), "--workers", "2",
                 "--json", "--reuse"]) == 0
    cap = capsys.readouterr()
    assert sorted(json.loads(cap.out)["reused"]) == ["update=standard_c=4",
                                                     "update=standard_c=5",
                                                     "update=thesis_c=5"]
    assert "not reusing 1 of 4 points' logs" in cap.err and "update=thesis_c=4" in cap.err
    assert open_log(out2 / "update=thesis_c=4.h5").attrs["code_hash"] != "0" * 64


def test_seed_axis_gives_tables_pooled_over_seeds(swept, tmp_path, capsys):
    d, _out = swept
    (d / "seeds.toml").write_text(SWEEP.replace('"interpreter.c" = [4, 5]',
                                                '"experiment.seed" = [1, 2]'))
    out = tmp_path / "seeds"
    assert main(["sweep", str(d / "seeds.toml"), "--out", str(out), "--workers", "2",
                 "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert len(doc["points"]) == 4 and len(doc["pooled"]) == 2
    for row in doc["pooled"]:  # each setting pools its two seed runs' trials
        runs = [open_log(p["log"]).summary() for p in doc["points"]
                if p["behaviours.avoid.update"] == row["behaviours.avoid.update"]]
        assert row["seeds"] == 2 and row["trials"] == 4
        coll = np.concatenate([t["eval.novel-1.collisions_per_1000"] for t in runs])
        assert row["eval_novel-1_coll_max"] == coll.max()
        assert row["eval_novel-1_coll_median"] == np.median(coll)
    with open(out / "summary-pooled.csv", encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    assert [r["behaviours.avoid.update"] for r in rows] == ["thesis", "standard"]
    assert "seeds" in (out / "summary-pooled.md").read_text()


def test_point_names_use_short_keys_unless_ambiguous():
    names = [n for n, _v in point_names({"interpreter.c": [8], "behaviours.a.p": [1.5],
                                         "behaviours.b.p": [2]})]
    assert names == ["c=8_behaviours.a.p=1.5_behaviours.b.p=2"]


@pytest.mark.parametrize(
    ("grid", "pattern"),
    [
        ('"interpreter.cc" = [4, 5]', r"grid.interpreter.cc: .*did you mean 'interpreter.c'"),
        ('"behaviours.avoid.updat" = ["thesis"]',
         r"did you mean 'behaviours.avoid.update'"),
        ('"behaviours.avod.update" = ["thesis"]', r"not a setting of the base experiment"),
        ('"experiment.iteration" = [10]', r"did you mean 'experiment.iterations'"),
        ('"robots.radius" = [0.2]', r"did you mean 'robot'"),
        ('"interpreter.c" = []', r"grid.interpreter.c: expected a non-empty list"),
        ('"interpreter.c" = [0]', r"point c=0: interpreter"),
        ('"sensor" = [{ component = "laser", beams = 0 }]',
         r"point sensor=laser-beams=0: sensor.beams: expected an integer"),
        ("", r"grid: the grid is empty"),
    ],
)
def test_bad_sweeps_one_line_exit_2(swept, tmp_path, capsys, grid, pattern):
    import re

    d, _out = swept
    f = tmp_path / "bad.toml"
    f.write_text(f'[sweep]\nbase = "{d / "base.toml"}"\n[grid]\n{grid}\n')
    out = tmp_path / "never"
    capsys.readouterr()
    assert main(["sweep", str(f), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and re.search(pattern, err), err
    assert not out.exists()


def test_sweep_unreachable_scheduler_exit_2(swept, tmp_path, capsys, monkeypatch):
    pytest.importorskip("distributed")
    monkeypatch.setattr("sitframe.runs.parallel.DASK_CONNECT_TIMEOUT", 0.5)  # (default 5 s)
    d, _out = swept
    out = tmp_path / "never"
    capsys.readouterr()
    assert main(["sweep", str(d / "mini.toml"), "--out", str(out), "--scheduler",
                 "tcp://127.0.0.1:9"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "cannot reach the Dask scheduler" in err
    assert not out.exists()


def test_sweep_file_errors(tmp_path, capsys):
    assert main(["sweep", str(tmp_path / "nope.toml")]) == 2
    assert "sweep file not found" in capsys.readouterr().err
    f = tmp_path / "s.toml"
    f.write_text('[sweep]\nbase = "obstacle-avoid"\n[grid]\n"interpreter.c" = [8]\n')
    assert main(["sweep", str(f)]) == 2
    err = capsys.readouterr().err
    assert "did you mean 'obstacle-avoidance'" in err and "sweep.base" in err


@pytest.mark.parametrize("name", ["ablation", "oa12-optimism", "oa8-optimism", "sensors",
                                  "sensors-beams", "obstacle-avoidance", "obstacle-avoidance-12"])
def test_shipped_sweeps_load(name):
    """The sweep files the README cites resolve every point (keys, values, presets)."""
    from pathlib import Path

    from sitframe.runs.sweep import load_sweep

    path = Path(__file__).resolve().parents[1] / "sweeps" / f"{name}.toml"
    sweep = load_sweep(str(path))
    assert len(sweep.points) == {"ablation": 60, "sensors": 20, "sensors-beams": 10,
                                 "oa12-optimism": 40, "oa8-optimism": 40}.get(name, 10)
    if name == "sensors":  # a whole [sensor] table per value, replacing the base's
        sonar, laser = sweep.points[0], sweep.points[-1]
        assert sonar.name == "sensor=pioneer-sonar-beam_width_deg=25-rays_per_beam=5_seed=0"
        assert laser.name == "sensor=laser-fov_deg=180-beams=16-max_range=4_seed=9"
        assert laser.experiment.cfg["sensor"] == {"component": "laser", "fov_deg": 180,
                                                  "beams": 16, "max_range": 4.0}


def test_sweep_on_a_two_worker_dask_cluster_gives_the_local_summaries(swept, tmp_path, capsys):
    """Two of the local sweep's points (c = 4), their trials spread over two Dask workers."""
    distributed = pytest.importorskip("distributed")
    d, local = swept
    (d / "dask.toml").write_text(SWEEP.replace('"interpreter.c" = [4, 5]', "")
                                 + '[set]\n"interpreter.c" = 4\n')
    out = tmp_path / "dask"
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False,
                                  protocol="tcp", host="127.0.0.1",
                                  dashboard_address="127.0.0.1:0") as cluster:
        assert main(["sweep", str(d / "dask.toml"), "--out", str(out), "--scheduler",
                     cluster.scheduler_address, "--json"]) == 0
        ran = [w.state.executed_count for w in cluster.workers.values()]
    capsys.readouterr()
    assert len(ran) == 2 and min(ran) > 0, ran  # both workers ran stages or trials

    def rows(folder):
        with open(folder / "summary.csv", encoding="utf-8") as fh:
            return {r["point"]: {k: v for k, v in r.items() if k not in ("point", "log",
                                                                        "interpreter.c")}
                    for r in csv.DictReader(fh)}

    there, here = rows(out), rows(local)
    for update in ("thesis", "standard"):
        assert there[f"update={update}"] == here[f"update={update}_c=4"]
        assert compare_logs(local / f"update={update}_c=4.h5", out / f"update={update}.h5") == []


def test_tables_give_an_episode_protocols_scores_per_world():
    """A goal sweep's tables show the goal episodes' scores (success, SPL, ...) per world,
    median [IQR] over the trials of every seed, not only frozen-run collisions."""
    from sitframe.runs.summaries import markdown_table, summarise_tables

    def table(success: list[float], spl: list[float]) -> np.ndarray:
        dt = [("trial", "i8"), ("converged", "?"), ("convergence_iteration", "f8"),
              ("eval.goal.success_rate", "f8"), ("eval.goal.spl", "f8"),
              ("eval.goal.episodes", "f8"), ("eval.u-trap.success_rate", "f8")]
        rows = [(i, False, np.nan, s, p, 50.0, np.nan) for i, (s, p) in
                enumerate(zip(success, spl, strict=True))]
        return np.array(rows + [(len(rows), False, np.nan, np.nan, np.nan, np.nan, 0.5)], dt)

    row = summarise_tables([table([1.0, 0.8], [0.6, 0.7]), table([0.9], [0.5])])
    assert row["eval_scores"] == {"goal": ["success_rate", "spl"], "u-trap": ["success_rate"]}
    assert row["eval_goal_success_rate_median"] == 0.9  # NaN rows (other worlds) left out
    assert row["eval_goal_spl_q25"] == np.percentile([0.6, 0.7, 0.5], 25)
    assert row["eval_u-trap_success_rate_median"] == 0.5
    md = markdown_table({"points": [{"point": "all", "trials": 5, **row}], "keys": []})
    assert "| world | success_rate | spl |" in md
    assert "| goal | 0.90 [0.85, 0.95] | 0.60 [0.55, 0.65] |" in md
    assert "| u-trap | 0.50 [0.50, 0.50] | – |" in md


def test_a_run_that_learned_nothing_shows_no_convergence_count():
    """Goal episodes of frozen behaviours: "–" where "0/N converged" would be untrue; a
    learning run whose trials did not converge still shows 0/N."""
    from sitframe.runs.summaries import markdown_table, summarise_tables

    t = np.array([(0, False, -1.0), (1, False, -1.0)],
                 [("trial", "i8"), ("converged", "?"), ("convergence_iteration", "f8")])
    for learned, cell in ((False, "| 2 | – |"), (True, "| 2 | 0/2 |")):
        row = summarise_tables([t], learned=learned)
        assert (row["convergence_rate"] == 0.0) is learned
        md = markdown_table({"points": [{"point": "all", **row}], "keys": []})
        assert md.splitlines()[2].startswith(cell)


def test_the_arbiters_reward_parameters_are_sweep_keys():
    """``arbiter.reward_params.NAME`` names one parameter of the arbiter's reward, as
    ``behaviours.LABEL.reward_params.NAME`` does a behaviour's; a misspelt one is refused."""
    from sitframe.contract.config import load_config
    from sitframe.contract.pluginmanager import Registry, get_plugin_manager
    from sitframe.errors import InputError
    from sitframe.runs.sweep import check_key

    cfg = load_config("goal-finding-learned")[0]
    reg = Registry.collect(get_plugin_manager())
    for key in ("arbiter.reward_params.distance", "arbiter.reward_params", "arbiter.gamma",
                "behaviours.avoid.policy_from"):
        check_key(key, cfg, reg)
    with pytest.raises(InputError, match=r"did you mean 'arbiter.reward_params.distance'"):
        check_key("arbiter.reward_params.distanse", cfg, reg)
    with pytest.raises(InputError, match="not a setting"):
        check_key("interpreter.reward_params", cfg, reg)
    # the [goal] table's optional keys (no default, so absent from most configs) too
    for key in ("goal.train", "goal.train_detour", "goal.detour_ratio"):
        check_key(key, cfg, reg)
    with pytest.raises(InputError, match=r"did you mean 'goal.train_detour'"):
        check_key("goal.train_detours", cfg, reg)


@pytest.mark.parametrize(("grid", "pattern"), [
    ('"arbiter.reward_params.distance" = ["paths"]',
     r"point distance=paths: arbiter.reward_params.distance: expected one of 'straight', "
     r"'path', got 'paths'"),
    ('"behaviours.avoid.p" = [-1]', r"point p=-1: behaviours.avoid.p: "),
])
def test_a_bad_point_value_is_refused_before_the_prerequisites_are_made(tmp_path, grid, pattern):
    """A grid value a component refuses is reported (one located line) before the base's
    prerequisite runs are made, not after them."""
    from sitframe.errors import InputError
    from sitframe.runs.sweep import load_sweep

    f = tmp_path / "s.toml"
    f.write_text(f'[sweep]\nbase = "goal-finding-learned"\n[grid]\n{grid}\n')
    made = []
    with pytest.raises(InputError, match=pattern) as exc:
        load_sweep(str(f), prerequisites=lambda cfg, base_dir: made.append(cfg))
    assert made == [] and "\n" not in str(exc.value)
