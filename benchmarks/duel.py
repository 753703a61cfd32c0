"""The duel: fuzzy Q-learning over situations vs Stable-Baselines3 DQN and PPO.

Same robot, sensor (the obstacle-avoidance preset's 8 sonar cones), reward
(the preset's ``obstacle-avoidance`` reward) and training room for every
method. Each method learns for a budget of environment steps; at checkpoints
its *frozen* policy is scored in the two rooms it never saw (``novel-1``,
``novel-2``), from ``--starts`` random start poses per room (the same poses
for every method and checkpoint), ``--eval-iterations`` iterations each:

- collisions per 1000 iterations (pooled over starts and rooms),
- coverage (fraction of free 0.5 m cells visited, mean over starts and rooms),

against environment steps and against training time (CPU seconds of the
learning process, evaluation excluded: the wall time on an idle core; the
machine the duel ran on was shared, so its wall clock measured the others).
Collisions while learning are the second score.

Methods
-------
``fuzzy-q``
    ``sitframe run obstacle-avoidance --trials 1 --seed S``: collect, cluster
    (8 FCM situations), learn 5000 iterations. Its budget counts the collected
    sonar samples (2992 in the preset) plus the learning iterations; the policy
    at iteration t is the greedy rule base of the last rule-base change before t
    (the converged one after convergence), read from the log.
``dqn`` / ``ppo``
    SB3 on ``sitframe/ObstacleAvoidance-v0`` (normalised readings, 7 discrete
    headings at 0.15 m/s, random start poses, 1000-step episodes); frozen =
    ``predict(deterministic=True)``. Hyper-parameters: :data:`CONFIGS`; the
    tuning behind them is in the README ("The duel"); ``tune`` scores
    :data:`CONFIGS` in the training room only, so tuning never sees the rooms
    the duel is judged in.

Run (extra ``baselines``; about 20 CPU minutes: 5 seeds x (fuzzy-q ~25 s, DQN
~45 s, PPO ~65 s CPU, evaluations included); it took 65 minutes of wall time
at ``nice -n 10`` on 2 cores shared with a load of ~20)::

    nice -n 10 python benchmarks/duel.py run --out duel --seeds 5 --workers 2
    python benchmarks/duel.py report --out duel          # figure + markdown table
    nice -n 10 python benchmarks/duel.py tune --out duel-tune --workers 2

Each (method, seed) job writes ``OUT/<config>-<seed>.json``; a rerun skips
finished jobs.
"""

from __future__ import annotations

import argparse
import copy
import json
import resource
import subprocess
import sys
import time
from multiprocessing import Pool
from pathlib import Path
from typing import Any

import numpy as np

from sitframe.metrics import coverage

PRESET = "obstacle-avoidance"
NOVEL = ("novel-1", "novel-2")

#: Hyper-parameter sets: name -> (algorithm, kwargs, total steps, checkpoints).
CONFIGS: dict[str, tuple[str, dict[str, Any], int, tuple[int, ...]]] = {
    # The issue's calibration: SB3's default learning rate (1e-4) and discount (0.99) learned
    # nothing in 50k steps; lr 1e-3 and gamma 0.9 (the fuzzy learner's gamma) did.
    "dqn": ("dqn", {"learning_rate": 1e-3, "gamma": 0.9, "learning_starts": 1000,
                    "target_update_interval": 1000, "exploration_fraction": 0.2,
                    "exploration_final_eps": 0.05}, 15_000, (2_500, 5_000, 10_000, 15_000)),
    "dqn-default": ("dqn", {}, 15_000, (5_000, 15_000)),
    # 8 envs x 256 steps = SB3's default 2048-step rollout, one batched forward pass per
    # 8 steps; gamma 0.9 as DQN's
    "ppo": ("ppo", {"n_envs": 8, "n_steps": 256, "gamma": 0.9}, 40_000,
            (10_000, 20_000, 40_000)),
    "ppo-default": ("ppo", {}, 40_000, (20_000, 40_000)),
}
FUZZY_CHECKPOINTS = (500, 1000, 2000, 5000)  # learning iterations


# ----------------------------------------------------------------------------- evaluation

