"""Duel v2: fuzzy Q-learning over situations against Stable-Baselines3 DQN and PPO, in rooms
no method, tuning or selection ever touched.

Question: trained in the same ten generated rooms, with the same robot, sonar and reward,
how do fuzzy Q-learning over situations (the shipped ``obstacle-avoidance`` preset) and
deep RL (SB3 DQN and PPO, tuned by one rule on training and validation rooms only) compare
in unseen rooms -- collisions per 1000 iterations and coverage -- per environment step
counted (collection, every trial, every validation episode) and per collision while
learning?

Output: ``OUT/`` holds every job (SB3 checkpoints every few thousand steps, the fuzzy-q
logs, each job's step accounting and scores as JSON); ``report`` publishes
``docs/results/tables/duel.md`` (the duel and its targets) and ``duel-tuning.md`` (the
grid ranked by the selection rule) through ``benchmarks/common/publish.py`` and draws
``docs/results/figures/duel-curves.png`` (unseen-room collisions/1000, coverage and
collisions while learning against counted steps, median and IQR over seeds).

Rooms (generator seeds, ``gen:SEED``; fixed with the preset's author)
---------------------------------------------------------------------
- training: ``gen:1000000`` ... ``gen:1000009`` (every method learns in exactly these),
- validation: ``gen:2000000`` ... ``gen:2000004`` (checkpoint selection and tuning only),
- test: ``novel-1``, ``novel-2`` and ``gen:3000000`` ... ``gen:3000019``, touched by
  nothing but the final scoring (:func:`check_rooms` refuses any overlap).

Protocol
--------
Every environment step a method takes is counted by :class:`Counted` (a Gymnasium
wrapper around every env it steps): SB3's training steps and the validation runs of
every checkpoint; fuzzy-q's steps are read from its log (collected sonar samples, every
learning iteration, its evaluate stage outside the test rooms). A frozen policy is scored
by :func:`drive`: ``starts`` robots per room from fixed start poses (the room's own start
pose, then poses drawn from a seed fixed per room: the same for every method), pooled
collisions per 1000 iterations and mean coverage. Validation: 5 rooms x 2 starts x 500
iterations per checkpoint (counted); test: 22 rooms x 3 starts x 1000 iterations
(the judge's, not counted).

**Selection rule** (:func:`merit`, the same for checkpoints, DQN and PPO): a policy is
*safe* on the validation rooms when it collides at most 3 times per 1000 iterations (the
issue's bar); the best checkpoint is the safe one with the highest coverage, else the
one with the fewest collisions. The grid (:data:`GRID`, one change at a time from v1's
selected sets, adding two knobs per algorithm) is screened on 2 seeds over the first half
of the budget (the same schedules, stopped at half); a set ranks by the share of seeds
whose best checkpoint is safe, then its median coverage, then its median collisions. The
selected set of each algorithm then runs 10 seeds at the full budget (DQN 100k, PPO 200k
steps) and is scored at each seed's best checkpoint. fuzzy-q is ``sitframe run
obstacle-avoidance --trials 1 --seed S`` (the preset as shipped, no tuning here), scored
as ``sitframe evaluate`` scores trial 0's frozen policy (its rule base over its logged
situations), from the same start poses.

Run (extra ``baselines``; one core, one process, torch on one thread)::

    taskset -c 1 nice -n 5 python benchmarks/duel/duel.py run --out duel2 --phase screen
    taskset -c 1 nice -n 5 python benchmarks/duel/duel.py score --out duel2 --phase screen
    taskset -c 1 nice -n 5 python benchmarks/duel/duel.py run --out duel2 --phase final \\
        --configs fuzzy-q selected --seeds 10
    taskset -c 1 nice -n 5 python benchmarks/duel/duel.py score --out duel2 --phase final
    python benchmarks/duel/duel.py report --out duel2

A rerun skips finished jobs (training and scoring apart). CPU per job on one core: DQN
100k steps about 70 s, PPO 200k about 95 s, fuzzy-q 2-4 s (its whole ``sitframe run``);
scoring a deep-RL job (11 checkpoints, validation and test rooms) about 50 s, a fuzzy-q
job about 3 s; the screening about 13 minutes (20 jobs at half budget) and 1 of scoring.
"""

from __future__ import annotations

import argparse
import io
import json
import os
import sys
import time
import zlib
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager, redirect_stdout
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

PRESET = "obstacle-avoidance"
ROOT = Path(__file__).resolve().parents[2]
FIGURE = ROOT / "docs" / "results" / "figures" / "duel-curves.png"


def _gen(first: int, n: int) -> tuple[str, ...]:
    return tuple(f"gen:{s}" for s in range(first, first + n))


#: Room sets: training, validation, test. ``shipped`` (shipped worlds only) is for the
#: tests and for trying the harness; the duel is ``gen``.
ROOMS: dict[str, dict[str, tuple[str, ...]]] = {
    "gen": {"train": _gen(1_000_000, 10), "valid": _gen(2_000_000, 5),
            "test": ("novel-1", "novel-2", *_gen(3_000_000, 20))},
    "shipped": {"train": ("training",), "valid": ("u-trap",), "test": ("novel-1", "novel-2")},
}


