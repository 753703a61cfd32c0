"""Evolving situations: the interpreter's rules, the learner's rows, the log and evaluate."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import run_config, run_json, small_config

from sitframe.contract.records import TrialInfo
from sitframe.learning.fuzzy_q import FuzzyQLearner, QLearningParams
from sitframe.logs.reader import open_log
from sitframe.plugins.evolving import EvolvingInterpreter
from sitframe.plugins.fcm_interpreter import FCMInterpreter
from sitframe.situations.events import SituationEvent, count_per_iteration


def _interp(**kw) -> EvolvingInterpreter:
    kw = {"capacity": 6, "create_distance": 0.5, "create_after": 2, "transform": "range",
          "adapt": False, "merge_distance": 0.0, "split_ratio": 0.0, **kw}
    ev = EvolvingInterpreter(**kw)
    ev.load_state(ev.state())
    return ev


def _start(ev: EvolvingInterpreter, kind: str = "learn") -> None:
    ev.trial_start(TrialInfo(0, kind, None, 100, np.random.default_rng(0)))


def test_creates_from_nothing_after_k_poorly_covered_readings() -> None:
    ev = _interp()
    _start(ev)
    a, b = np.zeros(3), np.full(3, 2.0)
    u = ev.memberships(a)
    assert u.shape == (6,) and u[0] == 1.0  # the first reading is situation 0
    (first,) = ev.events()
    assert (first.kind, first.id, first.parents) == ("create", 0, ())
    ev.memberships(b)  # one far reading: not yet
    assert ev.events() == []
    u = ev.memberships(b)  # the second in a row creates situation 1 at their mean
    (new,) = ev.events()
    assert (new.kind, new.id, new.parents) == ("create", 1, (0,))
    np.testing.assert_allclose(new.prototype, b)
    assert u[1] == pytest.approx(1.0) and u[2:].sum() == 0.0
    # the FCM formula over the alive prototypes, with the clustering's m
    x = np.full(3, 0.5)
    d2 = np.array([np.sum(x ** 2), np.sum((x - 2.0) ** 2)])
    w = (d2.min() / d2) ** (1 / (1.2 - 1))
    np.testing.assert_allclose(ev.memberships(x)[:2], w / w.sum())


def test_merge_keeps_the_older_id_and_ids_are_never_reused() -> None:
    ev = _interp(merge_distance=1.0, check_every=3)
    ev.load_state({"ids": np.array([0, 1]), "feature_centers": np.array([[0.0, 0], [0.5, 0]]),
                   "evidence": np.array([3.0, 1.0]), "next_id": 2, "capacity": 6,
                   "transform": "range", "offset": 0.1, "m": 1.2})
    _start(ev)
    for _ in range(3):
        ev.memberships(np.zeros(2))
    (merge,) = ev.events()
    assert (merge.kind, merge.id, merge.removed) == ("merge", 0, (1,))
    np.testing.assert_allclose(merge.weights, [0.75, 0.25])
    np.testing.assert_allclose(merge.prototype, [0.125, 0.0])
    for _ in range(2):  # a new situation gets id 2, not the freed 1
        ev.memberships(np.full(2, 3.0))
    assert [e.id for e in ev.events()] == [2]
    assert ev.state()["ids"].tolist() == [0, 2]


def test_frozen_evaluation_changes_nothing_and_state_round_trips() -> None:
    ev = _interp(adapt=True)
    _start(ev)
    for x in (np.zeros(2), np.full(2, 3.0), np.full(2, 3.0), np.ones(2)):
        ev.memberships(x)
    state = ev.state()
    ev2 = _interp(adapt=True)
    ev2.load_state(state)
    _start(ev2, "evaluate")
    for x in (np.full(2, 9.0),) * 5:
        u = ev2.memberships(x)
    assert ev2.events() == []
    np.testing.assert_array_equal(ev2.state()["feature_centers"], state["feature_centers"])
    assert u.sum() == pytest.approx(1.0)
    with pytest.raises(ValueError, match="capacity"):
        _interp(capacity=8).load_state(state)


def test_starts_from_an_fcm_state() -> None:
    fcm = FCMInterpreter(c=3, transform="log")
    fcm.load_state({"centers": np.array([[0.2, 0.2], [1.0, 1.0], [3.0, 3.0]]),
                    "transform": "log", "offset": 0.1, "m": 1.2})
    ev = _interp(transform="log", c=3)
    ev.load_state(fcm.state())
    assert ev.state()["ids"].tolist() == [0, 1, 2]
    _start(ev, "evaluate")
    np.testing.assert_allclose(ev.memberships(np.array([0.5, 0.9]))[:3],
                               fcm.memberships(np.array([0.5, 0.9])))


def test_nothing_is_created_or_split_after_grow_until_readings() -> None:
    """``grow_until = n``: the trial's first n readings may create situations, later ones
    are only assigned (learning can then converge on the situations it has)."""
    ev = _interp(grow_until=3)
    _start(ev)
    a, b, c = np.zeros(3), np.full(3, 2.0), np.full(3, 4.0)
    for x in (a, b, b):  # readings 1-3: situation 0, then 1 from the two far ones
        ev.memberships(x)
    assert [e.kind for e in ev.events()] == ["create", "create"]
    for _ in range(5):  # readings 4-8: as far again, but past grow_until
        u = ev.memberships(c)
    assert ev.events() == [] and u[1] > 0.99 and u[2:].sum() == 0.0

    def kinds(grow_until: int) -> list[str]:  # the split of the test below, at reading 9
        e = _interp(split_ratio=2.0, split_min_updates=2, split_min_distance=0.1, check_every=9,
                    create_distance=10.0, grow_until=grow_until)
        e.load_state({"ids": np.arange(3), "feature_centers": np.array([[0.0, 0], [5, 0],
                      [10, 0]]), "evidence": np.ones(3), "next_id": 3, "capacity": 6,
                      "transform": "range", "offset": 0.1, "m": 1.2})
        _start(e)
        for t, x in enumerate([np.array([v, 0.0]) for v in (1.0, 4.5, 9.5)] * 3):
            e.memberships(x)
            if t:
                err = np.zeros(6)
                err[(t - 1) % 3] = 1.0 if (t - 1) % 3 == 0 else 0.1
                e.observe_errors(err)
        return [v.kind for v in e.events()]

    assert kinds(0) == kinds(9) == ["split"] and kinds(8) == []
    with pytest.raises(ValueError, match="grow_until"):
        _interp(grow_until=-1)


def test_split_where_td_errors_stay_large() -> None:
    ev = _interp(split_ratio=2.0, split_min_updates=2, split_min_distance=0.1, check_every=9,
                 create_distance=10.0)
    ev.load_state({"ids": np.arange(3), "feature_centers": np.array([[0.0, 0], [5, 0], [10, 0]]),
                   "evidence": np.ones(3), "next_id": 3, "capacity": 6,
                   "transform": "range", "offset": 0.1, "m": 1.2})
    _start(ev)
    readings = [np.array([v, 0.0]) for v in (1.0, 4.5, 9.5)] * 3
    for t, x in enumerate(readings):
        ev.memberships(x)
        if t:  # the learner's errors concern the previous reading: large in situation 0
            err = np.zeros(6)
            j = (t - 1) % 3
            err[j] = 1.0 if j == 0 else 0.1
            ev.observe_errors(err)
    (split,) = ev.events()
    assert (split.kind, split.id) == ("split", 3)
    np.testing.assert_allclose(split.prototype, [1.0, 0.0])


def test_learner_rows_follow_the_situations() -> None:
    prm = QLearningParams(q_init_value=10.0)
    lr = FuzzyQLearner(4, 3, prm, np.random.default_rng(0), 10)
    lr.q[0] = [0.0, 20.0, 4.0]
    lr.q[1] = [8.0, 0.0, 4.0]
    lr.updates[:2] = [3, 1]
    lr.situations_changed(SituationEvent("create", 2, (0, 1), np.array([0.75, 0.25])), 0.5)
    np.testing.assert_allclose(lr.q[2], 0.5 * np.array([2.0, 15.0, 4.0]) + 5.0)
    lr.situations_changed(SituationEvent("merge", 0, (0, 1), np.array([0.5, 0.5]),
                                         removed=(1,)))
    np.testing.assert_allclose(lr.q[0], (4 * np.array([0.0, 20, 4]) + 2 * np.array([8.0, 0, 4]))
                               / 6)
    assert lr.updates[0] == 4 and lr.removed[1] and lr.q[1].tolist() == [10.0] * 3
    with pytest.raises(ValueError, match="weights"):
        SituationEvent("create", 3, (0, 1), np.array([0.5, 0.6]))


def test_count_per_iteration() -> None:
    ev = {"iteration": np.array([0, 2, 2, 4]), "kind": np.array([0, 0, 2, 3])}
    assert count_per_iteration(ev, 0, 6).tolist() == [1, 1, 1, 1, 0, 0]


ONLINE = """
[interpreter]
component = "evolving"
transform = "log"
capacity = 24
create_distance = 1.2
"""


def _online_config(iterations: int = 200) -> str:
    cfg = small_config(trials=1, iterations=iterations).replace(
        '[interpreter]\ncomponent = "fcm"\nc = 6\ntrials = 4', ONLINE.strip())
    return cfg.replace("[experiment]", '[experiment]\nstages = ["learn", "evaluate"]')


def test_online_run_logs_history_and_evaluates_own_situations(tmp_path, capsys) -> None:
    _cfg, out = run_config(tmp_path, _online_config(), "online.h5")
    assert '"situations"' in capsys.readouterr().out
    tl = open_log(str(out)).trial(0)
    state, events = tl.situations_part("state"), tl.situations_part("events")
    n = int(tl.situations["count"])
    assert n >= 2 and state["ids"].size == n and events["pose"].shape == (events["kind"].size, 3)
    assert tl.summary["situations"] == n and tl.arrays["memberships"].shape[1] == 24
    ev = run_json(capsys, "evaluate", str(out), "--world", "novel-1", "--trial", "0",
                  "--iterations", "100", "--json")
    assert ev["iterations"] == 100
    assert ev["collisions"] == tl.summary["eval/novel-1/collisions"]
    # its tables show the situations alive at the trial's end, by id, each described
    from sitframe.analysis.results import lookup_table, rule_base_table, rule_bases_across_trials

    for table in (rule_base_table(str(out), 0), lookup_table(str(out), 0)):
        assert table.column("Situation") == sorted(int(i) + 1 for i in state["ids"])
        assert all(table.column("Description")) and "left out" in table.notes[-1]
    assert rule_bases_across_trials(str(out)).rows == []  # (no fitted situations to compare)
    # the report of an online run has its evolving-situations section
    from sitframe.analysis import analyse
    from sitframe.cli.app import main

    rep = analyse(out, tmp_path / "report", dpi=40)
    evolving = {name for sec, name, _cap in rep.files if sec == "Evolving situations"}
    assert {"situation_counts.png", "situation_events.png",
            "final_prototypes_trial0.png"} <= evolving
    assert all((tmp_path / "report" / name).stat().st_size > 0 for name in evolving)
    gif = tmp_path / "online.gif"  # its replay counts the situations alive at each frame
    assert main(["replay", str(out), "--from", "150", "--to", "153", "-o", str(gif)]) == 0
    from PIL import Image

    with Image.open(gif) as im:
        assert im.n_frames == 3


def test_auto_c_rf_picks_the_crispest_partition_and_loads_any_c() -> None:
    rng = np.random.default_rng(1)
    centres = np.array([[0.3, 0.3], [2.5, 0.4], [1.2, 2.6]])
    X = np.concatenate([c + 0.05 * rng.standard_normal((60, 2)) for c in centres])
    fcm = FCMInterpreter(c="auto", auto_cs=[2, 3, 4, 5], auto_trials=3, trials=3,
                         auto_rule="rf")
    assert fcm.n_situations is None
    out = fcm.fit(X, np.random.default_rng(0))
    assert out["auto_c"] == 3 == fcm.n_situations and out["auto_rf"].shape == (4,)
    again = FCMInterpreter(c="auto")
    again.load_state(fcm.state())
    assert again.n_situations == 3
    with pytest.raises(ValueError, match="auto"):
        FCMInterpreter(c="many")
    with pytest.raises(ValueError, match="auto_rule"):
        FCMInterpreter(c="auto", auto_rule="xb")


def test_auto_c_cardinality_stops_where_the_smallest_situation_stops_shrinking() -> None:
    """A continuum of common readings (a uniform square) and, just off one corner, a rare
    group (40 of 1000 readings): while c is small the square's situations absorb it and the
    smallest situation shrinks with c; from the c that gives the rare group a situation of
    its own, the smallest situation is that group (until the square's are smaller still).
    The rule takes that first c."""
    rng = np.random.default_rng(3)
    X = np.concatenate([rng.uniform(0.0, 1.0, (960, 2)),
                        np.array([1.25, 1.25]) + 0.02 * rng.standard_normal((40, 2))])
    fcm = FCMInterpreter(c="auto", auto_cs=[2, 3, 4, 6, 8, 12, 16, 24, 32], auto_trials=3,
                         trials=3)
    out = fcm.fit(X, np.random.default_rng(0))
    card = out["auto_min_card"]
    own = out["auto_cs"][card == 40]  # the rare group is the smallest situation
    assert own.size >= 3 and card[0] > 80
    assert out["auto_c"] == own[0] == fcm.n_situations
    rf = FCMInterpreter(c="auto", auto_cs=[2, 3, 4, 6, 8, 12, 16, 24, 32], auto_trials=3,
                        trials=3, auto_rule="rf").fit(X, np.random.default_rng(0))
    assert rf["auto_min_card"].tolist() == card.tolist()  # (the same sweep, another rule)


def test_a_sweep_starts_online_runs_from_no_situations(tmp_path) -> None:
    from sitframe.cli.app import main

    (tmp_path / "base.toml").write_text(_online_config(iterations=100))
    (tmp_path / "s.toml").write_text('[sweep]\nbase = "base.toml"\n[grid]\n'
                                     '"interpreter.create_distance" = [1.0]\n')
    assert main(["sweep", str(tmp_path / "s.toml"), "--out", str(tmp_path / "o"),
                 "--workers", "1"]) == 0
    (log,) = (tmp_path / "o").glob("*.h5")
    assert open_log(str(log)).trial(0).situations["count"] >= 1


def test_split_median_is_numpys() -> None:
    """The split test's median (a hand-written one, for speed) is numpy's, bit for bit."""
    from sitframe.plugins.evolving import _median

    rng = np.random.default_rng(5)
    for n in range(1, 60):
        a = rng.random(n) * rng.lognormal(0.0, 3.0, n)
        assert _median(a) == float(np.median(a))


def test_auto_c_run_logs_its_sweep_and_the_report_draws_it(tmp_path) -> None:
    """An off-line run with c = "auto": the run logs the sweep the rule read, the situations
    are the chosen c, and the report shows the sweep with the choice marked."""
    from sitframe.analysis import analyse

    cfg = small_config(trials=1, iterations=60, eval_iterations=20).replace(
        "c = 6", 'c = "auto"\nauto_cs = [2, 3, 4, 5]\nauto_trials = 2')
    _cfg, out = run_config(tmp_path, cfg, "auto.h5")
    log = open_log(str(out))
    st = log.stage("cluster")
    assert int(st["auto_c"]) in (2, 3, 4, 5) and np.asarray(st["auto_min_card"]).shape == (4,)
    assert float(st["auto_plateau"]) > 0 and float(st["auto_knee"]) == 2.0
    assert np.asarray(log.interpreter_state()["centers"]).shape[0] == int(st["auto_c"])
    rep = analyse(out, tmp_path / "report", dpi=40)
    assert "auto_c.png" in {name for _sec, name, _cap in rep.files}
    assert (tmp_path / "report" / "auto_c.png").stat().st_size > 0


def test_situations_freeze_with_the_rules_only_when_asked() -> None:
    """``rules_converged()`` (the core's call once every learner converged) stops every
    change with ``freeze_with_rules``, and changes nothing without it."""
    rng = np.random.default_rng(3)
    first, later = rng.uniform(0, 3, (20, 4)), rng.uniform(0, 3, (40, 4))
    moved = {}
    for freeze in (False, True):
        ev = _interp(adapt=True, freeze_with_rules=freeze)
        _start(ev)
        for x in first:
            ev.memberships(x)
        ev.events()
        before = ev.state()
        ev.rules_converged()
        for x in later:
            ev.memberships(x)
        after = ev.state()
        moved[freeze] = (not np.array_equal(before["centers"], after["centers"])
                         or before["ids"].size != after["ids"].size or bool(ev.events()))
    assert moved == {False: True, True: False}


def test_an_online_run_freezes_its_situations_when_its_rules_converge(tmp_path) -> None:
    """With ``freeze_with_rules`` no situation event comes after the rule base converged,
    and the trial is the same as without it up to that iteration."""
    logs = {}
    for freeze in ("false", "true"):
        cfg = _online_config(600).replace(
            "create_distance = 1.2", f"create_distance = 1.2\nfreeze_with_rules = {freeze}")
        (tmp_path / freeze).mkdir()
        logs[freeze] = open_log(str(run_config(tmp_path / freeze, cfg, "online.h5")[1]))
    tl = logs["true"].trial(0)
    conv = int(tl.summary["convergence_iteration"])
    assert tl.summary["converged"] and 0 < conv < 600
    assert tl.situations_part("events")["iteration"].max() <= conv
    other = logs["false"].trial(0)
    assert np.array_equal(tl.arrays["memberships"][:conv], other.arrays["memberships"][:conv])
    assert not np.array_equal(tl.arrays["memberships"], other.arrays["memberships"])
