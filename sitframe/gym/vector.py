"""N robots stepped together: a :class:`gymnasium.vector.VectorEnv`.

Robot ``i`` behaves exactly as a :class:`sitframe.gym.env.SitframeEnv`
seeded ``seed + i`` (as :class:`gymnasium.vector.SyncVectorEnv` seeds its
copies): same start poses, goals, readings and rewards for the same actions
(tested, bit for bit, collisions included). What is shared is the numpy work
of :func:`sitframe.robot.step_robot`, re-arranged for N robots with the same
element-wise arithmetic (its private helpers are reused):

- the "can this robot reach any wall during the period?" test is one (N, S)
  call; robots in open space move by the closed form;
- the substep collision checks of the others are one (M, K, substeps) call,
  each robot against only the segments it can reach;
- the contact refinement and the back-off of the robots that touched a wall
  are batched too; the rare cases it leaves out (a start inside a wall, a
  dead-ahead contact whose turn side is drawn from the generator) run
  ``step_robot`` itself;
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
from sitframe.robot import (
    _BACKOFF_SAMPLES,
    _REFINE,
    Command,
    RobotParams,
    StepOutcome,
    _plan,
    _pose_at,
    _times,
    _wrap,
    step_robot,
)

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
        self._action_plans: np.ndarray | None = None
        self._ctx: list[Any] = [None] * num_envs  # each robot's last context
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
        self._ctx = [None] * self.num_envs
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
            self._ctx[i] = None
        if live.size:
            cmds = [task.command(acts[i], self.continuous) for i in live]
            befores = [self._ctx[i] or task.context(envs[i].t, envs[i].pose, envs[i]._reading,
                                                    envs[i].goal) for i in live]
            outs = self._move(live, cmds, acts)
            readings = self._read(live)
            nearest = readings.min(axis=1).tolist()
            for j, i in enumerate(live):
                env, out = envs[i], outs[j]
                env.t += 1
                self._ctx[i] = after = task.context(env.t, env.pose, env._reading, env.goal,
                                                    nearest[j])
                rew[i] = float(env.reward_fn(Transition(befores[j], cmds[j], out, after)))
                term[i] = task.terminated(after, out.collided)
                trunc[i] = not term[i] and env.t >= task.max_steps
                collided[i] = out.collided
            obs[live] = task.observe_many(readings, np.stack([envs[i].pose for i in live]),
                                          [envs[i].goal for i in live])
        self._done = term | trunc
        return obs, rew, term, trunc, self._infos(collided)

    def _plans(self, live: np.ndarray, acts: np.ndarray) -> np.ndarray:
        """``step_robot``'s plans (x0, y0, th0, v, omega, t_turn) of discrete actions (M, 6)."""
        if self._action_plans is None:  # v, omega, t_turn of each action, by _plan itself
            rp = self.task.res.robot
            self._action_plans = np.array([_plan(np.zeros(3), self.task.command(a, False), rp)
                                           for a in range(self.task.n_actions)])[:, 3:]
        poses = np.stack([self.envs[i].pose for i in live])
        if not np.isfinite(poses).all():
            raise ValueError("a robot's pose is not finite")
        return np.concatenate([poses, self._action_plans[acts[live].astype(int)]], axis=1)

    def _move(self, live: np.ndarray, cmds: list[Command],
              acts: np.ndarray) -> list[StepOutcome]:
        """Step robots ``live`` as :func:`sitframe.robot.step_robot` would, batched.

        One (N, S) test finds the robots that can reach a wall during the period
        (``step_robot``'s first step); robots in open space move by its closed
        form; the others' substeps are checked against their reachable segments
        in one (M, K, substeps) call, and the contacts of those that touch a wall
        are refined and recovered from in one more (:func:`_contacts`). A robot
        that call does not cover goes through ``step_robot`` itself.
        """
        envs, rp = self.envs, self.task.res.robot
        T = rp.control_period_s
        plans = np.array([_plan(envs[i].pose, c, rp) for i, c in zip(live, cmds, strict=True)]) \
            if self.continuous else self._plans(live, acts)
        x0, y0, th0, v, omega, t_turn = plans.T
        outs: list[StepOutcome | None] = [None] * live.size
        near = np.zeros((live.size, 0), dtype=bool)
        if self._seg is not None:
            reach = v * T + rp.radius + rp.recovery_backoff_m + 1e-9
            near = _dist2(x0, y0, self._seg) < (reach * reach)[:, None]
        busy = near.any(axis=1)
        for j in np.flatnonzero(~busy):  # open space: step_robot's own closed form
            x, y, th = _pose_at(T, *plans[j])
            final = np.array([x, y, _wrap(th)])
            outs[j] = StepOutcome(envs[live[j]].pose, final, False, _NAN2, final,
                                  float(v[j]) * T, math.degrees(th - float(th0[j])))
        b = np.flatnonzero(busy)
        if b.size:
            times = _times(T, rp.substep_s)[None, :]
            xs, ys, ths = _poses_many(times, plans[b])
            idx = _padded(near[b])
            ax, ay, ex, ey, inv = (a[idx][:, :, None] for a in self._seg)  # (M, K, 1)
            d2 = _dist2_kernel(xs[:, None, :], ys[:, None, :], ax, ay, ex, ey, inv)
            bad = (d2 < rp.radius * rp.radius).any(axis=1)  # (M, substeps)
            hit = bad.any(axis=1)
            for m, j in enumerate(b):
                if not hit[m]:
                    env = envs[live[j]]
                    final = np.array([xs[m, -1], ys[m, -1], _wrap(float(ths[m, -1]))])
                    outs[j] = StepOutcome(env.pose, final, False, _NAN2, final, float(v[j]) * T,
                                          math.degrees(float(ths[m, -1]) - float(th0[j])))
            if hit.any():
                h = np.flatnonzero(hit)
                got = _contacts(plans[b[h]], times[0], xs[h], ys[h], ths[h], bad[h],
                                (ax[h], ay[h], ex[h], ey[h], inv[h]), rp,
                                [envs[live[j]].pose for j in b[h]])
                for m, j in enumerate(b[h]):
                    env = envs[live[j]]
                    outs[j] = got[m] or step_robot(env.world, env.pose, cmds[j], rp,
                                                   env.np_random)
        for j, i in enumerate(live):
            envs[i].pose = outs[j].pose
        return outs  # type: ignore[return-value]

    def _read(self, live: np.ndarray) -> np.ndarray:
        """Read the sensors of robots ``live`` (batched if the sensor can); (M, d)."""
        envs = self.envs
        if self._many is not None:
            readings = self._many(self.task.world, np.stack([envs[i].pose for i in live]),
                                  [envs[i].np_random for i in live])
        else:
            readings = np.stack([envs[i].sensor.read(envs[i].world, envs[i].pose,
                                                     envs[i].np_random) for i in live])
        for j, i in enumerate(live):
            envs[i]._reading = readings[j]
        return readings

    def _infos(self, collided: np.ndarray) -> dict[str, Any]:
        mask = np.ones(self.num_envs, dtype=bool)
        return {"pose": np.stack([e.pose for e in self.envs]), "_pose": mask,
                "collided": collided, "_collided": mask}


