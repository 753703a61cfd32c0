"""The learned arbitration against CDB on the same pairs
(benchmarks/learning/paired_arbiters.py), at a reduced scale, and the arbiter's per-context
learning it reports on."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest
from helpers import run_config

from sitframe.learning.fuzzy_q import FuzzyQLearner, QLearningParams
from sitframe.logs.reader import open_log

SCRIPT = Path(__file__).parents[1] / "benchmarks" / "learning" / "paired_arbiters.py"

#: A learned arbitration of route-guided and straight goal seeking over 2 situations of the
#: arbiter's own (fitted on wander readings of its learning room), every context converged.
LEARNED = """
[experiment]
name = "paired"
trials = 2
iterations = 400
world = "goal-training"
default_speed = 0.15
stages = ["collect", "cluster", "learn", "evaluate"]

[collect]
worlds = ["collect-1"]

[interpreter]
component = "fcm"
c = 2
trials = 2

[spaces.arb]
component = "fcm"
c = 2
trials = 2
transform = "log"
collect = { mode = "wander", worlds = ["goal-training"], wander_samples = 60 }

[behaviours.route]
component = "route"

[behaviours.straight]
component = "goal"

[arbiter]
component = "fuzzy-q-arbiter"
space = "arb"
reward = "goal-progress"
reward_params = { signed = true, time = -10, distance = "path" }
sectors = 2
stall_iterations = 0
p = 3
q_init_value = -100
convergence = "every context"
min_context_updates = 5

[goal]
episodes = 3
timeout = 120
train = "episodes"
worlds = ["u-trap"]
"""


@pytest.fixture(scope="module")
def learned(tmp_path_factory):
    _cfg, log = run_config(tmp_path_factory.mktemp("paired"), LEARNED, "learned.h5")
    return log


def _script():
    spec = importlib.util.spec_from_file_location("paired_arbiters", SCRIPT)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_per_context_counts_are_logged(learned):
    tr = open_log(learned).trial(0)
    b = tr.behaviours["arbiter"]
    assert json.loads(b["arbitration/contexts"]) == ["ahead", "behind"] or \
        list(b["arbitration/contexts"]) == ["ahead", "behind"]
    visits = np.asarray(b["arbitration/context_visits"])
    assert visits.sum() == 400  # every learning iteration is in one context
    assert np.asarray(b["arbitration/context_updates"]).shape == (2,)
    assert b["space"] == "arbiter" or b["space"] == "arb"
    from sitframe.analysis import results as R

    t = R.contexts_table(learned)
    assert t.column("Context") == ["ahead", "behind"]
    assert t.column("Converged (trials)")[0].endswith("/2")


def test_paired_comparison_at_a_reduced_scale(learned, tmp_path):
    mod = _script()
    out = tmp_path / "t.md"
    assert mod.main([str(learned), "--worlds", "u-trap", "--seeds", "2", "--episodes", "3",
                     "--trial", "1", "--out", str(out), "--json", str(tmp_path / "t.json")]) == 0
    doc = json.loads((tmp_path / "t.json").read_text())
    rows = doc["rows"]
    assert len(rows) == 4  # 2 seeds x (learned, cdb)
    # the same pairs for both arbiters (they depend on the world and the seed only)
    by = {(r["arbiter"], r["seed"]): r["episodes"] for r in rows}
    for s in (0, 1):
        assert by[("learned", s)]["goal"] == by[("cdb", s)]["goal"]
        assert by[("learned", s)]["start"] == by[("cdb", s)]["start"]
    # each batch is the one command `sitframe evaluate ... --per-episode` prints
    one = mod.evaluate(str(learned), "u-trap", 1, 0, 3, "cdb")
    assert one["per_episode"] == by[("cdb", 0)]
    room = doc["summary"]["rooms"]["u-trap"]
    assert set(room["paired"]) == {"success", "collision_free", "cf_success", "spl"}
    text = out.read_text()
    assert "written by benchmarks/learning/paired_arbiters.py" in text
    assert "| u-trap | learned |" in text


def test_holm_and_the_paired_tests():
    mod = _script()
    assert mod.holm([0.01, 0.04, 0.03]) == pytest.approx([0.03, 0.06, 0.06])
    a = np.array([1, 1, 1, 1, 1, 1, 1, 1, 1, 1.0])
    b = np.array([0, 0, 0, 0, 0, 0, 0, 0, 1, 1.0])
    assert mod.worse_p(b, a, "success") < 0.01  # b loses 8 discordant pairs of 8
    assert mod.worse_p(a, b, "success") == 1.0
    assert mod.worse_p(a, a, "spl") == 1.0
    spl_a = np.linspace(0.8, 0.9, 20)
    assert mod.worse_p(spl_a - 0.05, spl_a, "spl") < 0.001


def test_learning_until_every_context_converged():
    """groups: a group (context) never updated does not hold learning back; one updated
    fewer than min_group_updates times does."""
    rng = np.random.default_rng(0)
    prm = QLearningParams(p=2, b=1, groups=2, min_group_updates=3, activation=0.3)
    lr = FuzzyQLearner(4, 2, prm, rng, 100)
    only_first = np.array([0.5, 0.5, 0.0, 0.0])
    for t in range(20):
        lr.update(only_first, 1.0, only_first, False, t)
    assert lr.converged_at is not None  # group 2 never updated: not waited for
    upd = lr.group_data()["group_updates"]
    assert upd[0] >= 3 and upd[1] == 0
    lr = FuzzyQLearner(4, 2, QLearningParams(p=2, b=1, groups=2, min_group_updates=3,
                                             activation=0.3), rng, 100)
    for t in range(30):
        u = np.array([0.5, 0.5, 0.0, 0.0]) if t != 0 else np.array([0.0, 0.0, 1.0, 0.0])
        lr.update(u, 1.0, u, False, t)
    assert lr.converged_at is None  # group 2 updated once, fewer than 3 times
    assert lr.group_data()["group_converged_at"][1] == -1
