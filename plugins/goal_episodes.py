"""The ``goal-episodes`` evaluation protocol: drive from a start to a goal, and score it.

An *episode* starts the robot at a start pose with a goal disc in the
context (:attr:`sitframe.contract.records.Context.goal`) and runs the configured
behaviours and arbiter, without learning, until

* the robot's centre is within the goal radius (**terminated**: success), or
* ``timeout`` iterations (default 300 = 7.5 min of robot time) have passed
  (**truncated**).

A collision never ends an episode: the robot recovers (as the simulator's
collision recovery does) and carries on; collisions are counted.

Parameters: the run config's ``[goal]`` table (:attr:`GoalEpisodes.table`);
its ``worlds`` list names the worlds the evaluate stage runs a batch in.
A run uses this protocol when one of its components declares
``evaluation_protocol = "goal-episodes"`` (the ``goal`` behaviour does).

Start/goal pairs (``[goal] pairs``):

``"random"`` (default)
    ``episodes`` seeded random pairs per world: start and goal are free
    positions for the robot disc with ``margin`` to spare (start heading
    uniform), at least ``min_distance`` (3 m) apart as the crow flies.
``"world"``
    The world file's start pose and ``[goal]``, ``episodes`` times (the runs
    differ only by sensor noise, if any).

Per episode: ``success``, ``iterations``, ``collisions``, ``path_length_m``
(robot centre), ``straight_m`` (straight-line distance from the start to the
*edge* of the goal disc, the shortest possible successful path ignoring
obstacles, used by ``spl``), ``shortest_m`` (the same for the shortest path
the robot's disc can drive, around walls and through doors:
:func:`sitframe.sim.paths.shortest_path_length` minus the goal radius; ``inf``
when the goal cannot be reached; used by ``spl_shortest``), ``time_s``
(iterations x control period, 1.5 s), ``heading_change_per_m`` (total
|heading change| per metre, path smoothness).

Aggregates over a batch (:meth:`GoalEpisodes.aggregate`): ``episodes``,
``success_rate``, ``collisions_per_episode``, ``collision_free_rate``
(fraction of episodes without a collision), ``spl``
(:func:`sitframe.sim.metrics.spl` against the straight line, as in logs before
``spl_shortest`` existed), ``spl_shortest`` (SPL as Anderson et al. 2018
define it, against the shortest path: the straight line passes through the
walls of a multi-room world, so there ``spl`` charges a detour no robot can
avoid), ``mean_time_s`` (mean time of the
*successful* episodes; NaN if none), ``heading_change_per_m`` (pooled: total
heading change over total path length of all episodes),
``mean_path_length_m``.
"""

from __future__ import annotations

import math
import weakref
from typing import Any, ClassVar

import numpy as np

from sitframe import (
    ABSENT,
    ConfigKey,
    ConfigTable,
    Context,
    InputError,
    RobotParams,
    World,
    heading_change_per_m,
    hookimpl,
    path_length,
    shortest_path_length,
    spl,
)
from sitframe import params as P

PAIR_MODES = ("random", "world")
TRAIN_MODES = ("world", "episodes")
#: Aggregate keys of a batch (``evaluate --goal-episodes --json``, ``eval/<world>/...``).
AGGREGATE_KEYS = ("episodes", "success_rate", "collisions_per_episode", "collision_free_rate",
                  "spl", "spl_shortest", "mean_time_s", "heading_change_per_m",
                  "mean_path_length_m")