@dataclass(frozen=True)
class EvalSpec:
    """Where and how long a frozen policy is driven: ``starts`` robots per room, fixed start
    poses from ``seed``, ``iterations`` each."""

    starts: int
    iterations: int
    seed: int


VALID = EvalSpec(starts=2, iterations=500, seed=2024)
TEST = EvalSpec(starts=3, iterations=1000, seed=12345)
SAFE = 3.0  # collisions per 1000 iterations: the issue's bar for a safe policy

_DQN = {"learning_rate": 1e-3, "gamma": 0.9, "learning_starts": 1000,
        "target_update_interval": 1000, "exploration_fraction": 0.2,
        "exploration_final_eps": 0.05}
_PPO = {"n_envs": 8, "n_steps": 256, "gamma": 0.9, "learning_rate": 1e-3}
DQN_CHECKPOINTS = (5_000, *range(10_000, 100_001, 10_000))
PPO_CHECKPOINTS = (10_000, *range(20_000, 200_001, 20_000))

#: One set of the grid: algorithm, SB3 keyword arguments (plus ``n_envs``), checkpoints (the
#: last is the full budget), and what it changes from its algorithm's base.
Config = tuple[str, dict[str, Any], tuple[int, ...], str]

#: The grid: v1's selected sets (``dqn-base``, ``ppo-base`` = v1's ``ppo-lr1e-3``), v1's two
#: knobs (learning rate, gamma) and two new knobs per algorithm (DQN: the exploration
#: schedule and the replay buffer; PPO: the entropy bonus and the rollout length), one
#: change at a time.
GRID: dict[str, Config] = {
    "dqn-base": ("dqn", _DQN, DQN_CHECKPOINTS, "v1's selected set"),
    "dqn-lr3e-3": ("dqn", {**_DQN, "learning_rate": 3e-3}, DQN_CHECKPOINTS, "learning rate 3e-3"),
    "dqn-g0.99": ("dqn", {**_DQN, "gamma": 0.99}, DQN_CHECKPOINTS, "gamma 0.99"),
    "dqn-eps0.05": ("dqn", {**_DQN, "exploration_fraction": 0.05}, DQN_CHECKPOINTS,
                    "exploration decays over 5 % of the budget (new)"),
    "dqn-buf20k": ("dqn", {**_DQN, "buffer_size": 20_000}, DQN_CHECKPOINTS,
                   "replay buffer 20k instead of 1M (new)"),
    "ppo-base": ("ppo", _PPO, PPO_CHECKPOINTS, "v1's selected set (ppo-lr1e-3)"),
    "ppo-lr3e-4": ("ppo", {**_PPO, "learning_rate": 3e-4}, PPO_CHECKPOINTS,
                   "learning rate 3e-4"),
    "ppo-g0.99": ("ppo", {**_PPO, "gamma": 0.99}, PPO_CHECKPOINTS, "gamma 0.99"),
    "ppo-ent0.01": ("ppo", {**_PPO, "ent_coef": 0.01}, PPO_CHECKPOINTS,
                    "entropy bonus 0.01 (new)"),
    "ppo-n128": ("ppo", {**_PPO, "n_steps": 128}, PPO_CHECKPOINTS,
                 "rollout 8 x 128 steps (new)"),
}
SCREEN_SEEDS = 2
SCREEN_FRACTION = 0.5  # screening stops each schedule at half its budget


def check_rooms(rooms: dict[str, tuple[str, ...]]) -> None:
    """Refuse room sets where training or validation rooms are test rooms."""
    touched = (set(rooms["train"]) | set(rooms["valid"])) & set(rooms["test"])
    if touched:
        raise SystemExit(f"test rooms used for training or validation: {sorted(touched)}")


# ----------------------------------------------------------------------------- step accounting

@dataclass
class Tally:
    """Environment steps and collisions counted by :class:`Counted` wrappers."""

    steps: int = 0
    collisions: int = 0


class Counted(gym.Wrapper):
    """Counts every ``step`` of the env it wraps (and the collisions) into a shared
    :class:`Tally`: the duel's step accounting."""

    def __init__(self, env: gym.Env, tally: Tally) -> None:
        super().__init__(env)
        self.tally = tally

    def step(self, action: Any) -> tuple[Any, Any, bool, bool, dict[str, Any]]:
        out = self.env.step(action)
        self.tally.steps += 1
        self.tally.collisions += bool(out[4].get("collided"))
        return out


# ----------------------------------------------------------------------------- frozen policies

@dataclass
class Frozen:
    """A frozen policy for :func:`drive`: ``act`` maps (N, d) observations to N actions of an
    env made with ``continuous`` and ``normalize``."""

    act: Callable[[np.ndarray], Any]
    continuous: bool
    normalize: bool


def start_poses(world: Any, n: int, seed: int, radius: float) -> list[np.ndarray]:
    """``n`` fixed start poses in ``world``: its own start, then free poses drawn from
    ``seed`` and the world's name (the same for every method)."""
    rng = np.random.default_rng([seed, zlib.crc32(world.name.encode())])
    return [np.asarray(world.start, float).copy(),
            *(world.random_free_pose(rng, radius, margin=0.1) for _ in range(n - 1))]


@dataclass
class _Robot:
    env: Any
    room: str
    path: list[np.ndarray] = field(default_factory=list)
    collisions: int = 0


