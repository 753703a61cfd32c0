"""N robots stepped together: a :class:`gymnasium.vector.VectorEnv`.

Robot ``i`` behaves exactly as a :class:`sitframe.gym.env.SitframeEnv`
seeded ``seed + i`` (as :class:`gymnasium.vector.SyncVectorEnv` seeds its
copies): same start poses, goals, readings and rewards for the same actions
(tested). What is shared is the numpy work:

- the "can this robot reach any wall during the period?" test of the
  simulator (:func:`sitframe.robot.step_robot`'s first step) is one (N, S)
  numpy call; robots in open space move by the closed form at once, only
  those near a wall go through ``step_robot``'s substep collision checks;
- sensors with a ``read_many(world, poses, rngs)`` method (the Pioneer sonar
  ring has one) read all N robots in one ray-casting call; others are read
  one by one.

Episodes end as in the single env; a finished robot is reset at the next
``step`` (Gymnasium's ``AutoresetMode.NEXT_STEP``: that step's action is
ignored, its reward is 0).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from sitframe.gym.env import SitframeEnv
from sitframe.gym.task import Task
from sitframe.records import Transition
from sitframe.robot import Command, StepOutcome, _plan, _pose_at, _wrap, step_robot

__all__ = ["SitframeVectorEnv"]

_NAN2 = np.full(2, np.nan)
_NAN2.setflags(write=False)


class SitframeVectorEnv(VectorEnv):
    """``num_envs`` robots of one config in one world, stepped together.

    Parameters
    ----------
    config
        Preset name, TOML path or validated config dict (as :class:`SitframeEnv`).
    num_envs
        Number of robots N.
    continuous
        Continuous ``Box`` actions.
    **task_kw
        As :class:`SitframeEnv`.

    ``infos`` holds ``pose`` (N, 3) and ``collided`` (N,) with their ``_`` masks.
    """

    metadata = {"render_modes": [], "autoreset_mode": AutoresetMode.NEXT_STEP}

    def __init__(self, config: str | dict[str, Any] = "obstacle-avoidance", *,
                 num_envs: int = 8, continuous: bool = False, render_mode: str | None = None,
                 **task_kw: Any) -> None:
        if isinstance(num_envs, bool) or not isinstance(num_envs, int) or num_envs < 1:
            raise ValueError(f"num_envs: expected a positive integer, got {num_envs!r}")
        if render_mode is not None:
            raise ValueError("render_mode: the vector env does not render; render a SitframeEnv")
        self.task = Task.from_config(config, **task_kw)
        self.num_envs = num_envs
        self.continuous = bool(continuous)
        # one env per robot holds its components and episode state; the stepping is batched here
        self.envs = [SitframeEnv(continuous=continuous, task=self.task) for _ in range(num_envs)]
        self.single_observation_space = self.envs[0].observation_space
        self.single_action_space = self.envs[0].action_space
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self.action_space = batch_space(self.single_action_space, num_envs)
        self._done = np.zeros(num_envs, dtype=bool)
        self._many = getattr(self.envs[0].sensor, "read_many", None)
        segs = self.task.world.segment_set
        self._seg = (segs.ax, segs.ay, segs.ex, segs.ey, segs.inv_len2) if segs.n else None

    def reset(self, *, seed: int | list[int | None] | None = None,
              options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        """Reset every robot; robot ``i`` is seeded ``seed + i`` (or ``seed[i]``)."""
        seeds = _seeds(seed, self.num_envs)
        if seed is not None:
            self._np_random, self._np_random_seed = seeding.np_random(seeds[0])
        obs = [env.reset(seed=s, options=options)[0] for env, s in zip(self.envs, seeds,
                                                                      strict=True)]
        self._done[:] = False
        return np.stack(obs), self._infos(np.zeros(self.num_envs, dtype=bool))

    def step(self, actions: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                                          dict[str, Any]]:
        n, task, envs = self.num_envs, self.task, self.envs
        acts = np.asarray(actions)
        if acts.shape[:1] != (n,):
            raise ValueError(f"actions: expected {n} actions (one per robot), got shape "
                             f"{acts.shape}")
        obs = np.empty((n, *self.single_observation_space.shape), dtype=np.float32)
        rew = np.zeros(n)
        term = np.zeros(n, dtype=bool)
        trunc = np.zeros(n, dtype=bool)
        collided = np.zeros(n, dtype=bool)
        live = np.flatnonzero(~self._done)
        for i in np.flatnonzero(self._done):  # NEXT_STEP autoreset
            obs[i] = envs[i].reset()[0]
        if live.size:
            cmds = [task.command(acts[i], self.continuous) for i in live]
            befores = [task.context(envs[i].t, envs[i].pose, envs[i]._reading, envs[i].goal)
                       for i in live]
            outs = self._move(live, cmds)
            self._read(live)
            for j, i in enumerate(live):
                env, out = envs[i], outs[j]
                env.t += 1
                after = task.context(env.t, env.pose, env._reading, env.goal)
                rew[i] = float(env.reward_fn(Transition(befores[j], cmds[j], out, after)))
                term[i] = task.terminated(after, out.collided)
                trunc[i] = not term[i] and env.t >= task.max_steps
                collided[i] = out.collided
                obs[i] = task.observe(env._reading, env.pose, env.goal)
        self._done = term | trunc
        return obs, rew, term, trunc, self._infos(collided)

    def _move(self, live: np.ndarray, cmds: list[Command]) -> list[StepOutcome]:
        """Step robots ``live``: one (N, S) reach test, then the closed form or ``step_robot``."""
        envs, rp = self.envs, self.task.res.robot
        plans = [_plan(envs[i].pose, c, rp) for i, c in zip(live, cmds, strict=True)]
        near = np.zeros(live.size, dtype=bool)
        if self._seg is not None:  # the test of step_robot, for all robots at once
            ax, ay, ex, ey, inv = self._seg
            x0 = np.array([p[0] for p in plans])[:, None]
            y0 = np.array([p[1] for p in plans])[:, None]
            reach = np.array([p[3] * rp.control_period_s + rp.radius + rp.recovery_backoff_m
                              + 1e-9 for p in plans])[:, None]
            wx, wy = x0 - ax, y0 - ay
            t = (wx * ex + wy * ey) * inv
            np.clip(t, 0.0, 1.0, out=t)
            dx, dy = wx - t * ex, wy - t * ey
            near = (dx * dx + dy * dy < reach * reach).any(axis=1)
        outs = []
        T = rp.control_period_s
        for j, i in enumerate(live):
            env = envs[i]
            if near[j]:
                out = step_robot(env.world, env.pose, cmds[j], rp, env.np_random)
            else:  # open space: step_robot's own closed form
                x0, y0, th0, v, omega, t_turn = plans[j]
                x, y, th = _pose_at(T, x0, y0, th0, v, omega, t_turn)
                final = np.array([x, y, _wrap(th)])
                out = StepOutcome(env.pose, final, False, _NAN2, final, v * T,
                                  math.degrees(th - th0))
            env.pose = out.pose
            outs.append(out)
        return outs

    def _read(self, live: np.ndarray) -> None:
        envs = self.envs
        if self._many is not None:
            readings = self._many(self.task.world, np.stack([envs[i].pose for i in live]),
                                  [envs[i].np_random for i in live])
            for j, i in enumerate(live):
                envs[i]._reading = readings[j]
        else:
            for i in live:
                envs[i]._reading = envs[i].sensor.read(envs[i].world, envs[i].pose,
                                                       envs[i].np_random)

    def _infos(self, collided: np.ndarray) -> dict[str, Any]:
        mask = np.ones(self.num_envs, dtype=bool)
        return {"pose": np.stack([e.pose for e in self.envs]), "_pose": mask,
                "collided": collided, "_collided": mask}


def _seeds(seed: int | list[int | None] | None, n: int) -> list[int | None]:
    if seed is None:
        return [None] * n
    if isinstance(seed, int | np.integer) and not isinstance(seed, bool):
        return [int(seed) + i for i in range(n)]
    seeds = list(seed)
    if len(seeds) != n:
        raise ValueError(f"seed: expected an int or {n} seeds, got {len(seeds)}")
    return seeds

