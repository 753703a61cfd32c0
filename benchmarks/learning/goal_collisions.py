"""Where goal episodes collide: which behaviour was driving, and whether the sonars saw it.

Question: When goal episodes collide, which behaviour was driving, and did the sonars see
the obstacle?
Output: a Markdown table of the collisions per world, sorted by the arbiter's weights,
printed.

Runs the goal episodes of a goal log's trial (exactly as ``sitframe evaluate
LOG --world W --trial K --goal-episodes N --seed S`` does, via
``compare_arbiters``) and sorts every collision by the arbiter's weights at
the iteration that ended in it:

* **avoid alone** (the avoiding behaviour's weight is 1): the avoidance rule
  base's own collision; counted apart when the reading lay *between
  prototypes* (no situation's membership reaches 0.5);
* **blended**: both behaviours had weight;
* **goal alone**: goal seeking drove; counted apart when the obstacle was
  **unseen** -- the nearest sonar reading was above 0.5 m while the robot's
  rim was within 0.2 m of a wall or obstacle edge (the obstacle lay in a gap
  between the sonar cones, or beside or behind the robot, where the eight
  front sonars do not look).

Usage (from the folder holding the logs)::

    python benchmarks/learning/goal_collisions.py logs/goal-finding.h5 --episodes 200
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))  # learning/: compare_arbiters
from compare_arbiters import WORLDS, _batch  # noqa: E402

UNSEEN_SONAR = 0.5  # m: the nearest reading above this ...
UNSEEN_RIM = 0.2  # m: ... while the rim is this close to an edge: the sonars missed it


def classify(log: str, trial: int, world: str, seed: int, episodes: int,
             avoid: str = "avoid") -> dict[str, Any]:
    """Counts of the collisions of one batch by class (module docstring)."""
    from sitframe.sim.geometry import min_distance
    from sitframe.sim.world import load_world

    edges = load_world(world).segment_set
    rows: list[tuple[float, float, float, float]] = []

    def hook(rec: Any) -> None:
        t = rec.transition
        if t.outcome.collided:
            labels = list(rec.proposals)
            w = float(rec.weights[labels.index(avoid)])
            rim = float(min_distance(t.before.pose[None, :2], edges)[0]) - 0.15
            rows.append((w, float(t.before.memberships.max()), float(t.before.nearest), rim))

    r = _batch(log, trial, None, world, seed, episodes, step_hook=hook)
    n_it = int(r.arrays["collision"].size)
    a = np.asarray(rows).reshape(-1, 4)
    alone, goal = a[:, 0] > 0.999, a[:, 0] < 0.001
    return {"world": world, "iterations": n_it, "collisions": len(a),
            "avoid alone": int(alone.sum()),
            "  between prototypes": int((alone & (a[:, 1] < 0.5)).sum()),
            "blended": int((~alone & ~goal).sum()), "goal alone": int(goal.sum()),
            "  unseen": int((goal & (a[:, 2] > UNSEEN_SONAR) & (a[:, 3] < UNSEEN_RIM)).sum()),
            "episodes with a collision": int((np.asarray(r.episodes["collisions"]) > 0).sum())}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("log")
    ap.add_argument("--trial", type=int, default=0)
    ap.add_argument("--worlds", nargs="+", default=list(WORLDS))
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--episodes", type=int, default=200)
    args = ap.parse_args()
    rows = [classify(args.log, args.trial, w, args.seed, args.episodes) for w in args.worlds]
    keys = [k for k in rows[0] if k != "world"]
    print("| world | " + " | ".join(k.strip() for k in keys) + " |")
    print("|---" * (len(keys) + 1) + "|")
    for r in rows:
        print(f"| {r['world']} | " + " | ".join(str(r[k]) for k in keys) + " |")
    tot = {k: sum(r[k] for r in rows) for k in keys}
    print("| all | " + " | ".join(str(tot[k]) for k in keys) + " |")


if __name__ == "__main__":
    main()