def _robots(frozen: Frozen, rooms: Sequence[str], spec: EvalSpec, tally: Tally | None
            ) -> tuple[list[_Robot], list[np.ndarray]]:
    """One env per (room, start), reset at its fixed start pose; their first observations."""
    from sitframe.gym import SitframeEnv, Task

    robots, obs = [], []
    for room in rooms:
        task = Task.from_config(PRESET, world=room, max_steps=spec.iterations,
                                normalize=frozen.normalize)
        for k, pose in enumerate(start_poses(task.world, spec.starts, spec.seed,
                                             task.res.robot.radius)):
            env: Any = SitframeEnv(task=task, continuous=frozen.continuous)
            if tally is not None:
                env = Counted(env, tally)
            o, info = env.reset(seed=spec.seed + 1000 * k + zlib.crc32(room.encode()) % 1000,
                                options={"pose": pose})
            robots.append(_Robot(env, room, [info["pose"][:2]]))
            obs.append(o)
    return robots, obs


def drive(frozen: Frozen, rooms: Sequence[str], spec: EvalSpec, tally: Tally | None = None
          ) -> dict[str, Any]:
    """Drive ``frozen`` in ``rooms`` (``spec``): pooled collisions per 1000 iterations, mean
    coverage, and both per room. ``tally`` (if given) counts the steps."""
    from sitframe.sim.metrics import coverage

    robots, obs = _robots(frozen, rooms, spec, tally)
    for _ in range(spec.iterations):
        acts = frozen.act(np.stack(obs))
        for j, (r, a) in enumerate(zip(robots, acts, strict=True)):
            obs[j], _r, _te, _tr, info = r.env.step(a)
            r.collisions += info["collided"]
            r.path.append(info["pose"][:2])
    per_room: dict[str, dict[str, float]] = {}
    for r in robots:
        u = r.env.unwrapped
        cov = coverage(u.world, np.array(r.path), radius=u.task.res.robot.radius)
        d = per_room.setdefault(r.room, {"collisions": 0, "coverage": 0.0})
        d["collisions"] += r.collisions
        d["coverage"] += cov / spec.starts
    n = len(robots) * spec.iterations
    return {"collisions_per_1000": 1000.0 * sum(r.collisions for r in robots) / n,
            "coverage": float(np.mean([d["coverage"] for d in per_room.values()])),
            "rooms": per_room}


def sb3_frozen(path: Path) -> Frozen:
    """The SB3 model saved at ``path`` (``predict(deterministic=True)``) as a frozen policy."""
    model = _sb3_class(path.name.split("-")[0]).load(path, device="cpu")

    def act(obs: np.ndarray) -> np.ndarray:
        a, _ = model.predict(obs.astype(np.float32), deterministic=True)
        return np.asarray(a, dtype=int).tolist()

    return Frozen(act, continuous=False, normalize=True)


def fuzzy_scores(log_path: Path, rooms: Sequence[str], spec: EvalSpec, trial: int = 0,
                 keep: list[Any] | None = None) -> dict[str, Any]:
    """Trial ``trial``'s frozen policies from a fuzzy-q log, scored as :func:`drive` scores a
    deep-RL policy (same rooms, start poses, iterations) by the loop ``sitframe evaluate``
    runs (:func:`sitframe.runs.loop.simulate`, frozen, the log's situations and rule base).
    Start 0 of each room (its own start pose) gets ``sitframe evaluate``'s default seed, so
    that run *is* ``sitframe evaluate LOG --world ROOM --iterations N``. ``keep``, a list,
    receives every run's :class:`~sitframe.runs.loop.TrialResult` (room by room, start by
    start), for a closer look (``benchmarks/learning/stuck.py``)."""
    from sitframe.contract.config import DEFAULT_PROTOCOL, validate_config
    from sitframe.contract.pluginmanager import Registry, get_plugin_manager
    from sitframe.contract.resolve import Resolved
    from sitframe.logs.policies import logged_policy, plugins_of
    from sitframe.logs.reader import open_log
    from sitframe.runs.loop import STAGE_EVAL, TrialSpec, simulate, stage_seed

    path = str(log_path)
    log = open_log(path)
    log.check()
    tl = log.trial(trial)
    policies = {lb: p for lb in tl.behaviours if (p := logged_policy(tl, lb, path)) is not None}
    state = tl.situations_part("state") if tl.situations else log.interpreter_state()
    cfg = validate_config(log.config, file=path, pending=True)
    with plugins_of(log, path, ()):
        res = Resolved.build(cfg, Registry.collect(get_plugin_manager()), path)
        table = res.protocol_table(DEFAULT_PROTOCOL)
        cfg[table] = {**cfg[table], "iterations": spec.iterations}
        res = Resolved.build(cfg, Registry.collect(get_plugin_manager()), path,
                             worlds=tuple(rooms))
    per_room: dict[str, dict[str, float]] = {}
    for room in rooms:
        d = per_room[room] = {"collisions": 0, "coverage": 0.0}
        for k, pose in enumerate(start_poses(res.world(room), spec.starts, spec.seed,
                                             res.robot.radius)):
            seed = stage_seed(0 if k == 0 else spec.seed + k, STAGE_EVAL, trial)
            out = simulate(res, TrialSpec(index=trial, seed=seed, world=room,
                                          iterations=spec.iterations, learn=False,
                                          interpreter_state=state, policies=policies,
                                          protocol=None,
                                          space_states=log.space_states(),
                                          start=tuple(pose)))
            d["collisions"] += int(out.summary["collisions"])
            d["coverage"] += float(out.summary["coverage"]) / spec.starts
            if keep is not None:
                keep.append(out)
    n = len(rooms) * spec.starts * spec.iterations
    return {"collisions_per_1000": 1000.0 * sum(d["collisions"] for d in per_room.values()) / n,
            "coverage": float(np.mean([d["coverage"] for d in per_room.values()])),
            "rooms": per_room}


