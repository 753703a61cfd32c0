"""Goal episodes: drive from a start to a goal with frozen behaviours, and score it.

An *episode* starts the robot at a start pose with a goal disc in the
context (:attr:`sitframe.records.Context.goal`) and runs the configured
behaviours and arbiter, without learning, until

* the robot's centre is within the goal radius (**success**), or
* ``timeout`` iterations (default 300 = 7.5 min of robot time) have passed.

A collision never ends an episode: the robot recovers (as the simulator's
collision recovery does) and carries on; collisions are counted.

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
obstacles, used by SPL), ``time_s`` (iterations x control period, 1.5 s),
``heading_change_per_m`` (total |heading change| per metre, path smoothness).

Aggregates over a batch (:func:`aggregate`): ``episodes``, ``success_rate``,
``collisions_per_episode``, ``collision_free_rate`` (fraction of episodes
without a collision), ``spl`` (:func:`sitframe.metrics.spl`), ``mean_time_s``
(mean time of the *successful* episodes; NaN if none), ``heading_change_per_m``
(pooled: total heading change over total path length of all episodes),
``mean_path_length_m``.

A *goal run* is a run with a component that declares ``requires_goal = True``
(a class attribute; e.g. a goal-seeking behaviour). Its evaluate stage runs
one batch of episodes per world of ``[goal] worlds`` instead of the frozen
evaluation of ``[evaluate]``; each batch is one trial in the log, with the
per-iteration arrays of all its episodes concatenated (``first_iteration``
gives each episode's first row; ``pose`` has one extra row per episode) and
one ``episodes/NNNN`` group per episode with its outcome as attributes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from sitframe import params as P
from sitframe.errors import InputError
from sitframe.metrics import coverage, heading_change_per_m, path_length, spl
from sitframe.records import TrialResult
from sitframe.world import World

if TYPE_CHECKING:
    from collections.abc import Callable

    from sitframe.records import StepRecord
    from sitframe.scheduler import Resolved, TrialSpec

#: Seed stage of goal-episode batches (see :func:`sitframe.scheduler.stage_seed`).
STAGE_GOAL = 4
PAIR_MODES = ("random", "world")
#: Aggregate keys of a batch (``evaluate --goal-episodes --json``, ``eval/<world>/...``).
AGGREGATE_KEYS = ("episodes", "success_rate", "collisions_per_episode", "collision_free_rate",
                  "spl", "mean_time_s", "heading_change_per_m", "mean_path_length_m")
_EPISODE_KEYS = ("success", "iterations", "collisions", "path_length_m", "straight_m", "time_s",
                 "heading_change_per_m")


@dataclass(frozen=True)
class EpisodeConfig:
    """How to run a batch of goal episodes (the ``[goal]`` config table).

    Attributes
    ----------
    episodes
        Episodes per world.
    timeout
        Iterations before an episode is given up.
    min_distance
        Minimum straight-line start-goal distance [m] of random pairs.
    pairs
        ``"random"`` or ``"world"`` (module docstring).
    radius
        Goal radius [m] of random goals.
    margin
        Clearance [m] beyond the robot's radius required at random starts and goals.
    """

    episodes: int = 50
    timeout: int = 300
    min_distance: float = 3.0
    pairs: str = "random"
    radius: float = 0.3
    margin: float = 0.1

    def __post_init__(self) -> None:
        P.number("episodes", self.episodes, lo=1, integer=True)
        P.number("timeout", self.timeout, lo=1, integer=True)
        P.number("min_distance", self.min_distance, lo=0.0)
        P.choice("pairs", self.pairs, PAIR_MODES)
        P.number("radius", self.radius, lo=0.0, lo_open=True)
        P.number("margin", self.margin, lo=0.0)

    @classmethod
    def from_config(cls, cfg: dict[str, Any], *, file: str | None = None) -> EpisodeConfig:
        """Build from a validated config's ``[goal]`` table (errors name ``goal.KEY``)."""
        g = cfg["goal"]
        kw = {k: g[k] for k in ("episodes", "timeout", "min_distance", "pairs", "radius",
                                "margin") if k in g}
        try:
            return cls(**kw)
        except InputError as exc:
            raise exc.at(file=file, key_prefix="goal") from None


