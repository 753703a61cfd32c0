"""Goal reaching by arbiter: hand CDB, priority and the learned arbitration, on the same pairs.

Question: On the same start/goal pairs, how do hand CDB, priority switching and the
learned arbitration reach goals?
Output: a Markdown table per world and arbiter (median over seeds, IQR, worst seed)
printed, and --figure a typical pair drawn; with --publish NAME the table in
docs/results/tables/NAME.md.

For each world and seed, every arbiter runs the same ``--episodes`` random
start/goal pairs (``sitframe evaluate LOG --world W --goal-episodes N --seed
S``: the pairs depend only on the world and the seed). Prints, per arbiter and
world, the median over seeds (IQR, worst) of success, collision-free success
(episodes without a collision), SPL against the straight line and against
the shortest path the robot's disc can drive, the mean time to the goal and the heading
change per metre, as a Markdown table; ``--json`` writes every batch's scores;
``--figure`` draws one typical pair per arbiter in ``--figure-world``.

Usage (from the repository root, with the logs of the presets in ``logs/``)::

    nice -n 10 python benchmarks/learning/compare_arbiters.py --seeds 10 --episodes 50 \\
        --json compare.json --figure docs/results/figures/arbiters-multi-room.png

The learned trial is ``--learned-trial`` or, by default, the one
:func:`select_trial` picks: the best of a short goal-episode run in the log's
own learning world (never a test world).
"""

from __future__ import annotations

import argparse
import json
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

WORLDS = ("goal", "novel-1", "novel-2", "multi-room", "u-trap")
KEYS = ("success_rate", "collision_free_rate", "spl", "spl_shortest", "mean_time_s",
        "heading_change_per_m")


_LOADED: dict[tuple[str, int, str | None], Any] = {}


def _load(log: str, trial: int, arbiter: str | None) -> Any:
    """The resolved config, policies and situations of a log's trial, read once per process
    (``evaluate_log`` re-reads and checksums the whole log on every call)."""
    key = (log, trial, arbiter)
    if key not in _LOADED:
        from sitframe.contract.config import validate_config
        from sitframe.contract.pluginmanager import Registry, get_plugin_manager
        from sitframe.logs.policies import logged_policy as _logged_policy
        from sitframe.logs.reader import open_log

        lg = open_log(log)
        cfg = validate_config(lg.config, file=log)
        tl = lg.trial(trial)
        policies = {lb: p for lb in tl.behaviours
                    if (p := _logged_policy(tl, lb, log)) is not None}
        state = open_log(cfg["experiment"]["clusters_from"]).interpreter_state() \
            if cfg["experiment"]["clusters_from"] else lg.interpreter_state()
        if arbiter is not None:
            params = cfg["arbiter"] if cfg["arbiter"].get("component") == arbiter else {}
            cfg["arbiter"] = {**params, "component": arbiter}
        _LOADED[key] = (cfg, policies, (state, lg.space_states()),
                        Registry.collect(get_plugin_manager()))
    return _LOADED[key]


def _batch(log: str, trial: int, arbiter: str | None, world: str, seed: int,
           episodes: int, step_hook: Any = None) -> Any:
    """One batch of goal episodes, exactly as ``sitframe evaluate LOG --world W --trial K
    --goal-episodes N --seed S [--arbiter A]`` runs it (``step_hook`` sees every
    iteration's :class:`sitframe.contract.records.StepRecord`)."""
    from sitframe.contract.resolve import Resolved
    from sitframe.runs.loop import STAGE_BATCH, TrialSpec, simulate, stage_seed

    cfg, policies, (state, spaces), registry = _load(log, trial, arbiter)
    cfg = {**cfg, "goal": {**cfg["goal"], "episodes": episodes}}
    res = Resolved.build(cfg, registry, log)
    spec = TrialSpec(index=trial, seed=stage_seed(seed, STAGE_BATCH, 0), world=world,
                     iterations=int(cfg["goal"]["timeout"]), learn=False,
                     interpreter_state=state, policies=policies, protocol="goal-episodes",
                     space_states=spaces)  # (situation spaces of their own, as evaluate_log)
    return simulate(res, spec, step_hook=step_hook)