#: The ``[goal]`` table: declared here, as a third-party protocol declares its own.
#: ``always``: every config holds it (it did before protocols declared their tables), with
#: ``train``, ``train_detour`` and ``detour_ratio`` only when given (so that a config's
#: text, and hash, stays what it was before they existed).
GOAL = ConfigTable("goal", (
    ConfigKey("episodes", "integer", 50, "episodes per world", lo=1, hi=100_000),
    ConfigKey("timeout", "integer", 300, "iterations before an episode is given up", lo=1,
              hi=10_000_000),
    ConfigKey("min_distance", "number", 3.0, "the least start-goal distance of random pairs",
              unit="m", lo=0.0),
    ConfigKey("worlds", "names", ["goal"], "the worlds a batch of goal episodes runs in"),
    ConfigKey("pairs", "choice", "random", "random start/goal pairs, or the world's own",
              choices=PAIR_MODES),
    ConfigKey("radius", "number", 0.3, "the goal radius of random goals", unit="m", lo=0.0,
              lo_open=True),
    ConfigKey("margin", "number", 0.1, "clearance beyond the robot's radius at random starts "
              "and goals", unit="m", lo=0.0),
    ConfigKey("train", "choice", ABSENT, "how a learning trial runs (default \"world\": from "
              "the world's start with its [goal])", choices=TRAIN_MODES),
    ConfigKey("train_detour", "number", ABSENT, "share of a learning trial's pairs drawn as "
              "detours (default 0)", lo=0.0, hi=1.0),
    ConfigKey("detour_ratio", "number", ABSENT, "shortest path over straight distance of a "
              "detour pair (default 1.25)", lo=1.0, lo_open=True),
), "The goal-episodes protocol's parameters (a goal run's evaluate stage).", always=True)

#: Pairs already drawn, per world, by the Generator's state and the draw's parameters
#: (:func:`_drawn_pairs`); at most ``_MAX_DRAWN`` per world, the oldest dropped first.
_DRAWN: weakref.WeakKeyDictionary[World, dict[tuple[Any, ...], tuple[np.ndarray, np.ndarray,
                                                                   dict[str, Any]]]] = (
    weakref.WeakKeyDictionary())
_MAX_DRAWN = 64


