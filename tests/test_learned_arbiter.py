"""Learned arbitration (fuzzy-q-arbiter, goal-progress reward) and learning in goal episodes."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from sitframe.contract.config import validate_config
from sitframe.contract.pluginmanager import Registry, get_plugin_manager
from sitframe.contract.records import Context, LearnedPolicy, Proposal, Transition
from sitframe.contract.resolve import Resolved
from sitframe.errors import InputError
from sitframe.plugins.learned_arbiter import FuzzyQArbiter, GoalProgressReward, goal_sector
from sitframe.runs.experiment import Experiment
from sitframe.runs.loop import TrialSpec, simulate
from sitframe.sim.world import Goal, load_world

STATE = {"centers": np.array([[0.5] * 8, [3.0] * 8]), "m": 1.2}
WORLD = load_world("goal")


def ctx(x: float, y: float, theta_deg: float = 0.0, goal=(5.0, 5.0), it: int = 1,
        u=(1.0, 0.0), nearest: float = 1.0) -> Context:
    return Context(it, np.array([x, y, math.radians(theta_deg)]), np.full(8, nearest),
                   np.asarray(u, float), nearest, WORLD, Goal(np.asarray(goal, float), 0.3))


def goal_run(**arbiter) -> dict:
    return validate_config({
        "experiment": {"trials": 1, "iterations": 200, "world": "goal", "stages": ["learn"]},
        "interpreter": {"component": "fcm", "c": 2},
        "behaviours": {"avoid": {"component": "fuzzy-q", "headings": [90, 0, -90],
                                 "reward": "obstacle-avoidance", "p": 10_000},
                       "goal": {"component": "goal"}},
        "arbiter": {"component": "fuzzy-q-arbiter", "reward": "goal-progress", **arbiter},
        "goal": {"episodes": 3, "timeout": 20, "train": "episodes", "worlds": ["goal"]},
    })


def test_goal_sector_is_centred_ahead_and_counter_clockwise():
    assert goal_sector(ctx(0, 0, goal=(5, 0.5)), 4) == 0       # ahead
    assert goal_sector(ctx(0, 0, goal=(0, 5)), 4) == 1         # left
    assert goal_sector(ctx(0, 0, goal=(-5, -0.5)), 4) == 2     # behind
    assert goal_sector(ctx(0, 0, goal=(0, -5)), 4) == 3        # right
    assert goal_sector(ctx(0, 0, theta_deg=90, goal=(0, -5)), 4) == 2


def test_reward_pays_new_approach_only_and_punishes_collision():
    r = GoalProgressReward(progress=100, time=-1, collision=-50, goal=50)
    ok, hit = SimpleNamespace(collided=False), SimpleNamespace(collided=True)

    def tr(a, b, out=ok):
        return Transition(a, None, out, b)  # type: ignore[arg-type]

    assert r(tr(ctx(0, 5, it=0), ctx(1, 5))) == pytest.approx(100 * 1 - 1)  # 1 m closer
    assert r(tr(ctx(1, 5), ctx(0.5, 5))) == -1      # moved away: time only
    assert r(tr(ctx(0.5, 5), ctx(0.8, 5))) == -1    # closer, but not closer than ever
    assert r(tr(ctx(0.8, 5), ctx(1.5, 5))) == pytest.approx(100 * 0.5 - 1)
    assert r(tr(ctx(1.5, 5), ctx(1.5, 5), hit)) == -50
    assert r(tr(ctx(1.5, 5), ctx(4.9, 5))) == 50     # inside the goal disc
    # a new goal (next episode) restarts the record distance
    assert r(tr(ctx(4.9, 5), ctx(4.9, 5, goal=(0, 0)))) == -1


def test_signed_reward_pays_every_step_towards_the_goal_and_charges_every_step_away():
    r = GoalProgressReward(progress=100, time=-1, signed=True, near=0.5, near_cost=10)
    ok = SimpleNamespace(collided=False)

    def tr(a, b):
        return Transition(a, None, ok, b)  # type: ignore[arg-type]

    assert r(tr(ctx(0, 5, it=0), ctx(1, 5))) == pytest.approx(100 * 1 - 1)
    assert r(tr(ctx(1, 5), ctx(0.5, 5))) == pytest.approx(-100 * 0.5 - 1)  # away: charged
    assert r(tr(ctx(0.5, 5), ctx(0.8, 5))) == pytest.approx(100 * 0.3 - 1)  # back: paid again
    assert r(tr(ctx(0.8, 5), ctx(1.0, 5, nearest=0.2))) == pytest.approx(100 * 0.2 - 1 - 3)
    with pytest.raises(InputError, match="signed"):
        GoalProgressReward(signed="yes")


def test_path_reward_pays_leaving_a_pocket_whose_floor_hides_the_goal():
    """At the floor of u-trap's first pocket (opening to -x) with the goal just behind the
    floor, a step back out of the pocket is a step away by the straight line but progress
    along the shortest path; the reward's distance = "path" pays it, "straight" charges it."""
    trap, ok = load_world("u-trap"), SimpleNamespace(collided=False)

    def at(x: float, it: int = 1) -> Context:
        return Context(it, np.array([x, 4.0, 0.0]), np.full(8, 1.0), np.ones(1), 1.0, trap,
                       Goal(np.array([6.5, 4.0]), 0.3))

    for distance, sign in (("straight", -1), ("path", 1)):
        r = GoalProgressReward(progress=100, time=0, signed=True, distance=distance)
        r(Transition(at(4.8, it=0), None, ok, at(5.0)))  # type: ignore[arg-type]
        gain = r(Transition(at(5.0), None, ok, at(4.5)))  # type: ignore[arg-type]
        assert 30 < sign * gain <= 50  # 0.5 m, along or at an angle to the path out
    with pytest.raises(InputError, match="distance"):
        GoalProgressReward(distance="manhattan")


