"""N robots stepped together: a :class:`gymnasium.vector.VectorEnv`.

Robot ``i`` behaves exactly as a :class:`sitframe.gym.env.SitframeEnv`
seeded ``seed + i`` (as :class:`gymnasium.vector.SyncVectorEnv` seeds its
copies): same start poses, goals, readings and rewards for the same actions
(tested, bit for bit, collisions included, with and without the compiled
kernels). What is shared is the simulator's work:

- the robots move in one :func:`sitframe.sim.fleet.step_robots` call (with the
  compiled kernels, a few compiled calls for all N robots: which walls each
  can reach, its substeps and first contact, the refinement of the contacts,
  the contact points and back-offs; two robots or fewer step one by one, with the
  single env's calls);
- sensors with a ``read_many(world, poses, rngs)`` method (the Pioneer sonar
  ring has one: :func:`sitframe.rim_ranges_many`, one compiled call) read all
  N robots at once; others are read one by one;
- the observations are built in one array operation.

What stays per robot is what a reward plugin needs: the contexts, the
:class:`~sitframe.contract.records.Transition` and the reward call. Without the
compiled kernels the robots are stepped one by one (the numpy reference).

Compiled, in one call: when the single env's step is compiled
(:class:`~sitframe.gym.env.CompiledStep`: a range finder without noise, no goals) and the
reward is the built-in ``obstacle-avoidance`` (without ``progress``), every robot's step,
contact included, reading, observation and reward are one call per world
(:func:`sitframe.sim.kernels_numba.env_steps`), and no Python runs per robot: their poses,
readings and step counts are kept in (N, ...) arrays, handed to the robots' own envs only
when something reads them there (:attr:`SitframeVectorEnv.envs`; a dead-ahead
contact, whose turn is a draw from the robot's generator and is stepped as above).

With several worlds (``worlds=[...]``) each robot draws its episode's world as
the single env does, and the robots are moved and read world by world (each
robot's own generator, so still bit-identical to its single env).

Episodes end as in the single env; a finished robot is reset at the next
``step`` (Gymnasium's ``AutoresetMode.NEXT_STEP``: that step's action is
ignored, its reward is 0).
"""

from __future__ import annotations

from contextlib import suppress
from typing import Any

import numpy as np
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from sitframe.contract.records import Context, Transition
from sitframe.gym.env import CompiledStep, SitframeEnv
from sitframe.gym.task import _NO_U, Task
from sitframe.sim.fleet import step_robots
from sitframe.sim.kernels import kernels, load
from sitframe.sim.robot import step_robot

__all__ = ["SitframeVectorEnv"]

#: Up to this many robots step one by one, with the single env's calls: the batched kernels
#: pay off only for several, and a robot stepped apart (a dead-ahead contact of the compiled
#: step) then costs no compile of kernels of its own on a first run.
_FEW = 2