def _drawn_pairs(world: World, n: int, rng: np.random.Generator, **kw: Any
                 ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`goal_pairs`, drawn once per process for each Generator state: every trial's
    evaluation in a world, and every trial a ``policy_from.trial`` selection scores, draws
    the same pairs from the same seed (some 0.1 s a draw, a tenth of a short goal run). A
    repeated draw returns copies of the first one's pairs and leaves ``rng`` in the state the
    first one left it, so results are bit-identical with and without this memory."""
    memo = _DRAWN.setdefault(world, {})
    key = (n, repr(rng.bit_generator.state), tuple(sorted(kw.items())))
    drawn = memo.get(key)
    if drawn is None:
        starts, goals = goal_pairs(world, n, rng, **kw)
        if len(memo) >= _MAX_DRAWN:
            del memo[next(iter(memo))]
        memo[key] = drawn = (starts, goals, rng.bit_generator.state)
    else:
        rng.bit_generator.state = drawn[2]
    return drawn[0].copy(), drawn[1].copy()


def goal_pairs(
    world: World,
    n: int,
    rng: np.random.Generator,
    *,
    min_distance: float = 3.0,
    goal_radius: float = 0.3,
    robot_radius: float = 0.15,
    margin: float = 0.1,
    max_tries: int = 1000,
    detour_share: float = 0.0,
    detour_ratio: float = 1.25,
) -> tuple[np.ndarray, np.ndarray]:
    """Draw ``n`` random start/goal pairs in ``world``.

    A share ``detour_share`` of the pairs (each pair drawn so with that
    probability) must be *detour* pairs: the shortest path of the robot's disc
    at least ``detour_ratio`` times the straight start-goal distance, a goal
    behind a wall or inside a pocket, where a straight-line goal seeker meets
    a local minimum. With ``detour_share = 0`` (default) no extra random
    number is drawn: the pairs are those of a run without the option.

    Returns
    -------
    (starts, goals)
        ``starts`` (n, 3): x [m], y [m], theta [rad]; ``goals`` (n, 3): x [m],
        y [m], radius [m]. Both positions are free for a disc of
        ``robot_radius + margin``; they are at least ``min_distance`` apart,
        and a path of the ``robot_radius`` disc joins them
        (:func:`sitframe.sim.paths.shortest_path_length` is finite): in a world of
        separate rooms a pair in two of them would fail every controller, and
        count as its failure.

    Raises
    ------
    InputError
        ``goal.min_distance`` (``goal.train_detour`` for a detour pair): no such
        pair found in ``max_tries``.
    """
    starts = np.empty((n, 3))
    goals = np.empty((n, 3))
    for e in range(n):
        detour = detour_share > 0 and rng.random() < detour_share
        for _ in range(max_tries):
            s = world.random_free_pose(rng, robot_radius, margin=margin)
            g = world.random_free_pose(rng, robot_radius, margin=margin)
            straight = math.hypot(g[0] - s[0], g[1] - s[1])
            if straight < min_distance:
                continue
            path = shortest_path_length(world, s[:2], g[:2], radius=robot_radius)
            if math.isfinite(path) and (not detour or path >= detour_ratio * straight):
                break
        else:
            if detour:
                raise InputError(f"found no start and goal {min_distance:g} m apart whose "
                                 f"shortest path is {detour_ratio:g} x their distance in world "
                                 f"'{world.name}' in {max_tries} tries; expected a smaller "
                                 "detour_ratio or a world with walls between its places",
                                 key="goal.train_detour")
            raise InputError(f"found no start and goal {min_distance:g} m apart and joined by a "
                             f"free path in world '{world.name}' in {max_tries} tries; expected "
                             "a smaller min_distance or a larger world", key="goal.min_distance")
        starts[e] = s
        goals[e] = (g[0], g[1], goal_radius)
    return starts, goals


def world_pairs(world: World, n: int) -> tuple[np.ndarray, np.ndarray]:
    """The world file's start and ``[goal]``, ``n`` times (InputError if it has no goal)."""
    if world.goal is None:
        raise InputError(f"world '{world.name}' has no [goal]; expected a [goal] table with "
                         "position = [x, y] or goal.pairs = \"random\"", file=world.source,
                         key="goal")
    g = (*world.goal.position, world.goal.radius)
    return np.tile(world.start, (n, 1)), np.tile(np.asarray(g, float), (n, 1))


class GoalEpisodes:
    """Goal episodes (module docstring): the ``[goal]`` table's parameters.

    Parameters
    ----------
    episodes
        Episodes per world.
    timeout
        Iterations before an episode is given up (truncated).
    min_distance
        Minimum straight-line start-goal distance [m] of random pairs.
    pairs
        ``"random"`` or ``"world"`` (module docstring).
    radius
        Goal radius [m] of random goals.
    margin
        Clearance [m] beyond the robot's radius required at random starts and goals.
    train
        How a *learning* trial of a goal run is driven: ``"world"`` (default)
        from the world's start with its ``[goal]`` for the trial's iterations;
        ``"episodes"``, as a chain of these episodes (the same pairs, timeout
        and end at the goal), the robot put at the next start with the next
        goal when one ends, learning carried on across them
        (:attr:`train_in_episodes`; what a learned arbitration needs: many
        start/goal pairs).
    train_detour
        Share (0 to 1) of a learning trial's random pairs drawn as *detour*
        pairs (:func:`goal_pairs`): a curriculum that puts the learner where a
        reactive goal seeker gets stuck (behind a wall, in a pocket) more often
        than uniform pairs do (a pocket may be a few per cent of a room's area,
        and the rules for being stuck there go untrained). Default 0: uniform
        pairs. The evaluation's pairs are never changed by it.
    detour_ratio
        Shortest path over straight distance a detour pair needs (default 1.25).
    """

    name = "goal-episodes"
    table: ClassVar[str] = "goal"
    config_table: ClassVar[ConfigTable] = GOAL

    def __init__(self, *, episodes: int = 50, timeout: int = 300, min_distance: float = 3.0,
                 pairs: str = "random", radius: float = 0.3, margin: float = 0.1,
                 train: str = "world", train_detour: float = 0.0,
                 detour_ratio: float = 1.25) -> None:
        self.episodes = int(P.number("episodes", episodes, lo=1, hi=100_000, integer=True))
        self.iterations = int(P.number("timeout", timeout, lo=1, hi=10_000_000, integer=True))
        self.min_distance = P.number("min_distance", min_distance, lo=0.0, unit="m")
        self.pairs = P.choice("pairs", pairs, PAIR_MODES)
        self.radius = P.number("radius", radius, lo=0.0, lo_open=True, unit="m")
        self.margin = P.number("margin", margin, lo=0.0, unit="m")
        self.train_in_episodes = P.choice("train", train, TRAIN_MODES) == "episodes"
        self.train_detour = P.number("train_detour", train_detour, lo=0.0, hi=1.0)
        self.detour_ratio = P.number("detour_ratio", detour_ratio, lo=1.0, lo_open=True)

    def check_world(self, world: World) -> None:
        """Refuse, before anything runs, a world ``pairs = "world"`` cannot use."""
        if self.pairs == "world" and world.goal is None:
            raise InputError(f"world '{world.name}' has no [goal] but goal.pairs = \"world\"; "
                             "expected a world with a [goal] table or goal.pairs = \"random\"")

    def episode_starts(self, world: World, rng: np.random.Generator,
                       robot: RobotParams) -> tuple[np.ndarray, np.ndarray]:
        """The ``episodes`` start poses (n, 3) and goals (n, 3: x, y, radius) in ``world``."""
        return self._starts(world, rng, robot, 0.0)

    def training_starts(self, world: World, rng: np.random.Generator,
                        robot: RobotParams) -> tuple[np.ndarray, np.ndarray]:
        """The pairs of a learning trial run in episodes: :meth:`episode_starts`'
        with ``train_detour`` of them detour pairs."""
        return self._starts(world, rng, robot, self.train_detour)

    def _starts(self, world: World, rng: np.random.Generator, robot: RobotParams,
                detour_share: float) -> tuple[np.ndarray, np.ndarray]:
        self._world = world  # (score_episode measures the shortest path in it)
        if self.pairs == "world":
            return world_pairs(world, self.episodes)
        return _drawn_pairs(world, self.episodes, rng, min_distance=self.min_distance,
                            goal_radius=self.radius, robot_radius=robot.radius,
                            margin=self.margin, detour_share=detour_share,
                            detour_ratio=self.detour_ratio)

    def terminated(self, context: Context) -> bool:
        """Whether the robot's centre is within the goal disc."""
        goal = context.goal
        if goal is None:
            return False
        pose, xy = context.pose, goal.position
        return bool((pose[0] - xy[0]) ** 2 + (pose[1] - xy[1]) ** 2 <= goal.radius ** 2)

    def score_episode(self, arrays: dict[str, np.ndarray], start: np.ndarray,
                      goal: np.ndarray | None, robot: RobotParams) -> dict[str, Any]:
        """Per-episode figures of one finished episode (module docstring)."""
        assert goal is not None  # episode_starts always gives goals
        pose = arrays["pose"]
        it = int(arrays["collision"].size)
        reached = math.hypot(pose[-1, 0] - goal[0], pose[-1, 1] - goal[1]) <= goal[2]
        straight = max(math.hypot(goal[0] - start[0], goal[1] - start[1]) - goal[2], 0.0)
        shortest = max(shortest_path_length(self._world, start[:2], goal[:2],
                                            radius=robot.radius) - goal[2], 0.0)
        return {
            "success": bool(reached),
            "iterations": it,
            "collisions": int(arrays["collision"].sum()),
            "path_length_m": path_length(pose[:, :2]),
            "straight_m": straight,
            "shortest_m": shortest,
            "time_s": it * float(robot.control_period_s),
            "heading_change_per_m": heading_change_per_m(pose[:, 2], pose[:, :2]),
        }

    def aggregate(self, ep: dict[str, np.ndarray]) -> dict[str, float]:
        """Batch figures from per-episode arrays (keys of :meth:`score_episode`)."""
        success = np.asarray(ep["success"], bool)
        n = int(success.size)
        coll = np.asarray(ep["collisions"], float)
        path = np.asarray(ep["path_length_m"], float)
        time_s = np.asarray(ep["time_s"], float)
        total_turn = np.nansum(np.asarray(ep["heading_change_per_m"], float) * path)
        nan = float("nan")
        return {
            "episodes": n,
            "success_rate": float(success.mean()) if n else nan,
            "collisions_per_episode": float(coll.mean()) if n else nan,
            "collision_free_rate": float((coll == 0).mean()) if n else nan,
            "spl": spl(success, ep["straight_m"], path),
            "spl_shortest": spl(success, ep["shortest_m"], path),
            "mean_time_s": float(time_s[success].mean()) if success.any() else nan,
            "heading_change_per_m": float(total_turn / path.sum()) if path.sum() > 0 else nan,
            "mean_path_length_m": float(path.mean()) if n else nan,
        }


@hookimpl
def sitframe_protocols() -> list[Any]:
    return [GoalEpisodes]