def is_goal_run(res: Resolved) -> bool:
    """Whether a component of the run declares ``requires_goal = True``."""
    comps = [b for b, _r in res.behaviours().values()] + [res.arbiter()]
    return any(getattr(c, "requires_goal", False) for c in comps)


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
) -> tuple[np.ndarray, np.ndarray]:
    """Draw ``n`` random start/goal pairs in ``world``.

    Returns
    -------
    (starts, goals)
        ``starts`` (n, 3): x [m], y [m], theta [rad]; ``goals`` (n, 3): x [m],
        y [m], radius [m]. Both positions are free for a disc of
        ``robot_radius + margin``; they are at least ``min_distance`` apart.

    Raises
    ------
    InputError
        ``goal.min_distance``: no pair that far apart found in ``max_tries``.
    """
    starts = np.empty((n, 3))
    goals = np.empty((n, 3))
    for e in range(n):
        for _ in range(max_tries):
            s = world.random_free_pose(rng, robot_radius, margin=margin)
            g = world.random_free_pose(rng, robot_radius, margin=margin)
            if math.hypot(g[0] - s[0], g[1] - s[1]) >= min_distance:
                break
        else:
            raise InputError(f"found no start and goal {min_distance:g} m apart in world "
                             f"'{world.name}' in {max_tries} tries; expected a smaller "
                             "min_distance or a larger world", key="goal.min_distance")
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


def episode_outcome(result: TrialResult, start: np.ndarray, goal: np.ndarray,
                    period_s: float) -> dict[str, Any]:
    """Per-episode figures of one simulated episode (module docstring)."""
    pose = result.arrays["pose"]
    it = int(result.arrays["collision"].size)
    reached = math.hypot(pose[-1, 0] - goal[0], pose[-1, 1] - goal[1]) <= goal[2]
    straight = max(math.hypot(goal[0] - start[0], goal[1] - start[1]) - goal[2], 0.0)
    return {
        "success": bool(reached),
        "iterations": it,
        "collisions": int(result.arrays["collision"].sum()),
        "path_length_m": path_length(pose[:, :2]),
        "straight_m": straight,
        "time_s": it * period_s,
        "heading_change_per_m": heading_change_per_m(pose[:, 2], pose[:, :2]),
    }


def aggregate(ep: dict[str, np.ndarray]) -> dict[str, float]:
    """Batch figures from per-episode arrays (keys of :func:`episode_outcome`)."""
    success = np.asarray(ep["success"], bool)
    n = int(success.size)
    coll = np.asarray(ep["collisions"], float)
    path = np.asarray(ep["path_length_m"], float)
    time_s = np.asarray(ep["time_s"], float)
    total_turn = np.nansum(np.asarray(ep["heading_change_per_m"], float) * path)
    return {
        "episodes": n,
        "success_rate": float(success.mean()) if n else float("nan"),
        "collisions_per_episode": float(coll.mean()) if n else float("nan"),
        "collision_free_rate": float((coll == 0).mean()) if n else float("nan"),
        "spl": spl(success, ep["straight_m"], path),
        "mean_time_s": float(time_s[success].mean()) if success.any() else float("nan"),
        "heading_change_per_m": float(total_turn / path.sum()) if path.sum() > 0
        else float("nan"),
        "mean_path_length_m": float(path.mean()) if n else float("nan"),
    }


