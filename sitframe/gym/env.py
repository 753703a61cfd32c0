"""One robot as a Gymnasium environment (:class:`SitframeEnv`).

Observation
    ``Box(float32)`` of shape (d,) — the sensor's reading, d = its beams (8 for the
    Pioneer sonar), ranges from the robot's rim in [0, max_range] metres, or in
    [0, 1] divided by ``max_range`` when ``normalize=True`` (default). A goal
    task appends the goal's distance (metres, in [0, world diagonal]; divided
    by the diagonal when normalised) and bearing (radians in [-pi, pi], positive
    = left; divided by pi when normalised): shape (d + 2,).
Action
    ``Discrete(H * V)``: action ``a`` is heading ``headings[a // V]`` [deg] at
    speed ``speeds[a % V]`` [m/s] (V = 1 at the config's default speed when it
    learns no speed); or, with ``continuous=True``, ``Box([-1, 1]^k)``: heading
    change ``a[0] * 90`` deg and, if the config learns speeds, speed ``a[1]``
    mapped onto [min_speed, max_speed].
Step
    One control iteration (1.5 s of robot time) through the simulator and
    sensor code paths of a sitframe trial (:func:`sitframe.sim.robot.step_robot`,
    the sensor plugin's ``read``), rewarded by the config's reward plugin.
Episode
    See :mod:`sitframe.gym.task` (worlds, start poses, goals, time limit,
    termination). All randomness (the episode's world when the env has several,
    start poses, goals, sensor noise, the simulator's tie-breaks) flows from the
    env's seeded generator ``np_random``: ``reset(seed=s)`` gives the same
    episode for the same actions.
Several worlds
    ``make_env(config, worlds=["gen:1000000", "gen:1000001", ...])`` trains over
    a family of rooms: each ``reset`` draws the episode's world uniformly from
    ``np_random`` (then its start pose, as with one world);
    ``reset(options={"world": name})`` picks one; ``info["world"]`` names it.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from sitframe.contract.records import Context, Transition
from sitframe.gym.task import _NO_U, Task
from sitframe.sim.kernels import contact, kernels
from sitframe.sim.robot import StepOutcome, _times, outcome_from, packed_params, step_robot
from sitframe.sim.world import Goal

__all__ = ["CompiledStep", "SitframeEnv", "render_frame"]


class SitframeEnv(gym.Env):
    """A sitframe config as a Gymnasium environment (module docstring for the spaces).

    Parameters
    ----------
    config
        Preset name, TOML config path, or a validated config dict.
    continuous
        Continuous ``Box`` actions instead of ``Discrete``.
    render_mode
        ``None`` or ``"rgb_array"`` (an (H, W, 3) uint8 frame of the world, the
        robot, its sensor beams and the goal).
    **task
        Passed to :meth:`sitframe.gym.task.Task.from_config`: ``world`` or
        ``worlds``, ``reward``, ``reward_params``, ``max_steps``, ``normalize``,
        ``start_margin``, ``terminate_on_collision``, ``plugins_dirs``.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 4}

    def __init__(self, config: str | dict[str, Any] = "obstacle-avoidance", *,
                 continuous: bool = False, render_mode: str | None = None,
                 task: Task | None = None, **task_kw: Any) -> None:
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode: expected None or 'rgb_array', got {render_mode!r}")
        self.task = task if task is not None else Task.from_config(config, **task_kw)
        self.continuous = bool(continuous)
        self.render_mode = render_mode
        lo, hi = self.task.observation_bounds()
        self.observation_space = gym.spaces.Box(lo, hi, dtype=np.float32)
        if self.continuous:
            k = 2 if self.task.learns_speed else 1
            self.action_space = gym.spaces.Box(-1.0, 1.0, (k,), dtype=np.float32)
        else:
            self.action_space = gym.spaces.Discrete(self.task.n_actions)
        self.sensor = self.task.make_sensor()
        self.reward_fn = self.task.make_reward()
        self.world = self.task.world
        self.pose = self.world.start.copy()
        self.goal = None
        self.t = 0
        self._reading: np.ndarray | None = None
        self._ctx: Any = None  # the last step's context: the next step's ``before``
        self._compiled: CompiledStep | None | bool = False  # (False: not decided yet)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None
              ) -> tuple[np.ndarray, dict[str, Any]]:
        """Start an episode at a random free pose (and goal) drawn from ``np_random``.

        With several worlds the episode's world is drawn first (or named by
        ``options={"world": name}``). ``options`` may give ``{"pose": (x, y, theta)}``
        (and ``"goal": (x, y, radius)``) to start from a chosen pose instead.
        """
        super().reset(seed=seed)
        rng = self.np_random
        self.world = self.task.pick_world(rng, (options or {}).get("world"))
        self.pose, self.goal = self.task.draw_start(rng, self.world)
        if options:
            self.pose, self.goal = _chosen_start(self.task, self.world, options, self.pose,
                                                 self.goal)
        self.t = 0
        if hasattr(self.reward_fn, "trial_start"):
            self.reward_fn.trial_start(self.task.trial_info(rng, self.world))
        self._reading = self.sensor.read(self.world, self.pose, rng)
        self._ctx = None
        return self.task.observe(self._reading, self.pose, self.goal), self._info(None)

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        if self._reading is None:
            raise RuntimeError("call reset() before step()")
        task, rng = self.task, self._np_random  # (reset() made it)
        cmd = task.command(action, self.continuous)
        before = self._ctx or task.context(self.t, self.pose, self._reading, self.goal,
                                           world=self.world)
        fast = self.compiled_step()
        got = None if fast is None else fast.step(self.world, self.pose, cmd)
        if got is not None:
            out, self._reading, obs, nearest = got
            self.pose = out.pose
        else:
            out = step_robot(self.world, self.pose, cmd, task.res.robot, rng)
            self.pose = out.pose
            self._reading = self.sensor.read(self.world, self.pose, rng)
            obs, nearest = task.observe_nearest(self._reading, self.pose, self.goal)
        self.t += 1
        # (Task.context, without its defaults' look-ups: this runs every step)
        after = self._ctx = Context(self.t, self.pose, self._reading, _NO_U, nearest, self.world,
                                    self.goal)
        reward = float(self.reward_fn(Transition(before, cmd, out, after)))
        terminated = task.terminated(after, out.collided)
        truncated = not terminated and self.t >= task.max_steps
        return obs, reward, terminated, truncated, self._info(out)

    def compiled_step(self) -> CompiledStep | None:
        """This env's step as one compiled call (:class:`CompiledStep`), or ``None`` (the
        Python step); decided for good once the kernels are loaded."""
        return self._compiled if self._compiled is not False else self._compile()

    def _compile(self) -> CompiledStep | None:
        """The compiled step of this env (:class:`CompiledStep`), once the kernels are loaded
        (decided then, for good), or ``None``."""
        if kernels() is None:
            return None  # (a process's first steps: numpy's path; asked again later)
        self._compiled = CompiledStep.create(self.task, self.sensor)
        return self._compiled

    def _info(self, out: Any) -> dict[str, Any]:
        if out is None:
            return {"pose": self.pose.copy(), "collided": False, "distance_m": 0.0,
                    "world": self.world.name}
        return {"pose": self.pose.copy(), "collided": bool(out.collided),
                "distance_m": float(out.distance_m), "world": self.world.name}

    def render(self) -> np.ndarray | None:
        if self.render_mode != "rgb_array":
            return None
        return render_frame(self.world, self.pose, self._reading, self.sensor, self.goal,
                            self.task.res.robot.radius)


