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
``dqn-*`` / ``ppo-*``
    SB3 on ``sitframe/ObstacleAvoidance-v0`` (normalised readings, 7 discrete
    headings at 0.15 m/s, random start poses, 1000-step episodes); frozen =
    ``predict(deterministic=True)``; one torch thread. Hyper-parameter sets:
    :data:`CONFIGS` (DQN 30k steps, PPO 80k).

Tuning and duel in one run
--------------------------
Every checkpoint is scored twice: in the training room (keys ``train_*``) and
in the unseen rooms. The tuning (:func:`tune_table`) ranks the sets of
:data:`CONFIGS` by their *training-room* scores only, over the first seeds
every set has; the selected set per algorithm then runs more seeds, and the
duel (:func:`table`, ``duel.png``) reports the unseen-room scores of fuzzy-q
and every set with ``--min-seeds`` seeds. The selection never reads an
unseen-room score, so the rooms the duel is judged in stay unseen by the
tuning; the selected sets' first seeds serve both. fuzzy-q gets no tuning:
it runs its preset as published.

Run (extra ``baselines``)::

    nice -n 10 python benchmarks/duel.py run --out duel --configs fuzzy-q --seeds 5
    nice -n 10 python benchmarks/duel.py run --out duel --seeds 2     # the grid
    python benchmarks/duel.py report --out duel                       # -> "selected: ..."
    nice -n 10 python benchmarks/duel.py run --out duel --seeds 5 --configs DQN_SET PPO_SET
    python benchmarks/duel.py report --out duel     # tune.png, duel.png, both tables

Each (set, seed) job writes ``OUT/<set>-<seed>.json``; a rerun skips finished
jobs. Learning CPU per job: fuzzy-q ~10 s, DQN ~55 s (30k steps), PPO ~85 s
(60k steps); scoring every checkpoint in three rooms adds about as much again.
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

from sitframe.sim.metrics import coverage

PRESET = "obstacle-avoidance"
NOVEL = ("novel-1", "novel-2")

#: One hyper-parameter set: (algorithm, SB3 kwargs (plus ``n_envs``), total steps, checkpoints).
Config = tuple[str, dict[str, Any], int, tuple[int, ...]]

_DQN = {"learning_rate": 1e-3, "gamma": 0.9, "learning_starts": 1000,
        "target_update_interval": 1000, "exploration_fraction": 0.2, "exploration_final_eps": 0.05}
_PPO = {"n_envs": 8, "n_steps": 256, "gamma": 0.9}  # 8 x 256 = SB3's 2048-step rollout
_DQN_T = (2_500, 5_000, 10_000, 15_000, 20_000, 30_000)
_PPO_T = (10_000, 20_000, 30_000, 40_000, 60_000)