def _contacts(plans: np.ndarray, times: np.ndarray, xs: np.ndarray, ys: np.ndarray,
              ths: np.ndarray, bad: np.ndarray, seg: tuple[np.ndarray, ...], rp: RobotParams,
              before: list[np.ndarray]) -> list[StepOutcome | None]:
    """Steps 3-4 of :func:`sitframe.robot.step_robot` (contact refinement, recovery) for C robots
    whose substeps touch a wall, batched; the arithmetic is ``step_robot``'s, element by element.

    ``seg``: each robot's reachable segments, (C, K, 1) arrays. Returns ``None`` for a robot
    this does not cover (it started inside a wall, the refinement's impossible case, a
    dead-ahead contact whose turn side is drawn from the rng, or no recovery): the caller
    runs ``step_robot`` for it, which has then drawn nothing from the robot's generator yet.
    """
    c = plans.shape[0]
    rows = np.arange(c)
    r2 = rp.radius * rp.radius
    k = bad.argmax(axis=1)
    ok = (k > 0) & (rp.recovery == "backoff-turn")
    j = np.maximum(k - 1, 0)
    t_c, cx, cy, cth = times[j], xs[rows, j], ys[rows, j], ths[rows, j]
    hi = times[k]
    for _ in range(2):
        ts = np.linspace(t_c, hi, _REFINE + 1, axis=1)  # (C, 17)
        fx, fy, fth = _poses_many(ts, plans)
        fbad = (_dist2_kernel(fx[:, None, :], fy[:, None, :], *seg) < r2).any(axis=1)
        fbad[:, -1] = True
        jj = fbad.argmax(axis=1)
        ok &= jj > 0
        hi = ts[rows, jj]
        jj = np.maximum(jj - 1, 0)
        t_c, cx, cy, cth = ts[rows, jj], fx[rows, jj], fy[rows, jj], fth[rows, jj]
    ax, ay, ex, ey, inv = (a[:, :, 0] for a in seg)  # the contact's nearest segment point
    wx, wy = cx[:, None] - ax, cy[:, None] - ay
    t = np.clip((wx * ex + wy * ey) * inv, 0.0, 1.0)
    dx, dy = wx - t * ex, wy - t * ey
    i = np.argmin(dx * dx + dy * dy, axis=1)
    tt = t[rows, i]
    px, py = ax[rows, i] + tt * ex[rows, i], ay[rows, i] + tt * ey[rows, i]
    # back-off samples along the contact normal, all robots at once
    nx, ny = cx - px, cy - py
    norm = np.hypot(nx, ny)
    ok &= norm > 0.0
    nx, ny = nx / np.where(ok, norm, 1.0), ny / np.where(ok, norm, 1.0)
    sb = np.linspace(0.0, rp.recovery_backoff_m, _BACKOFF_SAMPLES)[None, :]
    bx, by = cx[:, None] + sb * nx[:, None], cy[:, None] + sb * ny[:, None]
    d2b = _dist2_kernel(bx[:, None, :], by[:, None, :], *seg).min(axis=1)
    free = np.logical_and.accumulate(d2b >= r2, axis=1)
    mb = np.count_nonzero(free, axis=1) - 1
    out: list[StepOutcome | None] = [None] * c
    for q in np.flatnonzero(ok):
        x0c, y0c, thc = float(cx[q]), float(cy[q]), float(cth[q])
        cpose = np.array([x0c, y0c, _wrap(thc)])
        contact = np.array([px[q], py[q]])
        backoff = 0.0
        if rp.recovery_backoff_m > 0.0 and mb[q] > 0:
            backoff = float(sb[0, mb[q]])
            x0c, y0c = float(bx[q, mb[q]]), float(by[q, mb[q]])
        bearing = _wrap(math.atan2(float(contact[1]) - y0c, float(contact[0]) - x0c) - thc)
        if bearing == 0.0:
            continue  # the turn side is the rng's: step_robot draws it
        turn = min(math.radians(rp.recovery_turn_deg), math.pi - abs(bearing))
        if bearing > 0.0:
            turn = -turn
        out[q] = StepOutcome(before[q], np.array([x0c, y0c, _wrap(thc + turn)]), True, contact,
                             cpose, float(plans[q, 3]) * float(t_c[q]),
                             math.degrees(thc - float(plans[q, 2])), backoff,
                             math.degrees(turn))
    return out