class CompiledStep:
    """A Gym step in one compiled call (:func:`sitframe.sim.kernels_numba.env_step`): the
    robot's step, contact included, the range finder's read and the observation, bit for
    bit what ``step_robot``, the sensor's ``read`` and :meth:`Task.observe_nearest` give.

    Made (:meth:`create`) for a sensor that answers ``_fused()`` (the built-in range finders
    without noise or dropout), a task without goals (its observation is the reading alone)
    and where the whole step compiled agrees with Python's (:func:`sitframe.sim.kernels.
    contact`); the env steps through Python otherwise.
    """

    def __init__(self, k: Any, task: Task, spec: dict[str, Any]) -> None:
        rp = self.params = task.res.robot
        self.k, self.rp = k, packed_params(rp)
        self.times = _times(rp.control_period_s, rp.substep_s)
        self.rays = np.array(spec["rays"], dtype=np.float64)
        self.sensor = (float(spec["max_range"]), float(spec["radius"]),
                       int(spec["rays_per_beam"]))
        self.scale = float(task.max_range if task.normalize else 1.0)
        self.lo, self.hi = (np.array(b) for b in task.observation_bounds())
        self.d = self.rays.size // self.sensor[2]

    @classmethod
    def create(cls, task: Task, sensor: Any) -> CompiledStep | None:
        """The compiled step of ``task`` with ``sensor``, or ``None`` (class docstring)."""
        k = contact()
        f = getattr(sensor, "_fused", None)
        spec = f() if callable(f) else None
        if k is None or spec is None or task.protocol is not None:
            return None
        return cls(k, task, spec)

    def steps(self, world: Any, poses: np.ndarray, headings: np.ndarray, speeds: np.ndarray,
              reward: np.ndarray) -> tuple[np.ndarray, ...]:
        """N robots' steps in ``world`` in one call (the vector env's):
        :func:`~sitframe.sim.kernels_numba.env_steps`' ``codes`` (N,), ``out`` (N, 15),
        ``readings`` (N, d), ``obs`` (N, d) and ``rewards`` (N,) (``reward``: the
        ``obstacle-avoidance`` reward's collision, base and heading cost)."""
        n = poses.shape[0]
        codes, out, rewards = np.empty(n, np.int64), np.empty((n, 15)), np.empty(n)
        readings = np.empty((n, self.d))
        obs = np.empty((n, *self.lo.shape), dtype=np.float32)
        max_range, radius, group = self.sensor
        self.k.env_steps(poses, headings, speeds, self.rp, self.times, world.segment_set.packed,
                         True, True, self.rays, max_range, radius, group, self.scale, self.lo,
                         self.hi, reward, out, readings, obs, codes, rewards)
        return codes, out, readings, obs, rewards

    def step(self, world: Any, pose: np.ndarray, cmd: Any
             ) -> tuple[StepOutcome, np.ndarray, np.ndarray, float] | None:
        """The outcome of ``cmd`` from ``pose``, the reading there, its observation and its
        nearest range; ``None`` for a dead-ahead contact (its turn is a draw from the robot's
        generator: ``step_robot`` steps it)."""
        out, reading = np.empty(15), np.empty(self.d)
        obs = np.empty(self.lo.shape, dtype=np.float32)
        max_range, radius, group = self.sensor
        code = self.k.env_step(float(pose[0]), float(pose[1]), float(pose[2]),
                               float(cmd.heading_change_deg), float(cmd.speed_m_s), self.rp,
                               self.times, world.segment_set.packed, True, True, self.rays,
                               max_range, radius, group, self.scale, self.lo, self.hi, out,
                               reading, obs)
        if code == self.k.TIE:
            return None
        return outcome_from(pose, out, code != self.k.FREE, self.params), reading, obs, \
            float(out[14])