class SitframeVectorEnv(VectorEnv):
    """``num_envs`` robots of one config, stepped together (in one world, or each in the world
    its episode drew).

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

    Notes
    -----
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
        self._envs = [SitframeEnv(continuous=continuous, task=self.task) for _ in range(num_envs)]
        self.single_observation_space = self._envs[0].observation_space
        self.single_action_space = self._envs[0].action_space
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self.action_space = batch_space(self.single_action_space, num_envs)
        self._done = np.zeros(num_envs, dtype=bool)
        self._all = list(range(num_envs))
        self._table: list[Any] | None = None  # the command of each discrete action
        self._grid: tuple[np.ndarray, np.ndarray] | None = None  # (their heading changes
        # and speeds, (A,) each)
        self._ctx: list[Any] = [None] * num_envs  # each robot's last context
        self._many = getattr(self._envs[0].sensor, "read_many", None)
        self._fast: tuple[CompiledStep, np.ndarray] | None | bool = False  # (False: undecided)
        # The compiled step keeps the robots' poses (N, 3), readings (N, d) and step counts (N,)
        # here instead of in their envs (None: not taken from the envs yet); ``_stale``: the
        # envs' own are older, until :attr:`envs` or a robot stepped in Python brings them up.
        self._state: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self._stale = False

    @property
    def envs(self) -> list[SitframeEnv]:
        """The robots' single envs: their components and episode state, brought up to date, to
        read (a robot is placed by ``reset(options=...)``, not by setting its env's pose)."""
        if self._stale:
            self._push()
        return self._envs

    def _push(self) -> None:
        """Give every robot's env its pose, reading and step count from :attr:`_state`."""
        pose, reading, t = self._state  # type: ignore[misc]
        for i, env in enumerate(self._envs):
            env.pose, env._reading, env.t = pose[i].copy(), reading[i].copy(), int(t[i])
        self._stale = False

    def _pull(self, rows: list[int]) -> None:
        """Take the pose, reading and step count of the robots ``rows`` from their envs."""
        if self._state is None:  # (all of them, into new arrays)
            envs = self._envs
            self._state = (np.array([e.pose for e in envs], dtype=np.float64),
                           np.array([e._reading for e in envs], dtype=np.float64),
                           np.array([e.t for e in envs], dtype=np.int64))
            return
        for i in rows:
            env = self._envs[i]
            self._state[0][i], self._state[1][i], self._state[2][i] = env.pose, env._reading, \
                env.t

    def reset(self, *, seed: int | list[int | None] | None = None,
              options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        """Reset every robot; robot ``i`` is seeded ``seed + i`` (or ``seed[i]``)."""
        seeds = _seeds(seed, self.num_envs)
        if seed is not None:
            self._np_random, self._np_random_seed = seeding.np_random(seeds[0])
        obs = [env.reset(seed=s, options=options)[0] for env, s in zip(self._envs, seeds,
                                                                      strict=True)]
        self._state, self._stale = None, False  # (the envs hold it all again)
        self._done[:] = False
        self._ctx = [None] * self.num_envs
        return np.stack(obs), self._infos(np.zeros(self.num_envs, dtype=bool))

    def step(self, actions: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                                          dict[str, Any]]:
        n, envs = self.num_envs, self._envs
        acts = np.asarray(actions)
        if acts.shape[:1] != (n,):
            raise ValueError(f"actions: expected {n} actions (one per robot), got shape "
                             f"{acts.shape}")
        fast = self._compiled()
        if fast is not None and len(self.task.worlds) <= 1 and not self._done.any():
            lean = self._step_all(fast, acts)
            if lean is not None:
                return lean
        obs, at = None, None
        rew, term = np.zeros(n), np.zeros(n, dtype=bool)
        trunc, collided = np.zeros(n, dtype=bool), np.zeros(n, dtype=bool)
        live = self._all
        if self._done.any():
            obs = np.empty((n, *self.single_observation_space.shape), dtype=np.float32)
            done = np.flatnonzero(self._done).tolist()
            for i in done:  # NEXT_STEP autoreset
                obs[i] = envs[i].reset()[0]
                self._ctx[i] = None
            if self._state is not None:
                self._pull(done)
            live = np.flatnonzero(~self._done).tolist()
        if live:
            robots = [envs[i] for i in live]
            acts = acts if live is self._all else acts[live]
            figures = (rew, term, trunc, collided)
            seen, at = self._step_python(live, robots, self._commands(acts.tolist()), figures) \
                if fast is None else self._step_compiled(fast, live, robots, acts, figures)
            if obs is None:  # (all robots live)
                obs = seen
            else:
                obs[live] = seen
        self._done = term | trunc
        return obs, rew, term, trunc, self._infos(collided, at if live is self._all else None)

    def _step_python(self, live: list[int], robots: list[SitframeEnv], cmds: list[Any],
                     figures: tuple[list[Any], ...]) -> tuple[np.ndarray, np.ndarray]:
        """Step the ``live`` robots (batched kernels, contexts and rewards per robot); fill
        their ``figures`` (reward, terminated, truncated, collided); their observations and
        poses."""
        task, rew, term, trunc, collided = self.task, *figures
        rngs = [e.np_random for e in robots]
        outs, at, readings = self._move(robots, cmds, rngs)
        poses = [o.pose for o in outs]
        nearest = readings.min(axis=1).tolist()
        limit = task.max_steps
        ends, ctx = task.protocol is not None or task.terminate_on_collision, self._ctx
        for j, (i, env, out, reading) in enumerate(zip(live, robots, outs, readings,
                                                       strict=True)):
            # what stays per robot: the contexts and the reward (as SitframeEnv.step)
            before = ctx[i] or task.context(env.t, env.pose, env._reading, env.goal,
                                            world=env.world)
            env.pose, env._reading = out.pose, reading
            env.t += 1
            ctx[i] = after = Context(env.t, out.pose, reading, _NO_U, nearest[j], env.world,
                                     env.goal)
            rew[i] = float(env.reward_fn(Transition(before, cmds[j], out, after)))
            term[i] = ends and task.terminated(after, out.collided)
            trunc[i] = not term[i] and env.t >= limit
            collided[i] = out.collided
        return task.observe_many(readings, poses, [e.goal for e in robots]), at

    def _compiled(self) -> tuple[CompiledStep, np.ndarray] | None:
        """The compiled step and the reward's figures (collision, base, heading cost) when
        every robot's step can be one call (module docstring), else ``None``."""
        if self._fast is False:
            if kernels() is None:  # (N robots a step: load them now rather than after the
                load()  # numpy path's first calls, whose batch would compile kernels of its own)
            env = self._envs[0]
            fast = env.compiled_step()
            f = getattr(env.reward_fn, "_fused", None)
            spec = f() if callable(f) else None
            if fast is None or spec is None or spec["kind"] != "obstacle-avoidance":
                self._fast = None
            else:
                self._fast = (fast, np.array(spec["params"], dtype=np.float64))
        return self._fast

    def _step_all(self, fast: tuple[CompiledStep, np.ndarray], acts: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                             dict[str, Any]] | None:
        """:meth:`step` of every robot in one world in one compiled call, the common case
        (no robot to reset); ``None``, with nothing changed, when a robot meets a wall dead
        ahead (:meth:`_step_compiled` then steps them all)."""
        step, reward = fast
        if self._state is None:
            self._pull(self._all)
        pose, _reading, t = self._state  # type: ignore[misc]
        heads, speeds = self._command_arrays(acts)
        codes, out, readings, obs, rew = step.steps(self.task.world, pose, heads, speeds,
                                                    reward)
        if (codes == step.k.TIE).any():
            return None
        at = out[:, :3]
        self._state, self._stale = (at.copy(), readings, t + 1), True
        self._ctx = [None] * self.num_envs
        hit = codes != step.k.FREE
        term, trunc = self._ends(hit, self._state[2])
        self._done = term | trunc
        return obs, rew, term, trunc, self._infos(hit, at)

    def _step_compiled(self, fast: tuple[CompiledStep, np.ndarray], live: list[int],
                       robots: list[SitframeEnv], acts: np.ndarray,
                       figures: tuple[np.ndarray, ...]) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`_step_python` in one compiled call per world (a dead-ahead contact, whose
        turn is drawn from the robot's generator, stepped by :meth:`_step_python`), on the
        robots' state kept here (:attr:`_state`)."""
        step, reward = fast
        task = self.task
        if self._state is None:
            self._pull(self._all)
        everyone = live is self._all
        rows = np.arange(self.num_envs) if everyone else np.array(live)
        poses = self._state[0] if everyone else self._state[0][rows]
        heads, speeds = self._command_arrays(acts)
        whole = len(task.worlds) <= 1  # (one world: one call for them all, no grouping)
        groups = [range(len(robots))] if whole else _by_world(robots)
        obs = np.empty((len(robots), *self.single_observation_space.shape), np.float32)
        at = np.empty((len(robots), 3))
        self._ctx = [None] * self.num_envs  # (the robots stepped here have none; ties below)
        ties: list[int] = []
        for js in groups:
            codes, out, readings, seen, rewards = step.steps(
                robots[js[0]].world, poses if whole else poses[js],
                heads if whole else heads[js], speeds if whole else speeds[js], reward)
            obs[js], at[js] = seen, out[:, :3]
            ties += [js[q] for q in self._record(step, rows[js], codes, out, readings, rewards,
                                                 figures)]
        if ties:  # (rare: stepped apart, in their envs)
            self._push()
            cmds = self._commands(acts[ties].tolist())
            obs[ties], at[ties] = self._step_python([live[j] for j in ties],
                                                    [robots[j] for j in ties], cmds, figures)
            self._pull([live[j] for j in ties])
        return obs, at

    def _record(self, step: CompiledStep, rows: np.ndarray, codes: np.ndarray,
                out: np.ndarray, readings: np.ndarray, rewards: np.ndarray,
                figures: tuple[np.ndarray, ...]) -> list[int]:
        """Keep the compiled step's poses, readings and step counts of the robots ``rows``
        (:attr:`_state`) and fill their ``figures``; returns the positions in ``rows`` of
        dead-ahead contacts (not stepped: :data:`~sitframe.sim.kernels_numba.TIE`), which are
        left alone."""
        rew, term, trunc, collided = figures
        ties = np.flatnonzero(codes == step.k.TIE).tolist()
        keep = codes != step.k.TIE
        at, hit = rows[keep], codes[keep] != step.k.FREE
        pose, reading, t = self._state  # type: ignore[misc]
        pose[at], reading[at] = out[keep, :3], readings[keep]
        t[at] += 1
        self._stale = True
        rew[at], collided[at] = rewards[keep], hit
        term[at], trunc[at] = self._ends(hit, t[at])
        return ties

    def _ends(self, hit: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Terminated and truncated (M,) of robots stepped by the compiled step: ``hit``
        (M,) whether each touched a wall, ``t`` (M,) its step count now."""
        term = hit & self.task.terminate_on_collision
        return term, ~term & (t >= self.task.max_steps)

    def _command_arrays(self, acts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The heading changes [deg] and speeds [m/s] (M,) of the live robots' actions:
        discrete ones looked up (after one range check of them all), others through
        :meth:`_commands`."""
        if self._grid is None:  # (from the command table :meth:`_commands` looks up)
            cmds = self._commands(list(range(self.task.n_actions)))
            self._grid = (np.array([c.heading_change_deg for c in cmds]),
                          np.array([c.speed_m_s for c in cmds]))
        if not self.continuous and acts.ndim == 1 and acts.dtype.kind in "iu" and \
                acts.min() >= 0:
            with suppress(IndexError):  # (an action past the last: _commands says so)
                return self._grid[0].take(acts), self._grid[1].take(acts)
        cmds = self._commands(acts.tolist())  # (their own checks)
        return (np.array([c.heading_change_deg for c in cmds], dtype=np.float64),
                np.array([c.speed_m_s for c in cmds], dtype=np.float64))

    def _commands(self, acts: list[Any]) -> list[Any]:
        """The commands of the live robots' actions (discrete ones looked up, as
        :meth:`Task.command` maps them, after one range check of them all)."""
        task = self.task
        if self.continuous or not all(a.__class__ is int for a in acts) or \
                min(acts) < 0 or max(acts) >= task.n_actions:
            return [task.command(a, self.continuous) for a in acts]  # (its own checks)
        table = self._table
        if table is None:
            table = self._table = [task.command(a, False) for a in range(task.n_actions)]
        return [table[a] for a in acts]

    def _move(self, robots: list[SitframeEnv], cmds: list[Any],
              rngs: list[np.random.Generator]) -> tuple[list[Any], np.ndarray, np.ndarray]:
        """Step ``robots`` by ``cmds`` and read their sensors: the outcomes, the new poses
        (M, 3) and the readings (M, d); world by world when the robots are in several."""
        task = self.task
        if len(robots) <= _FEW:  # (one by one: the single env's calls, no batch kernels)
            outs = [step_robot(e.world, e.pose, c, task.res.robot, g)
                    for e, c, g in zip(robots, cmds, rngs, strict=True)]
            at = np.array([o.pose for o in outs])
            return outs, at, np.stack([e.sensor.read(e.world, p, g)
                                       for e, p, g in zip(robots, at, rngs, strict=True)])
        if len(task.worlds) <= 1:
            outs = step_robots(task.world, [e.pose for e in robots], cmds, task.res.robot, rngs)
            at = np.array([o.pose for o in outs])  # (M, 3)
            return outs, at, self._read(task.world, robots, at, rngs)
        outs: list[Any] = [None] * len(robots)
        at = np.empty((len(robots), 3))
        readings = np.empty((len(robots), task.sensor_dim))
        for js in _by_world(robots):
            world, g_rngs = robots[js[0]].world, [rngs[j] for j in js]
            g_outs = step_robots(world, [robots[j].pose for j in js], [cmds[j] for j in js],
                                 task.res.robot, g_rngs)
            g_at = np.array([o.pose for o in g_outs])
            readings[js] = self._read(world, [robots[j] for j in js], g_at, g_rngs)
            at[js] = g_at
            for j, o in zip(js, g_outs, strict=True):
                outs[j] = o
        return outs, at, readings

    def _read(self, world: Any, robots: list[SitframeEnv], at: np.ndarray,
              rngs: list[np.random.Generator]) -> np.ndarray:
        """The sensor readings (M, d) of ``robots`` in ``world`` at poses ``at`` (M, 3),
        batched if the sensor can."""
        if self._many is not None:
            return self._many(world, at, rngs)
        return np.stack([e.sensor.read(world, p, g)
                         for e, p, g in zip(robots, at, rngs, strict=True)])

    def _infos(self, collided: np.ndarray, poses: np.ndarray | None = None) -> dict[str, Any]:
        """``pose`` (N, 3) (``poses``, if given, are every robot's) and ``collided`` (N,)."""
        mask = np.ones(self.num_envs, dtype=bool)
        if poses is None:  # (the compiled step's state is every robot's, reset ones too)
            poses = self._state[0].copy() if self._state is not None else \
                np.array([e.pose for e in self._envs])
        return {"pose": poses, "_pose": mask,
                "collided": collided, "_collided": mask}


def _by_world(robots: list[SitframeEnv]) -> list[list[int]]:
    """The indices of ``robots`` grouped by the world each is in (in order of appearance)."""
    groups: dict[int, list[int]] = {}
    for j, e in enumerate(robots):
        groups.setdefault(id(e.world), []).append(j)
    return list(groups.values())


def _seeds(seed: int | list[int | None] | None, n: int) -> list[int | None]:
    if seed is None:
        return [None] * n
    if isinstance(seed, int | np.integer) and not isinstance(seed, bool):
        return [int(seed) + i for i in range(n)]
    seeds = list(seed)
    if len(seeds) != n:
        raise ValueError(f"seed: expected an int or {n} seeds, got {len(seeds)}")
    return seeds