def _dist2_kernel(px: np.ndarray, py: np.ndarray, ax: np.ndarray, ay: np.ndarray,
                  ex: np.ndarray, ey: np.ndarray, inv: np.ndarray) -> np.ndarray:
    """Squared point-segment distances, broadcast (the arithmetic of ``step_robot``'s tests)."""
    wx = px - ax
    wy = py - ay
    t = (wx * ex + wy * ey) * inv
    np.clip(t, 0.0, 1.0, out=t)
    dx = wx - t * ex
    dy = wy - t * ey
    return dx * dx + dy * dy


def _dist2(x: np.ndarray, y: np.ndarray, seg: tuple[np.ndarray, ...]) -> np.ndarray:
    """(N, S) squared distances from N points to every segment."""
    return _dist2_kernel(x[:, None], y[:, None], *seg)


def _padded(mask: np.ndarray) -> np.ndarray:
    """(M, K) indices of each row's true columns, padded with repeats of its first one."""
    k = max(int(mask.sum(axis=1).max()), 1)
    order = np.argsort(~mask, axis=1, kind="stable")[:, :k]
    return np.where(np.arange(k) < mask.sum(axis=1)[:, None], order, order[:, :1])


def _poses_many(t: np.ndarray, plans: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`sitframe.robot.trajectory`'s closed form for M plans at times ``t`` (1, T).

    The same element-wise arithmetic as ``step_robot``'s (the cosine of the final
    heading is taken per robot with :func:`math.cos`, as there).
    """
    x0, y0, th0, v, omega, t_turn = (c[:, None] for c in plans.T)
    tt = np.minimum(t, t_turn)
    half = (0.5 * omega) * tt
    chord = (v * tt) * np.sinc(half * (1.0 / math.pi))
    ang = th0 + half
    th_end = [float(a + w * b) for a, w, b in zip(th0[:, 0], omega[:, 0], t_turn[:, 0],
                                                   strict=True)]
    ce = np.array([math.cos(a) for a in th_end])[:, None]
    se = np.array([math.sin(a) for a in th_end])[:, None]
    ts = v * (t - tt)
    return x0 + chord * np.cos(ang) + ts * ce, y0 + chord * np.sin(ang) + ts * se, th0 + omega * tt


def _seeds(seed: int | list[int | None] | None, n: int) -> list[int | None]:
    if seed is None:
        return [None] * n
    if isinstance(seed, int | np.integer) and not isinstance(seed, bool):
        return [int(seed) + i for i in range(n)]
    seeds = list(seed)
    if len(seeds) != n:
        raise ValueError(f"seed: expected an int or {n} seeds, got {len(seeds)}")
    return seeds