def test_weights_follow_the_rules_and_policy_round_trips():
    arb = FuzzyQArbiter(actions=[{"avoid": 1}, {"goal": 1}, {"avoid": 1, "goal": 3}],
                        stall_iterations=0)
    arb._bind(["avoid", "goal"])
    arb.reset(np.random.default_rng(0), 2, 10)
    rules = np.zeros(8, dtype=np.intp)
    rules[0], rules[1] = 2, 1     # ahead: situation 0 -> 1/4 avoid, situation 1 -> goal
    arb.rules = rules
    arb.learner = None
    props = {"avoid": Proposal(60.0, None), "goal": Proposal(-20.0, None)}
    p, w = arb.combine(ctx(0, 0, goal=(5, 0), u=(0.5, 0.5)), props)
    np.testing.assert_allclose(w, [0.125, 0.875])
    assert p.heading_deg == pytest.approx(0.125 * 60 - 0.875 * 20)
    pol = arb.policy()
    assert list(pol.outputs) == ["ahead", "left", "behind", "right"]
    other = FuzzyQArbiter(actions=[{"avoid": 1}, {"goal": 1}, {"avoid": 1, "goal": 3}],
                          stall_iterations=0)
    other._bind(["avoid", "goal"])
    other.load_policy(LearnedPolicy(dict(reversed(pol.outputs.items()))))  # a log sorts them
    other.reset(np.random.default_rng(1), 2, 10)
    np.testing.assert_array_equal(other.rules, rules)
    with pytest.raises(ValueError, match="goal contexts"):
        FuzzyQArbiter(stall_iterations=5).load_policy(pol)


