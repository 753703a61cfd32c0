"""Where a frozen fuzzy-q rule base collides: runs of collisions and the situations deciding.

Question: when a learner's frozen rule base collides often in an unseen room, is it a
scatter of glancing contacts or the robot stuck, colliding iteration after iteration, and
which situation (how often was its rule updated while learning, what does it do) decides
there?
Output: printed, per start pose: collisions, the longest run of consecutive collisions,
and for the situations that decide in collisions (largest membership) their share of the
collisions, their rule's updates while learning and their greedy heading; with
``--figure PATH`` the paths (collisions marked) as one figure.

The runs are the duel's scoring (``benchmarks/duel/duel.py``'s :func:`fuzzy_scores`: the same
start poses, seed and iterations), so a duel figure can be looked at closely::

    python benchmarks/learning/stuck.py logs/duel2/fuzzy-q-preset-43e4e07/seed-2/run.h5 \\
        gen:3000010 --figure docs/results/figures/duel-worst-seed.png
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: duel
from duel import TEST, fuzzy_scores  # noqa: E402


def longest_run(flags: np.ndarray) -> int:
    """The longest run of consecutive ``True`` in a (n,) bool array."""
    best = cur = 0
    for f in flags:
        cur = cur + 1 if f else 0
        best = max(best, cur)
    return best


def deciding(out: Any, updates: np.ndarray, greedy: np.ndarray, headings: np.ndarray
             ) -> list[tuple[int, int, int, float]]:
    """(situation id, collisions it decided, its rule's updates, its greedy heading [deg])
    for the situations with the largest membership at a collision, most collisions first."""
    hit = np.asarray(out.arrays["collision"], dtype=bool)
    top = np.asarray(out.arrays["memberships"])[hit].argmax(axis=1)
    ids, counts = np.unique(top, return_counts=True)
    order = np.argsort(-counts, kind="stable")
    return [(int(ids[k]), int(counts[k]), int(updates[ids[k]]),
             float(headings[greedy[ids[k]]])) for k in order]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("log", type=Path, help="a fuzzy-q log (its trial is judged)")
    ap.add_argument("room", help="the room (a world name, gen:SEED or a .toml path)")
    ap.add_argument("--trial", type=int, default=0)
    ap.add_argument("--behaviour", default="avoid")
    ap.add_argument("--figure", type=Path, help="write the paths as a figure here")
    a = ap.parse_args(argv)

    from sitframe.logs.reader import open_log

    runs: list[Any] = []
    score = fuzzy_scores(a.log, [a.room], TEST, trial=a.trial, keep=runs)
    tl = open_log(str(a.log)).trial(a.trial)
    data = tl.behaviours[a.behaviour]
    updates = np.asarray(data["heading/updates"])
    greedy = np.asarray(tl.policy(a.behaviour)["heading"])
    headings = np.asarray(data["actions/heading"])
    print(f"{a.log} trial {a.trial} in {a.room}: {score['collisions_per_1000']:.2f} "
          f"collisions / 1000 over {len(runs)} starts x {TEST.iterations} iterations")
    for k, out in enumerate(runs):
        hit = np.asarray(out.arrays["collision"], dtype=bool)
        print(f"start {k}: {int(hit.sum())} collisions, longest run {longest_run(hit)}")
        for sid, n, upd, head in deciding(out, updates, greedy, headings)[:3]:
            print(f"    situation {sid}: decides {n} collisions; its rule updated {upd} times "
                  f"while learning; greedy heading {head:+.0f} deg")
    if a.figure:
        draw(runs, a.room, a.figure, f"{a.log.parent.name}, trial {a.trial}")
    return 0


def draw(runs: list[Any], room: str, path: Path, who: str) -> None:
    """One panel per start: the path coloured by iteration, collisions marked."""
    from matplotlib.figure import Figure

    from sitframe.analysis.learning_plots import _draw_path
    from sitframe.sim.world import load_world

    world = load_world(room)
    fig = Figure(figsize=(3.3 * len(runs), 3.6), layout="constrained")
    for k, (ax, out) in enumerate(zip(fig.subplots(1, len(runs), squeeze=False)[0], runs,
                                      strict=True)):
        hit = np.asarray(out.arrays["collision"], dtype=bool)
        _draw_path(ax, world, np.asarray(out.arrays["pose"]), hit,
                   np.asarray(out.arrays["contact"]), 0, len(hit), 0.15, None, None)
        ax.set_title(f"start {k}: {int(hit.sum())} collisions, longest run "
                     f"{longest_run(hit)}", fontsize=8)
    fig.suptitle(f"{who} in {room}: frozen rule base, {len(runs[0].arrays['collision'])} "
                 "iterations per start", fontsize=9)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=150)
    print(f"figure: {path}")


if __name__ == "__main__":
    raise SystemExit(main())
