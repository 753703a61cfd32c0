"""Benchmark: steps per second of the Gymnasium envs against the plain simulator.

Question: How fast are the Gymnasium environments against the plain simulator, and the
vector env against the single one?
Output: steps per second of each loop and their ratios, printed; with --publish NAME also
a table in docs/results/tables/NAME.md.

Three loops, alternated ``--repeats`` times in one run (medians reported):

plain
    the simulator alone, as in ``bench_sim.py``: the obstacle-avoidance
    preset's sonar (8 cones of 5 rays) read + ``step_robot`` with a random
    heading of the preset's 7 each iteration;
single
    ``SitframeEnv`` (``sitframe/ObstacleAvoidance-v0``) under random actions,
    reset when an episode ends;
vector
    ``SitframeVectorEnv`` with ``--num-envs`` robots (robot-steps per second);
kernels
    the vector env's compiled work alone: one ``CompiledStep.steps`` call per step (every
    robot's step, reading, observation and reward: :func:`sitframe.sim.kernels_numba.env_steps`)
    for the same robots, poses and commands (recorded from a vector run, not timed); where
    the vector env is not compiled, :func:`sitframe.sim.fleet.step_robots` and the sonar's
    ``read_many``. No vector env can step faster than this, so kernels / single is the
    ceiling of vector / single with today's kernels.

With ``--against REV`` the single and the vector env are also timed in the sitframe of git
revision ``REV`` and of this checkout, in alternating fresh processes (one timed loop of each
per process, ``--repeats`` processes per tree): each env's rate against its rate at ``REV``,
and this checkout's vector env against ``REV``'s single env (another reading of issue 41's
6x, against the commit before the change).

Times are CPU seconds of this process (``time.process_time``): on a machine
shared with other jobs, wall time mostly measures the others.

Prints the rates and the ratios single / plain (issue 41: >= 0.8) and vector /
single (issue 41: >= 6 at N = 16) -- of the medians, and the median of each
repeat's own ratio (its loops ran back to back, under the same load) -- and
whether ``check_env`` passes for every registered id.

Run::

    python benchmarks/sim/bench_gym.py [--steps 3000] [--num-envs 16] [--repeats 5]
        [--against REV]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import gymnasium as gym
import numpy as np
from gymnasium.utils.env_checker import check_env

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: common
from common import against  # noqa: E402
from common.publish import publish  # noqa: E402

import sitframe.gym as sg  # noqa: E402
from sitframe.sim.fleet import step_robots  # noqa: E402
from sitframe.sim.robot import Command, step_robot  # noqa: E402


def plain(env: sg.SitframeEnv, steps: int, seed: int) -> float:
    """Seconds for ``steps`` simulator iterations (sensor read + step) with random headings."""
    rng = np.random.default_rng(seed)
    world, sensor, rp = env.world, env.sensor, env.task.res.robot
    heads = env.task.headings[rng.integers(0, env.task.headings.size, steps)]
    pose = world.random_free_pose(rng, rp.radius, margin=0.1)
    t0 = time.process_time()
    for i in range(steps):
        sensor.read(world, pose, rng)
        pose = step_robot(world, pose, Command(float(heads[i]), 0.15), rp, rng).pose
    return time.process_time() - t0


def single(env: sg.SitframeEnv, steps: int, seed: int) -> float:
    acts = np.random.default_rng(seed).integers(0, env.action_space.n, steps)
    env.reset(seed=seed)
    t0 = time.process_time()
    for i in range(steps):
        _o, _r, term, trunc, _i = env.step(acts[i])
        if term or trunc:
            env.reset()
    return time.process_time() - t0


def vector(venv: sg.SitframeVectorEnv, steps: int, seed: int) -> float:
    n = venv.num_envs
    acts = np.random.default_rng(seed).integers(0, venv.single_action_space.n, (steps // n, n))
    venv.reset(seed=seed)
    t0 = time.process_time()
    for a in acts:
        venv.step(a)
    return time.process_time() - t0


def kernels(venv: sg.SitframeVectorEnv, steps: int, seed: int) -> float:
    """Seconds for the simulator work of :func:`vector`'s steps alone (module docstring)."""
    n, task = venv.num_envs, venv.task
    acts = np.random.default_rng(seed).integers(0, venv.single_action_space.n, (steps // n, n))
    venv.reset(seed=seed)
    moves = []
    for a in acts:  # (recorded, not timed)
        moves.append(([e.pose for e in venv.envs], [task.command(int(x), False) for x in a]))
        venv.step(a)
    read_many, world, rp = venv.envs[0].sensor.read_many, task.world, task.res.robot
    rngs = [np.random.default_rng(seed + i) for i in range(n)]
    fast = venv._compiled()
    t0 = time.process_time()
    for poses, cmds in moves:
        if fast is not None:
            fast[0].steps(world, np.array(poses), np.array([c.heading_change_deg for c in cmds]),
                          np.array([c.speed_m_s for c in cmds]), fast[1])
            continue
        outs = step_robots(world, poses, cmds, rp, rngs)
        read_many(world, np.array([o.pose for o in outs]), rngs)
    return time.process_time() - t0


def env_rates(steps: int, num_envs: int) -> list[float]:
    """The single env's steps/s and the vector env's robot-steps/s of the sitframe imported,
    one timed loop each after a warm-up (what ``--against`` runs in each tree): the kernels
    loaded (compiled, the first time a tree runs) and a loop of each untimed."""
    from sitframe.sim.kernels import load

    load()
    env = sg.make_env("obstacle-avoidance")
    venv = sg.make_vector_env("obstacle-avoidance", num_envs)
    single(env, steps, 99)
    vector(venv, steps, 99)
    return [steps / single(env, steps, 0), steps / vector(venv, steps, 0)]


def against_rows(rev: str, steps: int, num_envs: int, repeats: int) -> list[str]:
    """The Markdown rows of ``--against``: each env's median rate in ``rev`` and this checkout
    (module docstring), printed too."""
    got = against(rev, Path(__file__), lambda _t, _o: f"m.env_rates({steps}, {num_envs})",
                  repeats)
    med = {name: (statistics.median(v[0::2]), statistics.median(v[1::2]))
           for name, v in got.items()}
    (s0, v0), (s1, v1) = med[rev], med["this checkout"]
    rows = [f"| | {rev} | this checkout | ratio |", "|---|---:|---:|---:|",
            f"| `SitframeEnv` (steps/s) | {s0:,.0f} | {s1:,.0f} | {s1 / s0:.2f}x |",
            f"| `SitframeVectorEnv`, N = {num_envs} (robot-steps/s) | {v0:,.0f} | {v1:,.0f} "
            f"| {v1 / v0:.2f}x |",
            f"| this checkout's vector env ÷ {rev}'s single env | | | {v1 / s0:.1f}x |"]
    print("\n".join(rows))
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--steps", type=int, default=3000, help="(robot-)steps per timed loop")
    ap.add_argument("--num-envs", type=int, default=16)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--against", metavar="REV",
                    help="also time both envs in git revision REV, in alternating processes")
    ap.add_argument("--publish", metavar="NAME",
                    help="also write the figures as a table to docs/results/tables/NAME.md")
    a = ap.parse_args()
    for env_id in sg.ENV_IDS:
        check_env(gym.make(env_id).unwrapped, skip_render_check=True)
        print(f"check_env {env_id}: passed")
    env = sg.make_env("obstacle-avoidance")
    venv = sg.make_vector_env("obstacle-avoidance", a.num_envs)
    steps = a.steps - a.steps % a.num_envs
    for fn, obj in ((plain, env), (single, env), (vector, venv), (kernels, venv)):  # warm-up
        fn(obj, 200 - 200 % a.num_envs, 99)
    t: dict[str, list[float]] = {"plain": [], "single": [], "vector": [], "kernels": []}
    for k in range(a.repeats):
        t["plain"].append(steps / plain(env, steps, k))
        t["single"].append(steps / single(env, steps, k))
        t["vector"].append(steps / vector(venv, steps, k))
        t["kernels"].append(steps / kernels(venv, steps, k))
    m = {key: statistics.median(v) for key, v in t.items()}
    # each repeat times the three loops back to back: its ratios share the machine's load
    paired = {key: statistics.median(x / y for x, y in zip(t[num], t[den], strict=True))
              for key, num, den in (("single/plain", "single", "plain"),
                                    ("vector/single", "vector", "single"),
                                    ("kernels/single", "kernels", "single"))}
    print(f"steps={steps} repeats={a.repeats} (medians)")
    print(f"plain simulator:   {m['plain']:10,.0f} iterations/s")
    print(f"single env:        {m['single']:10,.0f} steps/s   single/plain = "
          f"{m['single'] / m['plain']:.2f}  (issue 41: >= 0.8)")
    print(f"vector env N={a.num_envs:<3}: {m['vector']:10,.0f} robot-steps/s   vector/single = "
          f"{m['vector'] / m['single']:.2f}  (issue 41: >= 6)")
    print(f"its kernels alone: {m['kernels']:10,.0f} robot-steps/s   kernels/single = "
          f"{m['kernels'] / m['single']:.2f}  (the ceiling of vector/single)")
    print("median of the per-repeat ratios: " + ", ".join(f"{k} = {v:.2f}"
                                                          for k, v in paired.items()))
    rows = against_rows(a.against, steps, a.num_envs, a.repeats) if a.against else []
    if a.publish:
        publish(a.publish, "\n".join([
            f"| loop ({steps} steps, medians of {a.repeats} alternated repeats) | rate | "
            "ratio (of the medians / median of the repeats' ratios) |", "|---|---|---|",
            f"| plain simulator | {m['plain']:,.0f} iterations/s | |",
            f"| `SitframeEnv` | {m['single']:,.0f} steps/s | single ÷ plain "
            f"{m['single'] / m['plain']:.2f} / {paired['single/plain']:.2f} |",
            f"| `SitframeVectorEnv`, N = {a.num_envs} | {m['vector']:,.0f} robot-steps/s | "
            f"vector ÷ single {m['vector'] / m['single']:.2f} / {paired['vector/single']:.2f} |",
            f"| its compiled work alone (`env_steps`) | {m['kernels']:,.0f} "
            f"robot-steps/s | kernels ÷ single {m['kernels'] / m['single']:.2f} / "
            f"{paired['kernels/single']:.2f} |",
            *(["", f"Against {a.against}, the commit before issue 41's change (medians of "
                   f"{a.repeats} alternated fresh processes of each tree, one timed loop of "
                   f"{steps} steps each):", "", *rows] if rows else [])]))


if __name__ == "__main__":
    main()
