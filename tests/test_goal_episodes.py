"""Goal episodes (the goal-episodes protocol): pairs, ending at the goal or the timeout,
batches, goal runs, evaluate."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest

from sitframe.cli.app import main
from sitframe.contract.config import load_config, preset_text, validate_config
from sitframe.contract.pluginmanager import Registry, get_plugin_manager
from sitframe.contract.resolve import Resolved
from sitframe.errors import InputError
from sitframe.logs.reader import open_log
from sitframe.plugins.goal_episodes import AGGREGATE_KEYS, GoalEpisodes, goal_pairs, world_pairs
from sitframe.runs.evaluation import evaluate_log, select_trial
from sitframe.runs.loop import TrialSpec, batch_scores, simulate
from sitframe.runs.prepare import prepare_experiment
from sitframe.sim.world import load_world, parse_world

STATE = {"centers": np.array([[0.5] * 8, [3.0] * 8]), "m": 1.2}


def goal_only(goal: dict | None = None, **arbiter) -> Resolved:
    cfg = validate_config({
        "interpreter": {"component": "fcm", "c": 2},
        "behaviours": {"goal": {"component": "goal"}},
        "arbiter": {"component": "single", **arbiter},
        "goal": goal or {},
    })
    return Resolved.build(cfg, Registry.collect(get_plugin_manager()))


def spec(**kw) -> TrialSpec:
    base = {"index": 0, "seed": 7, "world": "goal", "iterations": 300, "learn": False,
            "interpreter_state": STATE}
    return TrialSpec(**{**base, **kw})


def test_episode_ends_at_goal():
    res = goal_only()
    r = simulate(res, spec(start=(1.0, 1.0, 0.0), goal=(3.0, 1.0, 0.3)), protocol=GoalEpisodes())
    n = r.arrays["collision"].size
    assert n < 20
    assert math.hypot(r.arrays["pose"][-1, 0] - 3.0, r.arrays["pose"][-1, 1] - 1.0) <= 0.3
    assert r.arrays["pose"].shape == (n + 1, 3)


def test_episode_ends_at_timeout_not_at_collision():
    res = goal_only()
    # the goal is behind the wall x = 6.5 (y < 3.5): the robot pushes into the wall
    r = simulate(res, spec(start=(5.5, 1.0, 0.0), goal=(8.0, 1.0, 0.3), iterations=25),
                 protocol=GoalEpisodes())
    assert r.arrays["collision"].size == 25
    assert r.arrays["collision"].sum() > 0


def test_random_pairs_are_free_far_apart_and_deterministic():
    w = load_world("goal")
    s1, g1 = goal_pairs(w, 6, np.random.default_rng(3), min_distance=3.0)
    s2, g2 = goal_pairs(w, 6, np.random.default_rng(3), min_distance=3.0)
    s3, _ = goal_pairs(w, 6, np.random.default_rng(4), min_distance=3.0)
    np.testing.assert_array_equal(s1, s2)
    np.testing.assert_array_equal(g1, g2)
    assert not np.array_equal(s1, s3)
    assert np.all(np.hypot(*(g1[:, :2] - s1[:, :2]).T) >= 3.0)
    assert w.is_free(g1[:, :2], 0.25).all() and w.is_free(s1[:, :2], 0.25).all()
    assert np.all(g1[:, 2] == 0.3)
    with pytest.raises(InputError, match="min_distance"):
        goal_pairs(w, 1, np.random.default_rng(0), min_distance=50.0, max_tries=20)


def test_a_repeated_draw_gives_the_same_pairs_and_leaves_the_generator_alike():
    """Trials drawing their evaluation pairs from one seed get them from memory after the
    first: the same pairs, and the Generator left where a fresh draw leaves it (so what
    comes after the pairs, the episodes, stays bit-identical)."""
    from sitframe.sim.robot import RobotParams

    w, proto, robot = load_world("goal"), GoalEpisodes(episodes=5), RobotParams()
    rng = np.random.default_rng(8)
    s0, g0 = goal_pairs(w, 5, rng, min_distance=proto.min_distance, goal_radius=proto.radius,
                        robot_radius=robot.radius, margin=proto.margin)
    after = rng.random(4)
    for _ in range(3):  # the first draw through the protocol, then from memory
        rng = np.random.default_rng(8)
        starts, goals = proto.episode_starts(w, rng, robot)
        np.testing.assert_array_equal(starts, s0)
        np.testing.assert_array_equal(goals, g0)
        np.testing.assert_array_equal(rng.random(4), after)
        starts[:] = 0.0  # a caller's change does not reach the memory
    assert not np.array_equal(proto.episode_starts(w, np.random.default_rng(9), robot)[0], s0)


def test_world_pairs_need_a_goal():
    s, g = world_pairs(load_world("goal"), 2)
    assert g[0].tolist() == [9.0, 7.0, 0.3]
    with pytest.raises(InputError, match="no \\[goal\\]"):
        world_pairs(load_world("training"), 1)


def test_batch_is_deterministic_and_scored():
    res = goal_only({"episodes": 3, "timeout": 60})
    assert res.protocol_name() == "goal-episodes"
    a = simulate(res, spec(protocol="goal-episodes"))
    b = simulate(res, spec(protocol="goal-episodes"))
    agg = batch_scores(a)
    assert set(AGGREGATE_KEYS) <= set(agg)
    assert json.dumps(agg) == json.dumps(batch_scores(b))  # NaN-safe equality
    assert agg["episodes"] == 3
    e = a.episodes
    assert e["success"].shape == (3,) and e["start"].shape == (3, 3)
    assert a.arrays["collision"].size == e["iterations"].sum()
    assert e["time_s"].tolist() == (e["iterations"] * 1.5).tolist()
    assert 0.0 <= agg["spl"] <= agg["success_rate"]
    assert e["0001"]["iterations"] == e["iterations"][1]


def test_episode_config_validation():
    with pytest.raises(InputError, match="pairs"):
        GoalEpisodes(pairs="fixed")
    # the protocol's table is declared (plugins/goal_episodes.py), so the config checks it,
    # a goal run or not; and the protocol checks it again when any run resolves
    with pytest.raises(InputError, match=r"goal\.timeout: expected an integer in \[1, inf\)"):
        validate_config({"behaviours": {"a": {"component": "fuzzy-q"}}, "goal": {"timeout": 0}})
    cfg = validate_config({"behaviours": {"a": {"component": "fuzzy-q"}}})
    cfg["goal"]["pairs"] = "fixed"  # (past the config's check)
    with pytest.raises(InputError, match=r"goal\.pairs.*expected one of"):
        Resolved.build(cfg, Registry.collect(get_plugin_manager()))


@pytest.mark.parametrize("goal, where", [("[20, 4]", "outside the walls"),
                                         ("[5.0, 4.0]", "inside an obstacle")])
def test_goal_outside_or_in_obstacle_is_an_input_error(goal, where):
    text = load_world("goal").text.replace("position = [9, 7]", f"position = {goal}")
    with pytest.raises(InputError, match=where):
        parse_world(text, file="bad.toml")


# ---------------------------------------------------------------------------
# with a (tiny) learned obstacle-avoidance log
# ---------------------------------------------------------------------------

@pytest.fixture(scope="module")
def oa_log(tmp_path_factory):
    d = tmp_path_factory.mktemp("oa")
    cfg, source, _ = load_config("obstacle-avoidance-12")  # the log goal-finding fuses
    cfg["experiment"].update(trials=1, iterations=200,
                             stages=["collect", "cluster", "learn", "evaluate"])
    cfg["evaluate"].update(worlds=["training"], iterations=50)  # lets trial = "best" rank
    cfg["collect"]["worlds"] = ["collect-1", "collect-2"]
    cfg["interpreter"]["trials"] = 3
    out = str(d / "oa.h5")
    exp, kw = prepare_experiment(cfg, source=source, out=out)
    exp.run(**kw)
    return out


def test_evaluate_goal_episodes(oa_log):
    r = evaluate_log(oa_log, world="goal", goal_episodes=2)
    assert set(AGGREGATE_KEYS) <= set(r) and r["episodes"] == 2 and r["arbiter"] == "cdb"
    p = evaluate_log(oa_log, world="goal", goal_episodes=2, arbiter="priority")
    assert p["arbiter"] == "priority"
    with pytest.raises(InputError, match="unknown arbiter 'nope'.*available: cdb, "
                       "fuzzy-q-arbiter, priority"):
        evaluate_log(oa_log, world="goal", goal_episodes=2, arbiter="nope")


def test_cli_evaluate_goal_json_and_errors(oa_log, capsys):
    assert main(["evaluate", oa_log, "--world", "goal", "--goal-episodes", "2", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    for key in ("episodes", "success_rate", "collisions_per_episode", "spl", "mean_time_s",
                "heading_change_per_m"):
        assert key in doc
    assert main(["evaluate", oa_log, "--world", "goal", "--goal-episodes", "2",
                 "--arbiter", "nope"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "available: cdb, fuzzy-q-arbiter, priority, single" in err[0]


def goal_config(tmp_path, oa_log, extra: str = "") -> str:
    # (our own small log instead of the preset's prerequisite run)
    text = preset_text("goal-finding").split("[prerequisites]")[0]
    text = text.replace("logs/obstacle-avoidance-12.h5", oa_log)
    text = text.replace("episodes = 100, seed = 0", "episodes = 2, seed = 0")  # (selection)
    text = text.replace("episodes = 50", "episodes = 2").replace(
        'worlds = ["goal", "novel-1", "novel-2"]', 'worlds = ["goal"]')
    p = tmp_path / "gf.toml"
    p.write_text(text + extra)
    return str(p)


def test_goal_finding_preset_reads_like_obstacle_avoidance():
    # the preset reuses the obstacle-avoidance log's situations: same sensor and interpreter
    oa = load_config("obstacle-avoidance-12")[0]
    gf = load_config("goal-finding")[0]
    assert gf["sensor"] == oa["sensor"]
    assert {k: gf["interpreter"][k] for k in ("c", "m", "transform", "offset")} == \
        {k: oa["interpreter"][k] for k in ("c", "m", "transform", "offset")}


def test_goal_run_writes_episodes(tmp_path, oa_log):
    path = goal_config(tmp_path, oa_log)
    out = str(tmp_path / "gf.h5")
    assert main(["run", path, "--out", out, "--json"]) == 0
    tr = open_log(out).trial(0)
    assert tr.world == "goal"
    assert tr.episodes["success"].shape == (2,)
    assert "0001/success" in tr.episodes
    assert "eval/goal/success_rate" in tr.summary


def test_goal_run_without_goal_in_world_is_an_input_error(tmp_path, oa_log, capsys):
    path = goal_config(tmp_path, oa_log)
    text = Path(path).read_text().replace('pairs = "random"', 'pairs = "world"').replace(
        'worlds = ["goal"]', 'worlds = ["training"]')
    Path(path).write_text(text)
    assert main(["run", path, "--out", str(tmp_path / "x.h5")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "goal.worlds[0]" in err[0] and "no [goal]" in err[0]


def test_unknown_arbiter_in_config_lists_available(tmp_path, oa_log, capsys):
    path = goal_config(tmp_path, oa_log)
    text = Path(path).read_text().replace('component = "cdb"', 'component = "cbd"')
    Path(path).write_text(text)
    assert main(["run", path, "--out", str(tmp_path / "x.h5")]) == 2
    err = capsys.readouterr().err.strip()
    assert "unknown arbiter 'cbd'" in err
    assert "available: cdb, fuzzy-q-arbiter, priority, single" in err


def test_learning_goal_run_evaluates_each_trials_learned_policy():
    """A goal run that learns scores each trial's *learned* rule base in its goal episodes.

    (Before, the episodes ran as extra trials after the learning trials with the
    untrained behaviour: the rule base all zeros.)
    """
    from sitframe.runs.experiment import Experiment
    from sitframe.runs.loop import evaluation_specs, simulate

    cfg = validate_config({
        "experiment": {"trials": 2, "iterations": 80, "world": "goal",
                       "stages": ["learn", "evaluate"]},
        "interpreter": {"component": "fcm", "c": 2},
        "behaviours": {"avoid": {"component": "fuzzy-q", "reward": "obstacle-avoidance",
                                 "headings": [90, 0, -90]},
                       "goal": {"component": "goal"}},
        "arbiter": {"component": "cdb", "sets": {"close": [0.0, 0.0, 0.3, 0.8],
                                                 "far": [0.3, 0.8, 3.0, 3.0]},
                    "rules": {"close": "avoid", "far": "goal"}},
        "goal": {"episodes": 2, "timeout": 20, "worlds": ["goal"]},
    })
    exp = Experiment(cfg)
    result = exp.run(interpreter_state=STATE)
    assert [t.index for t in result.trials] == [0, 1]  # no extra batch with an untrained policy
    # the run drives the batches as separate tasks (TrialPipeline) and attaches them exactly
    # as one simulate() call with the evaluations inline does
    inline = [simulate(exp.res, exp.trial_spec(k, STATE)) for k in (0, 1)]
    for t, p in zip(result.trials, inline, strict=True):
        assert json.dumps(t.summary, default=str) == json.dumps(p.summary, default=str)
        np.testing.assert_array_equal(t.episodes["eval/goal/pose"], p.episodes["eval/goal/pose"])
    rules = [t.policies["avoid"].outputs["heading"].rules for t in result.trials]
    assert any(r.any() for r in rules)  # learned: not the all-zeros rule base
    for t in result.trials:
        assert t.summary["eval/goal/episodes"] == 2 and "eval/goal/success" in t.episodes
        (ev,) = evaluation_specs(exp.trial_spec(t.index, STATE), t.policies)
        assert ev.protocol == "goal-episodes" and ev.policies["avoid"] is t.policies["avoid"]
        again = simulate(exp.res, ev)
        np.testing.assert_array_equal(t.episodes["eval/goal/pose"], again.arrays["pose"])
        untrained = simulate(exp.res, dataclasses.replace(ev, policies={}))
        assert not np.array_equal(untrained.arrays["pose"], again.arrays["pose"])


@pytest.fixture(scope="module")
def oa3_log(tmp_path_factory, oa_log):
    """Three short avoidance trials on oa_log's situations: rule bases that differ."""
    d = tmp_path_factory.mktemp("oa3")
    cfg, source, _ = load_config("obstacle-avoidance-12")
    cfg["experiment"].update(trials=3, iterations=150, stages=["learn"], clusters_from=oa_log)
    out = str(d / "oa3.h5")
    exp, kw = prepare_experiment(cfg, source=source, out=out)
    exp.run(**kw)
    return out


