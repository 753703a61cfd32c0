"""Evaluation protocols are plugins: a third-party protocol runs through the core's loop."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from sitframe import Proposal, hookimpl
from sitframe.contract.config import validate_config
from sitframe.contract.pluginmanager import get_plugin_manager
from sitframe.errors import InputError, PluginError, PluginFault
from sitframe.runs.experiment import Experiment
from sitframe.runs.loop import TrialSpec, simulate

STATE = {"centers": np.array([[0.5] * 8, [3.0] * 8]), "m": 1.2}


class Laps:
    """Three episodes from the world's start, no goal, each ended after ``stop`` iterations."""

    name = "laps"
    table = "evaluate"

    def __init__(self, *, iterations: int = 1000) -> None:
        self.iterations = iterations
        self.stop = 5

    def episode_starts(self, world: Any, rng: Any, robot: Any) -> tuple[np.ndarray, None]:
        return np.tile(world.start, (3, 1)), None

    def terminated(self, context: Any) -> bool:
        return context.iteration >= self.stop  # (the context after the iteration)

    def score_episode(self, arrays: dict[str, np.ndarray], start: Any, goal: Any,
                      robot: Any) -> dict[str, Any]:
        return {"steps": int(arrays["collision"].size)}

    def aggregate(self, figures: dict[str, np.ndarray]) -> dict[str, float]:
        return {"mean_steps": float(figures["steps"].mean())}


class Lapper:
    name = "lapper"
    evaluation_protocol = "laps"

    def reset(self, rng: Any, n_situations: int, iterations: int) -> None:
        pass

    def propose(self, context: Any) -> Proposal:
        return Proposal(0.0, None)


class Ahead(Lapper):
    """Names no evaluation protocol: its run gets the default, ``frozen``."""

    name = "ahead"
    evaluation_protocol = None


class Plugin:
    @hookimpl
    def sitframe_protocols(self) -> list[Any]:
        return [Laps]

    @hookimpl
    def sitframe_behaviours(self) -> list[Any]:
        return [Lapper, Ahead]


def experiment(behaviour: str = "lapper", noise: float = 0.0, **evaluate: Any) -> Experiment:
    pm = get_plugin_manager()
    pm.register(Plugin(), name="laps-plugin")
    cfg = validate_config({
        "experiment": {"stages": ["evaluate"]},
        "sensor": {"component": "pioneer-sonar", "noise_std": noise},
        "interpreter": {"component": "fcm", "c": 2},
        "behaviours": {"lap": {"component": behaviour}},
        "arbiter": {"component": "single"},
        "evaluate": {"worlds": ["training"], "iterations": 20, **evaluate},
    })
    return Experiment(cfg, pm=pm)


def test_a_plugin_protocol_runs_its_episodes_through_the_core():
    exp = experiment()
    assert exp.protocol == "laps"
    (trial,) = exp.run(interpreter_state=STATE).trials
    assert trial.summary["eval/training/mean_steps"] == 5.0
    assert trial.episodes["steps"].tolist() == [5, 5, 5]
    assert trial.episodes["first_iteration"].tolist() == [0, 5, 10]
    assert "goal" not in trial.episodes and trial.arrays["pose"].shape == (18, 3)


def test_a_protocol_breaking_the_contract_is_a_plugin_fault(monkeypatch):
    monkeypatch.setattr(Laps, "episode_starts", lambda self, world, rng, robot: (np.zeros(3), None))
    with pytest.raises(PluginFault, match="episode_starts.*expected \\(n, 3\\)"):
        experiment().run(interpreter_state=STATE)


def test_without_a_named_protocol_each_world_gets_one_frozen_run_on_the_batch_seed():
    exp = experiment("ahead", noise=0.05)  # (noisy readings: the seed shows)
    assert exp.protocol == "frozen"
    (trial,) = exp.run(interpreter_state=STATE).trials
    assert trial.arrays["collision"].size == 20 and trial.episodes == {}  # one run, no records
    # the run is the plain run from the world's start on the batch's own seed (what keeps the
    # numbers of every evaluation logged before the protocol was a plugin)
    plain = simulate(exp.res, TrialSpec(index=0, seed=trial.seed, world="training",
                                        iterations=20, learn=False, interpreter_state=STATE))
    assert np.array_equal(plain.arrays["reading"], trial.arrays["reading"])
    assert plain.summary["coverage"] == trial.summary["coverage"]


def test_a_continuing_protocol_with_several_starts_is_a_plugin_fault(monkeypatch):
    monkeypatch.setattr(Laps, "episodic", False, raising=False)
    with pytest.raises(PluginFault, match="episode_starts.*n = 1: episodic is False"):
        experiment().run(interpreter_state=STATE)


def test_an_unknown_protocol_lists_the_available_ones():
    with pytest.raises(InputError,
                       match="unknown protocol 'nope'.*available: frozen, goal-episodes, laps"):
        experiment().res.protocol("nope")


@pytest.mark.parametrize("attr, value, match", [  # each was a traceback, a silently wrong
    # batch (starts in a wall, a truthy string ending every episode, the core's collisions
    # replaced) or a missing table found only once the run was under way
    ("episode_starts", lambda self, world, rng, robot: np.tile(world.start, (3, 1)),
     "expected a tuple \\(starts, goals\\)"),
    ("episode_starts", lambda self, world, rng, robot: (np.array([[0.0, 0.0, 0.0]]), None),
     "start 0 = \\[0.0, 0.0, 0.0\\], expected finite x, y in free space of world 'training'"),
    ("episode_starts", lambda self, world, rng, robot: (np.array([world.start]),
                                                        np.array([[1.0, 1.0, np.nan]])),
     "goal 0 = \\[1.0, 1.0, nan\\], expected finite x, y in free space"),
    ("terminated", lambda self, context: "no", "terminated.*returned str 'no', expected True"),
    ("score_episode", lambda self, arrays, *a, n=[]: {f"steps{len(n.append(0) or n)}": 1},
     "score_episode.*expected the same keys for every episode"),
    ("aggregate", lambda self, figures: {"collisions": 0.0},
     "aggregate.*\\['collisions'\\], which the core measures itself"),
])
def test_a_protocol_breaking_the_contract_is_one_fault(monkeypatch, attr, value, match):
    monkeypatch.setattr(Laps, attr, value)
    with pytest.raises(PluginFault, match=match):
        experiment().run(interpreter_state=STATE)


@pytest.mark.parametrize("attr, value, match", [
    ("table", 3, "table is 3, expected the name of the config table"),
    ("__init__", lambda self, **kw: None, "has no attribute 'iterations'"),
    ("__init__", lambda self, **kw: setattr(self, "iterations", 2.5),
     "iterations is 2.5, expected an integer >= 1"),
])
def test_a_protocol_without_its_table_or_iterations_is_found_at_setup(monkeypatch, attr, value,
                                                                       match):
    monkeypatch.setattr(Laps, attr, value)
    with pytest.raises(PluginError, match=match):
        experiment()