def run_episode_batch(
    res: Resolved,
    spec: TrialSpec,
    *,
    step_hook: Callable[[StepRecord], Any] | None = None,
) -> TrialResult:
    """Run ``spec.episodes`` goal episodes in ``spec.world`` and return them as one trial.

    Called by :func:`sitframe.scheduler.simulate` for a spec whose ``episodes``
    is set. Pairs come from a Generator seeded by ``spec.seed``; episode ``e``
    runs with its own seed spawned from it, so a batch is reproducible and
    episode ``e`` does not depend on the others.
    """
    import dataclasses

    from sitframe.scheduler import simulate

    cfg: EpisodeConfig = spec.episodes  # type: ignore[assignment]
    world = res.world(spec.world, key="goal.worlds")
    ss = np.random.SeedSequence(spec.seed % 2**64)
    pair_rng = np.random.default_rng(ss.spawn(1)[0])
    if cfg.pairs == "world":
        starts, goals = world_pairs(world, cfg.episodes)
    else:
        starts, goals = goal_pairs(world, cfg.episodes, pair_rng, min_distance=cfg.min_distance,
                                   goal_radius=cfg.radius, robot_radius=res.robot.radius,
                                   margin=cfg.margin)
    seeds = np.random.SeedSequence(spec.seed % 2**64, spawn_key=(1,)).generate_state(
        cfg.episodes, np.uint64)
    period = float(res.robot.control_period_s)
    outcomes: list[dict[str, Any]] = []
    parts: list[TrialResult] = []
    for e in range(cfg.episodes):
        ep_spec = dataclasses.replace(
            spec, seed=int(seeds[e]), iterations=cfg.timeout, learn=False, evaluate=(),
            start=tuple(float(v) for v in starts[e]), goal=tuple(float(v) for v in goals[e]),
            stop_at_goal=True, episodes=None)
        r = simulate(res, ep_spec, step_hook=step_hook)
        parts.append(r)
        outcomes.append(episode_outcome(r, starts[e], goals[e], period))

    per_ep = {k: np.asarray([o[k] for o in outcomes]) for k in _EPISODE_KEYS}
    agg = aggregate(per_ep)
    arrays = {k: np.concatenate([p.arrays[k] for p in parts]) for k in parts[0].arrays}
    first = np.cumsum([0] + [int(p.arrays["collision"].size) for p in parts[:-1]])
    episodes: dict[str, Any] = {**per_ep, "start": starts, "goal": goals,
                                "first_iteration": first.astype(np.int64)}
    for e, o in enumerate(outcomes):
        episodes[f"{e:04d}"] = {**o, "start": starts[e], "goal": goals[e]}
    coll = arrays["collision"]
    summary: dict[str, Any] = {
        "iterations": int(coll.size),
        "converged": False,
        "convergence_iteration": -1,
        "collisions": int(coll.sum()),
        "collisions_per_1000": float(coll.sum() * 1000.0 / coll.size),
        "collisions_before_convergence": int(coll.sum()),
        "collisions_per_1000_after_convergence": float("nan"),
        "distance_m": float(per_ep["path_length_m"].sum()),
        "mean_speed_m_s": float(arrays["command"][:, 1].mean()),
        "coverage": coverage(world, arrays["pose"][:, :2], radius=res.robot.radius),
    }
    for k, v in agg.items():
        summary[f"eval/{world.name}/{k}"] = v
    return TrialResult(spec.index, spec.seed, world.name, arrays, parts[0].behaviours, summary,
                       episodes, policies=parts[0].policies)


def batch_aggregate(result: TrialResult) -> dict[str, float]:
    """The aggregate figures of a batch returned by :func:`run_episode_batch`."""
    prefix = f"eval/{result.world}/"
    return {k[len(prefix):]: v for k, v in result.summary.items() if k.startswith(prefix)}


def check_goal_config(cfg: dict[str, Any], res: Resolved, source: str | None) -> list[str]:
    """Check the ``[goal]`` table and its worlds before a goal run starts; return the worlds.

    Raises
    ------
    InputError
        A bad ``[goal]`` value, an unknown world, or ``pairs = "world"`` with a
        world that has no ``[goal]``.
    """
    ep = EpisodeConfig.from_config(cfg, file=source)
    names = list(cfg["goal"]["worlds"])
    for j, name in enumerate(names):
        world = res.world(name, key=f"goal.worlds[{j}]")
        if ep.pairs == "world" and world.goal is None:
            raise InputError(f"world '{name}' has no [goal] but goal.pairs = \"world\"; expected "
                             "a world with a [goal] table or goal.pairs = \"random\"",
                             file=source, key=f"goal.worlds[{j}]")
    return names


def goal_batch_specs(exp: Any, interpreter_state: dict[str, Any],
                     policies: dict[str, Any] | None,
                     first_index: int) -> list[TrialSpec]:
    """One episode-batch spec per world of the config's ``[goal] worlds`` (a goal run).

    Batch ``j`` is trial ``first_index + j``; its seed is derived from the run
    seed (stage :data:`STAGE_GOAL`, index ``j``). Checks the ``[goal]`` table
    and, for ``pairs = "world"``, that every world has a goal, before anything runs.
    """
    from sitframe.scheduler import TrialSpec, stage_seed

    cfg = exp.cfg
    ep = EpisodeConfig.from_config(cfg, file=exp.source)
    specs = []
    for j, name in enumerate(check_goal_config(cfg, exp.res, exp.source)):
        specs.append(TrialSpec(
            index=first_index + j, seed=stage_seed(int(cfg["experiment"]["seed"]), STAGE_GOAL, j),
            world=name, iterations=ep.timeout, learn=False, interpreter_state=interpreter_state,
            policies=policies or {}, episodes=ep))
    return specs