def test_safety_hands_over_to_one_behaviour_by_the_nearest_range():
    """``safety = [a, b]``: the safety behaviour's weight is 1 below ``a`` m, falls linearly
    to 0 at ``b``, and the learned weighting fills the rest; rules learn only by their share."""
    arb = FuzzyQArbiter(actions=[{"avoid": 1}, {"goal": 1}], stall_iterations=0,
                        safety=[0.3, 0.8], safety_behaviour="avoid")
    arb._bind(["avoid", "goal"])
    arb.reset(np.random.default_rng(0), 2, 10)
    arb.rules = np.ones(8, dtype=np.intp)  # every rule: goal alone
    arb.learner = None
    props = {"avoid": Proposal(60.0, None), "goal": Proposal(-20.0, None)}
    for nearest, w_avoid in ((0.1, 1.0), (0.3, 1.0), (0.55, 0.5), (0.8, 0.0), (2.0, 0.0)):
        p, w = arb.combine(ctx(0, 0, goal=(5, 0), nearest=nearest), props)
        np.testing.assert_allclose(w, [w_avoid, 1 - w_avoid])
        assert p.heading_deg == pytest.approx(w_avoid * 60 - (1 - w_avoid) * 20)
    reg = Registry.collect(get_plugin_manager())
    with pytest.raises(InputError, match="near < far") as info:
        Resolved.build(goal_run(safety=[0.8, 0.3]), reg)
    assert "arbiter.safety" in str(info.value)
    with pytest.raises(InputError, match="names behaviour 'avoyd'") as info:
        Resolved.build(goal_run(safety=[0.3, 0.8], safety_behaviour="avoyd"), reg).arbiter()
    assert "safety_behaviour" in str(info.value)


def test_bad_arbiter_config_names_the_key():
    reg = Registry.collect(get_plugin_manager())
    with pytest.raises(InputError, match="names behaviour 'folow'") as info:
        Resolved.build(goal_run(actions=[{"folow": 1}]), reg)
    assert "actions[0].folow" in str(info.value)
    with pytest.raises(InputError, match="sectors"):
        Resolved.build(goal_run(sectors=3), reg)
    cfg = goal_run()
    cfg["goal"]["train"] = "episode"
    with pytest.raises(InputError, match="'world', 'episodes'") as info:
        Resolved.build(cfg, reg).protocol("goal-episodes")
    assert "goal.train" in str(info.value)


@pytest.fixture(scope="module")
def learned() -> tuple[Experiment, object]:
    exp = Experiment(goal_run())
    (t,) = exp.run(interpreter_state=STATE).trials
    return exp, t


def test_learning_trial_is_a_chain_of_goal_episodes_and_learns_the_arbitration(learned):
    _exp, t = learned
    first = t.episodes["learn/first_iteration"]
    goals = t.episodes["learn/goal"]
    assert first[0] == 0 and len(first) >= 10 and np.all(np.diff(first) <= 20)
    assert len(goals) == len(first) and len({tuple(g) for g in goals.tolist()}) == len(first)
    pose = t.arrays["pose"]
    for e, f in enumerate(first[1:], start=1):  # each episode starts at a new start pose
        assert math.hypot(*(pose[f, :2] - pose[f - 1, :2])) > 0.3 or t.episodes[
            "learn/success"][e - 1]
    # the jumps between episodes are not distance travelled
    assert t.summary["distance_m"] < 0.15 * 1.5 * 200 + 1e-9
    q = t.behaviours["arbiter"]["arbitration/q"]
    assert np.count_nonzero(q) > 0 and "arbiter" in t.policies
    again = Experiment(goal_run()).run(interpreter_state=STATE).trials[0]
    np.testing.assert_array_equal(again.arrays["pose"], pose)  # deterministic


def test_learned_arbitration_runs_frozen_in_goal_episodes(learned):
    exp, t = learned
    spec = TrialSpec(index=0, seed=3, world="goal", iterations=20, learn=False,
                     interpreter_state=STATE, policies=dict(t.policies), protocol="goal-episodes")
    r = simulate(exp.res, spec)
    assert r.summary["eval/goal/episodes"] == 3
    assert set(r.episodes["success"].tolist()) <= {True, False}