def _sb3_class(algo: str) -> Any:
    from stable_baselines3 import DQN, PPO

    return {"dqn": DQN, "ppo": PPO}[algo]


# ----------------------------------------------------------------------------- jobs

def job_dir(out: Path, phase: str, name: str, seed: int) -> Path:
    return out / phase / name / f"seed-{seed}"


def train_sb3(name: str, seed: int, d: Path, rooms: tuple[str, ...], stop: int | None = None,
              config: Config | None = None) -> dict[str, Any]:
    """Train grid set ``name`` with ``seed`` in ``rooms``, saving ``d/<algo>-<steps>.zip`` at its
    checkpoints (up to ``stop`` steps); ``d/train.json``: steps, collisions and CPU per
    checkpoint, counted by :class:`Counted`."""
    import torch
    from stable_baselines3.common.callbacks import BaseCallback
    from stable_baselines3.common.vec_env import DummyVecEnv

    from sitframe.gym import make_env

    torch.set_num_threads(1)
    algo, kw, checkpoints, _what = config or GRID[name]
    kw = dict(kw)
    n_envs = kw.pop("n_envs", 1)
    stop = stop or checkpoints[-1]
    tally = Tally()
    venv = DummyVecEnv([lambda: Counted(make_env(PRESET, worlds=list(rooms)), tally)
                        for _ in range(n_envs)])
    venv.seed(seed)  # sub-env i: seed + i, at the first reset
    model = _sb3_class(algo)("MlpPolicy", venv, seed=seed, device="cpu", verbose=0, **kw)
    rows: list[dict[str, Any]] = []
    d.mkdir(parents=True, exist_ok=True)
    todo = [c for c in checkpoints if c <= stop]

    class Saver(BaseCallback):
        def _on_training_start(self) -> None:
            self.t0, self.paused = time.process_time(), 0.0

        def _on_step(self) -> bool:
            if rows and rows[-1]["steps"] >= stop:
                return False
            if len(rows) < len(todo) and self.num_timesteps >= todo[len(rows)]:
                p0 = time.process_time()
                self.model.save(d / f"{algo}-{self.num_timesteps}.zip")
                rows.append({"steps": tally.steps, "sb3_steps": self.num_timesteps,
                             "learning_collisions": tally.collisions,
                             "cpu_s": p0 - self.t0 - self.paused,
                             "model": f"{algo}-{self.num_timesteps}.zip"})
                self.paused += time.process_time() - p0
            return len(rows) < len(todo)

    model.learn(total_timesteps=checkpoints[-1], callback=Saver())
    res = {"config": name, "method": algo, "seed": seed, "rooms": list(rooms),
           "checkpoints": rows, "budget": checkpoints[-1], "stopped_at": stop,
           "steps": tally.steps, "learning_collisions": tally.collisions}
    (d / "train.json").write_text(json.dumps(res, indent=1))
    return res


def fuzzy_steps(log_path: Path, test_rooms: Sequence[str]) -> dict[str, int]:
    """fuzzy-q's environment steps from its log: collected samples, the learning iterations
    of every trial, and its evaluate stage inside and outside the test rooms."""
    from sitframe.logs.reader import open_log

    log = open_log(str(log_path))
    collect = int(log.stage("collect")["samples"].shape[0]) if log.has("collect") else 0
    learn = evaluate = judged = 0
    collisions = 0
    for k in log.trial_indices():
        tl = log.trial(k)
        learn += int(np.asarray(tl.arrays["collision"]).size)
        collisions += int(np.asarray(tl.arrays["collision"]).sum())
        for key, v in tl.summary.items():
            if key.startswith("eval/") and key.endswith("/iterations"):
                world = key.split("/")[1]
                judged += int(v) if world in test_rooms else 0
                evaluate += 0 if world in test_rooms else int(v)
    return {"collect": collect, "learn": learn, "evaluate_outside_test": evaluate,
            "evaluate_in_test_not_counted": judged, "counted": collect + learn + evaluate,
            "learning_collisions": collisions}


