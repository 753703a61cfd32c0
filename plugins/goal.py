"""Goal-finding behaviour (thesis 6.2): turn towards the goal.

Not learned. Every iteration it proposes the heading change that points the
robot at the goal: the bearing of the goal centre relative to the robot's
heading, wrapped to (-180, 180] degrees and clipped to ``+-max_turn_deg``
(90, the largest command). A goal straight behind the robot gives ``+90``
(turn left). It has no opinion on speed (``None``: the run's default speed).

The goal comes from the context (:attr:`sitframe.contract.records.Context.goal`):
the world's ``[goal]`` or the goal of the current goal episode. The class
attribute ``evaluation_protocol = "goal-episodes"`` makes a run with this
behaviour a *goal run*: its evaluate stage runs the goal episodes of the
``goal-episodes`` protocol (``plugins/goal_episodes.py``) in the ``[goal]
worlds``, with the ``[goal]`` table as the protocol's parameters.

Config::

    [behaviours.goal]
    component = "goal"
    max_turn_deg = 90
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from sitframe import Context, InputError, LearnedPolicy, Proposal, Transition, hookimpl
from sitframe import params as P


def goal_bearing_deg(pose: np.ndarray, goal_xy: np.ndarray) -> float:
    """Bearing [deg] of ``goal_xy`` relative to ``pose`` (x, y, theta rad), in (-180, 180]."""
    ang = math.degrees(math.atan2(goal_xy[1] - pose[1], goal_xy[0] - pose[0]) - pose[2])
    ang = math.fmod(ang, 360.0)
    if ang <= -180.0:
        ang += 360.0
    elif ang > 180.0:
        ang -= 360.0
    return ang


class GoalBehaviour:
    """Propose the heading change towards the goal, clipped to ``+-max_turn_deg``."""

    name = "goal"
    evaluation_protocol = "goal-episodes"

    def __init__(self, *, max_turn_deg: float = 90.0) -> None:
        self.max_turn_deg = P.number("max_turn_deg", max_turn_deg, lo=0.0, hi=90.0, unit="deg")

    def reset(self, rng: np.random.Generator, n_situations: int, iterations: int) -> None:
        pass

    def load_policy(self, policy: LearnedPolicy) -> None:
        pass  # nothing learned: a goal run may still hand it a policy

    def propose(self, context: Context) -> Proposal:
        if context.goal is None:
            raise InputError(f"the 'goal' behaviour needs a goal, but world "
                             f"'{context.world.name}' has no [goal] and the run gives none "
                             "(use goal episodes or add [goal] to the world)",
                             file=context.world.source, key="goal")
        b = goal_bearing_deg(context.pose, context.goal.position)
        return Proposal(min(max(b, -self.max_turn_deg), self.max_turn_deg), None)

    def learn(self, transition: Transition, reward: float) -> None:
        pass

    def trial_data(self) -> dict[str, Any]:
        return {}


@hookimpl
def sitframe_behaviours() -> list[Any]:
    return [GoalBehaviour]
