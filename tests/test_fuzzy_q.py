"""The fuzzy-q and crisp-q behaviours driven as the loop drives them, with hand-computed values."""

from __future__ import annotations

import numpy as np
import pytest

from sitframe import (
    Context,
    LearnedPolicy,
    PolicyOutput,
    QLearningParams,
    SituationEvent,
    Transition,
)
from sitframe.errors import InputError
from sitframe.plugins.fuzzy_q import CrispQBehaviour, FuzzyQBehaviour
from sitframe.sim.robot import Command, StepOutcome

H3 = [90.0, 0.0, -90.0]


def ctx(iteration: int, u: list[float]) -> Context:
    return Context(iteration, np.zeros(3), np.ones(8), np.asarray(u, float), 1.0, None)


def transition(iteration: int, u0: list[float], u1: list[float],
               collided: bool = False) -> Transition:
    outcome = StepOutcome(np.zeros(3), np.zeros(3), collided, np.full(2, np.nan), np.zeros(3),
                          0.1, 0.0)
    return Transition(ctx(iteration, u0), Command(0.0, 0.2), outcome, ctx(iteration + 1, u1))


def policy(**outputs: list[int]) -> LearnedPolicy:
    actions = {"heading": H3, "speed": [0.1, 0.3]}
    return LearnedPolicy({k: PolicyOutput(np.array(actions[k]), np.array(r), "")
                          for k, r in outputs.items()})


def test_configured_and_default_parameters_reach_the_learner():
    kw = dict(alpha=0.5, gamma=0.8, b=3, p=7, temperature=0.5, temperature_mode="absolute",
              temperature_decay=0.9, temperature_min=0.1, q_init="random", q_init_value=1.0,
              q_init_spread=0.5, update="standard", activation=0.2, terminal_on_collision=True,
              min_updates=2, tie_break="centre", alpha_visits=20.0)
    b = FuzzyQBehaviour(**kw, new_row_optimism=0.25)
    assert {k: getattr(b.qparams, k) for k in kw} == kw
    assert b.new_row_optimism == 0.25
    # the defaults the module docstring documents
    d = FuzzyQBehaviour()
    assert d.qparams == QLearningParams(
        alpha=0.3, gamma=0.9, b=5, p=50, temperature=0.25, temperature_mode="relative",
        temperature_decay=1.0, temperature_min=0.0, q_init="constant", q_init_value=0.0,
        q_init_spread=0.0, update="thesis", activation=0.3, terminal_on_collision=False,
        min_updates=0, tie_break="first", alpha_visits=0.0)
    assert d.new_row_optimism == 0.5
    assert list(d.singletons) == ["heading"] and d.learn_outputs == ["heading"]
    assert d.singletons["heading"].tolist() == [90, 60, 30, 0, -30, -60, -90]


def test_bad_configuration_names_the_key():
    with pytest.raises(ValueError, match="learn names 'speed' but no 'speeds' singletons"):
        FuzzyQBehaviour(learn=["speed"])
    with pytest.raises(ValueError, match=r"learn\[1\].*expected one of 'heading', 'speed'"):
        FuzzyQBehaviour(learn=["heading", "sped"])
    for kw, key in [({"headings": [-90.5, 0]}, "headings[0]"),
                    ({"headings": [0, 90.5]}, "headings[1]"),
                    ({"speeds": [0.2, -0.1]}, "speeds[1]"),
                    ({"new_row_optimism": 1.5}, "new_row_optimism"),
                    ({"new_row_optimism": -0.1}, "new_row_optimism")]:
        with pytest.raises(InputError) as e:
            FuzzyQBehaviour(**kw)
        assert e.value.key == key, kw
    # the bounds themselves are valid: headings within +-90 deg, optimism within [0, 1]
    assert FuzzyQBehaviour(headings=[-90, 90]).singletons["heading"].tolist() == [-90, 90]
    assert FuzzyQBehaviour(new_row_optimism=0.0).new_row_optimism == 0.0
    assert FuzzyQBehaviour(new_row_optimism=1.0).new_row_optimism == 1.0
    b = FuzzyQBehaviour(speeds=[0.1, 0.3], learn="speed")  # a lone name is a list of one
    assert b.learn_outputs == ["speed"]
    with pytest.raises(ValueError, match=r"output 'heading' is neither learned \(learn = "
                                         r"\[\.\.\.\]\) nor given by a learned policy "
                                         r"\(policy_from\)$"):
        b.reset(np.random.default_rng(0), 2, 10)