def _chosen_start(task: Task, world: Any, options: dict[str, Any], pose: np.ndarray,
                  goal: Any) -> tuple[np.ndarray, Any]:
    if "pose" in options:
        p = np.asarray(options["pose"], dtype=float).reshape(-1)
        if p.shape != (3,) or not world.is_free(p[None, :2], task.res.robot.radius)[0]:
            raise ValueError(f"options['pose']: expected a free (x, y, theta) pose in world "
                             f"'{world.name}', got {options['pose']!r}")
        pose = p
    if "goal" in options:
        g = np.asarray(options["goal"], dtype=float).reshape(-1)
        if g.shape != (3,) or task.protocol is None:
            raise ValueError("options['goal']: expected (x, y, radius) in a goal task")
        goal = Goal(g[:2], float(g[2]))
    return pose, goal


def render_frame(world: Any, pose: np.ndarray, reading: np.ndarray | None, sensor: Any,
                 goal: Any, radius: float, dpi: int = 60) -> np.ndarray:
    """An (H, W, 3) uint8 picture of ``world``: the robot at ``pose``, its beams, the goal."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.patches import Circle

    from sitframe.sim.draw import plot_world  # matplotlib: only when rendering

    fig = plot_world(world, show_trajectories=False, show_start=False, show_goal=False,
                     robot_radius=radius)
    ax = fig.axes[0]
    x, y, th = (float(v) for v in pose)
    ax.add_patch(Circle((x, y), radius, facecolor="tab:blue", edgecolor="k", zorder=5))
    ax.plot([x, x + radius * np.cos(th)], [y, y + radius * np.sin(th)], "k-", zorder=6)
    if reading is not None and hasattr(sensor, "angles_deg"):
        ang = th + np.radians(np.asarray(sensor.angles_deg, float))
        rr = radius + np.asarray(reading, float)
        for a, r in zip(ang, rr, strict=False):
            ax.plot([x, x + r * np.cos(a)], [y, y + r * np.sin(a)], "-", color="tab:orange",
                    lw=0.8, zorder=4)
    if goal is not None:
        ax.add_patch(Circle(tuple(goal.position), goal.radius, facecolor="none",
                            edgecolor="tab:green", lw=1.5, zorder=5))
        ax.plot(*goal.position, "*", color="tab:green", ms=12, zorder=6)
    canvas = FigureCanvasAgg(fig)
    fig.set_dpi(dpi)
    canvas.draw()
    return np.asarray(canvas.buffer_rgba())[..., :3].copy()
