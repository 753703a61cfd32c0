"""Benchmark: control iterations per second of one robot wandering a world.

Question: How many control iterations per second does the simulator run (one sonar read
and one 1.5 s step with collision checks), and how does that compare with the naive loop
or another revision?
Output: the median rate per run printed (and the ratio to --against REV's); --first-call
the cost of importing numba and loading or compiling the kernels.

One iteration = one 8-ray sonar read + one 1.5 s step with collision checks
(exactly the simulator work of one scheduler iteration). Commands are
random-ish from a seeded Generator, with a reflex that turns away when a
front reading is short, so the robot spends its time both in open space and
near walls (and collides now and then).

The same loop is also timed with a *naive* step — a Python loop over the 30
substeps, each checking the disc against every segment with numpy — to show
what the vectorised step buys.

Run::

    python benchmarks/sim/bench_sim.py [--world training] [--iterations 2000] [--repeats 5]

``--against REV`` times this checkout's loop and git revision ``REV``'s
(exported to a temporary folder) in one run, alternating fresh processes of
each, and prints both medians and their ratio (issue 17: >= 40,000 control
iterations per second, twice the rate before the compiled kernels).
``--first-call`` measures what the compiled kernels cost a fresh process:
importing numba and loading them from numba's cache, and compiling them with
an empty cache (the first run after an install); the simulator's kernels and the
compiled learning trial's apart, and both; then short learning runs and a Gymnasium
script (``FIRST_RUNS``) with an empty cache and a filled one, whose difference is what
the first run after an install spends compiling (the kernels compiled on first use
included)::

    python benchmarks/sim/bench_sim.py --against ef46ff4 --repeats 11
    python benchmarks/sim/bench_sim.py --first-call
"""

from __future__ import annotations

import argparse
import math
import os
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: common
import numpy as np
from common import against  # noqa: E402
from common.publish import publish  # noqa: E402

from sitframe.plugins.sonar import SonarRing
from sitframe.sim import geometry as geo
from sitframe.sim.robot import Command, RobotParams, StepOutcome, step_robot
from sitframe.sim.world import World, load_world

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


ROOT = Path(__file__).resolve().parent.parent


def _load_kernels() -> None:
    """Load the compiled kernels now (a revision without them: nothing to load)."""
    try:
        from sitframe.sim.kernels import load
    except ImportError:
        return
    load()


def _rates(world_name: str, iterations: int, repeats: int, seed: int) -> list[float]:
    """Control iterations per second of ``repeats`` wander runs (this process's sitframe)."""
    world = load_world(world_name)
    _load_kernels()
    run(world, step_robot, 200, seed)  # warm up caches
    return [iterations / run(world, step_robot, iterations, seed + k)[0] for k in range(repeats)]


def _against(rev: str, args: argparse.Namespace) -> None:
    rates = against(rev, Path(__file__), lambda _tree, _old: f"m._rates({args.world!r}, "
                    f"{args.iterations}, 3, {args.seed})", args.repeats)
    med = {k: statistics.median(v) for k, v in rates.items()}
    for k, v in med.items():
        print(f"{k:>14}: median {v:,.0f} control iterations/s ({len(rates[k])} runs of "
              f"{args.iterations} in {args.repeats} processes, world {args.world})")
    print(f"ratio this checkout / {rev}: {med['this checkout'] / med[rev]:.2f}x the rate")


_FIRST_CALL = """
import time
t0 = time.perf_counter()
import numpy, scipy.linalg, sitframe.sim.world, sitframe.sim.robot, sitframe.plugins.sonar
t1 = time.perf_counter()
from sitframe.sim.kernels import load
assert load() is not None
t2 = time.perf_counter()
from sitframe.runs import fused
assert not isinstance(fused._compiled(), str)
t3 = time.perf_counter()
print(t1 - t0, t2 - t1, t3 - t2)
"""