@contextmanager
def simulator_tally() -> Iterator[dict[str, Tally]]:
    """Count what a ``sitframe run`` in this process executes: the collect stage's sensor
    readings (``collect_readings``) and robot moves (``collect_moves``, the wander's, with
    their collisions, which the log does not keep), and the loop's robot moves
    (``loop_moves``: learning iterations and evaluation runs, with collisions).

    The compiled trial (``sitframe.runs.fused``) moves the robot without calling
    ``step_robot`` for each move, so trials run the Python loop while counted
    (``SITFRAME_FUSED=0``; the same results)."""
    import sitframe.runs.collect as collect
    import sitframe.runs.experiment as experiment
    import sitframe.runs.loop as loop

    t = {"collect_readings": Tally(), "collect_moves": Tally(), "loop_moves": Tally()}

    def moves(tally: Tally, fn: Callable[..., Any]) -> Callable[..., Any]:
        def step(*args: Any, **kw: Any) -> Any:
            out = fn(*args, **kw)
            tally.steps += 1
            tally.collisions += bool(out.collided)
            return out
        return step

    class Reads:
        """The sensor, its ``read`` calls counted."""

        def __init__(self, sensor: Any) -> None:
            self._sensor = sensor

        def __getattr__(self, name: str) -> Any:
            return getattr(self._sensor, name)

        def read(self, *args: Any, **kw: Any) -> Any:
            t["collect_readings"].steps += 1
            return self._sensor.read(*args, **kw)

    def reads(fn: Callable[..., Any]) -> Callable[..., Any]:
        return lambda worlds, sensor, *args, **kw: fn(worlds, Reads(sensor), *args, **kw)

    patches = [(collect, "step_robot", moves(t["collect_moves"], collect.step_robot)),
               (loop, "step_robot", moves(t["loop_moves"], loop.step_robot)),
               (experiment, "collect_trajectories", reads(experiment.collect_trajectories)),
               (experiment, "collect_wander", reads(experiment.collect_wander))]
    saved = [(m, name, getattr(m, name)) for m, name, _f in patches]
    fused = os.environ.get("SITFRAME_FUSED")
    try:
        os.environ["SITFRAME_FUSED"] = "0"
        for m, name, f in patches:
            setattr(m, name, f)
        yield t
    finally:
        for m, name, f in saved:
            setattr(m, name, f)
        if fused is None:
            os.environ.pop("SITFRAME_FUSED", None)
        else:
            os.environ["SITFRAME_FUSED"] = fused


def run_fuzzy(seed: int, d: Path, rooms: dict[str, tuple[str, ...]], config: str = PRESET
              ) -> dict[str, Any]:
    """``sitframe run CONFIG --trials 1 --seed S --out d/run.h5`` (in this process, one
    trial runs serially), its steps read from the log (:func:`fuzzy_steps`) and the
    simulator's own count (:func:`simulator_tally`), its CPU time."""
    from sitframe.cli.app import main as sitframe_main

    d.mkdir(parents=True, exist_ok=True)
    log = d / "run.h5"
    log.unlink(missing_ok=True)
    c0 = time.process_time()
    with simulator_tally() as sim, redirect_stdout(io.StringIO()):
        rc = sitframe_main(["run", config, "--trials", "1", "--seed", str(seed),
                            "--out", str(log)])
    if rc != 0:
        raise SystemExit(f"sitframe run {config} --seed {seed} failed (exit {rc})")
    steps = fuzzy_steps(log, rooms["test"])
    res = {"config": "fuzzy-q", "method": "fuzzy-q", "seed": seed, "preset": config,
           "cpu_s": time.process_time() - c0, **steps,
           "simulator": {k: vars(v) for k, v in sim.items()},
           # collisions while learning: the trial's (logged) and the wander's (counted here)
           "learning_collisions": steps["learning_collisions"]
           + sim["collect_moves"].collisions}
    (d / "train.json").write_text(json.dumps(res, indent=1))
    return res


def score_sb3(d: Path, rooms: dict[str, tuple[str, ...]], test: bool,
              specs: tuple[EvalSpec, EvalSpec] = (VALID, TEST)) -> dict[str, Any]:
    """Validate every checkpoint of job ``d`` (counted), pick the best (:func:`merit`), and
    with ``test`` score every checkpoint in the test rooms (the learning curves); ``specs``:
    the validation's and the test's :class:`EvalSpec`."""
    train = json.loads((d / "train.json").read_text())
    rows, valid_steps = [], 0
    for ck in train["checkpoints"]:
        frozen = sb3_frozen(d / ck["model"])
        tally = Tally()
        v = drive(frozen, rooms["valid"], specs[0], tally)
        valid_steps += tally.steps
        row = {**ck, "valid": v, "valid_steps": tally.steps, "valid_collisions": tally.collisions,
               "counted_steps": ck["steps"] + valid_steps}
        if test:
            row["test"] = drive(frozen, rooms["test"], specs[1])
        rows.append(row)
    best = max(range(len(rows)), key=lambda i: merit(rows[i]["valid"]))
    return {**train, "rows": rows, "best": best, "valid_steps": valid_steps,
            "counted_steps": train["steps"] + valid_steps,
            "counted_collisions": train["learning_collisions"]
            + sum(r["valid_collisions"] for r in rows)}


def score_fuzzy(d: Path, rooms: dict[str, tuple[str, ...]], test: bool,
                specs: tuple[EvalSpec, EvalSpec] = (VALID, TEST)) -> dict[str, Any]:
    """Trial 0's frozen policy in the validation rooms (not counted: nothing is selected by
    it) and the test rooms."""
    train = json.loads((d / "train.json").read_text())
    log = d / "run.h5"
    row = {"steps": train["counted"], "counted_steps": train["counted"],
           "learning_collisions": train["learning_collisions"], "cpu_s": train["cpu_s"],
           "valid": fuzzy_scores(log, rooms["valid"], specs[0])}
    if test:
        row["test"] = fuzzy_scores(log, rooms["test"], specs[1])
    return {**train, "rows": [row], "best": 0, "counted_steps": train["counted"],
            "counted_collisions": train["learning_collisions"]}