def test_policy_from_selects_the_trial_with_the_best_short_episode_run(tmp_path, oa3_log,
                                                                        capsys):
    """``policy_from.trial = {world, episodes, score}``: the trial whose fusion scores highest
    in the same short goal-episode run (ties to the lowest index), said in one note line."""
    sel = {"world": "goal-training", "episodes": 3, "seed": 4}
    scores = {k: evaluate_log(oa3_log, world="goal-training", trial=k, seed=4, goal_episodes=3)
              for k in range(3)}
    for key in ("collision_free_rate", "spl"):
        want = max(range(3), key=lambda k, key=key: (scores[k][key], -k))
        assert select_trial(oa3_log, {**sel, "score": key}) == want
    text = Path(goal_config(tmp_path, oa3_log)).read_text()
    assert 'trial = { world = "goal-training"' in preset_text("goal-finding")
    path = tmp_path / "sel.toml"
    path.write_text(text.replace('episodes = 2, seed = 0', 'episodes = 3, seed = 4'))
    assert main(["run", str(path), "--out", str(tmp_path / "sel.h5")]) == 0
    err = capsys.readouterr().err
    want = max(range(3), key=lambda k: (scores[k]["collision_free_rate"], -k))
    assert f"behaviours.avoid.policy_from: trial {want} of {oa3_log} (highest " \
        "collision_free_rate in 3 episodes in 'goal-training', seed 4)" in err


