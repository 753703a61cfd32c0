"""The duel (benchmarks/duel/duel.py): its step accounting equals the steps the simulator executed,
fuzzy-q is scored as ``sitframe evaluate`` scores it, the rooms and the selection rule."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

pytest.importorskip("gymnasium", reason="the gym extra (gymnasium) is not installed")

BENCH = Path(__file__).resolve().parents[1] / "benchmarks"


@pytest.fixture(scope="module")
def duel() -> Any:
    sys.path.insert(0, str(BENCH))
    spec = importlib.util.spec_from_file_location("duel", BENCH / "duel" / "duel.py")
    assert spec and spec.loader
    module = importlib.util.module_from_spec(spec)
    sys.modules["duel"] = module  # (its dataclasses look their module up)
    spec.loader.exec_module(module)
    return module


TINY = """
[experiment]
name = "tiny-avoidance"
seed = 0
trials = 1
iterations = 300
world = "training"
default_speed = 0.15
stages = ["collect", "cluster", "learn", "evaluate"]

[sensor]
component = "pioneer-sonar"

[collect]
mode = "both"
wander_samples = 40
worlds = ["collect-1"]

[interpreter]
component = "fcm"
c = 4
trials = 2

[behaviours.avoid]
component = "fuzzy-q"
reward = "obstacle-avoidance"
headings = [90, 60, 30, 0, -30, -60, -90]

[arbiter]
component = "single"