def merit(v: dict[str, Any]) -> tuple[bool, float, float]:
    """The selection rule's key (higher is better): safe (at most :data:`SAFE` collisions per
    1000 iterations), then coverage if safe, else fewer collisions, then coverage."""
    safe = v["collisions_per_1000"] <= SAFE
    return (safe, v["coverage"] if safe else -v["collisions_per_1000"], v["coverage"])


# ----------------------------------------------------------------------------- driver

def _configs(names: list[str], out: Path) -> list[str]:
    """``selected`` expands to the sets the screening selected (:func:`selected`)."""
    expanded: list[str] = []
    for n in names:
        expanded += list(selected(load(out, "screen")).values()) if n == "selected" else [n]
    for n in expanded:
        if n != "fuzzy-q" and n not in GRID:
            raise SystemExit(f"--configs: unknown '{n}'; expected fuzzy-q, selected or one of "
                             f"{', '.join(GRID)}")
    return expanded


def cmd_run(a: argparse.Namespace) -> None:
    rooms = ROOMS[a.rooms]
    check_rooms(rooms)
    for name in _configs(a.configs, a.out):
        if name == "fuzzy-q" and a.phase == "screen":
            continue  # (fuzzy-q gets no tuning here: its preset is its author's)
        for seed in range(a.from_seed, a.seeds):
            d = job_dir(a.out, a.phase, name, seed)
            if (d / "train.json").exists():
                continue
            t0 = time.perf_counter()
            if name == "fuzzy-q":
                run_fuzzy(seed, d, rooms)
            else:
                stop = int(GRID[name][2][-1] * SCREEN_FRACTION) if a.phase == "screen" else None
                train_sb3(name, seed, d, rooms["train"], stop)
            print(f"trained {d} in {time.perf_counter() - t0:.0f} s", flush=True)


def cmd_score(a: argparse.Namespace) -> None:
    rooms = ROOMS[a.rooms]
    check_rooms(rooms)
    for train in sorted((a.out / a.phase).glob("*/seed-*/train.json")):
        d = train.parent
        if (d / "score.json").exists():
            continue
        t0 = time.process_time()
        fn = score_fuzzy if d.parent.name == "fuzzy-q" else score_sb3
        res = fn(d, rooms, test=a.phase == "final")
        res["score_cpu_s"] = time.process_time() - t0
        (d / "score.json").write_text(json.dumps(res, indent=1))
        print(f"scored {d} in {res['score_cpu_s']:.0f} s CPU", flush=True)


def load(out: Path, phase: str) -> dict[str, list[dict[str, Any]]]:
    """Every scored job of ``phase``, by set, in seed order."""
    runs: dict[str, list[dict[str, Any]]] = {}
    for p in sorted((out / phase).glob("*/seed-*/score.json"),
                    key=lambda p: (p.parent.parent.name, int(p.parent.name[5:]))):
        r = json.loads(p.read_text())
        runs.setdefault(r["config"], []).append(r)
    return runs


def rank_key(jobs: list[dict[str, Any]]) -> tuple[float, float, float]:
    """A set's key in the tuning (higher is better): the share of seeds whose best checkpoint
    is safe on the validation rooms, their median coverage, minus their median collisions."""
    best = [j["rows"][j["best"]]["valid"] for j in jobs]
    return (float(np.mean([b["collisions_per_1000"] <= SAFE for b in best])),
            float(np.median([b["coverage"] for b in best])),
            -float(np.median([b["collisions_per_1000"] for b in best])))


def selected(screen: dict[str, list[dict[str, Any]]]) -> dict[str, str]:
    """The best set per algorithm by :func:`rank_key` (validation rooms only)."""
    best: dict[str, str] = {}
    for name in sorted(screen, key=lambda n: rank_key(screen[n]), reverse=True):
        best.setdefault(GRID[name][0], name)
    if not best:
        raise SystemExit("no screened sets yet: run and score --phase screen first")
    return best


# ----------------------------------------------------------------------------- report

def _q(x: Sequence[float], fmt: str) -> str:
    """``median [q1–q3]`` of ``x``."""
    q1, m, q3 = np.percentile(np.asarray(x, float), [25, 50, 75])
    return f"{m:{fmt}} [{q1:{fmt}}–{q3:{fmt}}]"


def to_quality(job: dict[str, Any]) -> int:
    """Counted steps until the job first reached its own final quality: the first checkpoint
    whose test scores are at least as good (collisions and coverage) as the chosen one's."""
    rows = job["rows"]
    fin = rows[job["best"]]["test"]
    for r in rows:
        t = r["test"]
        if t["collisions_per_1000"] <= fin["collisions_per_1000"] and \
                t["coverage"] >= fin["coverage"]:
            return int(r["counted_steps"])
    raise AssertionError("the chosen checkpoint reaches its own quality")


