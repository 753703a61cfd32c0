"""A sitframe config seen as a reinforcement-learning task (shared by the single and vector envs).

:class:`Task` resolves a config (preset name or TOML path) with the same
code a run uses (:class:`sitframe.contract.resolve.Resolved`): its robot, its sensor
plugin, the reward plugin of its learning behaviour, its worlds, and — for a
goal task (a config whose components ask for the ``goal-episodes``
protocol) — that protocol's start/goal pairs and its ``terminated`` test.
Nothing here imports Gymnasium; the envs build their spaces from it.

Choices the issue leaves open (also in docs/how-to/gymnasium.md):

- **Actions** are the headings (and speeds, if configured) of the config's
  *task behaviour*: the first behaviour with a ``reward``, else the first with
  ``headings``. Discrete action ``a`` is heading ``a // n_speeds`` and speed
  ``a % n_speeds``; without ``speeds`` every action drives at
  ``experiment.default_speed``.
- **Reward**: the task behaviour's reward plugin. A goal config whose
  behaviours learn nothing (the ``goal-finding`` preset) gets
  ``goal-progress`` (``plugins/learned_arbiter.py``). ``reward=`` overrides both.
- **Worlds**: one (``world=``, default the config's ``experiment.world``) or several
  (``worlds=[...]``, any names a config accepts, e.g. generated rooms ``"gen:SEED"``):
  with several, each episode's world is drawn uniformly from the env's generator
  ``np_random`` at ``reset`` (before its start pose), so ``reset(seed=s)`` repeats
  the world too; ``options={"world": name}`` picks one. A single world draws
  nothing (its episodes are those of before the option existed).
- **Episodes**: a start pose drawn uniformly among free poses with
  ``start_margin`` (0.1 m) of clearance beyond the robot's radius; goal tasks
  draw start and goal from the protocol (``[goal]`` table: min_distance,
  margin, radius). The time limit is the run's evaluation protocol's (goal:
  ``timeout``; else ``evaluate.iterations``, 1000): it *truncates*. A goal task *terminates*
  when the goal is reached; a collision terminates only with
  ``terminate_on_collision=True`` (the robot recovers and carries on, as in
  sitframe's own trials).
- **Contexts** handed to the reward carry no memberships (an empty array):
  the env has no situation interpreter, its observation is the raw reading.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from sitframe.contract.config import Component, load_config
from sitframe.contract.pluginmanager import Registry, get_plugin_manager
from sitframe.contract.records import Context, TrialInfo
from sitframe.contract.resolve import Resolved
from sitframe.errors import InputError
from sitframe.params import check_environment
from sitframe.sim.kernels import kernels
from sitframe.sim.robot import Command
from sitframe.sim.world import Goal, World

__all__ = ["GOAL_REWARD", "Task", "goal_features"]

#: The reward a goal task gets when its config learns nothing.
GOAL_REWARD = "goal-progress"
_NO_U = np.empty(0)
_NO_U.setflags(write=False)


def goal_features(pose: np.ndarray, goal: Goal) -> tuple[float, float]:
    """Distance [m] from the robot's centre to the goal's centre and its bearing [rad] in
    (-pi, pi] relative to the heading (positive = left)."""
    dx, dy = goal.position[0] - pose[0], goal.position[1] - pose[1]
    return math.hypot(dx, dy), math.remainder(math.atan2(dy, dx) - pose[2], 2.0 * math.pi)


@dataclass
class Task:
    """A config resolved into what an RL environment needs.

    Attributes
    ----------
    res
        The resolved config (its components are created fresh per env).
    world
        The world episodes run in (the first of :attr:`worlds`).
    headings, speeds
        (H,) heading changes [deg] and (V,) speeds [m/s] of the discrete actions
        (``speeds`` holds only ``default_speed`` when the config learns no speed).
    learns_speed
        Whether the config's task behaviour has ``speeds`` (a continuous action
        then has a speed dimension).
    reward_name, reward_params
        The reward plugin and its parameters.
    protocol
        The goal-episodes protocol (episodes = 1) for goal tasks, else None.
    max_steps
        Time limit of an episode (truncation).
    normalize
        Observations scaled to [0, 1] (ranges) and [-1, 1] (bearing).
    start_margin
        Clearance beyond the robot's radius of random start poses [m].
    terminate_on_collision
        Whether a collision ends the episode.
    worlds
        Every world an episode may run in (each episode draws one when there are
        several); ``(world,)`` for one.
    """

    res: Resolved
    world: World
    headings: np.ndarray
    speeds: np.ndarray
    learns_speed: bool
    reward_name: str
    reward_params: dict[str, Any]
    protocol: Any
    max_steps: int
    normalize: bool
    start_margin: float
    terminate_on_collision: bool
    worlds: tuple[World, ...] = ()
    _bounds: tuple[np.ndarray, np.ndarray] | None = None
    _commands: list[Command] | None = None
    _scale: float | None = None  # what :meth:`observe_nearest` divides the ranges by

    @classmethod
    def from_config(cls, config: str | dict[str, Any] = "obstacle-avoidance", *,
                    world: str | None = None, worlds: Sequence[str] | None = None,
                    reward: str | None = None,
                    reward_params: dict[str, Any] | None = None, max_steps: int | None = None,
                    normalize: bool = True, start_margin: float = 0.1,
                    terminate_on_collision: bool = False,
                    plugins_dirs: tuple[str, ...] = ()) -> Task:
        """Resolve ``config`` (preset name, TOML path or a validated config dict).

        ``world`` names the one world of every episode (default: the config's
        ``experiment.world``); ``worlds`` names several, one drawn per episode
        (not both).

        Raises
        ------
        sitframe.errors.InputError
            A bad config, world or plugin parameter (names file and key).
        ValueError
            The config has no behaviour with headings, or a bad argument.
        """
        check_environment()  # (a bad SITFRAME_NUMBA, say: said here, not ignored)
        if isinstance(config, dict):
            cfg, source, base = copy.deepcopy(config), None, "."
        else:
            cfg, source, base = load_config(str(config), plugin_folders=bool(plugins_dirs))
        label = _task_behaviour(cfg, source)
        table = cfg["behaviours"][label]
        registry = Registry.collect(get_plugin_manager(plugins_dirs=plugins_dirs))
        names = _world_names(world, worlds, cfg["experiment"]["world"])
        res = Resolved.build(cfg, registry, source, worlds=names, base_dir=base)
        loaded = tuple(res.world(n, key="worlds" if worlds is not None else "world")
                       for n in names)
        goal_task = res.protocol_name() == "goal-episodes"
        rname = reward or table.get("reward") or (GOAL_REWARD if goal_task else None)
        if rname is None:
            raise ValueError(f"config {source or '<dict>'}: behaviour '{label}' has no reward; "
                             "expected a reward in its table or reward=... for the env")
        rparams = dict(reward_params if reward_params is not None else
                       (table.get("reward_params", {}) if rname == table.get("reward") else {}))
        proto = None
        if goal_task:
            proto = res.protocol("goal-episodes")
            proto.episodes = 1
            if hasattr(proto, "check_world"):
                for w in loaded:
                    proto.check_world(w)
        if max_steps is None:
            max_steps = int((proto or res.protocol(res.protocol_name())).iterations)
        if isinstance(max_steps, bool) or not isinstance(max_steps, int) or max_steps < 1:
            raise ValueError(f"max_steps: expected a positive integer, got {max_steps!r}")
        if not (isinstance(start_margin, int | float) and start_margin >= 0):
            raise ValueError(f"start_margin: expected a number >= 0 [m], got {start_margin!r}")
        speeds = np.asarray(table.get("speeds", ()), dtype=np.float64)
        learns_speed = speeds.size > 0
        if not learns_speed:
            speeds = np.array([float(cfg["experiment"]["default_speed"])])
        task = cls(res, loaded[0],
                   np.asarray(table["headings"], dtype=np.float64), speeds, learns_speed,
                   rname, rparams, proto, int(max_steps), bool(normalize), float(start_margin),
                   bool(terminate_on_collision), loaded)
        task.make_reward()  # a bad reward name or parameter fails here, not at the first step
        return task

    # -- components -------------------------------------------------------
    def make_sensor(self) -> Any:
        """A fresh sensor, created and bound as a run creates it."""
        return self.res.sensor()

    def make_reward(self) -> Any:
        """A fresh reward plugin, created and bound as a run creates it."""
        return self.res._create("reward", "env.reward",  # the run's own factory
                                Component(self.reward_name, dict(self.reward_params)))

    # -- spaces -------------------------------------------------------------
    @property
    def sensor_dim(self) -> int:
        return int(self.res.run.sensor.dim)

    @property
    def max_range(self) -> float:
        return float(self.res.run.sensor.max_range)

    @property
    def n_actions(self) -> int:
        return self.headings.size * self.speeds.size

    @property
    def diagonal(self) -> float:
        """Diagonal of the worlds' bounding boxes [m] (the largest of them): the largest goal
        distance."""
        return max(math.hypot(w.bounds[2] - w.bounds[0], w.bounds[3] - w.bounds[1])
                   for w in self.worlds or (self.world,))

    def pick_world(self, rng: np.random.Generator, name: str | None = None) -> World:
        """The world of a new episode: ``name`` if given (one of :attr:`worlds`), else one
        drawn uniformly from ``rng`` when there are several (nothing is drawn for one)."""
        worlds = self.worlds or (self.world,)
        if name is not None:
            for w in worlds:
                if w.name == name:
                    return w
            raise ValueError(f"options['world']: expected one of the env's worlds "
                             f"({', '.join(w.name for w in worlds)}), got {name!r}")
        return worlds[int(rng.integers(len(worlds)))] if len(worlds) > 1 else worlds[0]

    def observation_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Lower and upper bounds, (d,) or (d + 2,) with goal distance and bearing."""
        if self._bounds is None:
            self._bounds = self._observation_bounds()
        return self._bounds

    def _observation_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        d = self.sensor_dim
        top = 1.0 if self.normalize else self.max_range
        lo, hi = [0.0] * d, [top] * d
        if self.protocol is not None:
            lo += [0.0, -1.0 if self.normalize else -math.pi]
            hi += [1.0 if self.normalize else self.diagonal, 1.0 if self.normalize else math.pi]
        return np.asarray(lo, np.float32), np.asarray(hi, np.float32)

    def observe(self, reading: np.ndarray, pose: np.ndarray, goal: Goal | None) -> np.ndarray:
        """The observation of ``reading`` at ``pose`` (float32, in :meth:`observation_bounds`)."""
        if self.protocol is not None:
            return self.observe_many(reading[None, :], pose[None, :], [goal])[0]
        obs = (reading / self.max_range if self.normalize else reading).astype(np.float32)
        lo, hi = self.observation_bounds()  # the ranges alone: observe_many's steps, unbatched
        return np.minimum(np.maximum(obs, lo, out=obs), hi, out=obs)

    def observe_nearest(self, reading: np.ndarray, pose: np.ndarray, goal: Goal | None
                        ) -> tuple[np.ndarray, float]:
        """:meth:`observe` and the reading's smallest range (the context's ``nearest``), the
        pair in one compiled call when the kernels are loaded (the same numbers either way)."""
        k = kernels()
        lo, hi = self._bounds or self.observation_bounds()
        if (k is None or self.protocol is not None or reading.dtype != np.float64
                or reading.shape != lo.shape):
            return self.observe(reading, pose, goal), float(reading.min())
        scale = self._scale
        if scale is None:
            scale = self._scale = self.max_range if self.normalize else 1.0
        out = np.empty_like(lo)
        return out, k.observe(reading, scale, lo, hi, out)

    def observe_many(self, readings: np.ndarray, poses: np.ndarray | list[np.ndarray],
                     goals: list[Goal | None]) -> np.ndarray:
        """Observations (N, d[+2]) of N robots' readings (N, d) at poses (N, 3) (or N (3,)
        arrays)."""
        obs = readings / self.max_range if self.normalize else readings
        if self.protocol is not None:
            extra = np.array([goal_features(p, g) for p, g in zip(poses, goals, strict=True)])
            extra[:, 0] = np.minimum(extra[:, 0], self.diagonal)
            if self.normalize:
                extra /= (self.diagonal, math.pi)
            obs = np.concatenate([obs, extra], axis=1)
        lo, hi = self.observation_bounds()
        return np.clip(obs.astype(np.float32), lo, hi)

    def command(self, action: Any, continuous: bool) -> Command:
        """The command of a discrete action index or a continuous action in [-1, 1]^k."""
        if continuous:
            a = np.clip(np.asarray(action, dtype=np.float64).reshape(-1), -1.0, 1.0)
            rp = self.res.robot
            heading = float(a[0]) * rp.max_heading_change_deg
            speed = (rp.min_speed + 0.5 * (float(a[1]) + 1.0) * (rp.max_speed - rp.min_speed)
                     if self.learns_speed else float(self.speeds[0]))
            return Command(heading, speed)
        i = int(action)
        if not 0 <= i < self.n_actions:
            raise ValueError(f"action {action!r} out of range: expected 0..{self.n_actions - 1}")
        if self._commands is None:
            v = self.speeds.size
            self._commands = [Command(float(self.headings[a // v]), float(self.speeds[a % v]))
                              for a in range(self.n_actions)]
        return self._commands[i]

    # -- episodes -------------------------------------------------------------
    def draw_start(self, rng: np.random.Generator, world: World | None = None
                   ) -> tuple[np.ndarray, Goal | None]:
        """A random free start pose (3,) and, for goal tasks, a goal, drawn from ``rng`` in
        ``world`` (default :attr:`world`)."""
        world = self.world if world is None else world
        if self.protocol is None:
            return world.random_free_pose(rng, self.res.robot.radius,
                                          margin=self.start_margin), None
        starts, goals = self.protocol.episode_starts(world, rng, self.res.robot)
        g = None if goals is None else Goal(np.asarray(goals[0][:2], float), float(goals[0][2]))
        return np.asarray(starts[0], dtype=float), g

    def trial_info(self, rng: np.random.Generator, world: World | None = None) -> TrialInfo:
        """What a reward is told when an episode starts (in ``world``, default :attr:`world`)."""
        return TrialInfo(0, "learn", self.world if world is None else world, self.max_steps, rng)

    def context(self, t: int, pose: np.ndarray, reading: np.ndarray, goal: Goal | None,
                nearest: float | None = None, world: World | None = None) -> Context:
        """The loop's context for the reward (no memberships: the env has no interpreter);
        ``nearest`` is the reading's smallest range (computed if not given); ``world``
        the episode's (default :attr:`world`)."""
        return Context(t, pose, reading, _NO_U,
                       float(reading.min()) if nearest is None else nearest,
                       self.world if world is None else world, goal)

    def terminated(self, ctx: Context, collided: bool) -> bool:
        """Goal reached (goal tasks), or a collision with ``terminate_on_collision``."""
        if collided and self.terminate_on_collision:
            return True
        return self.protocol is not None and bool(self.protocol.terminated(ctx))


def _world_names(world: str | None, worlds: Sequence[str] | None, default: str
                 ) -> tuple[str, ...]:
    """The env's world names: ``worlds`` (several), ``world`` (one), else the config's."""
    if worlds is None:
        return (world or default,)
    if world is not None:
        raise ValueError("world and worlds: expected one of them, not both")
    if isinstance(worlds, str) or not worlds or not all(isinstance(w, str) for w in worlds):
        raise ValueError(f"worlds: expected a non-empty list of world names, got {worlds!r}")
    return tuple(dict.fromkeys(worlds))


def _task_behaviour(cfg: dict[str, Any], source: str | None) -> str:
    """The label of the behaviour the env's actions are: the first with a reward, else the
    first with headings."""
    beh = cfg["behaviours"]
    for pick in (lambda t: "reward" in t and "headings" in t, lambda t: "headings" in t):
        for label, table in beh.items():
            if pick(table):
                return label
    raise InputError("no behaviour has 'headings'; the env's discrete actions are a behaviour's "
                     "headings (expected e.g. headings = [90, 60, 30, 0, -30, -60, -90])",
                     file=source, key="behaviours")
