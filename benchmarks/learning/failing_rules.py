"""Which rules decide where a preset's frozen rule bases fail in unseen rooms (issue 39)?

Question: In the evaluations of ``preset_safety.py`` above 10 collisions per 1000, is the
rule that decides at a collision (the situation of largest membership, its greedy action)
one whose action was never tried while learning (its Q still at ``q_init_value``), or a
tried one, and how well was it learnt: how often was the situation's rule updated, and by
how much does its greedy action's Q lead the runner-up's?
Output: a Markdown table, one row per preset folder of ``preset_safety.py``'s cache
(``logs/preset-safety/LABEL``, which keeps each seed's log), printed and with
``--publish`` written to ``docs/results/tables/failing-rules.md``.

Every failing evaluation is driven again as ``preset_safety.py`` judged it (``sitframe
evaluate LOG --world ROOM --trial K``: 1000 iterations from the room's start, evaluation
seed 0; the collision counts equal the cached ones, checked). "Never tried" means the
greedy action's Q equals ``q_init_value`` exactly (an update landing exactly on it is not
told apart). Usage::

    python benchmarks/learning/failing_rules.py logs/preset-safety/obstacle-avoidance-12-one-room \\
        logs/preset-safety/obstacle-avoidance-8-one-room --publish
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: duel, common
from common.publish import publish  # noqa: E402
from duel import EvalSpec, fuzzy_scores  # noqa: E402

#: ``sitframe evaluate``'s judging: one start (the room's own), 1000 iterations, seed 0.
JUDGED = EvalSpec(starts=1, iterations=1000, seed=0)
BAD = 10.0


def deciding_rules(folder: Path, behaviour: str, seeds: range = range(10)) -> dict[str, Any]:
    """For every failing evaluation cached in ``folder`` for ``seeds`` (the run seeds
    ``preset_safety.py`` judged; a folder may hold others, e.g. seeds 10-19 held out):
    each collision's deciding rule."""
    from sitframe.logs.reader import open_log

    untried = tried = 0
    updates: list[int] = []  # the top deciding situation's, one per failing evaluation
    gaps: list[float] = []  # its greedy Q minus its runner-up's
    all_updates: list[int] = []  # every situation of the failing learners, for scale
    n_eval = n_fail = 0
    seen: set[tuple[int, int]] = set()
    for js in [folder / f"seed-{s}.json" for s in seeds]:
        if not js.is_file():
            raise SystemExit(f"{folder}: no {js.name} (run preset_safety.py for seed "
                             f"{js.stem.removeprefix('seed-')} first)")
        d = json.loads(js.read_text("utf-8"))
        log_path = js.with_suffix(".h5")
        log = open_log(str(log_path))
        q0 = float(log.config["behaviours"][behaviour].get("q_init_value", 0.0))
        for key, v in d["evaluations"].items():
            n_eval += 1
            if v["collisions_per_1000"] <= BAD:
                continue
            n_fail += 1
            trial, room = int(key.split("@")[0]), key.split("@", 1)[1]
            runs: list[Any] = []
            score = fuzzy_scores(log_path, [room], JUDGED, trial=trial, keep=runs)
            if abs(score["collisions_per_1000"] - v["collisions_per_1000"]) > 1e-9:
                raise SystemExit(f"{log_path} trial {trial} in {room}: "
                                 f"{score['collisions_per_1000']} collisions / 1000 driven "
                                 f"again, {v['collisions_per_1000']} cached")
            data = log.trial(trial).behaviours[behaviour]
            q = np.asarray(data["q/heading"])
            upd = np.asarray(data["heading/updates"])
            greedy = np.asarray(log.trial(trial).policy(behaviour)["heading"])
            if (d["seed"], trial) not in seen:
                seen.add((d["seed"], trial))
                all_updates += upd.tolist()
            hit = np.asarray(runs[0].arrays["collision"], dtype=bool)
            top = np.asarray(runs[0].arrays["memberships"])[hit].argmax(axis=1)
            never = q[top, greedy[top]] == q0
            untried += int(never.sum())
            tried += int((~never).sum())
            s = int(np.bincount(top).argmax())
            updates.append(int(upd[s]))
            row = np.sort(q[s])
            gaps.append(float(row[-1] - row[-2]))
    return {"evaluations": n_eval, "failing": n_fail, "learners": len(seen),
            "untried": untried, "tried": tried, "updates": updates, "gaps": gaps,
            "all_updates": all_updates}


def _iqr(x: list[float], fmt: str) -> str:
    if not x:
        return "–"
    q1, med, q3 = np.percentile(x, [25, 50, 75])
    return f"{med:{fmt}} ({q1:{fmt}}–{q3:{fmt}})"


def table(rows: list[tuple[str, dict[str, Any]]]) -> str:
    head = ("| preset | failing evaluations | collisions in them | decided by an action never "
            "tried | deciding situation's updates, median (IQR) | every situation's updates "
            "(same learners) | its greedy Q's lead over the runner-up |\n"
            "|---|---|---|---|---|---|---|\n")
    body = ""
    for name, r in rows:
        n = r["untried"] + r["tried"]
        body += (f"| `{name}` | {r['failing']} of {r['evaluations']} ({r['learners']} "
                 f"learners) | {n} | {r['untried']} ({100 * r['untried'] / max(n, 1):.1f} %) | "
                 f"{_iqr(r['updates'], '.0f')} | {_iqr(r['all_updates'], '.0f')} | "
                 f"{_iqr(r['gaps'], '.1f')} |\n")
    return head + body


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("folders", nargs="+", type=Path,
                    help="preset_safety.py's per-preset folders (seed-K.json + seed-K.h5)")
    ap.add_argument("--behaviour", default=None,
                    help="the learning behaviour's label (default: the config's only one)")
    ap.add_argument("--seeds", type=int, default=10, help="how many run seeds (default 10)")
    ap.add_argument("--first-seed", type=int, default=0, help="the first run seed (default 0)")
    ap.add_argument("--publish", nargs="?", const="failing-rules", default=None)
    a = ap.parse_args(argv)
    seeds = range(a.first_seed, a.first_seed + a.seeds)
    rows = []
    for folder in a.folders:
        beh = a.behaviour or _behaviour(folder)
        rows.append((folder.name, deciding_rules(folder, beh, seeds)))
        print(f"{folder.name}: done", file=sys.stderr, flush=True)
    md = table(rows)
    print(md)
    if a.publish:
        publish(a.publish, md)
    return 0


def _behaviour(folder: Path) -> str:
    from sitframe.logs.reader import open_log

    first = next(iter(sorted(folder.glob("seed-*.h5"))), None)
    if first is None:
        raise SystemExit(f"{folder}: no seed-K.h5 log (run preset_safety.py first)")
    labels = list(open_log(str(first)).config["behaviours"])
    if len(labels) != 1:
        raise SystemExit(f"{folder}: behaviours {labels}; name one with --behaviour")
    return labels[0]


if __name__ == "__main__":
    raise SystemExit(main())