@dataclass
class Summary:
    """One method's final figures over its seeds (each seed at its chosen checkpoint)."""

    name: str
    seeds: int
    collisions: np.ndarray
    coverage: np.ndarray
    counted: np.ndarray
    to_quality: np.ndarray
    learning_collisions: np.ndarray
    cpu_s: np.ndarray
    score_cpu_s: np.ndarray

    @classmethod
    def of(cls, name: str, jobs: list[dict[str, Any]]) -> Summary:
        fin = [j["rows"][j["best"]]["test"] for j in jobs]
        cpu = [j["cpu_s"] if "cpu_s" in j else j["rows"][-1]["cpu_s"] for j in jobs]
        return cls(name, len(jobs), np.array([f["collisions_per_1000"] for f in fin]),
                   np.array([f["coverage"] for f in fin]),
                   np.array([j["counted_steps"] for j in jobs], float),
                   np.array([to_quality(j) for j in jobs], float),
                   np.array([j["counted_collisions"] for j in jobs], float),
                   np.array(cpu, float), np.array([j["score_cpu_s"] for j in jobs], float))


def duel_table(sums: list[Summary]) -> str:
    """Markdown: every method's final figures in the test rooms, and its costs."""
    lines = ["| method | seeds | collisions/1000: median [IQR], worst | coverage: median "
             "[IQR], worst | counted steps, whole run | counted steps to its own final "
             "quality | collisions while learning (whole run) | training CPU s (median) |",
             "|" + "---|" * 8]
    for s in sums:
        lines.append(f"| {s.name} | {s.seeds} | {_q(s.collisions, '.1f')}, "
                     f"{s.collisions.max():.1f} | {_q(s.coverage, '.3f')}, "
                     f"{s.coverage.min():.3f} | {_q(s.counted, ',.0f')} | "
                     f"{_q(s.to_quality, ',.0f')} | {_q(s.learning_collisions, '.0f')} | "
                     f"{np.median(s.cpu_s):.0f} |")
    return "\n".join(lines)


def targets_table(fq: Summary, deep: list[Summary]) -> str:
    """Markdown: the issue's targets for fuzzy-q against the best deep-RL method (the lower
    median test collision rate; coverage breaks a tie)."""
    best = min(deep, key=lambda s: (np.median(s.collisions), -np.median(s.coverage)))
    rows = [
        (f"median collisions/1000 <= {best.name}'s median", np.median(fq.collisions),
         np.median(best.collisions), np.median(fq.collisions) <= np.median(best.collisions)),
        ("worst seed's collisions/1000 <= 3", fq.collisions.max(), 3.0,
         fq.collisions.max() <= 3.0),
        ("median coverage >= 0.50", np.median(fq.coverage), 0.50,
         np.median(fq.coverage) >= 0.50),
        ("worst seed's coverage >= 0.40", fq.coverage.min(), 0.40, fq.coverage.min() >= 0.40),
        (f"steps <= 1/5 of {best.name}'s steps to its own final quality",
         np.median(fq.counted), np.median(best.to_quality) / 5,
         np.median(fq.counted) <= np.median(best.to_quality) / 5),
        (f"collisions while learning <= 1/20 of {best.name}'s",
         np.median(fq.learning_collisions), np.median(best.learning_collisions) / 20,
         np.median(fq.learning_collisions) <= np.median(best.learning_collisions) / 20),
    ]
    lines = [f"Best deep-RL method: {best.name} (lower median test collision rate).\n",
             "| target (fuzzy-q) | fuzzy-q | bound | met |", "|---|---|---|---|"]
    lines += [f"| {t} | {_num(v)} | {_num(b)} | {'yes' if ok else '**no**'} |"
              for t, v, b, ok in rows]
    return "\n".join(lines)


def _num(v: float) -> str:
    """A figure of the targets' table: steps and counts whole, rates to 3 digits."""
    return f"{v:,.0f}" if abs(v) >= 100 else f"{v:.3g}"


def tuning_table(screen: dict[str, list[dict[str, Any]]]) -> str:
    """Markdown: the grid ranked by :func:`rank_key` (validation rooms only)."""
    chosen = set(selected(screen).values())
    lines = ["| set | change | seeds | screened to (steps) | share of seeds safe | validation "
             "collisions/1000 at best checkpoint (median) | validation coverage (median) | "
             "best checkpoints (steps) | selected |", "|" + "---|" * 9]
    for name in sorted(screen, key=lambda n: (GRID[n][0], [-x for x in
                                                            rank_key(screen[n])])):
        jobs = screen[name]
        share, cov, neg = rank_key(jobs)
        best = " ".join(f"{j['rows'][j['best']]['steps'] / 1000:g}k" for j in jobs)
        lines.append(f"| {name} | {GRID[name][3]} | {len(jobs)} | "
                     f"{jobs[0]['stopped_at']:,} | {share:.2f} | {-neg:.1f} | {cov:.3f} | "
                     f"{best} | {'**yes**' if name in chosen else ''} |")
    return "\n".join(lines)


def _curve(jobs: list[dict[str, Any]], key: str) -> tuple[np.ndarray, np.ndarray]:
    """Counted steps (median over seeds) and (seeds, checkpoints) test values of ``key``
    (``learning_collisions``: training and validation collisions so far)."""
    n = min(len(j["rows"]) for j in jobs)
    x = np.median([[r["counted_steps"] for r in j["rows"][:n]] for j in jobs], axis=0)
    if key == "learning_collisions":
        v = [np.cumsum([r.get("valid_collisions", 0) for r in j["rows"][:n]])
             + [r["learning_collisions"] for r in j["rows"][:n]] for j in jobs]
    else:
        v = [[r["test"][key] for r in j["rows"][:n]] for j in jobs]
    return x, np.asarray(v, float)