[evaluate]
worlds = ["training", "novel-1"]
iterations = 120
"""


@pytest.fixture(scope="module")
def fuzzy_run(duel: Any, tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict]:
    d = tmp_path_factory.mktemp("fuzzy")
    cfg = d / "tiny.toml"
    cfg.write_text(TINY)
    return d, duel.run_fuzzy(3, d / "job", duel.ROOMS["shipped"], config=str(cfg))


def test_room_sets_keep_the_test_rooms_untouched(duel: Any) -> None:
    gen = duel.ROOMS["gen"]
    assert len(gen["train"]) == 10 and len(gen["valid"]) == 5
    assert gen["test"][:2] == ("novel-1", "novel-2") and len(gen["test"]) == 22
    assert gen["train"][0] == "gen:1000000" and gen["valid"][0] == "gen:2000000"
    assert gen["test"][2] == "gen:3000000"
    for rooms in duel.ROOMS.values():
        duel.check_rooms(rooms)  # disjoint
    with pytest.raises(SystemExit, match="novel-1"):
        duel.check_rooms({"train": ("novel-1",), "valid": (), "test": ("novel-1",)})


class _Moves:
    """Counts the gym env's calls of the simulator's robot step."""

    def __init__(self, monkeypatch: pytest.MonkeyPatch) -> None:
        import sitframe.gym.env as genv

        self.steps = self.collisions = 0
        real = genv.step_robot

        def step(*args: Any, **kw: Any) -> Any:
            out = real(*args, **kw)
            self.steps += 1
            self.collisions += bool(out.collided)
            return out

        monkeypatch.setattr(genv, "step_robot", step)

    def take(self) -> tuple[int, int]:
        out = (self.steps, self.collisions)
        self.steps = self.collisions = 0
        return out


@pytest.mark.parametrize(("algo", "kw", "checkpoints", "stop"), [
    ("dqn", {"learning_starts": 50, "buffer_size": 500}, (150, 300, 400), 300),
    ("ppo", {"n_envs": 2, "n_steps": 32, "batch_size": 32, "n_epochs": 1}, (64, 128), None),
])
def test_step_accounting_equals_the_simulator_steps(duel: Any, tmp_path: Path, algo: str,
                                                    kw: dict, checkpoints: tuple, stop: Any,
                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    pytest.importorskip("stable_baselines3", reason="the baselines extra is not installed")
    moves = _Moves(monkeypatch)
    rooms = duel.ROOMS["shipped"]
    res = duel.train_sb3("tiny", 0, tmp_path, rooms["train"], stop=stop,
                         config=(algo, kw, checkpoints, "tiny"))
    steps, coll = moves.take()
    assert res["steps"] == steps == res["checkpoints"][-1]["sb3_steps"]
    assert res["learning_collisions"] == coll
    assert [c["steps"] for c in res["checkpoints"]] == [c for c in checkpoints
                                                      if c <= (stop or checkpoints[-1])]
    specs = (duel.EvalSpec(2, 30, 1), duel.EvalSpec(1, 25, 2))
    sc = duel.score_sb3(tmp_path, rooms, test=True, specs=specs)
    steps, coll = moves.take()
    n_ck = len(res["checkpoints"])
    judged = n_ck * len(rooms["test"]) * 25  # the test rooms: the judge's, not counted
    assert sc["valid_steps"] == n_ck * len(rooms["valid"]) * 2 * 30
    assert steps == sc["valid_steps"] + judged
    assert sc["counted_steps"] == res["steps"] + sc["valid_steps"]
    assert sc["rows"][-1]["counted_steps"] == sc["counted_steps"]
    valid_coll = sum(r["valid_collisions"] for r in sc["rows"])
    assert sc["counted_collisions"] == res["learning_collisions"] + valid_coll
    judged_coll = sum(sum(d["collisions"] for d in r["test"]["rooms"].values())
                      for r in sc["rows"])
    assert coll == valid_coll + judged_coll


def test_fuzzy_q_steps_read_from_its_log_are_the_simulators(fuzzy_run: tuple) -> None:
    _d, res = fuzzy_run
    sim = res["simulator"]
    assert res["collect"] == sim["collect_readings"]["steps"] > 40  # trajectories + wander
    assert sim["collect_moves"]["steps"] == 40  # the wander's moves
    assert res["learn"] == 300 and res["evaluate_outside_test"] == 120
    assert res["evaluate_in_test_not_counted"] == 120  # novel-1 is a test room
    assert res["learn"] + res["evaluate_outside_test"] + res["evaluate_in_test_not_counted"] \
        == sim["loop_moves"]["steps"]
    assert res["counted"] == res["collect"] + res["learn"] + res["evaluate_outside_test"]
    assert res["learning_collisions"] >= sim["collect_moves"]["collisions"]


def test_fuzzy_q_is_scored_as_sitframe_evaluate_scores_it(duel: Any, fuzzy_run: tuple) -> None:
    from sitframe.runs.evaluation import evaluate_log

    d, _res = fuzzy_run
    log = d / "job" / "run.h5"
    for room in ("novel-1", "novel-2"):
        ours = duel.fuzzy_scores(log, [room], duel.EvalSpec(2, 150, 7))["rooms"][room]
        own = duel.fuzzy_scores(log, [room], duel.EvalSpec(1, 150, 7))["rooms"][room]
        theirs = evaluate_log(str(log), world=room, iterations=150)
        assert own == {"collisions": theirs["collisions"], "coverage": theirs["coverage"]}
        assert ours != own  # the second start pose is another run


def test_start_poses_are_fixed_and_free(duel: Any) -> None:
    from sitframe.sim.world import load_world

    w = load_world("novel-2")
    a = duel.start_poses(w, 3, 5, 0.15)
    np.testing.assert_array_equal(np.stack(a), np.stack(duel.start_poses(w, 3, 5, 0.15)))
    np.testing.assert_array_equal(a[0], w.start)
    assert w.is_free(np.stack(a)[:, :2], 0.15).all()
    assert not np.array_equal(np.stack(a), np.stack(duel.start_poses(w, 3, 6, 0.15)))


def _job(config: str, valid: list[tuple[float, float]], test: list[tuple[float, float]] | None
         = None) -> dict:
    rows = [{"steps": 1000 * (i + 1), "counted_steps": 1500 * (i + 1),
             "valid": {"collisions_per_1000": c, "coverage": v},
             **({"test": {"collisions_per_1000": test[i][0], "coverage": test[i][1]}}
                if test else {})} for i, (c, v) in enumerate(valid)]
    return {"config": config, "rows": rows, "stopped_at": 1000 * len(rows),
            "best": max(range(len(rows)), key=lambda i: _merit(rows[i]["valid"]))}


def _merit(v: dict) -> tuple:
    safe = v["collisions_per_1000"] <= 3.0
    return (safe, v["coverage"] if safe else -v["collisions_per_1000"], v["coverage"])


def test_selection_rule(duel: Any) -> None:
    m = duel.merit
    assert m({"collisions_per_1000": 3.0, "coverage": 0.3}) > \
        m({"collisions_per_1000": 3.1, "coverage": 0.9})  # safe first
    assert m({"collisions_per_1000": 1.0, "coverage": 0.5}) > \
        m({"collisions_per_1000": 0.0, "coverage": 0.4})  # then coverage
    assert m({"collisions_per_1000": 5.0, "coverage": 0.1}) > \
        m({"collisions_per_1000": 9.0, "coverage": 0.9})  # unsafe: fewer collisions
    screen = {"dqn-base": [_job("dqn-base", [(9, 0.5), (2, 0.4)])] * 2,
              "dqn-g0.99": [_job("dqn-g0.99", [(1, 0.45)]), _job("dqn-g0.99", [(4, 0.6)])],
              "ppo-base": [_job("ppo-base", [(5, 0.5)])] * 2,
              "ppo-ent0.01": [_job("ppo-ent0.01", [(6, 0.5)])] * 2}
    assert duel.selected(screen) == {"dqn": "dqn-base", "ppo": "ppo-base"}
    table = duel.tuning_table(screen)
    assert "| dqn-base |" in table and table.index("dqn-base") < table.index("dqn-g0.99")


def test_steps_to_own_quality_and_targets(duel: Any) -> None:
    job = _job("dqn-base", [(9, 0.2), (2, 0.4), (2, 0.5)], [(5, 0.3), (1, 0.45), (1, 0.4)])
    job["counted_steps"], job["counted_collisions"] = 4500, 400
    job["score_cpu_s"], job["cpu_s"] = 1.0, 2.0
    assert job["best"] == 2 and duel.to_quality(job) == 3000  # checkpoint 2 already as good
    fq = {**_job("fuzzy-q", [(0, 0.5)], [(0.5, 0.55)]), "counted_steps": 500,
          "counted_collisions": 10, "score_cpu_s": 1.0, "cpu_s": 1.0}
    text = duel.targets_table(duel.Summary.of("fuzzy-q", [fq] * 3),
                              [duel.Summary.of("dqn-base", [job] * 3)])
    rows = [r for r in text.splitlines() if r.startswith("| ") and "target" not in r]
    assert [r.rstrip(" |").rsplit("| ", 1)[1] for r in rows] == \
        ["yes", "yes", "yes", "yes", "yes", "yes"]
    text = duel.targets_table(duel.Summary.of("fuzzy-q", [{**fq, "counted_steps": 900}] * 3),
                              [duel.Summary.of("dqn-base", [job] * 3)])
    assert "| **no** |" in text  # 900 > 3000 / 5
