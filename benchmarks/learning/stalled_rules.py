"""What the learned arbitration's stalled contexts are worth: learned, or set by hand.

Question: What are the learned arbitration's stalled contexts worth: learned, or set by
hand?
Output: success and collision-free rates per trial with the rules as learned and as set,
printed.

The ``fuzzy-q-arbiter`` of ``goal-finding-learned`` has one block of rules per
goal context; the ``*_stalled`` blocks fire when the robot has not come closer
to the goal for ``stall_iterations``. This runs every trial of a log's learned
arbitration in goal episodes twice on the same pairs: as learned, and with
every stalled rule set to one weighting (``--action``, an index into the
arbiter's ``actions``; the preset's 2 is wall following alone, Bug2's "follow
the boundary when stuck"). It bounds what learning the stalled contexts
better could give with these frozen behaviours. ``--contexts all`` sets every
rule instead (``--action 0``: goal seeking alone wherever the safety hand-over
leaves the arbiter a choice, the straightest these behaviours drive; the
ceiling of SPL). Prints, per mode, the median (mean, worst) over trials of
success, collision-free success and SPL against the shortest path.

Usage (where the log and its prerequisite logs are)::

    python benchmarks/learning/stalled_rules.py logs/goal-finding-learned.h5 --world u-trap \\
        --episodes 50 --workers 2
"""

from __future__ import annotations

import argparse
from concurrent.futures import ProcessPoolExecutor
from typing import Any

import numpy as np

KEYS = ("success_rate", "collision_free_rate", "spl_shortest")


def _run(log: str, world: str, trial: int, episodes: int, seed: int,
         action: int | None, every: bool, dirs: tuple[str, ...] = ()) -> dict[str, Any]:
    """One trial's goal batch, its stalled rules (``every``: all rules) set to ``action``
    (None: as learned)."""
    import sitframe.plugins.learned_arbiter as la
    from sitframe.runs.evaluation import evaluate_log

    load = la.FuzzyQArbiter.load_policy

    def load_policy(self: Any, policy: Any) -> None:
        load(self, policy)
        c = self.fixed.size // len(self.contexts)
        for j, name in enumerate(self.contexts):
            if (every or name.endswith("_stalled")) and action is not None:
                self.fixed[j * c:(j + 1) * c] = action

    la.FuzzyQArbiter.load_policy = load_policy
    try:
        out = evaluate_log(log, world=world, trial=trial, seed=seed, goal_episodes=episodes,
                           plugins_dirs=dirs)
    finally:
        la.FuzzyQArbiter.load_policy = load
    return {k: float(out[k]) for k in KEYS}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("log", help="a goal-finding-learned log")
    ap.add_argument("--world", default="u-trap")
    ap.add_argument("--episodes", type=int, default=50)
    ap.add_argument("--seed", type=int, default=0, help="the pairs' seed")
    ap.add_argument("--action", type=int, default=2,
                    help="index of the weighting every stalled rule gets (preset: 2 = follow)")
    ap.add_argument("--contexts", choices=("stalled", "all"), default="stalled",
                    help="which rules get --action: the stalled contexts' or every one")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--plugins-dir", action="append", default=[],
                    help="a plugin folder the log's run loaded (as its --plugins-dir)")
    args = ap.parse_args()
    from sitframe.logs.reader import open_log

    trials = open_log(args.log).trial_indices()
    with ProcessPoolExecutor(args.workers) as pool:
        every = args.contexts == "all"
        runs = {mode: [pool.submit(_run, args.log, args.world, k, args.episodes, args.seed, a,
                                   every, tuple(args.plugins_dir)) for k in trials]
                for mode, a in (("as learned", None),
                                (f"{args.contexts} -> action {args.action}", args.action))}
        print(f"{args.world}, {len(trials)} trials x {args.episodes} pairs (seed {args.seed}): "
              "median (mean, worst) over trials")
        for mode, futs in runs.items():
            res = [f.result() for f in futs]
            cells = []
            for k in KEYS:
                v = np.array([r[k] for r in res])
                cells.append(f"{k} {np.median(v):.2f} ({v.mean():.3f}, {v.min():.2f})")
            print(f"  {mode}: " + "; ".join(cells))


if __name__ == "__main__":
    main()