def test_propose_blends_the_learned_rules_and_records_them():
    b = FuzzyQBehaviour(headings=H3, speeds=[0.1, 0.3], learn=["heading", "speed"])
    b.reset(np.random.default_rng(4), 2, 10)
    hd, sp = b.learners["heading"], b.learners["speed"]
    assert hd.q.shape == (2, 3) and sp.q.shape == (2, 2)
    for out, lr in b.learners.items():
        assert b.fcs[out].rule_actions.tolist() == lr.rule_base.tolist()

    def blend(values: list[float], rules: np.ndarray, u: list[float]) -> float:
        if rules[0] == rules[1]:
            return values[rules[0]]
        return u[0] * values[rules[0]] + u[1] * values[rules[1]]  # strengths sum to 1

    u = [0.25, 0.75]
    p = b.propose(ctx(7, u))
    assert p.heading_deg == pytest.approx(blend(H3, hd.rule_base, u))
    assert p.speed_m_s == pytest.approx(blend([0.1, 0.3], sp.rule_base, u))
    assert hd.rules_per_iteration[7].tolist() == hd.rule_base.tolist()
    assert sp.rules_per_iteration[7].tolist() == sp.rule_base.tolist()
    assert not np.delete(hd.rules_per_iteration, 7, axis=0).any()  # that iteration's row only
    assert (hd.rule_base > 0).any()  # (a record that differs from no record)
    h = FuzzyQBehaviour(headings=H3)
    h.reset(np.random.default_rng(0), 2, 10)
    assert h.propose(ctx(0, u)).speed_m_s is None


def test_learn_updates_q_from_the_transition_and_reloads_changed_rules():
    b = FuzzyQBehaviour(headings=H3, b=100, p=100)
    b.reset(np.random.default_rng(1), 2, 20)
    lr = b.learners["heading"]
    r0, r1 = lr.rule_base.tolist()
    # thesis Eq.: q[i, a] += alpha * (w r + gamma w V(s') - q[i, a]); V(s') = 0 with q = 0
    b.learn(transition(3, [1.0, 0.0], [0.0, 1.0]), 2.0)
    assert lr.q[0, r0] == pytest.approx(0.3 * 2.0) and lr.q[1].tolist() == [0.0] * 3
    assert lr.n_changes == 0
    # V(s') = u1 . max_a q = 0.6 now; rule 1 (strength 0.5 >= activation 0.3) learns from it
    b.learn(transition(4, [0.5, 0.5], [1.0, 0.0]), 0.0)
    assert lr.q[1, r1] == pytest.approx(0.3 * (0.9 * 0.5 * 0.6))
    assert lr.n_changes == 0
    # a collision changes the rule base at once; the controller follows it
    b.learn(transition(5, [1.0, 0.0], [1.0, 0.0], collided=True), -1.0)
    assert lr.n_changes == 1
    assert lr.data(20)["snapshot_iteration"].tolist() == [0, 6]  # in force from iteration 6
    assert b.fcs["heading"].rule_actions.tolist() == lr.rule_base.tolist()
    fast = FuzzyQBehaviour(headings=H3, b=1, temperature=5.0)
    fast.reset(np.random.default_rng(2), 3, 20)
    for it in range(12):
        fast.learn(transition(it, [0.6, 0.4, 0.0], [0.0, 0.4, 0.6]), float(it % 3))
        assert fast.fcs["heading"].rule_actions.tolist() == \
            fast.learners["heading"].rule_base.tolist()


def test_a_loaded_policy_fixes_its_outputs():
    b = FuzzyQBehaviour(headings=H3, speeds=[0.1, 0.3], learn=["heading", "speed"])
    other = LearnedPolicy({"heading": PolicyOutput(np.array([90.0, -90.0]), np.array([0, 1]))})
    with pytest.raises(ValueError, match=r"the policy's heading actions \[90.0, -90.0\] differ "
                                         r"from this behaviour's headings \[90.0, 0.0, -90.0\]; "
                                         r"configure the same singletons as the run that "
                                         r"learned it$"):
        b.load_policy(other)
    same_size = LearnedPolicy({"heading": PolicyOutput(np.array([90.0, 10.0, -90.0]),
                                                       np.array([0, 1]))})
    with pytest.raises(ValueError, match="differ"):
        b.load_policy(same_size)
    b.load_policy(policy(speed=[1, 0]))  # before reset: used from the next reset on
    b.reset(np.random.default_rng(0), 2, 10)
    assert list(b.learners) == ["heading"]
    assert b.fcs["speed"].rule_actions.tolist() == [1, 0]
    assert b.propose(ctx(0, [0.75, 0.25])).speed_m_s == pytest.approx(0.75 * 0.3 + 0.25 * 0.1)
    b.load_policy(policy(heading=[2, 2]))  # after reset: at once, and heading stops learning
    assert b.learners == {} and b.trial_data() == {}
    assert b.propose(ctx(1, [0.75, 0.25])).heading_deg == -90.0
    pol = b.policy()
    assert pol.rules()["heading"].tolist() == [2, 2] and pol.outputs["heading"].q is None
    assert pol.outputs["speed"].unit == "m/s" and pol.outputs["heading"].unit == "deg"
    with pytest.raises(ValueError, match="the fixed heading rule base has 2 rules but the "
                                         "interpreter has 3 situations"):
        b.reset(np.random.default_rng(0), 3, 10)
    h = FuzzyQBehaviour(headings=H3)
    h.load_policy(policy(speed=[0, 1], heading=[0, 1]))  # outputs it lacks are ignored
    assert list(h.fixed) == ["heading"]