def curves_figure(final: dict[str, list[dict[str, Any]]], path: Path) -> None:
    """Test-room collisions/1000, coverage and collisions while learning against counted
    steps: median and IQR band over seeds per deep-RL set, fuzzy-q's point (median, IQR)."""
    from matplotlib.figure import Figure

    panels = [("collisions_per_1000", "collisions / 1000 iterations, 22 unseen rooms", SAFE),
              ("coverage", "coverage, 22 unseen rooms", 0.5),
              ("learning_collisions", "collisions while learning (cumulative)", None)]
    fig = Figure(figsize=(15, 5.8))
    for ax, (key, label, bar) in zip(fig.subplots(1, 3), panels, strict=True):
        for name, jobs in final.items():
            x, v = _curve(jobs, key)
            q1, med, q3 = np.percentile(v, [25, 50, 75], axis=0)
            if name == "fuzzy-q":
                ax.errorbar(x, med, yerr=[med - q1, q3 - med], fmt="*", ms=14, color="k",
                            capsize=4, label=f"fuzzy-q ({len(jobs)} seeds)", zorder=5)
                continue
            line, = ax.plot(x, med, "o-", ms=3, label=f"{name} ({len(jobs)} seeds)")
            ax.fill_between(x, q1, q3, color=line.get_color(), alpha=0.18)
            if key != "learning_collisions":  # the duel's score: each seed's chosen checkpoint
                fin = [j["rows"][j["best"]]["test"][key] for j in jobs]
                ax.plot(x[-1], np.median(fin), "D", mfc="none", mew=2, ms=10,
                        color=line.get_color(), label=f"{name}: at the checkpoints chosen on "
                        "validation rooms (median)")
        if bar is not None:
            ax.axhline(bar, color="grey", ls=":", lw=1, label="the issue's bar")
        ax.set_xscale("log")
        ax.set_xlabel("environment steps counted (training + validation)")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
        if key != "coverage":
            ax.set_yscale("symlog", linthresh=1.0 if key != "learning_collisions" else 10.0)
            ax.set_ylim(bottom=0)
    fig.legend(*fig.axes[0].get_legend_handles_labels(), loc="lower center", ncol=3,
               fontsize=9, frameon=False)
    fig.suptitle("Duel v2: frozen policies at each checkpoint in the 22 test rooms (median and "
                 "IQR over seeds; fuzzy-q: its final policy)")
    fig.tight_layout(rect=(0, 0.11, 1, 1))
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)


def cmd_report(a: argparse.Namespace) -> None:
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: common
    from common.publish import publish

    screen = load(a.out, "screen")
    if screen and a.table == "duel":
        publish("duel-tuning", tuning_table(screen) + "\n\nSelected (validation rooms only): "
                + ", ".join(selected(screen).values()) + ".")
        jobs = [j for js in screen.values() for j in js]
        print(f"screening CPU s: training {sum(j['checkpoints'][-1]['cpu_s'] for j in jobs):.0f}"
              f", scoring {sum(j['score_cpu_s'] for j in jobs):.0f}")
    final = load(a.out, "final")
    if "fuzzy-q" not in final or len(final) < 2:
        raise SystemExit("report: expected fuzzy-q and at least one deep-RL set in --phase final")
    sums = [Summary.of(n, jobs) for n, jobs in final.items()]
    fq = next(s for s in sums if s.name == "fuzzy-q")
    deep = [s for s in sums if s.name != "fuzzy-q"]
    publish(a.table, duel_table([fq, *deep]) + "\n\n" + targets_table(fq, deep))
    curves_figure(final, a.figure)
    print(f"figure: {a.figure}")
    print("CPU s per method (training + scoring, summed over seeds): " + ", ".join(
        f"{s.name} {s.cpu_s.sum():.0f} + {s.score_cpu_s.sum():.0f}" for s in sums))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("command", choices=("run", "score", "report"))
    ap.add_argument("--out", type=Path, default=Path("duel2"))
    ap.add_argument("--phase", choices=("screen", "final"), default="final")
    ap.add_argument("--rooms", choices=tuple(ROOMS), default="gen",
                    help="room sets (shipped: the shipped worlds, to try the harness)")
    ap.add_argument("--configs", nargs="+", default=[*GRID],
                    help=f"fuzzy-q, selected (the screening's choice) or any of {' '.join(GRID)}")
    ap.add_argument("--seeds", type=int, default=SCREEN_SEEDS, help="seeds 0 .. N-1")
    ap.add_argument("--from-seed", type=int, default=0)
    ap.add_argument("--figure", type=Path, default=FIGURE, help="report: the figure's path")
    ap.add_argument("--table", default="duel",
                    help="report: the published table's name (a second duel beside the first)")
    a = ap.parse_args()
    a.out.mkdir(parents=True, exist_ok=True)
    {"run": cmd_run, "score": cmd_score, "report": cmd_report}[a.command](a)


if __name__ == "__main__":
    main()
