"""Wall-following reward, goal behaviour, CDB and priority arbiters (unit level)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sitframe.errors import InputError
from sitframe.plugins.arbiters import CDBArbiter, PriorityArbiter, trapezoid
from sitframe.plugins.goal import GoalBehaviour, goal_bearing_deg
from sitframe.plugins.sonar import PIONEER_ANGLES_DEG as PIONEER
from sitframe.plugins.wall_following import WallFollowingReward
from sitframe.records import Context, Proposal, Transition
from sitframe.robot import Command, StepOutcome
from sitframe.world import Goal, load_world

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
