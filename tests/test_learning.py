"""Situation FCS inference and fuzzy Q-learning behaviour users rely on."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sitframe.errors import InputError
from sitframe.learning.fcs import SituationFCS, centre_of_gravity, label_strengths
from sitframe.learning.fuzzy_q import FuzzyQLearner, QLearningParams, softmax_choice

HEADINGS = np.array([90, 60, 30, 0, -30, -60, -90], float)


def test_min_max_inference_and_cog():
    # Two rules conclude +90 with strengths 0.2 and 0.5: max gives 0.5.
    u = np.array([0.2, 0.5, 0.3])
    fcs = SituationFCS(HEADINGS, np.array([0, 0, 3]))
    expected = (0.5 * 90 + 0.3 * 0) / 0.8
    assert fcs.output(u) == pytest.approx(expected)
    assert centre_of_gravity(label_strengths(u, np.array([0, 0, 3]), 7), HEADINGS) == \
        pytest.approx(expected)


@given(st.lists(st.floats(0, 1), min_size=2, max_size=16).filter(lambda v: sum(v) > 1e-3),
       st.data())
@settings(max_examples=200, deadline=None)
def test_output_is_within_singleton_range(u, data):
    u = np.asarray(u) / np.sum(u)
    actions = np.asarray(data.draw(st.lists(st.integers(0, 6), min_size=len(u),
                                            max_size=len(u))))
    out = SituationFCS(HEADINGS, actions).output(u)
    used = HEADINGS[actions]
    assert used.min() - 1e-9 <= out <= used.max() + 1e-9


def test_fcs_rejects_bad_rules():
    with pytest.raises(ValueError, match="rule_actions must index the 7 singletons"):
        SituationFCS(HEADINGS, np.array([0, 7]))
    with pytest.raises(ValueError, match=r"non-empty 1-D array, got shape \(0,\)"):
        SituationFCS(HEADINGS, np.array([], dtype=int))
    fcs = SituationFCS(HEADINGS, np.array([1, 2]))
    with pytest.raises(ValueError, match=r"non-empty 1-D array, got shape \(2, 2\)"):
        fcs.set_rules(np.array([[0, 1], [2, 3]]))
    assert fcs.rule_actions.tolist() == [1, 2]  # a refused rule base leaves the old one
    # a fractional or NaN action is no index: refused, not truncated to the one below
    for bad in ([0.5, 1.0], [float("nan"), 1.0], ["a", "b"]):
        with pytest.raises(ValueError, match="whole action indices"):
            fcs.set_rules(bad)
    assert fcs.rule_actions.tolist() == [1, 2]


def test_fcs_rule_base_forms():
    # One situation, one rule: its action whatever the membership.
    assert SituationFCS(HEADINGS, np.array([2])).output(np.array([1.0])) == 30.0
    # Whole numbers as floats (a TOML list, a rule base read back as float) index the singletons.
    fcs = SituationFCS(HEADINGS, [0.0, 3.0])
    assert fcs.rule_actions.dtype.kind == "i"
    assert fcs.output(np.array([0.25, 0.75])) == 22.5
    # set_rules replaces the rule base the controller reports and uses.
    fcs.set_rules([6, 6])
    assert fcs.rule_actions.tolist() == [6, 6]
    assert fcs.output(np.array([0.25, 0.75])) == -90.0


def test_params_validate_with_key():
    with pytest.raises(InputError, match="alpha: expected a number in"):
        QLearningParams(alpha=0.0)
    with pytest.raises(InputError, match=r"update: expected one of 'thesis', 'standard', got "
                                         r"'standrd' \(did you mean 'standard'\?\)"):
        QLearningParams(update="standrd")


@pytest.mark.parametrize("key, bad, good", [
    ("alpha", [0.0, 1.001, "x"], [1.0, 1e-9]),
    ("gamma", [1.0, -0.001], [0.0, 0.999]),
    ("b", [0, 2.5], [1, 2.0]),
    ("p", [0, 1.5], [1]),
    ("temperature", [0.0, -1.0], [1e-9]),
    ("temperature_mode", ["rel"], ["absolute"]),
    ("temperature_decay", [0.0, 1.001], [1.0, 0.01]),
    ("temperature_min", [-0.1], [0.0]),
    ("q_init", ["zero"], ["random"]),
    ("q_init_value", [float("nan"), "x"], [-5.0]),
    ("q_init_spread", [-0.1], [0.0]),
    ("update", ["q"], ["standard"]),
    ("activation", [-0.1, 1.1], [0.0, 1.0]),
    ("terminal_on_collision", [1, "yes"], [True]),
    ("min_updates", [-1, 0.5], [0]),
    ("tie_break", ["middle"], ["centre"]),
    ("alpha_visits", [-1.0, "x"], [0.0, 20.0]),
    ("replay", [-1, 1.5], [0, 4]),
    ("replay_priority", ["rarest"], ["uniform", "rare"]),
])
def test_every_learning_parameter_is_checked_at_its_bounds(key, bad, good):
    """Table A.1's ranges: a value outside is refused naming the key; the bound itself (or
    the nearest value inside an open bound) is accepted."""
    for value in bad:
        with pytest.raises(InputError, match=rf"^{key}: expected"):
            QLearningParams(**{key: value})
    for value in good:
        assert getattr(QLearningParams(**{key: value}), key) == value


def test_softmax_prefers_high_q_and_is_scale_free():
    rng = np.random.default_rng(0)
    q = np.array([[10.0, 0.0, 0.0]] * 2000)
    picks = softmax_choice(q, QLearningParams(temperature=0.25), rng)
    frac = np.mean(picks == 0)
    # worst:best = exp(-4): P(best) = 1 / (1 + 2 exp(-4)) ~ 0.965
    assert frac == pytest.approx(1 / (1 + 2 * np.exp(-4)), abs=0.02)
    picks2 = softmax_choice(q * 100, QLearningParams(temperature=0.25),
                            np.random.default_rng(0))
    assert np.array_equal(picks, picks2)  # relative mode ignores the Q scale


def _learner(**kw):
    params = QLearningParams(**kw)
    return FuzzyQLearner(2, 3, params, np.random.default_rng(1), 100)


def test_thesis_update_matches_eq_4_14():
    lr = _learner(alpha=0.5, gamma=0.9, activation=0.3, b=100)
    lr.q[:] = [[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]
    lr.rule_base[:] = [0, 1]
    u0, u1 = np.array([0.8, 0.2]), np.array([0.5, 0.5])
    v = 0.5 * 3.0 + 0.5 * 6.0
    lr.update(u0, 10.0, u1, False, 0)
    assert lr.q[0, 0] == pytest.approx(1.0 + 0.5 * (0.8 * 10 + 0.9 * 0.8 * v - 1.0))
    assert lr.q[1, 1] == 5.0  # strength 0.2 < activation 0.3: not updated


def test_standard_update():
    lr = _learner(alpha=0.5, gamma=0.9, activation=0.0, update="standard", b=100)
    lr.q[:] = [[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]
    lr.rule_base[:] = [0, 1]
    u0, u1 = np.array([0.8, 0.2]), np.array([0.5, 0.5])
    v = 4.5
    lr.update(u0, 10.0, u1, False, 0)
    assert lr.q[0, 0] == pytest.approx(1.0 + 0.5 * 0.8 * (10 + 0.9 * v - 1.0))
    assert lr.q[1, 1] == pytest.approx(5.0 + 0.5 * 0.2 * (10 + 0.9 * v - 5.0))


def test_alpha_visits_decays_the_rate_per_rule_and_action():
    """``alpha_visits = k``: the n-th update (from 0) of a rule's action uses alpha*k/(k+n),
    counted separately per rule and action; 0 keeps the constant rate."""
    lr = _learner(alpha=0.5, gamma=0.0, activation=0.0, update="standard", b=100,
                  alpha_visits=2.0)
    lr.q[:] = 0.0
    lr.rule_base[:] = [0, 1]
    u = np.array([1.0, 1.0])
    expect, rates = 0.0, [0.5 * 2 / (2 + n) for n in range(4)]
    for rate in rates:
        lr.update(u, 8.0, u, False, 0)
        expect += rate * (8.0 - expect)
    assert lr.q[0, 0] == pytest.approx(expect) and lr.q[1, 1] == pytest.approx(expect)
    lr.rule_base[:] = [1, 1]  # rule 0's action 1 was never updated: it starts at alpha
    lr.update(np.array([1.0, 0.0]), 8.0, u, False, 0)
    assert lr.q[0, 1] == pytest.approx(0.5 * 8.0)
    const = _learner(alpha=0.5, gamma=0.0, activation=0.0, update="standard", b=100)
    const.q[:] = 0.0
    const.rule_base[:] = [0, 0]
    for _ in range(4):
        const.update(u, 8.0, u, False, 0)
    assert const.q[0, 0] == pytest.approx(8.0 * (1 - 0.5 ** 4))


def test_replay_learns_again_from_stored_transitions_with_the_current_q():
    """``replay = k``: after its own update the learner repeats k stored transitions (drawn by
    its generator), each toward r + gamma V(s') under the Q of then; 0 changes nothing."""
    lr = _learner(alpha=0.5, gamma=0.0, activation=0.3, update="standard", b=100, replay=3)
    lr.q[:] = 0.0
    lr.rule_base[:] = [0, 1]
    one = np.array([1.0, 0.0])
    lr.update(one, 8.0, one, False, 0)  # 1 update of its own, then 3 replays of the same
    assert lr.q[0, 0] == pytest.approx(8.0 * (1 - 0.5 ** 4))
    assert lr.updates.tolist() == [4, 0] and lr.replayed == 3
    assert lr.data(1)["replayed"] == 3
    plain = _learner(alpha=0.5, gamma=0.0, activation=0.3, update="standard", b=100)
    plain.q[:] = 0.0
    plain.rule_base[:] = [0, 1]
    plain.update(one, 8.0, one, False, 0)
    assert plain.q[0, 0] == 4.0 and "replayed" not in plain.data(1)


def test_rare_replay_draws_rarely_updated_situations_more_often():
    """``replay_priority = "rare"`` draws a transition with probability ~ 1 / (1 + updates of
    its strongest rule): a situation met once is replayed about as often as one met 50 times;
    ``"uniform"`` replays in proportion to how often each was met."""
    counts = {}
    for priority in ("rare", "uniform"):
        lr = _learner(alpha=0.1, gamma=0.0, activation=0.3, update="standard", b=10**6,
                      replay=1, replay_priority=priority)
        lr.rule_base[:] = [0, 0]
        for it in range(50):
            lr.update(np.array([1.0, 0.0]), 1.0, np.array([1.0, 0.0]), False, it)
        before = lr.updates[1]
        lr.update(np.array([0.0, 1.0]), 1.0, np.array([0.0, 1.0]), False, 50)  # rule 1 once
        start = lr.updates.copy()
        for it in range(200):  # situation 0 again: replays of situation 1 show in its count
            lr.update(np.array([1.0, 0.0]), 1.0, np.array([1.0, 0.0]), False, 51 + it)
        counts[priority] = int(lr.updates[1] - start[1])
        assert before == 0
    assert counts["rare"] > 5 * max(counts["uniform"], 1)


def test_replay_is_deterministic_and_skips_removed_situations():
    """Replays are drawn from the trial's generator (same seed, same Q); a transition that
    involves a row an evolving interpreter removed is not replayed (the row stays reset)."""
    def run(seed: int, remove: bool) -> FuzzyQLearner:
        lr = FuzzyQLearner(2, 3, QLearningParams(activation=0.3, update="standard", b=5,
                                                  replay=2), np.random.default_rng(seed), 400)
        g = np.random.default_rng(seed + 100)
        for it in range(300):
            u = g.dirichlet([0.3, 0.3])
            if remove and it >= 150:
                u = np.array([1.0, 0.0])  # (only row 0 active from now on)
            lr.update(u, float(g.normal()), g.dirichlet([0.3, 0.3]), bool(g.random() < 0.1),
                      it)
            if remove and it == 149:
                lr.removed[1], lr.q[1], lr.updates[1] = True, 0.0, 0
        return lr
    assert np.array_equal(run(1, False).q, run(1, False).q)
    assert not np.array_equal(run(1, False).q, run(2, False).q)
    removed = run(1, True)
    assert removed.q[1].tolist() == [0.0, 0.0, 0.0] and removed.updates[1] == 0
    assert removed.replayed > 0


def test_rule_base_changes_after_b_iterations_or_collision():
    lr = _learner(b=5)
    u = np.array([1.0, 0.0])
    for t in range(4):
        lr.update(u, 1.0, u, False, t)
    assert len(lr._snap_iter) == 1
    lr.update(u, 1.0, u, False, 4)
    assert lr._snap_iter[-1] == 5
    lr.update(u, -30.0, u, True, 5)
    assert lr._snap_iter[-1] == 6


def test_converges_when_greedy_is_stable_for_p_changes_then_freezes():
    lr = _learner(b=1, p=3)
    lr.q[:] = [[5.0, 0.0, 0.0], [0.0, 0.0, 5.0]]
    lr.greedy = lr.q.argmax(axis=1)
    u = np.array([0.0, 0.0])  # nothing activated: Q does not move
    for t in range(3):
        lr.update(u, 0.0, u, False, t)
    assert lr.converged_at == 3
    assert list(lr.rule_base) == [0, 2]
    q_before = lr.q.copy()
    lr.update(np.array([1.0, 0.0]), -30.0, u, True, 3)
    assert np.array_equal(lr.q, q_before)  # frozen: no more learning
    data = lr.data(4)
    assert data["converged"] and data["convergence_iteration"] == 3
    assert list(data["final_rule_base"]) == [0, 2]


def test_a_greedy_change_restarts_the_count_of_stable_changes():
    """Convergence means p rule-base changes in a row without a new greedy rule base."""
    lr = _learner(b=1, p=3)
    lr.q[:] = [[5.0, 0.0, 0.0], [0.0, 0.0, 5.0]]
    lr.greedy = lr.q.argmax(axis=1)
    u = np.array([0.0, 0.0])  # nothing activated: Q moves only when the test says
    for t in range(2):
        lr.update(u, 0.0, u, False, t)
    assert lr.stable_changes == 2 and lr.converged_at is None
    lr.q[0] = [0.0, 5.0, 0.0]  # situation 0 now prefers action 1
    lr.update(u, 0.0, u, False, 2)
    assert lr.stable_changes == 0 and lr.converged_at is None
    for t in range(3, 5):
        lr.update(u, 0.0, u, False, t)
    assert lr.converged_at is None
    lr.update(u, 0.0, u, False, 5)
    assert lr.converged_at == 6  # 3 stable changes after the one at iteration 3
    assert list(lr.rule_base) == [1, 2]
    greedy = lr.data(6)["snapshot_greedy"][1:]  # (the first row is the initial Q's)
    assert greedy.tolist() == [[0, 2]] * 2 + [[1, 2]] * 4


def test_learner_is_deterministic():
    def run():
        lr = FuzzyQLearner(4, 7, QLearningParams(), np.random.default_rng(7), 200)
        rng = np.random.default_rng(3)
        for t in range(200):
            u = rng.dirichlet(np.ones(4))
            lr.update(u, float(rng.normal()), rng.dirichlet(np.ones(4)), bool(t % 17 == 0), t)
        return lr.data(200)

    a, b = run(), run()
    for k in a:
        assert np.array_equal(np.asarray(a[k]), np.asarray(b[k]))


def test_terminal_on_collision_drops_the_bootstrap():
    lr = _learner(alpha=1.0, gamma=0.9, activation=0.0, b=100, terminal_on_collision=True)
    lr.q[:] = [[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]
    lr.rule_base[:] = [0, 1]
    u0 = np.array([1.0, 0.0])
    lr.update(u0, -30.0, np.array([0.0, 1.0]), True, 0)
    assert lr.q[0, 0] == pytest.approx(-30.0)  # target is the reward alone
    lr.q[0, 0] = 1.0
    lr.rule_base[:] = [0, 1]  # the collision changed the rule base
    lr.update(u0, 30.0, np.array([0.0, 1.0]), False, 1)
    assert lr.q[0, 0] == pytest.approx(30.0 + 0.9 * 6.0)  # no collision: bootstraps


def test_temperature_anneals_per_rule_base_change():
    lr = _learner(temperature=4.0, temperature_mode="absolute", temperature_decay=0.5,
                  temperature_min=1.5, b=1)
    u = np.array([0.0, 0.0])
    assert lr.temperature == 4.0
    lr.update(u, 0.0, u, False, 0)
    assert lr.temperature == 2.0
    lr.update(u, 0.0, u, False, 1)
    assert lr.temperature == 1.5  # floored at temperature_min


def test_min_updates_delays_convergence_until_every_situation_was_updated():
    lr = _learner(b=1, p=2, min_updates=3, activation=0.5)
    lr.q[:] = [[5.0, 0.0, 0.0], [0.0, 0.0, 5.0]]
    lr.greedy = lr.q.argmax(axis=1)
    only_first = np.array([1.0, 0.0])
    for t in range(6):  # greedy stays stable, but situation 1 is never updated
        lr.update(only_first, 1.0, only_first, False, t)
    assert lr.converged_at is None
    both = np.array([0.5, 0.5])
    for t in range(6, 9):
        lr.update(both, 1.0, both, False, t)
    assert lr.updates.min() >= 3 and lr.converged_at is not None


def test_greedy_tie_break_first_or_centre():
    from sitframe.learning.fuzzy_q import greedy_actions

    q = np.array([[5.0, 5.0, 5.0, 5.0, 5.0],    # never updated: all tied
                  [1.0, 7.0, 2.0, 7.0, 0.0],    # tie between 1 and 3
                  [0.0, 1.0, 2.0, 3.0, 9.0]])   # no tie
    assert greedy_actions(q, "first").tolist() == [0, 1, 4]
    assert greedy_actions(q, "centre").tolist() == [2, 1, 4]  # equal distance: lower index
    even = np.zeros((1, 4))
    assert greedy_actions(even, "centre").tolist() == [1]
    with pytest.raises(ValueError, match="tie_break"):
        QLearningParams(tie_break="middle")


def test_random_q_init_spreads_around_the_value_and_rules_start_uniform():
    lr = FuzzyQLearner(400, 7, QLearningParams(q_init="random", q_init_value=10.0,
                                               q_init_spread=2.0), np.random.default_rng(0), 5)
    assert lr.q.shape == (400, 7)
    assert 8.0 <= lr.q.min() < 8.1 and 11.9 < lr.q.max() <= 12.0
    assert lr.q.mean() == pytest.approx(10.0, abs=0.05)
    # thesis Alg. 3 step 5: the first rule base is drawn uniformly over every action
    assert np.bincount(lr.rule_base, minlength=7).min() > 400 / 7 * 0.6
    constant = FuzzyQLearner(3, 2, QLearningParams(q_init_value=-4.0), np.random.default_rng(0), 5)
    assert constant.q.tolist() == [[-4.0, -4.0]] * 3


@pytest.mark.parametrize("tie_break, action", [("first", 0), ("centre", 3)])
def test_the_logged_greedy_rule_base_breaks_ties_as_configured(tie_break, action):
    """Never-updated situations (all Q tied) get the tie-break's action in every record."""
    lr = FuzzyQLearner(3, 7, QLearningParams(b=1, p=2, tie_break=tie_break),
                       np.random.default_rng(0), 10)
    none = np.zeros(3)
    for t in range(2):
        lr.update(none, 0.0, none, False, t)
    data = lr.data(2)
    assert data["snapshot_greedy"].tolist() == [[action] * 3] * 3
    assert data["final_rule_base"].tolist() == [action] * 3
    assert data["converged"] and data["convergence_iteration"] == 2


def test_changes_come_every_b_iterations_and_stop_after_convergence():
    lr = FuzzyQLearner(2, 3, QLearningParams(b=5, p=3), np.random.default_rng(0), 40)
    lr.q[:] = [[5.0, 0.0, 0.0], [0.0, 0.0, 5.0]]
    lr.greedy = lr.q.argmax(axis=1)
    u = np.zeros(2)
    changed = [t for t in range(25) if lr.update(u, 0.0, u, False, t)]
    assert changed == [4, 9, 14]
    assert lr.converged_at == 15
    assert lr.data(25)["snapshot_iteration"].tolist() == [0, 5, 10, 15]


def test_an_unconverged_learner_reports_the_greedy_not_the_explored_rule_base():
    lr = FuzzyQLearner(2, 3, QLearningParams(b=100), np.random.default_rng(0), 10)
    lr.q[:] = [[0.0, 5.0, 0.0], [0.0, 0.0, 5.0]]
    lr.rule_base[:] = [0, 0]  # exploring
    assert lr.final_rule_base().tolist() == [1, 2]
    data = lr.data(0)
    assert not data["converged"] and data["convergence_iteration"] == -1


def test_the_rule_base_draws_use_the_annealed_temperature():
    """After two changes the temperature is 0.01: every draw takes the best action (at the
    initial temperature 1 each of the 6 others would be exp(-1) as likely)."""
    lr = FuzzyQLearner(50, 7, QLearningParams(b=1, p=1000, temperature=1.0, temperature_decay=0.1,
                                              temperature_min=0.01), np.random.default_rng(0), 10)
    lr.q[:, 0] = 1.0
    u = np.zeros(50)
    for t in range(3):
        lr.update(u, 0.0, u, False, t)
    assert lr.rule_base.tolist() == [0] * 50


def test_min_updates_of_one_waits_for_every_situation():
    lr = FuzzyQLearner(2, 3, QLearningParams(b=1, p=2, min_updates=1, activation=0.5),
                       np.random.default_rng(0), 20)
    only_first = np.array([1.0, 0.0])
    for t in range(6):
        lr.update(only_first, 1.0, only_first, False, t)
    assert lr.converged_at is None  # situation 1 never updated


def test_logged_learner_arrays_have_the_log_layout():
    """The arrays a log stores: names, dtypes and shapes are the log format."""
    lr = FuzzyQLearner(4, 7, QLearningParams(b=2), np.random.default_rng(3), 50)
    rng = np.random.default_rng(4)
    for t in range(9):
        u = rng.dirichlet(np.ones(4))
        lr.record_rules(t)
        lr.update(u, 1.0, rng.dirichlet(np.ones(4)), False, t)
    data = lr.data(9)
    assert set(data) == {"q", "q_snapshots", "snapshot_iteration", "snapshot_rule_base",
                         "snapshot_greedy", "rule_base", "final_rule_base", "updates",
                         "converged", "convergence_iteration"}
    dtypes = {k: np.asarray(v).dtype for k, v in data.items()}
    assert dtypes["snapshot_rule_base"] == dtypes["snapshot_greedy"] == np.int16
    assert dtypes["final_rule_base"] == np.int16 and dtypes["rule_base"] == np.int8
    assert dtypes["updates"] == dtypes["snapshot_iteration"] == np.int64
    assert data["rule_base"].shape == (9, 4) and data["q_snapshots"].shape == (5, 4, 7)
    assert data["snapshot_iteration"].tolist() == [0, 2, 4, 6, 8]
    assert data["updates"].sum() > 0 and np.array_equal(data["q"], lr.q)


def test_td_errors_are_tracked_only_for_the_rules_just_updated_and_after_convergence():
    """An evolving interpreter reads ``td_abs``: this iteration's |TD error| of each
    activated rule, 0 elsewhere; after convergence the errors the frozen rules would get."""
    for activation in (0.3, 0.0):
        lr = FuzzyQLearner(3, 2, QLearningParams(alpha=0.5, gamma=0.5, b=100,
                                                 activation=activation),
                           np.random.default_rng(0), 10)
        lr.track_td = True
        lr.q[:] = [[1.0, 2.0], [3.0, 4.0], [5.0, 6.0]]
        lr.rule_base[:] = [0, 1, 0]
        u0, u1 = np.array([0.8, 0.2, 0.0]), np.array([0.0, 0.0, 1.0])
        lr.update(u0, 10.0, u1, False, 0)  # V(s') = 6
        expect = [abs(0.8 * 10 + 0.5 * 0.8 * 6 - 1.0), abs(0.2 * 10 + 0.5 * 0.2 * 6 - 4.0), 5.0]
        if activation:
            expect[1:] = [0.0, 0.0]
        np.testing.assert_allclose(lr.td_abs, expect)
        lr.converged_at = 1
        q = lr.q.copy()
        assert lr.update(u0, 10.0, u1, False, 1) is False  # frozen: no reload
        assert np.array_equal(lr.q, q)
        expect = np.abs(u0 * 10 + 0.5 * u0 * 6 - q[[0, 1, 2], [0, 1, 0]])
        if activation:
            expect[1:] = 0.0
        np.testing.assert_allclose(lr.td_abs, expect)


def test_min_updates_counts_only_live_situations_of_an_evolving_interpreter():
    """A pruned situation, or one created and not yet visited, does not block convergence;
    a visited live one still needs its updates."""
    from sitframe.situations.events import SituationEvent

    def learner():
        lr = FuzzyQLearner(4, 3, QLearningParams(b=1, p=2, min_updates=2, activation=0.5),
                           np.random.default_rng(0), 20)
        lr.q[:, 0] = 1.0
        lr.greedy = lr.q.argmax(axis=1)
        return lr

    first_two = np.array([0.5, 0.5, 0.0, 0.0])
    lr = learner()
    lr.situations_changed(SituationEvent("create", 3, (), np.zeros(0)))
    for t in range(4):
        lr.update(first_two, 1.0, first_two, False, t)
    assert lr.converged_at == 2  # rows 0, 1 updated twice; 2 and the new 3 never visited
    lr = learner()
    lr.situations_changed(SituationEvent("prune", 3, (), np.zeros(0), removed=(3,)))
    lr.updates[2] = 1  # visited once: too few
    for t in range(4):
        lr.update(first_two, 1.0, first_two, False, t)
    assert lr.converged_at is None
    lr = learner()  # a fixed set of situations: every one must be updated
    for t in range(4):
        lr.update(first_two, 1.0, first_two, False, t)
    assert lr.converged_at is None


def test_softmax_draws_follow_the_boltzmann_probabilities():
    """Frequencies of 6000 draws per row against ``exp(logits) / sum``, rows of different
    scales and spreads in one call (each row uses its own max and min)."""
    from sitframe.learning.fuzzy_q import greedy_actions

    def freq(q_rows, params, temperature=None):
        q = np.repeat(np.asarray(q_rows, float), 6000, axis=0)
        picks = softmax_choice(q, params, np.random.default_rng(0), temperature)
        return np.array([np.bincount(row, minlength=3) / 6000
                         for row in picks.reshape(len(q_rows), 6000)])

    e = np.exp([-2.0, -1.0, 0.0])
    p = e / e.sum()
    rel = QLearningParams(temperature=0.5)
    got = freq([[0, 1, 2], [10, 10, 10], [-5, 5, 0], [0, 0.25, 0.5]], rel)
    np.testing.assert_allclose(got, [p, [1 / 3] * 3, p[[0, 2, 1]], p], atol=0.02)
    absolute = QLearningParams(temperature=100.0, temperature_mode="absolute")
    got = freq([[0, 2, 4], [-4, 0, 0], [7, 7, 7]], absolute, temperature=2.0)
    e2 = np.exp([-2.0, 0.0, 0.0])
    np.testing.assert_allclose(got, [p, e2 / e2.sum(), [1 / 3] * 3], atol=0.02)
    assert greedy_actions(np.array([[3.0, 3.0, 1.0]])).tolist() == [0]  # default: first


def test_no_rule_strength_gives_the_mean_singleton():
    assert centre_of_gravity(np.zeros(3), np.array([90.0, 0.0, -30.0])) == 20.0
    fcs = SituationFCS(np.array([90.0, 0.0, -30.0]), np.array([0, 1]))
    assert fcs.output(np.zeros(2)) == 20.0


def _evolving_learner(converged: bool = False, tie_break: str = "first") -> FuzzyQLearner:
    lr = FuzzyQLearner(5, 3, QLearningParams(q_init_value=10.0, alpha_visits=4.0,
                                             tie_break=tie_break),
                       np.random.default_rng(0), 20)
    lr.q[:] = [[1.0, 4.0, 2.0], [6.0, 0.0, 3.0], [2.0, 2.0, 8.0], [5.0, 1.0, 1.0],
               [0.0, 9.0, 3.0]]
    lr.updates[:] = [3, 1, 0, 5, 7]
    lr.greedy = lr.q.argmax(axis=1)
    lr._visits = {(i, a): 2 for i in range(5) for a in range(3)}
    if converged:
        lr.converged_at, lr.stable_changes = 7, 50
        lr.rule_base = lr.greedy.copy()
    return lr


@pytest.mark.parametrize("kind", ["create", "split"])
def test_a_new_situation_starts_from_its_parents_pulled_to_the_optimistic_start(kind):
    """create/split: Q of the new row = (1 - optimism) * sum_j w_j Q_j + optimism * Q0, no
    updates yet, alive; a converged learner re-opens learning; the learning rates of the
    new row and its parents start anew; other rows are untouched."""
    from sitframe.situations.events import SituationEvent

    lr = _evolving_learner(converged=True)
    before = lr.q.copy()
    lr.removed[4] = True
    lr.situations_changed(SituationEvent(kind, 4, (0, 1), np.array([0.25, 0.75])),
                          optimism=0.2)
    want = 0.8 * (0.25 * before[0] + 0.75 * before[1]) + 0.2 * 10.0
    np.testing.assert_allclose(lr.q[4], want, rtol=1e-15)
    np.testing.assert_array_equal(lr.q[:4], before[:4])
    assert lr.updates[4] == 0 and not lr.removed[4]
    assert lr.converged_at is None and lr.stable_changes == 0
    assert {k[0] for k in lr._visits} == {2, 3}
    orphan = _evolving_learner()
    orphan.situations_changed(SituationEvent(kind, 2, (), np.zeros(0)))
    np.testing.assert_array_equal(orphan.q[2], [10.0, 10.0, 10.0])
    assert orphan.converged_at is None
    halfway = _evolving_learner()  # the default optimism: half way to Q0
    halfway.situations_changed(SituationEvent(kind, 4, (3,), np.array([1.0])))
    np.testing.assert_allclose(halfway.q[4], 0.5 * before[3] + 0.5 * 10.0, rtol=1e-15)


def test_merging_averages_by_visits_and_pruning_resets():
    """merge: the survivor's Q is the mean of the merged rows weighted by updates + 1 and
    it inherits their updates; absorbed rows go back to Q0 with no updates and are marked
    removed; the greedy rule base follows, and a converged learner executes it. prune resets
    and removes the row only."""
    from sitframe.situations.events import SituationEvent

    lr = _evolving_learner(converged=True)
    before = lr.q.copy()
    lr.situations_changed(SituationEvent("merge", 0, (0, 3), np.array([0.5, 0.5]),
                                         removed=(3,)))
    np.testing.assert_allclose(lr.q[0], (4 * before[0] + 6 * before[3]) / 10, rtol=1e-15)
    assert lr.updates[0] == 8 and lr.updates[3] == 0
    np.testing.assert_array_equal(lr.q[3], [10.0, 10.0, 10.0])
    np.testing.assert_array_equal(lr.removed, [False, False, False, True, False])
    np.testing.assert_array_equal(lr.greedy, lr.q.argmax(axis=1))
    np.testing.assert_array_equal(lr.rule_base, lr.greedy)
    assert lr.converged_at == 7  # a merge does not re-open learning
    assert {k[0] for k in lr._visits} == {1, 2, 4}
    lr = _evolving_learner(tie_break="centre")
    rules = lr.rule_base.copy()
    lr.situations_changed(SituationEvent("prune", 4, (), np.zeros(0), removed=(4,)))
    np.testing.assert_array_equal(lr.q[4], [10.0, 10.0, 10.0])
    assert lr.updates[4] == 0 and lr.removed[4] and lr.removed.sum() == 1
    np.testing.assert_array_equal(lr.greedy, [*lr.q[:4].argmax(axis=1), 1])  # the tie: centre
    np.testing.assert_array_equal(lr.rule_base, rules)  # not converged: rules stay learned


@pytest.mark.parametrize("update", ["thesis", "standard"])
@pytest.mark.parametrize("terminal", [False, True])
def test_frozen_rules_report_the_td_errors_of_their_update_rule(update, terminal):
    """After convergence the errors the frozen rules would get follow the update rule
    (thesis: weighted by the rule strength; standard: unweighted), a collision ends the
    episode only with ``terminal_on_collision``, and a rule exactly at ``activation`` is
    active. Counts of updates are exact: one per active rule and iteration."""
    prm = QLearningParams(alpha=0.5, gamma=0.5, b=100, activation=0.2, update=update,
                          terminal_on_collision=terminal)
    lr = FuzzyQLearner(3, 2, prm, np.random.default_rng(0), 10)
    lr.q[:] = [[1.0, 2.0], [3.0, 4.0], [5.0, 6.0]]
    lr.rule_base[:] = [0, 1, 0]
    u0, u1 = np.array([0.7, 0.2, 0.1]), np.array([0.0, 0.0, 1.0])
    for t in range(3):
        lr.update(u0, 10.0, u1, False, t)
    np.testing.assert_array_equal(lr.updates, [3, 3, 0])
    lr.track_td, lr.converged_at = True, 3
    q = lr.q.copy()
    lr.update(u0, 10.0, u1, True, 3)  # a collision
    v_next = 0.0 if terminal else q.max(axis=1) @ u1
    w = u0[:2] if update == "thesis" else 1.0
    cur = q[[0, 1], [0, 1]]
    np.testing.assert_allclose(lr.td_abs, [*np.abs(w * 10 + 0.5 * w * v_next - cur), 0.0])
    np.testing.assert_array_equal(lr.q, q)
    np.testing.assert_array_equal(lr.updates, [3, 3, 0])


def test_an_evolving_learner_without_any_update_yet_does_not_converge():
    """With situations created on-line, rows never updated are not yet situations: a run
    whose rules were never strong enough to be updated has not met ``min_updates = 1``."""
    from sitframe.situations.events import SituationEvent

    lr = FuzzyQLearner(3, 2, QLearningParams(b=1, p=1, activation=0.5, min_updates=1),
                       np.random.default_rng(0), 10)
    lr.situations_changed(SituationEvent("create", 0, (), np.zeros(0)))
    weak = np.full(3, 1 / 3)
    for t in range(5):
        lr.update(weak, 1.0, weak, False, t)
    assert lr.updates.sum() == 0 and lr.converged_at is None


def test_final_rule_base_breaks_ties_as_configured():
    """Before convergence the final rule base is the greedy one, ties broken by
    ``tie_break`` (``centre``: the action nearest the middle)."""
    for tie_break, want in (("centre", [1, 0, 1]), ("first", [0, 0, 0])):
        lr = FuzzyQLearner(3, 3, QLearningParams(tie_break=tie_break),
                           np.random.default_rng(0), 5)
        lr.q[:] = [[2.0, 2.0, 2.0], [5.0, 1.0, 5.0], [5.0, 5.0, 1.0]]
        np.testing.assert_array_equal(lr.final_rule_base(), want)


def test_softmax_is_finite_for_large_q_values_and_rows_far_apart():
    """Q-values in the thousands, rows thousands apart, small temperatures: the soft-max
    still draws by its own row's Boltzmann weights (no overflow, no 0/0)."""
    q = np.repeat([[1000.0, 999.0, 998.0], [0.0, 1.0, 2.0]], 4000, axis=0)
    for params in (QLearningParams(temperature=0.5),
                   QLearningParams(temperature=1.0, temperature_mode="absolute")):
        with np.errstate(all="raise"):
            picks = softmax_choice(q, params, np.random.default_rng(1))
        first, second = (np.bincount(picks[k * 4000:(k + 1) * 4000], minlength=3) / 4000
                         for k in (0, 1))
        scale = 0.5 * 2.0 if params.temperature_mode == "relative" else 1.0  # tau * spread
        p = np.exp(np.array([0.0, -1.0, -2.0]) / scale)
        p /= p.sum()
        np.testing.assert_allclose(first, p, atol=0.03)
        np.testing.assert_allclose(second, p[::-1], atol=0.03)