def evaluate(policy: Any, *, starts: int, iterations: int, seed: int,
             worlds: tuple[str, ...] = NOVEL) -> dict[str, float]:
    """Score ``policy`` (raw readings (N, d) -> heading changes (N,) [deg]) frozen in ``worlds``.

    Every world runs ``starts`` robots at once (the vector env) from start poses
    drawn by seed ``seed`` (the same for every policy).
    """
    from sitframe.gym import SitframeVectorEnv

    coll, cov, n = 0, [], 0
    for w in worlds:
        env = SitframeVectorEnv(PRESET, num_envs=starts, world=w, max_steps=iterations,
                                normalize=False, continuous=True)
        obs, info = env.reset(seed=seed)
        xy = [info["pose"][:, :2]]
        for _ in range(iterations):
            obs, _r, _te, _tr, info = env.step((policy(obs) / 90.0)[:, None])
            coll += int(info["collided"].sum())
            xy.append(info["pose"][:, :2])
        path = np.stack(xy, axis=1)  # (starts, iterations + 1, 2)
        cov += [coverage(env.task.world, path[i]) for i in range(starts)]
        n += starts * iterations
    return {"collisions_per_1000": 1000.0 * coll / n, "coverage": float(np.mean(cov))}


# ----------------------------------------------------------------------------- fuzzy Q

def run_fuzzy(seed: int, out: Path, a: argparse.Namespace) -> dict[str, Any]:
    """Learn with sitframe itself (one trial), then score the logged rule bases."""
    from sitframe.fuzzy import SituationFCS
    from sitframe.gym import Task
    from sitframe.logs import open_log

    log_path = out / f"fuzzy-q-{seed}.h5"
    cpu_path = log_path.with_suffix(".cpu")
    if not cpu_path.exists():  # (a rerun reuses a finished learning run)
        c0 = resource.getrusage(resource.RUSAGE_CHILDREN)
        subprocess.run([str(Path(sys.executable).parent / "sitframe"), "run", PRESET,
                        "--trials", "1", "--seed", str(seed), "--out", str(log_path)],
                       check=True, stdout=subprocess.DEVNULL)
        c1 = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpu_path.write_text(json.dumps(c1.ru_utime + c1.ru_stime - c0.ru_utime - c0.ru_stime))
    cpu = float(json.loads(cpu_path.read_text()))
    log = open_log(log_path)
    n_collect = int(log.stage("collect")["samples"].shape[0])
    trial = log.trial(0)
    data = trial.behaviours["avoid"]
    snap_it = np.asarray(data["heading/snapshot_iteration"])
    snap = np.asarray(data["heading/snapshot_greedy"])
    singles = trial.learned_policy("avoid").outputs["heading"].actions
    collided = np.asarray(trial.arrays["collision"], dtype=bool)
    L = collided.size
    interp = Task.from_config(PRESET).res.interpreter()  # the preset's fcm, fitted state below
    interp.load_state(log.interpreter_state())
    rows = []
    for t in FUZZY_CHECKPOINTS:
        rules = snap[int(np.searchsorted(snap_it, t, side="right")) - 1]
        fcs = SituationFCS(singles, rules.astype(np.intp))

        def policy(obs: np.ndarray, fcs: SituationFCS = fcs) -> np.ndarray:
            return np.array([fcs.output(interp.memberships(r.astype(np.float64))) for r in obs])

        score = evaluate(policy, starts=a.starts, iterations=a.eval_iterations, seed=a.eval_seed)
        rows.append({"steps": n_collect + t, "learning_collisions": int(collided[:t].sum()),
                     # the run's CPU time up to t (collect + cluster + learning, pro rata;
                     # its own evaluation stage of 3 x 1000 iterations is counted too)
                     "cpu_s": cpu * (n_collect + t) / (n_collect + L), **score})
    return {"config": "fuzzy-q", "method": "fuzzy-q", "seed": seed, "collected": n_collect,
            "rows": rows}


# ----------------------------------------------------------------------------- SB3

def run_sb3(name: str, seed: int, a: argparse.Namespace,
            worlds: tuple[str, ...] = NOVEL) -> dict[str, Any]:
    """Train SB3 ``name`` (:data:`CONFIGS`), snapshot the policy at checkpoints, score them."""
    import torch
    from stable_baselines3 import DQN, PPO
    from stable_baselines3.common.callbacks import BaseCallback
    from stable_baselines3.common.env_util import make_vec_env

    from sitframe.gym import make_env

    torch.set_num_threads(1)
    algo, kw, total, checkpoints = CONFIGS[name]
    kw = dict(kw)
    n_envs = kw.pop("n_envs", 1)
    env = make_env(PRESET)
    venv = make_vec_env(make_env, n_envs, seed=seed, env_kwargs={"config": PRESET}) \
        if n_envs > 1 else env
    cls = {"dqn": DQN, "ppo": PPO}[algo]
    model = cls("MlpPolicy", venv, seed=seed, device="cpu", verbose=0, **kw)
    snaps: list[dict[str, Any]] = []

    class Checkpoints(BaseCallback):
        def _on_training_start(self) -> None:
            self.collisions, self.t0, self.paused = 0, time.process_time(), 0.0

        def _on_step(self) -> bool:
            self.collisions += sum(bool(i.get("collided")) for i in self.locals["infos"])
            if len(snaps) < len(checkpoints) and self.num_timesteps >= checkpoints[len(snaps)]:
                p0 = time.process_time()
                snaps.append({"steps": self.num_timesteps, "learning_collisions": self.collisions,
                              "cpu_s": p0 - self.t0 - self.paused,
                              "state": copy.deepcopy(self.model.policy.state_dict())})
                self.paused += time.process_time() - p0
            return True

    model.learn(total_timesteps=total, callback=Checkpoints())
    max_range = env.task.max_range
    headings = env.task.headings
    rows = []
    for s in snaps:
        model.policy.load_state_dict(s.pop("state"))

        def policy(obs: np.ndarray) -> np.ndarray:
            act, _ = model.predict((obs / max_range).astype(np.float32), deterministic=True)
            return headings[np.asarray(act, dtype=int)]

        rows.append({**s, **evaluate(policy, starts=a.starts, iterations=a.eval_iterations,
                                     seed=a.eval_seed, worlds=worlds)})
    if a.save_models:
        model.save(a.out / f"{name}-{seed}.zip")
    return {"config": name, "method": algo, "seed": seed, "rows": rows}