@pytest.mark.parametrize("table, where, what", [
    ('{ world = "goal-training", episode = 3 }', "policy_from.trial.episode",
     "did you mean 'episodes'"),
    ('{ episodes = 3 }', "policy_from.trial.world", "expected the world"),
    ('{ world = "goal-training", episodes = 0 }', "policy_from.trial", "episodes"),
    ('{ world = "goal-training", episodes = 2, score = "speed" }', "policy_from.trial.score",
     "no such score"),
])
def test_a_bad_selection_table_is_one_line(tmp_path, oa3_log, capsys, table, where, what):
    text = Path(goal_config(tmp_path, oa3_log)).read_text()
    start = text.index("trial = {")
    text = text[:start] + "trial = " + table + text[text.index("}", start) + 1:]
    path = tmp_path / "bad.toml"
    path.write_text(text)
    assert main(["run", str(path), "--out", str(tmp_path / "bad.h5")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and where in err[0] and what in err[0], err


def test_spl_shortest_measures_against_the_path_round_walls():
    res = goal_only({"episodes": 4, "timeout": 40})
    r = simulate(res, spec(world="multi-room", protocol="goal-episodes"))
    e, agg = r.episodes, batch_scores(r)
    # the shortest path a disc can drive is never shorter than the straight line
    assert np.all(e["shortest_m"] >= e["straight_m"] - 1e-9)
    assert agg["spl_shortest"] >= agg["spl"]
    assert 0.0 <= agg["spl_shortest"] <= agg["success_rate"]


def test_random_pairs_are_joined_by_a_path_in_a_world_of_separate_rooms():
    from sitframe.sim.paths import shortest_path_length

    # two 4 m x 4 m rooms side by side with no door: a pair across the wall is no test
    text = ('name = "apart"\ndescription = "two rooms, no door"\n[robot]\nstart = [1, 1, 0]\n'
            "[[walls]]\npoints = [[0, 0], [8.2, 0], [8.2, 4], [0, 4], [0, 0]]\n"
            "[[walls]]\npoints = [[4.1, 0], [4.1, 4]]\n")
    w = parse_world(text)
    s, g = goal_pairs(w, 30, np.random.default_rng(0), min_distance=2.0)
    assert np.all((s[:, 0] < 4.1) == (g[:, 0] < 4.1))  # both in the same room
    assert all(math.isfinite(shortest_path_length(w, a[:2], b[:2], radius=0.15))
               for a, b in zip(s, g, strict=True))
    with pytest.raises(InputError, match="joined by a free path"):
        goal_pairs(w, 1, np.random.default_rng(0), min_distance=5.0, max_tries=50)


def test_detour_pairs_need_a_path_longer_than_the_straight_line():
    from sitframe.sim.paths import shortest_path_length

    w = load_world("goal-training")

    def ratios(s, g):
        return np.array([shortest_path_length(w, a[:2], b[:2], radius=0.15)
                         / math.hypot(*(b[:2] - a[:2])) for a, b in zip(s, g, strict=True)])

    s, g = goal_pairs(w, 20, np.random.default_rng(1), detour_share=1.0, detour_ratio=1.3)
    assert np.all(ratios(s, g) >= 1.3)
    # uniform pairs in this room are mostly straight (a few per cent need a detour)
    s0, g0 = goal_pairs(w, 20, np.random.default_rng(1))
    assert np.mean(ratios(s0, g0) >= 1.3) < 0.5
    # share 0 draws nothing extra: the pairs of a run without the option
    s1, g1 = goal_pairs(w, 20, np.random.default_rng(1), detour_share=0.0, detour_ratio=1.3)
    np.testing.assert_array_equal(s0, s1)
    np.testing.assert_array_equal(g0, g1)
    # an open room has no detour: one clear error naming the option
    open_room = parse_world('name = "open"\ndescription = "empty"\n[robot]\nstart = [1, 1, 0]\n'
                            "[[walls]]\npoints = [[0, 0], [6, 0], [6, 6], [0, 6], [0, 0]]\n")
    with pytest.raises(InputError, match="detour") as err:
        goal_pairs(open_room, 1, np.random.default_rng(0), detour_share=1.0, max_tries=30)
    assert err.value.key == "goal.train_detour"


def test_train_detour_changes_the_training_pairs_only():
    from sitframe.sim.robot import RobotParams

    robot, w = RobotParams(), load_world("goal-training")
    plain = GoalEpisodes(episodes=8, margin=0.3)
    curric = GoalEpisodes(episodes=8, margin=0.3, train_detour=1.0, detour_ratio=1.3)
    for a, b in zip(plain.episode_starts(w, np.random.default_rng(2), robot),
                    curric.episode_starts(w, np.random.default_rng(2), robot), strict=True):
        np.testing.assert_array_equal(a, b)   # evaluation pairs unchanged
    s, g = curric.training_starts(w, np.random.default_rng(2), robot)
    s0, _ = plain.training_starts(w, np.random.default_rng(2), robot)
    assert not np.array_equal(s, s0)
    with pytest.raises(InputError, match="train_detour"):
        GoalEpisodes(train_detour=1.5)
    with pytest.raises(InputError, match="detour_ratio"):
        GoalEpisodes(detour_ratio=1.0)


@pytest.fixture(scope="module")
def learned_log(tmp_path_factory, oa_log) -> str:
    """A short ``goal-finding-learned`` run on oa_log's situations and rule base (the wall
    follower is oa_log's avoider under another label, over oa_log's situations as a space
    of its own: only the arbitration matters here)."""
    d = tmp_path_factory.mktemp("gfl")
    text = preset_text("goal-finding-learned").split("\n[prerequisites]")[0]
    text = text.replace("logs/obstacle-avoidance-12.h5", oa_log).replace(
        'c = 16\nm = 1.2\ntransform = "inverse"', 'c = 12\nm = 1.2\ntransform = "log"').replace(
        "wander_samples = 1500", "wander_samples = 100").replace(
        "logs/wall-following.h5", oa_log).replace(
        'behaviour = "avoid", trial = { world = "goal-training", episodes = 100, seed = 0 }',
        'behaviour = "avoid", trial = 0').replace(
        'trial = "best", behaviour = "follow"', 'trial = 0, behaviour = "avoid"').replace(
        "headings = [90, 60, 40, 20, 0, -20, -40, -60, -90]",
        "headings = [90, 60, 30, 0, -30, -60, -90]").replace(
        "trials = 11", "trials = 1").replace("iterations = 20000", "iterations = 300").replace(
        "episodes = 50", "episodes = 2").replace(
        'worlds = ["goal", "novel-1", "novel-2", "multi-room", "u-trap"]', 'worlds = ["goal"]')
    (d / "gfl.toml").write_text(text)
    out = str(d / "gfl.h5")
    assert main(["run", str(d / "gfl.toml"), "--out", out]) == 0
    return out


def test_evaluate_runs_the_learned_arbitration_in_any_world_file(learned_log, tmp_path,
                                                                 capsys, monkeypatch):
    """``sitframe evaluate LOG --world W --goal-episodes N --json`` on a learned-arbitration
    log freezes the arbiter with the trial's learned arbitration, in a world of our own."""
    import sitframe.plugins.learned_arbiter as la

    world = tmp_path / "l-room.toml"
    world.write_text('name = "l-room"\n[robot]\nstart = [1, 1, 0]\n[[walls]]\npoints = '
                     '[[0, 0], [9, 0], [9, 4], [4, 4], [4, 9], [0, 9], [0, 0]]\n')
    loaded = []
    load = la.FuzzyQArbiter.load_policy
    monkeypatch.setattr(la.FuzzyQArbiter, "load_policy",
                        lambda self, p: (loaded.append(p), load(self, p))[1])
    assert main(["evaluate", learned_log, "--world", str(world), "--goal-episodes", "3",
                 "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["arbiter"] == "fuzzy-q-arbiter" and doc["episodes"] == 3
    assert set(AGGREGATE_KEYS) <= set(doc)
    rules = open_log(learned_log).trial(0).policies["arbiter"]
    assert loaded
    for got in loaded:
        assert set(got.outputs) == set(rules.outputs)
        for name, o in rules.outputs.items():
            np.testing.assert_array_equal(got.outputs[name].rules, o.rules)


def test_evaluate_with_another_arbiter_drops_the_learned_arbitration(learned_log, oa_log,
                                                                     capsys):
    """``--arbiter cdb`` on a learned-arbitration log runs CDB over the same behaviours (was
    "the log's contents are damaged": the learned arbitration was handed to CDB); a learning
    arbiter asked for on a log that learned none is refused instead of run untrained."""
    assert evaluate_log(learned_log, world="goal", goal_episodes=2,
                        arbiter="cdb")["arbiter"] == "cdb"
    assert main(["evaluate", oa_log, "--world", "goal", "--goal-episodes", "2",
                 "--arbiter", "fuzzy-q-arbiter"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"sitframe: error: {oa_log}: --arbiter: ")
    assert "arbiter 'fuzzy-q-arbiter' learns its arbitration, but trial 0 of the log has no " \
        "arbitration learned by 'fuzzy-q-arbiter'" in err[0]


def test_a_setting_found_wrong_while_running_names_the_config_file(tmp_path, oa_log, capsys):
    """``min_distance`` no pair of the world meets is found when the pairs are drawn, as the
    run goes: the one line names the config file too (it named only the key)."""
    path = goal_config(tmp_path, oa_log)
    Path(path).write_text(Path(path).read_text().replace("min_distance = 3.0",
                                                         "min_distance = 40.0"))
    assert main(["run", path, "--out", str(tmp_path / "x.h5")]) == 2
    err = [ln for ln in capsys.readouterr().err.splitlines() if "error" in ln]
    assert len(err) == 1 and err[0].startswith(f"sitframe: error: {path}: goal.min_distance: "
                                               "found no start and goal 40 m apart")


def test_evaluate_in_a_room_too_small_for_the_pairs_names_where_min_distance_is_set(
        oa_log, learned_log, tmp_path, capsys):
    """The pairs' ``min_distance`` comes from the fusion config (a log without a protocol) or
    from the log's own config (a goal run): the one line names that file, not just the key."""
    small = tmp_path / "small.toml"
    small.write_text('name = "small"\n[robot]\nstart = [1, 1, 0]\n[[walls]]\n'
                     'points = [[0, 0], [3, 0], [3, 3], [0, 3], [0, 0]]\n')
    for log, where in ((learned_log, learned_log), (oa_log, "preset:goal-finding")):
        assert main(["evaluate", log, "--world", str(small), "--goal-episodes", "2"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith(
            f"sitframe: error: {where}: goal.min_distance: found no start and goal 3 m apart")


def test_a_sweep_point_failing_on_a_setting_names_the_sweep_file_and_the_point(tmp_path, oa_log,
                                                                              capsys):
    base = goal_config(tmp_path, oa_log)
    sw = tmp_path / "sw.toml"
    sw.write_text(f'[sweep]\nbase = "{base}"\n[grid]\n"goal.min_distance" = [40.0]\n')
    assert main(["sweep", str(sw), "--out", str(tmp_path / "out")]) == 2
    err = [ln for ln in capsys.readouterr().err.splitlines() if "error" in ln]
    assert len(err) == 1 and err[0].startswith(
        f"sitframe: error: {sw}: point min_distance=40: goal.min_distance: found no start")


def test_a_goal_runs_log_is_complete_and_a_missing_evaluation_is_named(learned_log, tmp_path):
    """The log records the evaluation protocol's worlds (a goal run's ``[goal] worlds``), so
    an incomplete-log check does not expect ``[evaluate] worlds`` (it said "evaluation in
    'training' missing" for every complete goal-finding-learned log) and still names a world
    a trial lacks."""
    import shutil

    import h5py

    from sitframe.analysis.report import log_problems

    assert json.loads(open_log(learned_log).attrs["evaluation"]) == {
        "protocol": "goal-episodes", "worlds": ["goal"]}
    assert log_problems(learned_log) == []
    cut = tmp_path / "cut.h5"
    shutil.copy(learned_log, cut)
    with h5py.File(cut, "a") as f:
        del f["trials/0000/episodes/eval/goal"]
    assert log_problems(str(cut)) == ["evaluation in 'goal' missing for trial(s) 0"]


def test_path_figures_of_goal_episodes_draw_no_jump_between_episodes(learned_log):
    """A chain of goal episodes (a batch: one more pose row per episode; a learning trial:
    the next start replaces the last step's end) is drawn episode by episode: no segment
    joins one episode's end to the next one's start (they crossed walls in the figures),
    and each episode's goal is starred."""
    from matplotlib.collections import LineCollection

    from sitframe.analysis import learning_plots as LP
    from sitframe.analysis.results import evaluation_episodes

    log = open_log(learned_log)
    tr = log.trial(0)
    world = parse_world(log.worlds["goal"])
    ep = evaluation_episodes(tr)["goal"]
    n_it = len(ep["collision"])
    assert ep["pose"].shape[0] == n_it + len(ep["first_iteration"])  # (the batch layout)
    training = parse_world(log.worlds["goal-training"])
    for fig, n in ((LP.plot_evaluation_paths({"goal": world}, {"goal": ep}), n_it),
                   (LP.plot_trajectory(training, tr.arrays["pose"],
                                       collision=tr.arrays["collision"],
                                       first=tr.episodes["learn/first_iteration"],
                                       goals=tr.episodes["learn/goal"]),
                    len(tr.arrays["collision"]) - (len(tr.episodes["learn/first_iteration"]) - 1))):
        ax = fig.axes[0]
        (lc,) = [c for c in ax.collections if isinstance(c, LineCollection)]
        seg = np.asarray(lc.get_segments())
        step = np.hypot(*(seg[:, 1] - seg[:, 0]).T)
        assert len(seg) == n and step.max() < 0.2  # (0.10 m/s x 1.5 s = 0.15 m per step)
        stars = [ln for ln in ax.lines if ln.get_marker() == "*"]
        assert len(stars) == 1 and len(stars[0].get_xdata()) >= 1


def test_replay_of_goal_episodes_keeps_each_frame_at_its_reading(learned_log, tmp_path,
                                                                 oa_log):
    """A batch's extra pose row per episode shifted the replayed robot one row per episode
    behind its readings; each episode now has one pose per iteration and one more."""
    from sitframe.analysis.replay_data import replay_payload

    path = goal_config(tmp_path, oa_log)
    out = str(tmp_path / "gf.h5")
    assert main(["run", path, "--out", out]) == 0
    for name in (learned_log, out):
        log = open_log(name)
        eps = replay_payload(log, {k: log.trial(k) for k in log.trial_indices()})["episodes"]
        batches = [e for e in eps if e["kind"] in ("evaluation", "run")]
        assert batches
        for e in batches:
            assert e["xy"]["shape"][0] == e["n"] + 1 == e["reading"]["shape"][0] + 1
            assert e["goal"]["shape"] == [e["n"], 3]  # (each iteration's episode goal)
    learning = [e for e in replay_payload(open_log(learned_log), {0: open_log(
        learned_log).trial(0)})["episodes"] if e["kind"] == "learning"]
    assert learning and learning[0]["goal"]["shape"] == [learning[0]["n"], 3]
