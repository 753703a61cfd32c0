"""The thesis rewards (Alg. 4 and Alg. 6) on hand-made transitions."""

from __future__ import annotations

import numpy as np
import pytest

from sitframe.contract.records import Context, Transition
from sitframe.plugins.rewards import ObstacleAvoidanceReward, SpeedReward
from sitframe.sim.robot import Command, StepOutcome
from sitframe.sim.world import load_world

WORLD = load_world("training")


def tr(nearest_before: float, nearest_after: float, *, heading: float = 0.0,
       speed: float = 0.15, collided: bool = False) -> Transition:
    def ctx(nearest: float, it: int) -> Context:
        r = np.full(8, 3.0)
        r[3] = nearest
        return Context(it, np.zeros(3), r, np.zeros(0), nearest, WORLD, None)

    p = np.zeros(3)
    out = StepOutcome(pose_before=p, pose=p, collided=collided, contact_xy=np.full(2, np.nan),
                      contact_pose=p, distance_m=0.2, heading_change_deg=heading)
    return Transition(ctx(nearest_before, 0), Command(heading, speed), out, ctx(nearest_after, 1))


def test_obstacle_avoidance_penalises_the_magnitude_of_the_heading():
    r = ObstacleAvoidanceReward()
    assert r(tr(1.0, 1.0, heading=0.0)) == 30.0
    assert r(tr(1.0, 1.0, heading=60.0)) == pytest.approx(24.0)
    assert r(tr(1.0, 1.0, heading=-60.0)) == pytest.approx(24.0)  # not 36: magnitude
    assert r(tr(1.0, 0.0, heading=-60.0, collided=True)) == -30.0


def test_speed_reward_alg6():
    r = SpeedReward()
    assert r(tr(1.0, 1.0, speed=0.3)) == pytest.approx(10 + 0.2 * 300)
    assert r(tr(0.25, 0.20, speed=0.1)) == pytest.approx(-5.0)  # closing in below 30 cm
    assert r(tr(0.25, 0.28, speed=0.1)) == pytest.approx(30.0)  # moving away: bonus
    assert r(tr(0.40, 0.20, speed=0.3)) == pytest.approx(70.0)  # fixed 30 cm: no penalty
    assert r(tr(0.40, 0.20, speed=0.5)) == pytest.approx(110.0)  # whatever the speed
    assert r(tr(0.5, 0.1, speed=0.3, collided=True)) == -30.0


def test_speed_reward_stopping_distance_threshold():
    r = SpeedReward(near_time_s=1.5)
    # at 0.3 m/s the threshold is 0.45 m: closing in from 0.40 m is penalised
    assert r(tr(0.40, 0.20, speed=0.3)) == pytest.approx(-20.0)
    # at 0.1 m/s it stays 0.30 m (the larger of the two)
    assert r(tr(0.40, 0.20, speed=0.1)) == pytest.approx(30.0)


def test_speed_reward_boundaries_and_parameters():
    r = SpeedReward()
    assert r(tr(0.30, 0.20, speed=0.1)) == pytest.approx(30.0)  # at 30 cm: not yet "near"
    assert r(tr(0.25, 0.25, speed=0.1)) == pytest.approx(30.0)  # holding its distance
    custom = SpeedReward(collision=-5.0, near=0.5, base=1.0, per_mm_s=0.01)
    assert custom(tr(0.45, 0.40, speed=0.2)) == pytest.approx(-5.0)  # (0.40 - 0.45) m in cm
    assert custom(tr(0.6, 0.4, speed=0.2)) == pytest.approx(1.0 + 0.01 * 200)
    assert custom(tr(0.6, 0.4, collided=True)) == -5.0
    oa = ObstacleAvoidanceReward(collision=-1.0, base=5.0, heading_cost=0.5)
    assert oa(tr(1.0, 1.0, heading=-4.0)) == pytest.approx(3.0)
    assert oa(tr(1.0, 1.0, collided=True)) == -1.0
    for cls, key in ((SpeedReward, "near"), (SpeedReward, "near_time_s"),
                     (ObstacleAvoidanceReward, "heading_cost")):
        with pytest.raises(ValueError, match=key):
            cls(**{key: -0.1})


@pytest.mark.parametrize("cls, key", [
    (ObstacleAvoidanceReward, "collision"), (ObstacleAvoidanceReward, "base"),
    (ObstacleAvoidanceReward, "heading_cost"), (SpeedReward, "collision"), (SpeedReward, "near"),
    (SpeedReward, "base"), (SpeedReward, "per_mm_s"), (SpeedReward, "near_time_s")])
def test_a_bad_reward_parameter_is_named(cls, key):
    """A non-number in a reward's table is refused with the key the user wrote."""
    with pytest.raises(ValueError, match=rf"^{key}: expected a number"):
        cls(**{key: "high"})
    with pytest.raises(ValueError, match=rf"^{key}: "):
        cls(**{key: float("nan")})
