"""Benchmark: control iterations per second of one robot wandering a world.

One iteration = one 8-ray sonar read + one 1.5 s step with collision checks
(exactly the simulator work of one scheduler iteration). Commands are
random-ish from a seeded Generator, with a reflex that turns away when a
front reading is short, so the robot spends its time both in open space and
near walls (and collides now and then).

The same loop is also timed with a *naive* step — a Python loop over the 30
substeps, each checking the disc against every segment with numpy — to show
what the vectorised step buys.

Run::

    python benchmarks/bench_sim.py [--world training] [--iterations 2000] [--repeats 5]
"""

from __future__ import annotations

import argparse
import math
import statistics
import time
from collections.abc import Callable

import numpy as np

from sitframe import geometry as geo
from sitframe.plugins.sonar import SonarRing
from sitframe.robot import Command, RobotParams, StepOutcome, step_robot
from sitframe.world import World, load_world

StepFn = Callable[[World, np.ndarray, Command, RobotParams, np.random.Generator], StepOutcome]


def naive_step(world: World, pose: np.ndarray, command: Command, params: RobotParams,
               rng: np.random.Generator) -> StepOutcome:
    """Per-substep Euler loop, all segments each substep, stall (no recovery)."""
    x, y, th = (float(v) for v in pose)
    dh = math.radians(max(-90.0, min(90.0, command.heading_change_deg)))
    v = max(params.min_speed, min(params.max_speed, command.speed_m_s))
    rate = math.radians(params.max_turn_rate_deg_s) * params.substep_s
    target = th + dh
    n = round(params.control_period_s / params.substep_s)
    dist = 0.0
    for _ in range(n):
        nth = th + max(-rate, min(rate, target - th))
        nx = x + v * params.substep_s * math.cos(0.5 * (th + nth))
        ny = y + v * params.substep_s * math.sin(0.5 * (th + nth))
        if geo.min_distance(np.array([[nx, ny]]), world.segments)[0] < params.radius:
            final = np.array([x, y, th])
            return StepOutcome(pose, final, True, np.full(2, np.nan), final, dist,
                               math.degrees(th - pose[2]))
        x, y, th, dist = nx, ny, nth, dist + v * params.substep_s
    final = np.array([x, y, th])
    return StepOutcome(pose, final, False, np.full(2, np.nan), final, dist,
                       math.degrees(th - pose[2]))


def run(world: World, step: StepFn, iterations: int, seed: int) -> tuple[float, int]:
    """Return (seconds, collisions) for ``iterations`` wander iterations."""
    rng = np.random.default_rng(seed)
    sonar = SonarRing()
    params = RobotParams()
    pose = world.start.copy()
    collisions = 0
    turns = rng.normal(0.0, 30.0, iterations)
    t0 = time.perf_counter()
    for i in range(iterations):
        r = sonar.read(world, pose, rng)
        front = min(r[2], r[3], r[4], r[5])
        if front < 0.5:
            turn = 80.0 if r[0] + r[1] > r[6] + r[7] else -80.0
        else:
            turn = float(turns[i])
        out = step(world, pose, Command(turn, 0.15 if front < 1.0 else 0.3), params, rng)
        pose = out.pose
        collisions += out.collided
    return time.perf_counter() - t0, collisions


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--world", default="training")
    ap.add_argument("--iterations", type=int, default=2000)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--no-naive", action="store_true", help="skip the naive reference")
    args = ap.parse_args()
    world = load_world(args.world)
    run(world, step_robot, 200, args.seed)  # warm up caches
    times, coll = [], 0
    for k in range(args.repeats):
        dt, coll = run(world, step_robot, args.iterations, args.seed + k)
        times.append(dt)
    rate = args.iterations / statistics.median(times)
    print(f"world={world.name} iterations={args.iterations} repeats={args.repeats} "
          f"collisions/run~{coll}")
    print(f"vectorised step: {rate:,.0f} control iterations/s (median)")
    if not args.no_naive:
        nt = [run(world, naive_step, args.iterations, args.seed + k)[0]
              for k in range(max(1, args.repeats // 2))]
        nrate = args.iterations / statistics.median(nt)
        print(f"naive per-substep loop: {nrate:,.0f} control iterations/s (median); "
              f"speed-up x{rate / nrate:.1f}")


if __name__ == "__main__":
    main()