def _evaluate(task: tuple[str, str, int, str | None, str, int, int]) -> dict[str, Any]:
    from sitframe.runs.loop import batch_scores

    name, log, trial, arbiter, world, seed, episodes = task
    out = batch_scores(_batch(log, trial, arbiter, world, seed, episodes))
    return {"arbiter": name, "world": world, "seed": seed, **{k: out[k] for k in KEYS}}


def select_trial(log: str, episodes: int = 100, seed: int = 1000, workers: int = 2) -> int:
    """The trial whose frozen policies do best in a short goal-episode run in the log's
    learning world: most collision-free episodes, then success, then SPL."""
    from sitframe.logs.reader import open_log

    lg = open_log(log)
    world = lg.config["experiment"]["world"]
    tasks = [("t", log, k, None, world, seed, episodes) for k in lg.trial_indices()]
    with ProcessPoolExecutor(workers) as pool:
        rows = list(pool.map(_evaluate, tasks))
    keys = [(r["collision_free_rate"], r["success_rate"], r["spl"]) for r in rows]
    return lg.trial_indices()[max(range(len(rows)), key=keys.__getitem__)]


def table(rows: list[dict[str, Any]], arbiters: list[str], worlds: list[str]) -> str:
    """Markdown: median (IQR) [worst] over seeds, per world and arbiter."""
    lines = ["| world | arbiter | success | collision-free | SPL | SPL (shortest path) | "
             "time to goal [s] | heading change [deg/m] |", "|---|---|---|---|---|---|---|---|"]
    for w in worlds:
        for a in arbiters:
            sel = [r for r in rows if r["world"] == w and r["arbiter"] == a]
            cells = []
            for k in KEYS:
                v = np.asarray([r[k] for r in sel], float)
                q1, med, q3 = np.nanpercentile(v, [25, 50, 75])
                worst = np.nanmax(v) if k in ("mean_time_s", "heading_change_per_m") \
                    else np.nanmin(v)
                fmt = ".0f" if k in ("mean_time_s", "heading_change_per_m") else ".2f"
                cells.append(f"{med:{fmt}} ({q1:{fmt}}–{q3:{fmt}}) [{worst:{fmt}}]")
            lines.append(f"| {w} | {a} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def draw_paths(runs: list[tuple[str, str, int, str | None]], world: str, seed: int,
               episodes: int, out: str) -> None:
    """One typical episode per arbiter (the pair whose SPLs are nearest the arbiters'
    median SPL among pairs every arbiter reaches) in ``world``, on one figure."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from sitframe.sim.draw import plot_world

    paths = {name: _episode_paths(log, trial, arbiter, world, seed, episodes)
             for name, log, trial, arbiter in runs}
    ok = np.all([p["success"] for p in paths.values()], axis=0)
    spl = np.asarray([p["spl"] for p in paths.values()])
    med = np.median(spl, axis=1, keepdims=True)
    score = np.where(ok, np.abs(spl - med).sum(axis=0), np.inf)
    e = int(np.argmin(score))
    fig, axes = plt.subplots(1, len(runs), figsize=(5.2 * len(runs), 3.9), squeeze=False)
    from sitframe.sim.world import load_world
    w = load_world(world)
    for ax, (name, p) in zip(axes[0], paths.items(), strict=True):
        plot_world(w, ax=ax, show_start=False, show_goal=False)
        xy = p["poses"][e]
        gx, gy, gr = p["goals"][e]
        ax.add_patch(plt.Circle((gx, gy), gr, color="gold", alpha=0.6))
        ax.plot(gx, gy, "*", color="darkgoldenrod", ms=10)
        ax.plot(xy[:, 0], xy[:, 1], "-", color="tab:blue", lw=1.5)
        hits = p["hits"][e]
        if len(hits):
            ax.plot(hits[:, 0], hits[:, 1], "x", color="red", ms=8, mew=2, label="collision")
            ax.legend(loc="lower right", fontsize=8)
        ax.plot(*xy[0], "o", color="tab:green", ms=7)
        ax.set_title(f"{name}: {'reached' if p['success'][e] else 'not reached'} in "
                     f"{p['time'][e]:.0f} s, SPL {p['spl'][e]:.2f}, {len(hits)} collision"
                     f"{'' if len(hits) == 1 else 's'}",
                     fontsize=9)
    fig.suptitle(f"Goal episode {e} of seed {seed} in '{world}' (start: green dot, goal: star)")
    fig.tight_layout()
    fig.savefig(out, dpi=110)


def _episode_paths(log: str, trial: int, arbiter: str | None, world: str, seed: int,
                   episodes: int) -> dict[str, Any]:
    """Per-episode paths of one arbiter's batch (as ``evaluate_log`` runs it)."""
    from sitframe.sim.metrics import spl as spl_of

    r = _batch(log, trial, arbiter, world, seed, episodes)
    first = list(r.episodes["first_iteration"]) + [r.arrays["collision"].size]
    pose, coll = r.arrays["pose"], r.arrays["collision"]
    poses, hits = [], []
    for e in range(len(first) - 1):
        a, b = first[e], first[e + 1]
        poses.append(pose[a + e:b + e + 1, :2])  # one extra pose row per episode
        hits.append(pose[a + e + 1:b + e + 1, :2][coll[a:b]])
    ep = r.episodes
    spls = [spl_of(np.asarray([s]), np.asarray([st]), np.asarray([pl])) for s, st, pl in
            zip(ep["success"], ep["straight_m"], ep["path_length_m"], strict=True)]
    return {"poses": poses, "hits": hits, "success": np.asarray(ep["success"], bool),
            "goals": np.asarray(ep["goal"], float),
            "spl": np.asarray(spls), "time": np.asarray(ep["time_s"], float)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--cdb-log", default="logs/goal-finding.h5")
    ap.add_argument("--learned-log", default="logs/goal-finding-learned.h5")
    ap.add_argument("--learned-trial", type=int, default=None)
    ap.add_argument("--select-episodes", type=int, default=100,
                    help="episodes of the short run that picks the learned trial")
    ap.add_argument("--worlds", nargs="+", default=list(WORLDS))
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--episodes", type=int, default=50)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--json", default=None, help="write every batch's scores here")
    ap.add_argument("--figure", default=None, help="PNG of one typical episode per arbiter")
    ap.add_argument("--figure-world", default="multi-room")
    ap.add_argument("--publish", metavar="NAME",
                    help="also write the table to docs/results/tables/NAME.md")
    args = ap.parse_args()
    k = args.learned_trial
    if k is None:
        k = select_trial(args.learned_log, args.select_episodes, workers=args.workers)
        print(f"learned trial {k}: the best of a {args.select_episodes}-episode goal run in "
              "its learning world")
    runs = [("cdb", args.cdb_log, 0, None), ("priority", args.cdb_log, 0, "priority"),
            ("learned", args.learned_log, k, None)]
    tasks = [(name, log, trial, arb, w, s, args.episodes) for w in args.worlds
             for s in range(args.seeds) for name, log, trial, arb in runs]
    with ProcessPoolExecutor(args.workers) as pool:
        rows = list(pool.map(_evaluate, tasks))
    text = table(rows, [r[0] for r in runs], args.worlds)
    print(text)
    if args.publish:
        sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: common
        from common.publish import publish

        publish(args.publish, text)
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"learned_trial": k, "rows": rows}, f, indent=1)
    if args.figure:
        draw_paths(runs, args.figure_world, 0, args.episodes, args.figure)
        print(f"figure: {args.figure}")


if __name__ == "__main__":
    main()