# ----------------------------------------------------------------------------- driver

def job(args: tuple[str, int, argparse.Namespace]) -> str:
    name, seed, a = args
    path = a.out / f"{name}-{seed}.json"
    if path.exists():
        return f"{path} (done before)"
    t0 = time.perf_counter()
    if name == "fuzzy-q":
        res = run_fuzzy(seed, a.out, a)
    else:
        res = run_sb3(name, seed, a, worlds=("training",) if a.command == "tune" else NOVEL)
    res["job_wall_s"] = time.perf_counter() - t0
    res["eval"] = {"starts": a.starts, "iterations": a.eval_iterations, "seed": a.eval_seed,
                   "worlds": ["training"] if a.command == "tune" else list(NOVEL)}
    path.write_text(json.dumps(res, indent=1))
    return f"{path} in {res['job_wall_s']:.0f} s"


def load(out: Path) -> dict[str, list[dict[str, Any]]]:
    runs: dict[str, list[dict[str, Any]]] = {}
    for p in sorted(out.glob("*.json")):
        r = json.loads(p.read_text())
        runs.setdefault(r["config"], []).append(r)
    return runs


def curves(runs: list[dict[str, Any]], key: str) -> tuple[np.ndarray, np.ndarray]:
    """Checkpoint steps (median over seeds) and the (seeds, checkpoints) values of ``key``."""
    n = min(len(r["rows"]) for r in runs)
    steps = np.median([[row["steps"] for row in r["rows"][:n]] for r in runs], axis=0)
    return steps, np.array([[row[key] for row in r["rows"][:n]] for r in runs], dtype=float)


def report(out: Path) -> None:
    """Figure (median and IQR over seeds) and a markdown table of the finished jobs."""
    from matplotlib.figure import Figure
    from matplotlib.ticker import FuncFormatter, NullFormatter

    runs = load(out)
    if "fuzzy-q" not in runs:
        raise SystemExit(f"{out}: no fuzzy-q results yet")
    _s, fz_c = curves(runs["fuzzy-q"], "collisions_per_1000")
    _s, fz_v = curves(runs["fuzzy-q"], "coverage")
    target_c, target_v = float(np.median(fz_c[:, -1])), float(np.median(fz_v[:, -1]))
    panels = [("steps", "collisions_per_1000", "collisions / 1000 iterations, unseen rooms"),
              ("steps", "coverage", "coverage, unseen rooms"),
              ("steps", "learning_collisions", "collisions while learning"),
              ("cpu_s", "collisions_per_1000", "collisions / 1000 iterations, unseen rooms")]
    fig = Figure(figsize=(12, 8.5))
    axes = fig.subplots(2, 2).ravel()
    for name, rs in runs.items():
        for ax, (xkey, key, label) in zip(axes, panels, strict=True):
            x = np.median(curves(rs, xkey)[1], axis=0)
            _s, v = curves(rs, key)
            q1, med, q3 = np.percentile(v, [25, 50, 75], axis=0)
            line, = ax.plot(x, med, "o-", ms=4, label=f"{name} ({len(rs)} seeds)")
            ax.fill_between(x, q1, q3, color=line.get_color(), alpha=0.2)
            ax.set_ylabel(label)
    for ax, (xkey, key, _label) in zip(axes, panels, strict=True):
        ax.set_xscale("log")
        ax.xaxis.set_minor_formatter(NullFormatter())
        if xkey == "steps":
            ax.set_xlabel("environment steps (fuzzy-q: collected samples + iterations)")
            ax.set_xticks([2500, 5000, 10_000, 20_000, 40_000])
            ax.xaxis.set_major_formatter(FuncFormatter(lambda x, _p: f"{x / 1000:g}k"))
        else:
            ax.set_xlabel("training CPU seconds (median over seeds)")
            ax.set_xticks([2, 5, 10, 20, 50, 100])
            ax.xaxis.set_major_formatter(FuncFormatter(lambda x, _p: f"{x:g}"))
        if key == "collisions_per_1000":
            ax.set_yscale("symlog", linthresh=1.0)
            ax.set_ylim(bottom=0.0)
            ax.axhline(target_c, color="k", ls=":", lw=1, label="fuzzy-q final (median)")
        if key == "coverage":
            ax.axhline(target_v, color="k", ls=":", lw=1, label="fuzzy-q final (median)")
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.suptitle("Obstacle avoidance, frozen policies scored in two unseen rooms "
                 "(median and IQR over seeds)")
    fig.tight_layout()
    fig.savefig(out / "duel.png", dpi=100)
    print(table(runs, target_c, target_v))
    print(f"\nfigure: {out / 'duel.png'}")