def test_trial_data_and_policy_of_learned_outputs():
    b = FuzzyQBehaviour(headings=H3, speeds=[0.1, 0.3], learn=["heading", "speed"])
    b.reset(np.random.default_rng(0), 2, 10)
    hd, sp = b.learners["heading"], b.learners["speed"]
    d = b.trial_data()
    assert {"heading/q", "speed/q", "heading/rule_base", "speed/final_rule_base"} <= set(d)
    assert d["heading/rule_base"].shape == (10, 2)
    assert d["converged"] is False and d["convergence_iteration"] == -1
    hd.converged_at = 12
    d = b.trial_data()
    assert d["converged"] is False and d["convergence_iteration"] == -1  # speed has not
    sp.converged_at = 30
    d = b.trial_data()
    assert d["converged"] is True and d["convergence_iteration"] == 30  # the later output
    hd.q[:] = [[0.0, 1.0, 0.0], [0.0, 0.0, 2.0]]
    hd.converged_at = None
    pol = b.policy()
    out = pol.outputs["heading"]
    assert out.rules.tolist() == [1, 2] and out.rules.dtype == np.int16  # the greedy rules
    assert out.unit == "deg" and out.actions.tolist() == H3
    out.q[0, 0] = 5.0
    assert hd.q[0, 0] == 0.0  # a copy: logging it cannot change learning


def test_situation_errors_and_changes_follow_the_learners():
    fixed = FuzzyQBehaviour(headings=H3)
    fixed.load_policy(policy(heading=[0, 1]))
    fixed.reset(np.random.default_rng(0), 2, 10)
    assert fixed.situation_errors() is None
    one = FuzzyQBehaviour(headings=H3, b=100)
    one.reset(np.random.default_rng(0), 2, 10)
    one.situation_errors()
    one.learn(transition(0, [0.0, 1.0], [0.0, 1.0]), -1.5)
    assert one.situation_errors().tolist() == [0.0, 1.5]
    b = FuzzyQBehaviour(headings=H3, speeds=[0.1, 0.3], learn=["heading", "speed"], b=100,
                        new_row_optimism=0.25)
    b.reset(np.random.default_rng(0), 3, 10)
    assert b.situation_errors().tolist() == [0.0] * 3
    assert all(lr.track_td for lr in b.learners.values())
    b.learn(transition(0, [1.0, 0.0, 0.0], [1.0, 0.0, 0.0]), 2.0)
    # |delta| = w r = 2 for each output's active rule, summed over the two outputs
    assert b.situation_errors().tolist() == [4.0, 0.0, 0.0]
    hd = b.learners["heading"]
    hd.q[0] = [0.0, 4.0, 0.0]
    b.situations_changed(SituationEvent("create", 2, parents=(0,), weights=np.array([1.0])))
    assert hd.q[2].tolist() == [0.0, 0.75 * 4.0, 0.0]  # pulled towards q_init_value by 0.25
    for out, lr in b.learners.items():
        assert b.fcs[out].rule_actions.tolist() == lr.rule_base.tolist()
    hd.converged_at = 3
    b.situations_changed(SituationEvent("prune", 2, removed=(2,)))
    assert b.fcs["heading"].rule_actions.tolist() == hd.greedy.tolist()


def test_crisp_q_acts_and_learns_on_the_dominant_situation():
    b = CrispQBehaviour(headings=H3, b=100)
    b.load_policy(policy(heading=[0, 2]))
    b.reset(np.random.default_rng(0), 2, 10)
    assert b.propose(ctx(0, [0.4, 0.6])).heading_deg == -90.0  # fuzzy-q: -18
    assert b.propose(ctx(0, [0.5, 0.5])).heading_deg == 90.0  # ties: the first
    c = CrispQBehaviour(headings=H3, b=100)
    c.reset(np.random.default_rng(3), 2, 10)
    lr = c.learners["heading"]
    r0, r1 = lr.rule_base.tolist()
    c.propose(ctx(4, [0.9, 0.1]))
    assert lr.rules_per_iteration[4].tolist() == [r0, r1] and (r0, r1) != (0, 0)
    assert not np.delete(lr.rules_per_iteration, 4, axis=0).any()
    c.learn(transition(0, [0.4, 0.6], [0.5, 0.5]), 1.0)  # only the dominant rule, strength 1
    assert lr.q[1, r1] == pytest.approx(0.3) and not lr.q[0].any()
    # V(s') of the dominant next situation (row 1: 0.3), not the blend 0.8 * 0.3
    c.learn(transition(1, [0.9, 0.1], [0.2, 0.8]), 0.0)
    assert lr.q[0, r0] == pytest.approx(0.3 * 0.9 * 0.3)


def test_a_learned_policy_is_built_of_policy_outputs():  # was an AttributeError at logging
    from sitframe import LearnedPolicy, PolicyOutput

    with pytest.raises(TypeError, match="dict of output names .* to PolicyOutput"):
        LearnedPolicy({"heading": {"actions": [0.0], "rules": [0]}})
    with pytest.raises(TypeError, match="no '/'"):
        LearnedPolicy({"a/b": PolicyOutput([0.0], [0])})
    assert isinstance(PolicyOutput([0.0, 1.0], [1, 0]).rules, np.ndarray)  # (a list was kept)