#: The tuning grid and the duel in one: every set changes one thing from its
#: starting point (``*-base``: the issue's calibration for DQN, lr 1e-3 and gamma
#: 0.9 (the fuzzy learner's gamma); gamma 0.9 and 8 envs x 256 steps (SB3's
#: 2048-step rollout, batched forward passes) for PPO). Every checkpoint is scored
#: in the training room (``train_*``: the only scores the selection sees, see
#: :func:`tune_table`) and in the unseen rooms (the duel's scores).
CONFIGS: dict[str, Config] = {
    "dqn-base": ("dqn", _DQN, 30_000, _DQN_T),
    "dqn-lr3e-3": ("dqn", {**_DQN, "learning_rate": 3e-3}, 30_000, _DQN_T),
    "dqn-g0.99": ("dqn", {**_DQN, "gamma": 0.99}, 30_000, _DQN_T),
    "ppo-base": ("ppo", _PPO, 60_000, _PPO_T),
    "ppo-lr1e-3": ("ppo", {**_PPO, "learning_rate": 1e-3}, 60_000, _PPO_T),
    "ppo-g0.99": ("ppo", {**_PPO, "gamma": 0.99}, 60_000, _PPO_T),
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


def score(policy: Any, a: argparse.Namespace) -> dict[str, float]:
    """The unseen rooms' scores and the training room's (keys prefixed ``train_``)."""
    train = evaluate(policy, starts=a.starts, iterations=a.eval_iterations, seed=a.eval_seed,
                     worlds=("training",))
    return {**evaluate(policy, starts=a.starts, iterations=a.eval_iterations, seed=a.eval_seed),
            **{f"train_{k}": v for k, v in train.items()}}


# ----------------------------------------------------------------------------- fuzzy Q

def run_fuzzy(seed: int, out: Path, a: argparse.Namespace) -> dict[str, Any]:
    """Learn with sitframe itself (one trial), then score the logged rule bases."""
    from sitframe.gym import Task
    from sitframe.learning.fcs import SituationFCS
    from sitframe.logs.reader import open_log

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

        rows.append({"steps": n_collect + t, "learning_collisions": int(collided[:t].sum()),
                     # the run's CPU time up to t (collect + cluster + learning, pro rata;
                     # its own evaluation stage of 3 x 1000 iterations is counted too)
                     "cpu_s": cpu * (n_collect + t) / (n_collect + L), **score(policy, a)})
    return {"config": "fuzzy-q", "method": "fuzzy-q", "seed": seed, "collected": n_collect,
            "rows": rows}


# ----------------------------------------------------------------------------- SB3

def run_sb3(name: str, seed: int, a: argparse.Namespace) -> dict[str, Any]:
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

        rows.append({**s, **score(policy, a)})
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
    res = run_fuzzy(seed, a.out, a) if name == "fuzzy-q" else run_sb3(name, seed, a)
    res["job_wall_s"] = time.perf_counter() - t0
    res["eval"] = {"starts": a.starts, "iterations": a.eval_iterations, "seed": a.eval_seed,
                   "worlds": list(NOVEL), "tuning_world": "training"}
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


def targets(runs: dict[str, list[dict[str, Any]]], prefix: str = "") -> tuple[float, float]:
    """fuzzy-q's final frozen policies: median collisions per 1000 and median coverage.

    ``prefix`` ``"train_"`` gives the training room's scores, ``""`` the unseen rooms'.
    """
    if "fuzzy-q" not in runs:
        raise SystemExit("no fuzzy-q results yet: its scores are the targets")
    _s, c = curves(runs["fuzzy-q"], f"{prefix}collisions_per_1000")
    _s, v = curves(runs["fuzzy-q"], f"{prefix}coverage")
    return float(np.median(c[:, -1])), float(np.median(v[:, -1]))


def _band(ax: Any, x: np.ndarray, v: np.ndarray, label: str) -> None:
    """Median line and IQR band over the rows (seeds) of ``v`` (seeds, checkpoints)."""
    q1, med, q3 = np.percentile(v, [25, 50, 75], axis=0)
    line, = ax.plot(x, med, "o-", ms=3, label=label)
    ax.fill_between(x, q1, q3, color=line.get_color(), alpha=0.15)


def _axes_style(ax: Any, xkey: str, key: str, tc: float, tv: float) -> None:
    from matplotlib.ticker import FuncFormatter, NullFormatter

    ax.set_xscale("log")
    ax.xaxis.set_minor_formatter(NullFormatter())
    if xkey == "steps":
        ax.set_xlabel("environment steps (fuzzy-q: collected samples + iterations)")
        ax.set_xticks([2500, 5000, 10_000, 20_000, 50_000, 100_000])
        ax.xaxis.set_major_formatter(FuncFormatter(lambda x, _p: f"{x / 1000:g}k"))
    else:
        ax.set_xlabel("training CPU seconds (median over seeds)")
        ax.set_xticks([2, 5, 10, 20, 50, 100, 200])
        ax.xaxis.set_major_formatter(FuncFormatter(lambda x, _p: f"{x:g}"))
    if key.endswith("collisions_per_1000"):
        ax.set_yscale("symlog", linthresh=1.0)
        ax.set_ylim(bottom=0.0)
        ax.axhline(tc, color="k", ls=":", lw=1, label="fuzzy-q final (median)")
    if key.endswith("coverage"):
        ax.axhline(tv, color="k", ls=":", lw=1, label="fuzzy-q final (median)")
    ax.grid(alpha=0.3)


def tune_figure(runs: dict[str, list[dict[str, Any]]], path: Path) -> None:
    """Every set of the grid in the training room (the selection's view), DQN and PPO rows."""
    from matplotlib.figure import Figure

    tc, tv = targets(runs, "train_")
    fig = Figure(figsize=(12, 8.5))
    for row, algo in zip(fig.subplots(2, 2), ("dqn", "ppo"), strict=True):
        for ax, key, label in zip(row, ("train_collisions_per_1000", "train_coverage"),
                                  ("collisions / 1000 iterations", "coverage"), strict=True):
            for name, rs in runs.items():
                if name.startswith(algo):
                    _band(ax, curves(rs, "steps")[0], curves(rs, key)[1],
                          f"{name} ({len(rs)} seeds)")
            _axes_style(ax, "steps", key, tc, tv)
            ax.set_xlabel("environment steps")
            ax.set_ylabel(f"{label}, training room")
        row[0].legend(fontsize=7, ncol=2)
    fig.suptitle("Tuning: frozen policies scored in the training room (median and IQR over "
                 "the seeds every set has)")
    fig.tight_layout()
    fig.savefig(path, dpi=100)


def duel_figure(runs: dict[str, list[dict[str, Any]]], path: Path) -> None:
    """The duel: fuzzy-q and the selected sets in the unseen rooms, four panels."""
    from matplotlib.figure import Figure

    tc, tv = targets(runs)
    panels = [("steps", "collisions_per_1000", "collisions / 1000 iterations, unseen rooms"),
              ("steps", "coverage", "coverage, unseen rooms"),
              ("steps", "learning_collisions", "collisions while learning (cumulative)"),
              ("cpu_s", "collisions_per_1000", "collisions / 1000 iterations, unseen rooms")]
    fig = Figure(figsize=(12, 8.5))
    axes = fig.subplots(2, 2).ravel()
    for ax, (xkey, key, label) in zip(axes, panels, strict=True):
        for name, rs in runs.items():
            _band(ax, np.median(curves(rs, xkey)[1], axis=0), curves(rs, key)[1],
                  f"{name} ({len(rs)} seeds)")
        _axes_style(ax, xkey, key, tc, tv)
        ax.set_ylabel(label)
        if key == "learning_collisions":
            ax.set_yscale("log")
    axes[0].legend(fontsize=8)
    fig.suptitle("Obstacle avoidance, frozen policies scored in two unseen rooms "
                 "(median and IQR over seeds)")
    fig.tight_layout()
    fig.savefig(path, dpi=100)


def report(out: Path, min_seeds: int) -> None:
    """Tuning table + ``tune.png`` (training room), then the duel's table + ``duel.png``.

    The duel shows fuzzy-q and every set with at least ``min_seeds`` seeds (the
    selected ones, run with more seeds after the tuning).
    """
    runs = load(out)
    n = min(len(rs) for k, rs in runs.items() if k != "fuzzy-q")  # the seeds every set has
    tuning = {k: rs if k == "fuzzy-q" else rs[:n] for k, rs in runs.items()}
    tune_figure(tuning, out / "tune.png")
    print(tune_table(tuning, *targets(tuning, "train_")))
    duel = {k: rs for k, rs in runs.items() if k == "fuzzy-q" or len(rs) >= min_seeds}
    if len(duel) > 1:
        duel_figure(duel, out / "duel.png")
        print("\n" + table(duel, *targets(duel)))
    print(f"\nfigures: {out / 'tune.png'} {out / 'duel.png' if len(duel) > 1 else ''}")


def tune_table(runs: dict[str, list[dict[str, Any]]], tc: float, tv: float) -> str:
    """Markdown: the grid ranked by the selection rule, training-room scores only.

    Rule: over seeds x the checkpoints in the second half of the budget, the share
    of frozen policies that meet fuzzy-q's training-room collision rate *and*
    coverage (higher first), then the median collisions per 1000 there (lower
    first). Later checkpoints count so that a set which reaches the target and
    loses it again scores lower than one that holds it.
    """
    lines = [f"Target (fuzzy-q's final frozen policies in the training room, median over "
             f"seeds): {tc:.1f} collisions/1000, coverage {tv:.3f}\n",
             "| set | seeds | budget | share meeting both (2nd half) | collisions/1000 "
             "(2nd half, median) | coverage (2nd half, median) | collisions while learning "
             "(final, median) | training CPU s (median) |", "|" + "---|" * 8]
    ranked = []
    for name, rs in runs.items():
        if name == "fuzzy-q":
            continue
        steps, c = curves(rs, "train_collisions_per_1000")
        late = steps >= steps[-1] / 2
        _s, v = curves(rs, "train_coverage")
        _s, lc = curves(rs, "learning_collisions")
        _s, w = curves(rs, "cpu_s")
        met = float(np.mean((c[:, late] <= tc) & (v[:, late] >= tv)))
        ranked.append((name.split("-")[0], -met, float(np.median(c[:, late])), name,
                       f"| {name} | {len(rs)} | {int(steps[-1]):,} | {met:.2f} | "
                       f"{np.median(c[:, late]):.1f} | {np.median(v[:, late]):.3f} | "
                       f"{np.median(lc[:, -1]):.0f} | {np.median(w[:, -1]):.0f} |"))
    ranked.sort()
    lines += [r[-1] for r in ranked]
    best: dict[str, str] = {}
    for r in ranked:
        best.setdefault(r[0], r[3])
    lines.append("\nselected: " + ", ".join(f"{k}: {v}" for k, v in best.items()))
    return "\n".join(lines)


def table(runs: dict[str, list[dict[str, Any]]], target_c: float, target_v: float) -> str:
    """Markdown: final scores, steps each seed needs to reach fuzzy-q's final median scores."""
    lines = [f"Target (fuzzy-q's final frozen policies, median over seeds): {target_c:.1f} "
             f"collisions/1000, coverage {target_v:.3f}\n",
             "| method | seeds | budget (steps) | collisions/1000, final: median [IQR] | "
             "coverage, final: median [IQR] | steps to reach the collision rate, per seed | "
             "steps to reach both | seeds meeting both at the end | collisions while learning "
             "(final) | training CPU s |",
             "|" + "---|" * 10]

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
        end = int(np.sum((c[:, -1] <= target_c) & (v[:, -1] >= target_v)))
        if name == "fuzzy-q":
            rc = rb = "(the target)"
        lines.append(f"| {name} | {len(rs)} | {int(steps[-1]):,} | {iqr(c[:, -1], '.1f')} | "
                     f"{iqr(v[:, -1], '.3f')} | {rc} | {rb} | {end} of {len(rs)} | "
                     f"{iqr(lc[:, -1], '.0f')} | {np.median(w[:, -1]):.0f} |")
    return "\n".join(lines)


def _first(steps: np.ndarray, ok: np.ndarray) -> str:
    """The first checkpoint (in thousands of steps) where ``ok`` holds, or a dash."""
    i = np.flatnonzero(ok)
    return f"{steps[i[0]] / 1000:g}k" if i.size else "—"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("command", choices=("run", "report"))
    ap.add_argument("--out", type=Path, default=Path("duel"))
    ap.add_argument("--seeds", type=int, default=2, help="seeds 0 .. N-1 of every set")
    ap.add_argument("--from-seed", type=int, default=0,
                    help="skip seeds below this one (to split a run between processes)")
    ap.add_argument("--configs", nargs="+", default=["fuzzy-q", *CONFIGS],
                    help=f"any of fuzzy-q {' '.join(CONFIGS)} (default all)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--starts", type=int, default=5, help="start poses per evaluation room")
    ap.add_argument("--eval-iterations", type=int, default=1000)
    ap.add_argument("--eval-seed", type=int, default=12345)
    ap.add_argument("--min-seeds", type=int, default=5,
                    help="report: sets with this many seeds enter the duel's table and figure")
    ap.add_argument("--save-models", action="store_true", help="keep the final SB3 models")
    a = ap.parse_args()
    a.out.mkdir(parents=True, exist_ok=True)
    if a.command == "report":
        report(a.out, a.min_seeds)
        return
    for c in a.configs:
        if c != "fuzzy-q" and c not in CONFIGS:
            raise SystemExit(f"--configs: unknown '{c}'; expected fuzzy-q or one of "
                             f"{', '.join(CONFIGS)}")
    jobs = [(c, s, a) for c in a.configs for s in range(a.from_seed, a.seeds)]  # set by set
    with Pool(a.workers, maxtasksperchild=1) as pool:
        for msg in pool.imap_unordered(job, jobs):
            print(msg, flush=True)


if __name__ == "__main__":
    main()