def _first_call(repeats: int) -> list[tuple[str, float, float]]:
    """What the compiled kernels cost a fresh process: ``(what, median s from the cache,
    median s with an empty cache)``, printed as it goes; numpy's import first, for scale."""
    def once(env: dict[str, str]) -> tuple[float, float, float]:
        res = subprocess.run([sys.executable, "-c", _FIRST_CALL], capture_output=True, text=True,
                             env=env, check=True, cwd=ROOT)
        base, load, trial = (float(v) for v in res.stdout.split())
        return base, load, trial

    env = dict(os.environ, SITFRAME_FUSED="wait")  # (the trial kernel compiled here, timed)
    once(env)  # make sure numba's cache is filled
    warm = [once(env) for _ in range(repeats)]
    with tempfile.TemporaryDirectory() as cache:
        cold = [once(dict(env, NUMBA_CACHE_DIR=str(Path(cache) / str(k))))
                for k in range(max(1, repeats // 3))]
    rows = [("importing numpy, scipy and the simulator (for scale)",
             statistics.median(b for b, _, _ in warm), statistics.median(b for b, _, _ in cold))]
    for name, i in (("importing numba and loading (or compiling) the simulator's kernels", 1),
                    ("then the compiled learning trial's (`sitframe.runs.fused_kernels`)", 2)):
        rows.append((name, statistics.median(w[i] for w in warm),
                     statistics.median(c[i] for c in cold)))
    rows.append(("both", statistics.median(w[1] + w[2] for w in warm),
                 statistics.median(c[1] + c[2] for c in cold)))
    for name, w, c in rows:
        print(f"{name}: from the cache, median {w:.3f} s per process ({repeats} processes); "
              f"with an empty cache (compiling, once after an install): median {c:.3f} s "
              f"({len(cold)} processes)")
    return rows


#: What a Gymnasium user's first script runs: 3000 steps of the single env, then 200 steps
#: of a vector env of 16 robots (the obstacle-avoidance task, random actions).
GYM_FIRST = """
import numpy as np
import sitframe.gym as sg
env = sg.make_env("obstacle-avoidance")
env.reset(seed=0)
for a in np.random.default_rng(0).integers(0, env.action_space.n, 3000):
    if any(env.step(int(a))[2:4]):
        env.reset()
venv = sg.make_vector_env("obstacle-avoidance", 16)
venv.reset(seed=0)
for a in np.random.default_rng(0).integers(0, venv.single_action_space.n, (200, 16)):
    venv.step(a)
"""

#: The first runs measured by ``--first-call`` (a name, the arguments after ``python``): the
#: main job (its situations evolve, so its trials run the Python loop) and the thesis's
#: preset (its trials run compiled), short, and the thesis's preset whole (its later trials
#: run compiled once the background compile has cached the trial kernel); and a Gymnasium
#: script (:data:`GYM_FIRST`).
FIRST_RUNS = [*((f"a whole run: `sitframe {cmd}`", ["-m", "sitframe.cli", *cmd.split()])
                for cmd in (f"run {preset} --trials 1 --iterations 1000 --workers 1"
                            for preset in ("obstacle-avoidance", "obstacle-avoidance-thesis"))),
              ("a whole run: `sitframe run obstacle-avoidance-thesis` (11 trials of 5000 "
               "iterations, the worker pool)",
               ["-m", "sitframe.cli", "run", "obstacle-avoidance-thesis"]),
              ("the main job: `sitframe run obstacle-avoidance` (11 trials of 5000 iterations, "
               "the worker pool)", ["-m", "sitframe.cli", "run", "obstacle-avoidance"]),
              ("a Gymnasium script: 3000 steps of `sitframe/ObstacleAvoidance-v0`, then 200 "
               "steps of its vector env of 16 robots", ["-c", GYM_FIRST])]


def _first_run(repeats: int, name: str, argv: list[str]) -> tuple[str, float, float]:
    """What the first run of ``python ARGV`` after an install spends more than a later one:
    the same run with an empty kernel cache and with a filled one, in fresh processes;
    the difference is what compiling costs that run (every kernel it calls, the variants
    compiled on first use included). A kernel compiled in a background process meanwhile
    (``sitframe.sim.numba_cache.compile_elsewhere``: the compiled trial's) is waited for
    after the run, and when it was cached is printed. ``(what, median s with the cache,
    median s without)``."""
    def once(cache: str) -> tuple[float, float]:
        with tempfile.TemporaryDirectory() as out:
            log = ["--out", str(Path(out) / "r.h5")] if argv[0] == "-m" else []
            t0 = time.perf_counter()
            subprocess.run([sys.executable, *argv, *log], check=True, capture_output=True,
                           env=dict(os.environ, SITFRAME_CACHE_DIR=cache), cwd=ROOT)
            wall = time.perf_counter() - t0
            busy = False
            while list(Path(cache).glob("numba/*.compiling")):  # (a background compile)
                busy = True
                time.sleep(0.05)
            return wall, (time.perf_counter() - t0 if busy else math.nan)

    with tempfile.TemporaryDirectory() as root:
        cold = [once(str(Path(root) / f"c{k}")) for k in range(max(1, repeats // 3))]
        warm = [once(str(Path(root) / "c0"))[0] for _ in range(repeats)]
    w, c = statistics.median(warm), statistics.median(t for t, _ in cold)
    ready = statistics.median(r for _, r in cold)
    what = name
    if not math.isnan(ready):
        what += (f" (its trial kernel compiled meanwhile in a background process, cached "
                 f"{ready:.1f} s after the start; its trials until then run the Python loop, "
                 f"and the difference holds their time too)")
    print(f"{name}: with an empty cache median {c:.2f} s ({len(cold)} runs), with the cache "
          f"filled {w:.2f} s ({len(warm)} runs): the first run after an install pays "
          f"{c - w:.2f} s of compiling" +
          ("" if math.isnan(ready) else f"; a background compile cached its kernel "
           f"{ready:.2f} s after the start"))
    return what, w, c


def _first_table(rows: list[tuple[str, float, float]]) -> str:
    """The Markdown table of :func:`_first_call`'s and :func:`_first_run`'s rows."""
    lines = ["| what | kernels cached (median s) | cache empty: the first run after an "
             "install (median s) | compiling costs (s) |", "|---|---:|---:|---:|"]
    lines += [f"| {name} | {w:.2f} | {c:.2f} | {c - w:.2f} |" for name, w, c in rows]
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--world", default="training")
    ap.add_argument("--iterations", type=int, default=2000)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--no-naive", action="store_true", help="skip the naive reference")
    ap.add_argument("--against", metavar="REV",
                    help="compare this checkout's rate with git revision REV's")
    ap.add_argument("--first-call", action="store_true",
                    help="measure the kernels' import, load and compile costs")
    ap.add_argument("--publish", metavar="NAME",
                    help="with --first-call: write its table to docs/results/tables/NAME.md")
    args = ap.parse_args()
    if args.against:
        _against(args.against, args)
        return
    if args.first_call:
        rows = _first_call(args.repeats) + [_first_run(args.repeats, name, argv)
                                            for name, argv in FIRST_RUNS]
        if args.publish:
            publish(args.publish, _first_table(rows))
        return
    world = load_world(args.world)
    _load_kernels()
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
