"""Route behaviour: goal seeking over the waypoints of a planned shortest route.

A reactive goal seeker turns towards the goal; behind a wall or a door in a
side wall it meets a local minimum that no arbitration of reactive behaviours
leaves reliably (README, "Learned arbitration": every arbiter 0.40-0.46 in an
office). ``route`` is the global planner a robotics user puts above learned
local behaviours: from the world it is given (the map: ``Context.world``) it
plans the shortest route of the robot's disc, kept ``clearance`` off walls
and obstacles, to the goal (a visibility graph over arc points round every
wall end and obstacle corner, searched by Dijkstra in
``scipy.sparse.csgraph``: :func:`sitframe.sim.paths.shortest_route`), and
hands its waypoints to goal seeking as sub-goals: it proposes the heading
change towards the current waypoint exactly as the ``goal`` behaviour does
towards the goal (clipped to ``+-max_turn_deg``, no speed).

Following the route:

* a waypoint within ``reach`` [m] is reached: the next one becomes current;
* the farthest later waypoint that a disc ``skip_margin`` wider than the
  planning disc sees straight from the robot becomes current at once (the
  route is followed by line of sight, so a detour the avoider forced is not
  walked back, but a corner is not cut closer than the plan keeps off it);
* **re-planned** from where the robot is when it is *blocked*: the current
  waypoint is out of sight even for the robot's own disc (``sight_margin``
  beyond its radius; the avoider pushed it round a corner), or the robot has
  come no closer to the current waypoint for ``replan_after`` iterations.

The planner first keeps ``clearance`` beyond the robot's radius; where no
route of that disc exists (a door or a gap narrower than the disc, the robot
pressed against a wall) it plans with ``clearance_step`` less, and so on down
to ``min_clearance`` (so a narrow gap is passed by its middle, as far off both
sides as it allows), and with no route at all it seeks the goal straight, as
``goal`` does.

The arbiter (CDB, priority, the learned ``fuzzy-q-arbiter``) weights this
behaviour like any other; given the label ``goal`` in a config
(``[behaviours.goal] component = "route"``) the arbiters' rules and action
weightings written for goal seeking apply to it unchanged.

Config::

    [behaviours.goal]
    component = "route"
    clearance = 0.25      # m kept off walls beyond the robot's radius when planning
    clearance_step = 0.05 # m less for each next try where no route keeps clearance
    min_clearance = 0.05  # the last clearance tried before seeking the goal straight
    reach = 0.3           # m: a waypoint this close is reached
    replan_after = 15     # iterations without approaching the waypoint: re-plan
    sight_margin = 0.02   # m beyond the robot's radius for "the waypoint is in sight"
    skip_margin = 0.1     # m beyond the planning disc for "a later waypoint is in sight"
    max_turn_deg = 90

Trial data: ``plans`` (routes planned, the first of each episode included)
and ``replans`` (of them, re-planned because the robot was blocked).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from sitframe import Context, Proposal, RunContext, hookimpl, route_graph
from sitframe import params as P

from .goal import GoalBehaviour, goal_bearing_deg


class RouteBehaviour(GoalBehaviour):
    """Seek the goal along the planned shortest route (module docstring)."""

    name = "route"
    evaluation_protocol = "goal-episodes"

    def __init__(self, *, max_turn_deg: float = 90.0, clearance: float = 0.25,
                 min_clearance: float = 0.05, reach: float = 0.3, replan_after: int = 15,
                 sight_margin: float = 0.02, clearance_step: float = 0.05,
                 skip_margin: float = 0.1) -> None:
        super().__init__(max_turn_deg=max_turn_deg)
        self.clearance = P.number("clearance", clearance, lo=0.0)
        self.min_clearance = P.number("min_clearance", min_clearance, lo=0.0)
        if self.min_clearance > self.clearance:
            raise ValueError(f"min_clearance ({self.min_clearance:g}) must not exceed "
                             f"clearance ({self.clearance:g})")
        self.clearance_step = P.number("clearance_step", clearance_step, lo=0.0, lo_open=True)
        n = int(math.floor((self.clearance - self.min_clearance) / self.clearance_step + 1e-9))
        #: the clearances tried, widest first
        self.clearances = [round(self.clearance - i * self.clearance_step, 9) for i in range(n + 1)]
        if self.clearances[-1] > self.min_clearance:
            self.clearances.append(self.min_clearance)
        self.reach = P.number("reach", reach, lo=0.0, lo_open=True)
        self.replan_after = int(P.number("replan_after", replan_after, lo=1, integer=True))
        self.sight_margin = P.number("sight_margin", sight_margin, lo=0.0)
        self.skip_margin = P.number("skip_margin", skip_margin, lo=0.0)
        self.radius = 0.15  # (bind gives the run's robot)
        self._key: tuple[Any, ...] | None = None
        self.waypoints = np.zeros((0, 2))
        self.plan_radius = 0.0
        self.k = 0
        self._best = math.inf
        self._since = 0
        self.plans = 0
        self.replans = 0

    def bind(self, run: RunContext) -> None:
        self.radius = float(run.robot.radius)

    def trial_start(self, trial: Any) -> None:
        self._key = None
        self.plans = self.replans = 0

    # -- planning ------------------------------------------------------------
    def _plan(self, ctx: Context) -> None:
        """Plan from the robot's position to the goal, the widest clearance first."""
        assert ctx.goal is not None
        self.plans += 1
        here, goal = ctx.pose[:2], np.asarray(ctx.goal.position, dtype=np.float64)
        for extra in self.clearances:
            radius = self.radius + extra
            wp, length = route_graph(ctx.world, radius).route(here, goal)
            if math.isfinite(length):
                self.waypoints, self.plan_radius = wp, radius
                break
        else:  # no route: seek the goal straight
            self.waypoints, self.plan_radius = goal[None].copy(), self.radius
        self.k = 0
        self._best, self._since = math.inf, 0

    def _advance(self, ctx: Context) -> None:
        """Reach, skip ahead by line of sight, or re-plan when blocked."""
        here = ctx.pose[:2]
        wp = self.waypoints
        while self.k < len(wp) - 1 and math.dist(here, wp[self.k]) <= self.reach:
            self.k += 1
            self._best, self._since = math.inf, 0
        graph = route_graph(ctx.world, self.plan_radius)
        ahead = wp[self.k + 1:]
        seen = graph.visible(here, ahead, self.plan_radius + self.skip_margin) if len(ahead) \
            else ahead[:0, 0].astype(bool)
        if seen.any():  # a later waypoint in sight with room to spare: cut the route to it
            self.k, self._best, self._since = self.k + 1 + int(np.flatnonzero(seen)[-1]), \
                math.inf, 0
        elif not graph.visible(here, wp[self.k][None], self.radius + self.sight_margin)[0]:
            self.replans += 1
            self._plan(ctx)
            return
        d = math.dist(here, wp[self.k])
        if d < self._best - 0.05:
            self._best, self._since = d, 0
        else:
            self._since += 1
            if self._since >= self.replan_after:
                self.replans += 1
                self._plan(ctx)

    def propose(self, context: Context) -> Proposal:
        goal = context.goal
        if goal is None:
            return super().propose(context)  # (the one-line error: no goal)
        key = (id(context.world), float(goal.position[0]), float(goal.position[1]))
        if key != self._key or context.iteration == 0:
            self._key = key
            self._plan(context)
        else:
            self._advance(context)
        b = goal_bearing_deg(context.pose, self.waypoints[self.k])
        return Proposal(min(max(b, -self.max_turn_deg), self.max_turn_deg), None)

    def trial_data(self) -> dict[str, Any]:
        return {"plans": int(self.plans), "replans": int(self.replans)}


@hookimpl
def sitframe_behaviours() -> list[Any]:
    return [RouteBehaviour]
