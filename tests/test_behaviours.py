"""Wall-following reward, goal behaviour, CDB and priority arbiters (unit level)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sitframe.contract.records import Context, Proposal, Transition
from sitframe.errors import InputError
from sitframe.plugins.arbiters import CDBArbiter, PriorityArbiter, trapezoid
from sitframe.plugins.goal import GoalBehaviour, goal_bearing_deg
from sitframe.plugins.sonar import PIONEER_ANGLES_DEG as PIONEER
from sitframe.plugins.wall_following import WallFollowingReward
from sitframe.sim.robot import Command, StepOutcome
from sitframe.sim.world import Goal, load_world

WORLD = load_world("goal")
FAR = 3.0  # max range: nothing seen


def ctx(reading=None, *, pose=(1.0, 1.0, 0.0), goal=None, it=0) -> Context:
    r = np.full(8, FAR) if reading is None else np.asarray(reading, float)
    return Context(it, np.asarray(pose, float), r, np.zeros(0), float(r.min()), WORLD, goal)


def side(left=FAR, right=FAR) -> np.ndarray:
    """A reading with a wall parallel to the robot at ``left``/``right`` metres (90-deg beams)."""
    r = np.full(8, FAR)
    r[0], r[7] = left, right
    return r


def transition(before, after, *, heading=0.0, collided=False) -> Transition:
    p = np.zeros(3)
    out = StepOutcome(pose_before=p, pose=p, collided=collided,
                      contact_xy=np.full(2, np.nan), contact_pose=p, distance_m=0.2,
                      heading_change_deg=heading)
    return Transition(ctx(before), Command(heading, 0.15), out, ctx(after, it=1))


# ---------------------------------------------------------------------------
# wall-following reward
# ---------------------------------------------------------------------------

@pytest.fixture()
def wf() -> WallFollowingReward:
    return WallFollowingReward(angles_deg=PIONEER)


def test_wall_distance_definition(wf):
    assert wf.wall_distance(side(right=0.25)) == pytest.approx(0.25)
    assert wf.wall_distance(side(left=0.4, right=0.2)) == pytest.approx(0.2)  # nearer side
    assert math.isinf(wf.wall_distance(np.full(8, FAR)))  # nothing seen
    r = np.full(8, FAR)
    r[1] = 0.3  # +50 deg beam: lateral clearance (R + r) sin 50 - R
    assert wf.wall_distance(r) == pytest.approx(0.45 * math.sin(math.radians(50)) - 0.15)
    r = np.full(8, FAR)
    r[3] = 0.05  # front beams do not measure the wall distance
    assert math.isinf(wf.wall_distance(r))


def test_reward_cases(wf):
    assert wf(transition(side(right=0.25), side(right=0.25), collided=True)) == -30
    assert wf(transition(side(right=0.25), side(right=0.10))) == -20          # too close
    assert wf(transition(side(right=0.25), side(right=0.25))) == 30           # in band
    assert wf(transition(side(right=0.25), side(right=0.25), heading=-40)) == pytest.approx(26)
    assert wf(transition(side(right=0.30), side(right=0.60))) == -20          # lost the wall
    assert wf(transition(side(right=1.0), side(right=0.8), heading=20)) == pytest.approx(18)
    assert wf(transition(side(right=0.8), side(right=1.0))) == 0              # exploring
    assert wf(transition(np.full(8, FAR), np.full(8, FAR))) == 0              # open space
    # the heading cost uses the magnitude: left and right turns cost the same
    assert wf(transition(side(left=0.2), side(left=0.2), heading=30)) == \
        wf(transition(side(left=0.2), side(left=0.2), heading=-30))


def test_reward_params_and_metrics():
    r = WallFollowingReward(near=0.2, far=0.5, inside=10.0, angles_deg=PIONEER)
    assert r(transition(side(right=0.45), side(right=0.45))) == 10
    sonar = np.stack([side(right=0.25), side(right=0.10), np.full(8, FAR), side(left=0.30)])
    m = WallFollowingReward(angles_deg=PIONEER).metrics({"sonar": sonar})
    assert m["wall_band_fraction"] == pytest.approx(0.5)
    assert m["wall_lost_fraction"] == pytest.approx(0.25)
    assert m["wall_band_rmse_m"] == pytest.approx(math.sqrt((0.05 ** 2 + 2.65 ** 2) / 4))
    with pytest.raises(ValueError, match="knows no beam angles"):  # unbound, no angles
        WallFollowingReward().wall_distance(side(right=0.25))
    with pytest.raises(InputError, match="near"):
        WallFollowingReward(near=-1)
    with pytest.raises(ValueError, match="greater than near"):
        WallFollowingReward(near=0.4, far=0.3)


# ---------------------------------------------------------------------------
# goal behaviour
# ---------------------------------------------------------------------------

@pytest.mark.parametrize("goal_xy, theta, expected", [
    ((2.0, 1.5), 0.0, math.degrees(math.atan2(0.5, 1.0))),   # ahead-left: positive
    ((2.0, 0.5), 0.0, -math.degrees(math.atan2(0.5, 1.0))),  # ahead-right: negative
    ((1.0, 3.0), 0.0, 90.0),                                 # straight left
    ((1.0, -1.0), 0.0, -90.0),                               # straight right
    ((0.0, 0.9), 0.0, -90.0),                                # behind-right: clipped
    ((0.0, 1.1), 0.0, 90.0),                                 # behind-left: clipped
    ((0.0, 0.9), math.pi / 2, 90.0),                         # facing +y, goal behind-left
    ((2.0, 1.0), math.pi, 90.0),                             # goal right behind: +90
    ((1.0, 2.0), math.pi / 2, 0.0),                          # facing the goal
    ((2.0, 1.1), math.pi - 0.01, -90.0),                     # facing -x, behind-right
    ((2.0, 0.9), math.pi - 0.01, 90.0),                      # facing -x, behind-left
])
def test_goal_bearing_sign_and_clip(goal_xy, theta, expected):
    g = GoalBehaviour()
    p = g.propose(ctx(pose=(1.0, 1.0, theta), goal=Goal(np.asarray(goal_xy), 0.3)))
    assert p.heading_deg == pytest.approx(expected, abs=1e-6)
    assert p.speed_m_s is None


def test_goal_bearing_wraps():
    assert goal_bearing_deg(np.array([0, 0, math.radians(170)]),
                            np.array([1.0, -0.2])) == pytest.approx(
        -170 - math.degrees(math.atan2(0.2, 1.0)) + 360)
    assert GoalBehaviour(max_turn_deg=30).propose(
        ctx(pose=(0, 0, 0), goal=Goal(np.array([0.0, 1.0])))).heading_deg == 30


def test_goal_behaviour_needs_a_goal():
    with pytest.raises(InputError, match="needs a goal"):
        GoalBehaviour().propose(ctx())


# ---------------------------------------------------------------------------
# CDB
# ---------------------------------------------------------------------------

PROPS = {"avoid": Proposal(60.0), "goal": Proposal(-30.0)}


def near(d: float) -> Context:
    r = np.full(8, FAR)
    r[3] = d
    return ctx(r)


def test_trapezoid_shapes():
    assert trapezoid(0.0, (0, 0, 0.2, 0.6)) == 1.0
    assert trapezoid(0.4, (0, 0, 0.2, 0.6)) == pytest.approx(0.5)
    assert trapezoid(0.7, (0, 0, 0.2, 0.6)) == 0.0
    assert trapezoid(10.0, (0.2, 0.6, 3, 3)) == 1.0        # right shoulder
    assert trapezoid(0.5, (0.2, 0.5, 0.5, 0.8)) == 1.0     # triangle peak
    assert trapezoid(0.35, (0.2, 0.5, 0.5, 0.8)) == pytest.approx(0.5)


def test_cdb_close_far_blend():
    cdb = CDBArbiter(sets={"close": [0, 0, 0.2, 0.6], "far": [0.2, 0.6, 3, 3]},
                     rules={"close": "avoid", "far": "goal"})
    p, w = cdb.combine(near(0.1), PROPS)                   # close: avoid alone
    assert w.tolist() == [1.0, 0.0] and p.heading_deg == 60.0
    p, w = cdb.combine(near(2.0), PROPS)                   # far: goal alone
    assert w.tolist() == [0.0, 1.0] and p.heading_deg == -30.0
    p, w = cdb.combine(near(0.3), PROPS)                   # in between: a blend
    mu_close, mu_far = 0.75, 0.25
    assert w == pytest.approx([0.75, 0.25])
    assert p.heading_deg == pytest.approx((mu_close * 60 - mu_far * 30) / (mu_close + mu_far))
    assert p.speed_m_s is None
    p, w = cdb.combine(near(0.25), PROPS)                  # avoid dominates while close
    assert w[0] > w[1]


def test_cdb_general_rules_and_speed():
    props = {"a": Proposal(90.0, 0.1), "b": Proposal(0.0, None), "c": Proposal(-90.0, 0.3)}
    cdb = CDBArbiter(sets={"close": [0, 0, 0.3, 0.5]}, rules=[
        {"behaviour": "a", "set": "close"},
        {"behaviour": "b", "set": [0.3, 0.5, 1.0, 1.5]},
        {"behaviour": "c", "set": [1.0, 1.5, 3, 3]},
    ])
    p, w = cdb.combine(near(1.25), props)                  # b and c half each
    assert w == pytest.approx([0, 0.5, 0.5])
    assert p.heading_deg == pytest.approx(-45.0)
    assert p.speed_m_s == pytest.approx(0.3)               # only c has a speed
    # default rules: i-th set drives the i-th behaviour
    p, w = CDBArbiter().combine(near(0.05), PROPS)
    assert w.tolist() == [1.0, 0.0]


@pytest.mark.parametrize(
    ("sets", "d", "expected"),
    [  # memberships summing to 0.5 (a dip between the sets) and to 2 (two full sets)
        ({"close": [0, 0, 0.2, 0.6], "far": [0.4, 0.8, 3, 3]}, 0.5, [0.5, 0.5]),
        ({"close": [0, 0, 0.5, 0.8], "far": [0.2, 0.4, 3, 3]}, 0.45, [0.5, 0.5]),
        ({"close": [0, 0, 0.2, 0.6], "far": [0.3, 0.7, 3, 3]}, 0.4, [0.5 / 0.75, 0.25 / 0.75]),
    ],
)
def test_cdb_normalises_when_context_sets_do_not_sum_to_one(sets, d, expected):
    """The command is the centre of gravity of the proposals, whatever the set shapes."""
    props = {"avoid": Proposal(60.0, 0.1), "goal": Proposal(-30.0, 0.3)}
    p, w = CDBArbiter(sets=sets, rules={"close": "avoid", "far": "goal"}).combine(near(d), props)
    assert w == pytest.approx(expected) and w.sum() == pytest.approx(1.0)
    assert p.heading_deg == pytest.approx(expected[0] * 60.0 - expected[1] * 30.0)
    assert p.speed_m_s == pytest.approx(expected[0] * 0.1 + expected[1] * 0.3)


def test_cdb_gap_falls_back_to_nearest_set():
    cdb = CDBArbiter(sets={"close": [0, 0, 0.2, 0.3], "far": [0.8, 1.0, 3, 3]},
                     rules={"close": "avoid", "far": "goal"})
    assert cdb.combine(near(0.4), PROPS)[1].tolist() == [1.0, 0.0]
    assert cdb.combine(near(0.75), PROPS)[1].tolist() == [0.0, 1.0]


def test_cdb_bad_params():
    with pytest.raises(InputError, match="a <= b <= c <= d"):
        CDBArbiter(sets={"close": [0.5, 0.2, 0.3, 0.4]})
    with pytest.raises(InputError, match="unknown context set 'near'"):
        CDBArbiter(rules={"near": "avoid"})
    cdb = CDBArbiter(rules={"close": "avoid", "far": "seek"})
    with pytest.raises(InputError, match="names behaviour 'seek'.*avoid, goal"):
        cdb.combine(near(1.0), PROPS)


# ---------------------------------------------------------------------------
# priority switching
# ---------------------------------------------------------------------------

def test_priority_switching():
    pr = PriorityArbiter(rules=[{"behaviour": "avoid", "nearest_below": 0.5},
                                {"behaviour": "goal"}])
    p, w = pr.combine(near(0.3), PROPS)
    assert p == PROPS["avoid"] and w.tolist() == [1.0, 0.0]
    p, w = pr.combine(near(0.7), PROPS)
    assert p == PROPS["goal"] and w.tolist() == [0.0, 1.0]
    # defaults: all but the last behaviour win below the threshold
    d = PriorityArbiter(threshold=0.4)
    assert d.combine(near(0.39), PROPS)[1].tolist() == [1.0, 0.0]
    assert d.combine(near(0.41), PROPS)[1].tolist() == [0.0, 1.0]
    # no condition holds: the last rule wins
    only = PriorityArbiter(rules=[{"behaviour": "goal", "nearest_above": 5.0},
                                  {"behaviour": "avoid", "nearest_below": 0.1}])
    assert only.combine(near(1.0), PROPS)[1].tolist() == [1.0, 0.0]
    with pytest.raises(InputError, match="at most one condition"):
        PriorityArbiter(rules=[{"behaviour": "a", "nearest_blow": 1.0}])


def test_priority_defaults_threshold_half_a_metre_and_activation_half():
    d = PriorityArbiter()
    assert d.combine(near(0.49), PROPS)[1].tolist() == [1.0, 0.0]
    assert d.combine(near(0.51), PROPS)[1].tolist() == [0.0, 1.0]
    labels = list(PROPS)
    assert d.winner(3.0, labels, [0.5, None]) == 0  # an activation of 0.5 is enough
    assert d.winner(0.1, labels, [0.49, None]) == 1  # below it, even when close


@pytest.mark.parametrize(
    ("kwargs", "key"),
    [
        ({"threshold": -0.1}, "threshold"),
        ({"activation": 1.5}, "activation"),
        ({"activation": -0.1}, "activation"),
        ({"rules": []}, "rules"),
        ({"rules": "avoid"}, "rules"),
        ({"rules": [{"nearest_below": 1.0}]}, "rules[0]"),
        ({"rules": [{"behaviour": "a", "nearest_below": 1.0, "nearest_above": 2.0}]},
         "rules[0]"),
        ({"rules": [{"behaviour": "a", "farthest": 1.0}]}, "rules[0]"),
        ({"rules": [{"behaviour": "a", "activation_above": 1.5}]}, "rules[0].activation_above"),
        ({"rules": [{"behaviour": "a", "nearest_below": -1.0}]}, "rules[0].nearest_below"),
    ],
)
def test_priority_bad_parameters_name_their_key(kwargs, key):
    with pytest.raises(InputError) as info:
        PriorityArbiter(**kwargs)
    assert info.value.key == key


# ------------------------------------------------------- arbiter contracts, messages, bounds

def _refused(make, message):
    """``make()`` raises an InputError whose one line is exactly ``message``."""
    with pytest.raises(InputError) as err:
        make()
    assert str(err.value) == message


def test_trapezoid_shoulders_and_set_checks():
    assert trapezoid(-1.0, (0.0, 0.0, 0.2, 0.6)) == 1.0  # left shoulder
    assert trapezoid(9.0, (0.2, 0.6, 3.0, 3.0)) == 1.0  # right shoulder
    assert CDBArbiter(sets={"t": [0.0, 0.3, 0.3, 0.6]}).sets["t"] == (0.0, 0.3, 0.3, 0.6)
    for bad in ([0.0, 0.5, 0.2, 0.6], [0.0, 0.6, 0.5, 0.7]):
        _refused(lambda b=bad: CDBArbiter(sets={"t": b}),
                 f"sets.t: expected a trapezoid [a, b, c, d] with a <= b <= c <= d [m], "
                 f"got {bad}")
    _refused(lambda: CDBArbiter(sets={"t": [0.0, 0.1, 0.2]}),
             "sets.t: expected a list of 4 numbers, got 3")


@pytest.mark.parametrize("kw, message", [
    ({"sets": {}}, "sets: expected a table of named trapezoids {name = [a, b, c, d]}"),
    ({"sets": "close"}, "sets: expected a table of named trapezoids {name = [a, b, c, d]}"),
    ({"rules": {"near": "avoid"}}, "rules.near: unknown context set 'near'; sets are: close, far"),
    ({"rules": {"close": 3}}, "rules.close: expected a non-empty string, got 3"),
    ({"rules": [{"behaviour": "a"}]},
     'rules[0]: expected a table {behaviour = "label", set = NAME or [a, b, c, d]}'),
    ({"rules": ["a"]},
     'rules[0]: expected a table {behaviour = "label", set = NAME or [a, b, c, d]}'),
    ({"rules": [{"behaviour": "a", "set": "near"}]},
     "rules[0].set: unknown context set 'near'; sets are: close, far"),
    ({"rules": [{"behaviour": "a", "set": [0, 1]}]},
     "rules[0].set: expected a list of 4 numbers, got 2"),
    ({"rules": [{"behaviour": "", "set": "far"}]},
     "rules[0].behaviour: expected a non-empty string, got ''"),
    ({"rules": 5}, 'rules: expected a table {set = "behaviour"} or a list of {behaviour, set} '
                   'tables'),
    ({"rules": "close"}, 'rules: expected a table {set = "behaviour"} or a list of '
                         '{behaviour, set} tables'),
    ({"rules": []}, "rules: expected at least one rule"),
])
def test_cdb_configuration_errors_name_the_key(kw, message):
    _refused(lambda: CDBArbiter(**kw), message)


def test_cdb_rules_are_checked_against_the_behaviours_at_bind():
    from types import SimpleNamespace

    _refused(lambda: CDBArbiter().bind(SimpleNamespace(labels=("avoid",))),
             '2 context sets but only 1 behaviours (avoid); give rules = {set = "behaviour"}'
             .join(["rules: ", ""]))
    _refused(lambda: CDBArbiter(rules={"close": "dodge"}).bind(
        SimpleNamespace(labels=("avoid", "goal"))),
        "rules.close: the 'cdb' arbiter names behaviour 'dodge', but the run's behaviours "
        "are: avoid, goal")
    CDBArbiter(rules={"close": "goal"}).bind(SimpleNamespace(labels=("avoid", "goal")))


def test_cdb_weights_follow_the_rules_not_the_order_of_the_sets():
    """Rules name the behaviour: close drives ``goal`` here although it is second; in a gap
    between sets the set whose core [b, c] is nearest fires alone."""
    cdb = CDBArbiter(sets={"near": [0.0, 0.0, 0.2, 0.3], "away": [0.5, 0.6, 1.0, 1.0]},
                     rules={"near": "goal", "away": "avoid"})
    assert cdb.weights(0.1, ["avoid", "goal"]).tolist() == [0.0, 1.0]
    assert cdb.weights(0.8, ["avoid", "goal"]).tolist() == [1.0, 0.0]
    # 0.45 m: 0.25 above near's core, 0.15 below away's core (not 0.15 past near's foot)
    assert cdb.weights(0.45, ["avoid", "goal"]).tolist() == [1.0, 0.0]
    inline = CDBArbiter(rules=[{"behaviour": "goal", "set": [0.0, 0.0, 1.0, 2.0]}])
    assert inline.weights(1.5, ["avoid", "goal"]).tolist() == [0.0, 1.0]


@pytest.mark.parametrize("kw, message", [
    ({"rules": "avoid"}, 'rules: expected a non-empty list of {behaviour = "label", '
                         'nearest_below = x} tables'),
    ({"rules": []}, 'rules: expected a non-empty list of {behaviour = "label", '
                    'nearest_below = x} tables'),
    ({"rules": [{"nearest_below": 0.3}]},
     'rules[0]: expected a table {behaviour = "label"[, nearest_below = x | nearest_above = x]}'),
    ({"rules": [{"behaviour": "a", "nearest_below": 0.3, "nearest_above": 1.0}]},
     "rules[0]: expected at most one condition of nearest_below, nearest_above, "
     "activation_above, got nearest_below, nearest_above"),
    ({"rules": [{"behaviour": "a", "closer": 0.3}]},
     "rules[0]: expected at most one condition of nearest_below, nearest_above, "
     "activation_above, got closer"),
    ({"rules": [{"behaviour": 1}]}, "rules[0].behaviour: expected a non-empty string, got 1"),
    ({"rules": [{"behaviour": "a", "activation_above": 1.5}]},
     "rules[0].activation_above: expected a number in [0.0, 1.0], got 1.5"),
])
def test_priority_configuration_errors_name_the_key(kw, message):
    _refused(lambda: PriorityArbiter(**kw), message)


def test_priority_conditions_at_their_bounds():
    """Below/above are strict, an activation at the threshold holds; with no condition
    holding the *last* rule wins; the default rules use the distance when a behaviour gives
    no activation."""
    from types import SimpleNamespace

    labels = ["avoid", "wall", "goal"]
    pr = PriorityArbiter(rules=[{"behaviour": "avoid", "nearest_below": 0.3},
                                {"behaviour": "wall", "nearest_above": 2.0},
                                {"behaviour": "goal", "activation_above": 0.6}])
    assert pr.winner(0.3, labels, [0.9, 0.9, 0.6]) == 2  # 0.3 not below 0.3; 0.6 holds
    assert pr.winner(0.29, labels, [None, None, None]) == 0
    assert pr.winner(2.0, labels, [None, None, 0.59]) == 2  # none holds: the last rule
    assert pr.winner(2.01, labels, [None, None, 0.9]) == 1
    assert pr.winner(1.0, labels) == 2  # no activations given: the last rule
    order = PriorityArbiter(rules=[{"behaviour": "goal", "activation_above": 0.6},
                                   {"behaviour": "avoid", "nearest_below": 0.3},
                                   {"behaviour": "wall", "nearest_below": 0.2}])
    assert order.winner(1.0, labels, [0.9, 0.9, None]) == 1  # the last rule's: wall
    default = PriorityArbiter(threshold=0.5, activation=0.7)
    assert default.winner(0.5, ["avoid", "goal"]) == 1  # not below 0.5
    assert default.winner(0.49, ["avoid", "goal"]) == 0
    assert default.winner(3.0, ["avoid", "goal"], [0.7, None]) == 0  # activation says so
    assert default.winner(0.1, ["avoid", "goal"], [0.69, None]) == 1
    default.bind(SimpleNamespace(labels=("avoid", "goal")))
    _refused(lambda: pr.bind(SimpleNamespace(labels=("avoid", "goal"))),
             "rules[1].behaviour: the 'priority' arbiter names behaviour 'wall', but the run's "
             "behaviours are: avoid, goal")
    far = ctx()  # nothing within 3 m: the distance alone would pick goal
    props = {"avoid": Proposal(30.0, None, activation=0.9), "goal": Proposal(-10.0, 0.2)}
    fused, w = default.combine(far, props)
    assert fused is props["avoid"] and w.tolist() == [1.0, 0.0]


def test_single_arbiter_passes_one_proposal_and_refuses_several():
    from sitframe.plugins.arbiters import SingleArbiter

    p = Proposal(12.0, 0.2)
    fused, w = SingleArbiter().combine(ctx(), {"avoid": p})
    assert fused is p and w.tolist() == [1.0]
    with pytest.raises(ValueError, match=r"^the 'single' arbiter needs exactly one behaviour, "
                                         r"got 2 \(avoid, goal\); use 'cdb' or 'priority'$"):
        SingleArbiter().combine(ctx(), {"avoid": p, "goal": p})


def test_cdb_defaults_are_the_thesis_close_and_far_shoulders():
    """Defaults (thesis Fig. 6.4): close = [0, 0, 0.2, 0.6], far = [0.2, 0.6, 3, 3] [m]."""
    labels = ["avoid", "goal"]
    cdb = CDBArbiter()
    for d, want in [(0.2, [1.0, 0.0]), (0.3, [0.75, 0.25]), (0.5, [0.25, 0.75]),
                    (0.6, [0.0, 1.0]), (5.0, [0.0, 1.0])]:
        assert cdb.weights(d, labels) == pytest.approx(want), d


def test_cdb_gap_is_measured_to_the_cores_and_errors_list_every_behaviour():
    from types import SimpleNamespace

    # 0.5 m: 0.4 past near's core [0, 0.1] (but only 0.05 past its foot), 0.2 below away's
    cdb = CDBArbiter(sets={"near": [0.0, 0.0, 0.1, 0.45], "away": [0.52, 0.7, 3.0, 3.0]},
                     rules={"near": "avoid", "away": "goal"})
    assert cdb.weights(0.5, ["avoid", "goal"]).tolist() == [0.0, 1.0]
    three = CDBArbiter(sets={"a": [0, 0, 1, 1], "b": [1, 2, 2, 3], "c": [2, 3, 9, 9]})
    _refused(lambda: three.bind(SimpleNamespace(labels=("avoid", "goal"))),
             'rules: 3 context sets but only 2 behaviours (avoid, goal); give rules = '
             '{set = "behaviour"}')


def test_priority_activation_rule_wins_before_later_rules():
    pr = PriorityArbiter(rules=[{"behaviour": "avoid", "activation_above": 0.6},
                                {"behaviour": "goal"}])
    labels = ["avoid", "goal"]
    assert pr.winner(3.0, labels, [0.6, None]) == 0  # at the threshold: holds
    assert pr.winner(0.1, labels, [0.59, None]) == 1
    assert pr.winner(0.1, labels, [None, None]) == 1  # no activation given: does not hold