def table(runs: dict[str, list[dict[str, Any]]], target_c: float, target_v: float) -> str:
    """Markdown: final scores, steps each seed needs to reach fuzzy-q's final median scores."""
    lines = [f"Target (fuzzy-q's final frozen policies, median over seeds): {target_c:.1f} "
             f"collisions/1000, coverage {target_v:.3f}\n",
             "| method | seeds | budget (steps) | collisions/1000, final: median [IQR] | "
             "coverage, final: median [IQR] | steps to reach the collision rate, per seed | "
             "steps to reach both | collisions while learning (final) | training CPU s |",
             "|" + "---|" * 9]

    def iqr(x: np.ndarray, fmt: str) -> str:
        q1, m, q3 = np.percentile(x, [25, 50, 75])
        return f"{m:{fmt}} [{q1:{fmt}}–{q3:{fmt}}]"

    for name, rs in runs.items():
        steps, c = curves(rs, "collisions_per_1000")
        _s, v = curves(rs, "coverage")
        _s, lc = curves(rs, "learning_collisions")
        _s, w = curves(rs, "cpu_s")

        rc = " ".join(_first(steps, c[k] <= target_c) for k in range(len(rs)))
        rb = " ".join(_first(steps, (c[k] <= target_c) & (v[k] >= target_v))
                      for k in range(len(rs)))
        if name == "fuzzy-q":
            rc = rb = "(the target)"
        lines.append(f"| {name} | {len(rs)} | {int(steps[-1]):,} | {iqr(c[:, -1], '.1f')} | "
                     f"{iqr(v[:, -1], '.3f')} | {rc} | {rb} | {iqr(lc[:, -1], '.0f')} | "
                     f"{np.median(w[:, -1]):.0f} |")
    return "\n".join(lines)


def _first(steps: np.ndarray, ok: np.ndarray) -> str:
    """The first checkpoint (in thousands of steps) where ``ok`` holds, or a dash."""
    i = np.flatnonzero(ok)
    return f"{steps[i[0]] / 1000:g}k" if i.size else "—"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("command", choices=("run", "tune", "report"))
    ap.add_argument("--out", type=Path, default=Path("duel"))
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--configs", nargs="+", default=["fuzzy-q", "dqn", "ppo"],
                    help=f"any of fuzzy-q {' '.join(CONFIGS)}")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--starts", type=int, default=5, help="start poses per evaluation room")
    ap.add_argument("--eval-iterations", type=int, default=1000)
    ap.add_argument("--eval-seed", type=int, default=12345)
    ap.add_argument("--save-models", action="store_true", help="keep the final SB3 models")
    a = ap.parse_args()
    a.out.mkdir(parents=True, exist_ok=True)
    if a.command == "report":
        report(a.out)
        return
    if a.command == "tune":  # scored in the training room only: the novel rooms stay unseen
        a.configs = [c for c in a.configs if c != "fuzzy-q"] or list(CONFIGS)
    for c in a.configs:
        if c != "fuzzy-q" and c not in CONFIGS:
            raise SystemExit(f"--configs: unknown '{c}'; expected fuzzy-q or one of "
                             f"{', '.join(CONFIGS)}")
    jobs = [(c, s, a) for s in range(a.seeds) for c in a.configs]  # seed by seed
    with Pool(a.workers, maxtasksperchild=1) as pool:
        for msg in pool.imap_unordered(job, jobs):
            print(msg, flush=True)
    if a.command == "run":
        report(a.out)


if __name__ == "__main__":
    main()
