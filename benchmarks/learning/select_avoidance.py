"""Which avoidance rule base to fuse with goal seeking: does a selection predict goal safety?

Question: Does a short goal run in a training room predict which avoidance rule base fuses
best with goal seeking?
Output: a Markdown table of every trial's collision-free rates and the Spearman
correlations, printed.

For every trial (rule base) of an obstacle-avoidance log this runs the
goal-finding fusion (CDB, ``sitframe evaluate LOG --trial K --goal-episodes N``)

* in the log's *training* room, a short run (``--short`` random pairs, a seed of
  its own): the proposed selection score, its collision-free rate;
* in each test room (``--test`` pairs, seed 0): what the selection should
  predict, the collision-free rate there.

and prints the Spearman correlation with the test rooms' collision-free rate
of (a) today's ``trial = "best"`` score (rank sum of training-room collisions
and coverage, :func:`sitframe.logs.policies.best_trial`; lower is better, so a
useful score correlates *negatively*) and (b) the short goal run's
collision-free rate (a useful score correlates positively), and the rule base
each picks.

Usage::

    nice -n 10 python benchmarks/learning/select_avoidance.py logs/obstacle-avoidance-12.h5
"""

from __future__ import annotations

import argparse
from concurrent.futures import ProcessPoolExecutor
from typing import Any

import numpy as np
from scipy.stats import rankdata, spearmanr

TEST_WORLDS = ("goal", "novel-1", "novel-2")


def _cf(task: tuple[str, int, str, int, int]) -> dict[str, Any]:
    from sitframe.runs.evaluation import evaluate_log

    log, trial, world, seed, episodes = task
    out = evaluate_log(log, world=world, trial=trial, seed=seed, goal_episodes=episodes)
    return {"trial": trial, "world": world, "cf": out["collision_free_rate"],
            "success": out["success_rate"]}


def rank_sums(log: str) -> dict[int, float]:
    """Trial -> the rank sum :func:`sitframe.logs.policies.best_trial` minimises."""
    from sitframe.logs.reader import open_log

    lg = open_log(log)
    t = lg.summary()
    w = lg.config["experiment"]["world"]
    score = rankdata(np.asarray(t[f"eval.{w}.collisions_per_1000"], float)) + \
        rankdata(-np.asarray(t[f"eval.{w}.coverage"], float))
    return dict(zip((int(i) for i in t["trial"]), score.tolist(), strict=True))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("log")
    ap.add_argument("--short", type=int, default=20, help="pairs of the short training run")
    ap.add_argument("--test", type=int, default=100, help="pairs per test room")
    ap.add_argument("--short-world", default=None,
                    help="room of the short run (default: the log's training room)")
    ap.add_argument("--worlds", nargs="+", default=list(TEST_WORLDS), help="test rooms")
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args()
    from sitframe.logs.policies import best_trial
    from sitframe.logs.reader import open_log

    lg = open_log(args.log)
    trials = lg.trial_indices()
    train_world = args.short_world or lg.config["experiment"]["world"]
    worlds = tuple(args.worlds)
    tasks = [(args.log, k, train_world, 1000, args.short) for k in trials]
    tasks += [(args.log, k, w, 0, args.test) for w in worlds for k in trials]
    with ProcessPoolExecutor(args.workers) as pool:
        rows = list(pool.map(_cf, tasks))
    short = {r["trial"]: r["cf"] for r in rows if r["world"] == train_world}
    test = {w: {r["trial"]: r["cf"] for r in rows if r["world"] == w} for w in worlds}
    rs = rank_sums(args.log)
    print(f"| trial | rank sum (training) | short goal run CF ({train_world}) | "
          + " | ".join(f"CF {w}" for w in worlds) + " |")
    print("|---|---|---|" + "---|" * len(worlds))
    for k in trials:
        print(f"| {k} | {rs[k]:.1f} | {short[k]:.2f} | "
              + " | ".join(f"{test[w][k]:.2f}" for w in worlds) + " |")
    print()
    best_rs, best_short = best_trial(lg), max(trials, key=lambda k: (short[k], -k))
    for w in worlds:
        y = [test[w][k] for k in trials]
        a = spearmanr([rs[k] for k in trials], y).statistic
        b = spearmanr([short[k] for k in trials], y).statistic
        print(f"{w}: Spearman with test CF: rank sum {a:+.2f}, short goal run {b:+.2f}; "
              f"CF of the pick: rank sum (trial {best_rs}) {test[w][best_rs]:.2f}, "
              f"short run (trial {best_short}) {test[w][best_short]:.2f}")


if __name__ == "__main__":
    main()
