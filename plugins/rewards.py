"""Reward plugins of the thesis: obstacle avoidance (Alg. 4) and speed (Alg. 6).

A reward is any callable class with a ``name`` that maps a
:class:`sitframe.contract.records.Transition` to a float. This module is the example
to copy; a new reward is ~20 lines::

    from sitframe import hookimpl

    class Cautious:
        name = "cautious"
        def __init__(self, *, margin: float = 0.5):
            self.margin = margin
        def __call__(self, tr):
            if tr.collided:
                return -30.0
            return 10.0 if tr.after.nearest > self.margin else -5.0

    @hookimpl
    def sitframe_rewards():
        return [Cautious]

Drop that file in a folder, run with ``--plugins-dir FOLDER`` and name it in
a behaviour's table: ``reward = "cautious"``.
"""

from __future__ import annotations

from collections import deque
from typing import Any

import numpy as np

from sitframe import Transition, hookimpl
from sitframe import params as P


class ObstacleAvoidanceReward:
    """Thesis Algorithm 4: -30 on collision, else ``30 - 0.1 * |heading|`` (degrees).

    The printed algorithm subtracts the *signed* crisp heading, which would
    reward right turns over left turns; the text's intent (prefer actions that
    need less energy) is the magnitude, which is what we use.

    ``progress`` (default 0: the thesis's reward) adds, to a step without
    collision, ``progress`` times how much farther [m] the step took the robot
    from where it was ``progress_window`` iterations before the step (fewer at
    the start of a trial or a training episode, recognised by a jump between one
    transition's end pose and the next one's start). Driving on in a line earns
    the whole step length, circling little (nothing once the window spans the
    circle), turning back loses:
    against a rule base that turns in open space, which the heading cost alone
    barely punishes (27 per step against 30). The term depends on the last
    ``progress_window`` poses, which the situations do not show; keep the window
    short.
    """

    name = "obstacle-avoidance"

    def __init__(self, *, collision: float = -30.0, base: float = 30.0,
                 heading_cost: float = 0.1, progress: float = 0.0,
                 progress_window: int = 8) -> None:
        self.collision = P.number("collision", collision)
        self.base = P.number("base", base)
        self.heading_cost = P.number("heading_cost", heading_cost, lo=0.0)
        self.progress = P.number("progress", progress, lo=0.0)
        self.progress_window = int(P.number("progress_window", progress_window, lo=1,
                                            integer=True))
        self._xy: deque[np.ndarray] = deque(maxlen=self.progress_window + 1)

    def __call__(self, tr: Transition) -> float:
        bonus = self._away(tr) * self.progress if self.progress else 0.0
        if tr.outcome.collided:
            return self.collision
        return self.base - self.heading_cost * abs(tr.command.heading_change_deg) + bonus

    def _fused(self) -> dict[str, Any] | None:
        """The compiled trial's reward (``sitframe.runs.fused``): without ``progress`` (it
        keeps poses), and not a subclass's own ``__call__``."""
        if self.progress or type(self).__call__ is not ObstacleAvoidanceReward.__call__:
            return None
        return {"kind": "obstacle-avoidance",
                "params": [self.collision, self.base, self.heading_cost]}

    def _away(self, tr: Transition) -> float:
        """How much farther [m] the transition's end is than its start from the position
        ``progress_window`` iterations before its start (or the episode's first)."""
        xy, before = self._xy, np.asarray(tr.before.pose[:2], dtype=float)
        if not xy or float(np.hypot(*(xy[-1] - before))) > 1e-6:  # a trial or episode starts
            xy.clear()
            xy.append(before)
        anchor = xy[0]
        xy.append(np.asarray(tr.after.pose[:2], dtype=float))
        return float(np.hypot(*(xy[-1] - anchor)) - np.hypot(*(before - anchor)))


class SpeedReward:
    """Thesis Algorithm 6: reward speed, penalise closing in on obstacles fast.

    -30 on collision; else if the previous closest distance was below ``near``
    (30 cm) and the current one is smaller, ``current - previous`` in cm
    (negative); else ``10 + 0.2 * speed`` with speed in mm/s. The closest
    distance is the smallest sonar range (from the robot's rim).

    ``near_time_s`` (default 0: the thesis's fixed threshold) makes the
    threshold a stopping distance, ``max(near, speed * near_time_s)``: at
    0.3 m/s the robot covers 45 cm per 1.5 s iteration, so a fixed 30 cm
    threshold only fires once it is too late to slow down.
    """

    name = "speed"

    def __init__(self, *, collision: float = -30.0, near: float = 0.30, base: float = 10.0,
                 per_mm_s: float = 0.2, near_time_s: float = 0.0) -> None:
        self.collision = P.number("collision", collision)
        self.near = P.number("near", near, lo=0.0)
        self.base = P.number("base", base)
        self.per_mm_s = P.number("per_mm_s", per_mm_s)
        self.near_time_s = P.number("near_time_s", near_time_s, lo=0.0, unit="s")

    def _fused(self) -> dict[str, Any] | None:
        """The compiled trial's reward (``sitframe.runs.fused``), unless a subclass's own
        ``__call__``."""
        if type(self).__call__ is not SpeedReward.__call__:
            return None
        return {"kind": "speed", "params": [self.collision, self.near, self.base,
                                            self.per_mm_s, self.near_time_s]}

    def __call__(self, tr: Transition) -> float:
        if tr.outcome.collided:
            return self.collision
        prev, cur = tr.before.nearest, tr.after.nearest
        near = max(self.near, self.near_time_s * tr.command.speed_m_s)
        if prev < near and cur < prev:
            return (cur - prev) * 100.0
        return self.base + self.per_mm_s * tr.command.speed_m_s * 1000.0


@hookimpl
def sitframe_rewards() -> list[Any]:
    return [ObstacleAvoidanceReward, SpeedReward]