def test_path_reward_refuses_a_goal_the_robot_cannot_reach():
    """A goal inside the disc's clearance of a wall has no path: an error naming the
    option, not a progress term that silently never pays."""
    trap, ok = load_world("u-trap"), SimpleNamespace(collided=False)
    goal = Goal(np.array([5.45, 4.0]), 0.3)  # 5 cm behind trap 1's floor wall (x = 5.4)

    def at(x: float, it: int = 1) -> Context:
        return Context(it, np.array([x, 6.5, 0.0]), np.full(8, 1.0), np.ones(1), 1.0, trap,
                       goal)

    r = GoalProgressReward(signed=True, distance="path")
    with pytest.raises(InputError, match=r"distance = \"path\": no free path .* 'u-trap'"):
        r(Transition(at(1.0, it=0), None, ok, at(1.2)))  # type: ignore[arg-type]


def test_train_detour_makes_the_training_episodes_detours_and_leaves_evaluation_alone(learned):
    """``[goal] train_detour = 1``: every training pair needs a path ``detour_ratio`` times
    the straight line (the curriculum reaches the loop through ``training_starts``)."""
    from sitframe.sim.paths import shortest_path_length

    cfg = goal_run()
    cfg["goal"].update(train_detour=1.0, detour_ratio=1.2)
    exp = Experiment(validate_config(cfg))
    (t,) = exp.run(interpreter_state=STATE).trials
    first, goals, pose = t.episodes["learn/first_iteration"], t.episodes["learn/goal"], \
        t.arrays["pose"]
    assert len(first) >= 3
    for f, g in zip(first, goals, strict=True):
        s = pose[f, :2]
        path = shortest_path_length(WORLD, s, g[:2], radius=0.15)
        assert path >= 1.2 * math.hypot(*(g[:2] - s)) - 1e-9
    _exp, plain = learned  # the uniform pairs of the same seed are mostly straight
    straight = [shortest_path_length(WORLD, pose0[:2], g[:2], radius=0.15)
                < 1.2 * math.hypot(*(g[:2] - pose0[:2]))
                for pose0, g in zip(plain.arrays["pose"][plain.episodes["learn/first_iteration"]],
                                    plain.episodes["learn/goal"], strict=True)]
    assert np.mean(straight) > 0.5


@pytest.mark.parametrize("value, error, match", [
    (lambda self, world: None, "PluginError",
     r"training_starts\(world\) cannot be called as training_starts\(world, rng, robot\)"),
    (lambda self, world, rng, robot: (np.zeros(3), None), "PluginFault",
     r"training_starts.*expected \(n, 3\)"),
])
def test_a_protocols_training_starts_breaking_the_contract_is_one_clear_error(
        monkeypatch, value, error, match):
    """The optional ``training_starts`` is checked as ``episode_starts`` is: its signature
    when the protocol is made, what it returns when a learning trial draws pairs."""
    import sitframe.errors as E
    from sitframe.plugins.goal_episodes import GoalEpisodes

    monkeypatch.setattr(GoalEpisodes, "training_starts", value)
    with pytest.raises(getattr(E, error), match=match):
        Experiment(goal_run()).run(interpreter_state=STATE)


def test_the_arbiter_takes_the_fuzzy_q_learning_keys_with_its_own_defaults():
    """One list of fuzzy-Q keys (QLearningParams) serves behaviour and arbiter: a key given
    in config reaches the learner, the arbiter's defaults are its own, and a key it leaves
    out is refused by the config check in one line naming it."""
    from sitframe.params import check_params
    from sitframe.plugins.fuzzy_q import FuzzyQBehaviour
    from sitframe.plugins.learned_arbiter import FuzzyQArbiter

    arb = FuzzyQArbiter(alpha=0.1, min_updates=7)
    assert (arb.qparams.alpha, arb.qparams.min_updates) == (0.1, 7)
    assert (arb.qparams.update, arb.qparams.terminal_on_collision) == ("standard", True)
    beh = FuzzyQBehaviour(replay=2)
    assert (beh.qparams.replay, beh.qparams.update) == (2, "thesis")
    with pytest.raises(InputError, match="unknown parameter 'q_init'"):
        check_params(FuzzyQArbiter, {"q_init": "random"}, file="run.toml",
                     key="arbiter")
    with pytest.raises(InputError, match="alpha"):
        FuzzyQBehaviour(alpha=2.0)
