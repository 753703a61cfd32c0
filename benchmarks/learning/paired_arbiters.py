"""Learned arbitration against CDB over the same behaviours, spaces and start/goal pairs.

Question: Does the learned arbitration do at least as well as hand-set CDB, pair by pair,
in every room (success, collision-free, SPL), and does it meet issue 40's targets?

Output: Markdown tables (per room and arbiter: pooled rates, median (IQR) [worst] over
seeds; the paired tests with Holm; the targets met or missed) written to ``--out`` (and the
per-context counts to ``--contexts``), published in docs/results/learned-arbitration.md.

For each room and seed, the log's learned arbitration and CDB (``--arbiter cdb``: the same
behaviours, situation spaces and policies, CDB's own context sets) run the same random
start/goal pairs, exactly as::

    sitframe evaluate LOG --world W --trial K --goal-episodes N --seed S --per-episode --json
    sitframe evaluate LOG --world W --trial K --goal-episodes N --seed S --per-episode --json \\
        --arbiter cdb

(the pairs depend only on the world and the seed). Per room it reports, for both arbiters,
the rates pooled over every pair and the median (IQR) [worst] over the seeds: success,
collision-free (episodes without a collision), collision-free success (reached without a
collision) and SPL against the shortest path of the robot's disc; and a paired test of
"learned is worse than CDB" on every pair (success and collision-free success: exact
McNemar, a one-sided binomial test on the discordant pairs; SPL: one-sided Wilcoxon
signed-rank on the per-pair differences), Holm-corrected over all rooms and figures
(scipy.stats). "learned >= CDB" holds in a cell unless that test rejects at 0.05.

Targets (issue 40) are checked in every room: success >= 0.99, collision-free (success)
>= 0.95 in every room and >= 0.97 pooled over the rooms, SPL >= 0.80 (``--targets office``:
0.95, 0.93 and 0.75, and no pooled target).

The learned trial is ``--trial`` or the one a short goal-episode run in the log's own
learning world picks (most collision-free episodes, then success, then SPL; seed 1000,
never a test seed or room). Tables go to ``--out`` (Markdown, written by this script, never
hand-copied); ``--json`` keeps every batch's per-episode figures.

Usage (from a folder with the log)::

    python benchmarks/learning/paired_arbiters.py logs/goal-finding-learned.h5 --seeds 10 \\
        --episodes 50 --out docs/results/tables/learned-vs-cdb-rooms.md
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

WORLDS = ("goal", "novel-1", "novel-2", "multi-room", "u-trap", "training", "wall-following")
FIGURES = ("success", "collision_free", "cf_success", "spl")
NAMES = {"success": "success", "collision_free": "collision-free",
         "cf_success": "collision-free success", "spl": "SPL (shortest path)"}
TARGETS = {"rooms": {"success": 0.99, "collision_free": 0.95, "cf_success": 0.95, "spl": 0.80,
                     "pooled_collision_free": 0.97},
           "office": {"success": 0.95, "collision_free": 0.93, "cf_success": 0.93, "spl": 0.75}}
ALPHA = 0.05

_LOGS: dict[str, Any] = {}


def evaluate(log: str, world: str, trial: int, seed: int, episodes: int,
             arbiter: str | None) -> dict[str, Any]:
    """One batch, as ``sitframe evaluate LOG --world W --trial K --goal-episodes N --seed S
    --per-episode [--arbiter A]`` runs it (the log is opened and checked once per process)."""
    from sitframe.logs.reader import open_log
    from sitframe.runs.evaluation import evaluate_log

    if log not in _LOGS:
        _LOGS[log] = open_log(log)
        _LOGS[log].check()
    return evaluate_log(log, world=world, trial=trial, seed=seed, goal_episodes=episodes,
                        arbiter=arbiter, per_episode=True, checked=_LOGS[log])


def _task(args: tuple[str, str, int, int, int, str | None]) -> dict[str, Any]:
    log, world, trial, seed, episodes, arbiter = args
    out = evaluate(log, world, trial, seed, episodes, arbiter)
    return {"world": world, "seed": seed, "arbiter": arbiter or "learned",
            "episodes": out["per_episode"]}


def open_log_trials(log: str) -> list[int]:
    """The log's trial indices."""
    from sitframe.logs.reader import open_log

    return open_log(log).trial_indices()


def _map(tasks: list[Any], workers: int) -> list[dict[str, Any]]:
    """The batches, in this process (one worker) or a pool of ``workers`` processes."""
    if workers <= 1:
        return [_task(t) for t in tasks]
    with ProcessPoolExecutor(workers) as pool:
        return list(pool.map(_task, tasks))


def figures(ep: dict[str, list[Any]]) -> dict[str, np.ndarray]:
    """Per-episode figures: success, collision-free, collision-free success, SPL (shortest)."""
    success = np.asarray(ep["success"], bool)
    free = np.asarray(ep["collisions"]) == 0
    short = np.asarray(ep["shortest_m"], float)
    path = np.asarray(ep["path_length_m"], float)
    spl = np.where(success, short / np.maximum(np.maximum(path, short), 1e-12), 0.0)
    return {"success": success.astype(float), "collision_free": free.astype(float),
            "cf_success": (success & free).astype(float), "spl": spl}


def select_trial(log: str, episodes: int, workers: int) -> int:
    """The trial that does best in ``episodes`` goal episodes in the log's learning world
    (seed 1000): most collision-free episodes, then success, then SPL."""
    from sitframe.logs.reader import open_log

    lg = open_log(log)
    world = lg.config["experiment"]["world"]
    tasks = [(log, world, k, 1000, episodes, None) for k in lg.trial_indices()]
    rows = _map(tasks, workers)
    keys = []
    for r in rows:
        f = figures(r["episodes"])
        keys.append((f["collision_free"].mean(), f["success"].mean(), f["spl"].mean()))
    return lg.trial_indices()[max(range(len(rows)), key=keys.__getitem__)]


def holm(p: list[float]) -> list[float]:
    """Holm's step-down adjustment of the p-values ``p`` (same order)."""
    order = np.argsort(p)
    adj = np.empty(len(p))
    running = 0.0
    for rank, i in enumerate(order):
        running = max(running, min(1.0, (len(p) - rank) * p[i]))
        adj[i] = running
    return adj.tolist()


def worse_p(learned: np.ndarray, cdb: np.ndarray, figure: str) -> float:
    """One-sided p of "learned is worse than CDB" over paired episodes."""
    from scipy import stats

    if figure == "spl":
        d = learned - cdb
        if not np.any(d != 0):
            return 1.0
        return float(stats.wilcoxon(d, alternative="less", zero_method="wilcox").pvalue)
    lose = int(np.sum((cdb == 1) & (learned == 0)))  # CDB succeeded where learned did not
    win = int(np.sum((learned == 1) & (cdb == 0)))
    if lose + win == 0:
        return 1.0
    return float(stats.binomtest(lose, lose + win, 0.5, alternative="greater").pvalue)


def _cell(v: np.ndarray) -> str:
    q1, med, q3 = np.percentile(v, [25, 50, 75])
    return f"{med:.2f} ({q1:.2f}–{q3:.2f}) [{v.min():.2f}]"


def tables(rows: list[dict[str, Any]], worlds: list[str], targets: dict[str, float],
           trial: int, log: str) -> tuple[str, str, dict[str, Any]]:
    """(rates table, paired-test table, summary) as Markdown and a dict."""
    by: dict[tuple[str, str], dict[str, list[np.ndarray]]] = {}
    for r in sorted(rows, key=lambda r: r["seed"]):
        f = figures(r["episodes"])
        box = by.setdefault((r["world"], r["arbiter"]), {k: [] for k in FIGURES})
        for k in FIGURES:
            box[k].append(f[k])
    rates = ["| room | arbiter | pairs | " + " | ".join(
        f"{NAMES[k]} pooled | {NAMES[k]} median (IQR) [worst seed]" for k in FIGURES) + " |",
             "|---|---|---|" + "---|---|" * len(FIGURES)]
    summary: dict[str, Any] = {"trial": trial, "log": log, "rooms": {}, "targets": targets}
    pooled: dict[str, list[np.ndarray]] = {"learned": [], "cdb": []}
    tests = []
    for w in worlds:
        for a in ("learned", "cdb"):
            box = by[(w, a)]
            cells = []
            for k in FIGURES:
                per_seed = np.asarray([x.mean() for x in box[k]])
                cells += [f"{np.concatenate(box[k]).mean():.3f}", _cell(per_seed)]
            n = sum(x.size for x in box["success"])
            rates.append(f"| {w} | {a} | {n} | " + " | ".join(cells) + " |")
            pooled[a].append(np.concatenate(box["collision_free"]))
        room = {a: {k: float(np.concatenate(by[(w, a)][k]).mean()) for k in FIGURES}
                for a in ("learned", "cdb")}
        summary["rooms"][w] = room
        for k in FIGURES:
            le, cd = np.concatenate(by[(w, "learned")][k]), np.concatenate(by[(w, "cdb")][k])
            tests.append((w, k, le, cd, worse_p(le, cd, k), worse_p(cd, le, k)))
    adj = holm([t[4] for t in tests])
    adj_better = holm([t[5] for t in tests])
    paired = ["| room | figure | learned | CDB | learned − CDB | p (learned worse) | "
              "Holm p | p (learned better), Holm | learned ≥ CDB |",
              "|---|---|---|---|---|---|---|---|---|"]
    for (w, k, le, cd, p, _pb), pa, pb in zip(tests, adj, adj_better, strict=True):
        ok = pa >= ALPHA
        summary["rooms"][w].setdefault("paired", {})[k] = {
            "p_worse": p, "holm_p_worse": pa, "holm_p_better": pb, "learned_ge_cdb": ok}
        paired.append(f"| {w} | {NAMES[k]} | {le.mean():.3f} | {cd.mean():.3f} | "
                      f"{le.mean() - cd.mean():+.3f} | {p:.3g} | {pa:.3g} | {pb:.3g} | "
                      f"{'yes' if ok else '**no**'} |")
    cf_pooled = float(np.concatenate(pooled["learned"]).mean())
    summary["pooled_collision_free"] = {"learned": cf_pooled,
                                        "cdb": float(np.concatenate(pooled["cdb"]).mean())}
    lines = [f"Learned arbitration (trial {trial} of `{log}`) and CDB on the same pairs; "
             "pooled = over every pair of the room, median (IQR) [worst] over seeds.", "",
             *rates, "", f"Collision-free pooled over the rooms: learned {cf_pooled:.3f}, "
             f"CDB {summary['pooled_collision_free']['cdb']:.3f}.", ""]
    checks = ["| target | " + " | ".join(worlds) + " |", "|---|" + "---|" * len(worlds)]
    for k in FIGURES:
        vals = [summary["rooms"][w]["learned"][k] for w in worlds]
        checks.append(f"| learned {NAMES[k]} ≥ {targets[k]:.2f} | " + " | ".join(
            f"{v:.3f} {'met' if v >= targets[k] else '**missed**'}" for v in vals) + " |")
    if "pooled_collision_free" in targets:
        t = targets["pooled_collision_free"]
        lines.append(f"Target collision-free pooled ≥ {t:.2f}: {cf_pooled:.3f} "
                     f"{'met' if cf_pooled >= t else '**missed**'}.")
        lines.append("")
    lines += ["Targets, per room (pooled rates):", "", *checks]
    return "\n".join(lines) + "\n", "\n".join(paired) + "\n", summary


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("log")
    ap.add_argument("--worlds", nargs="+", default=list(WORLDS))
    ap.add_argument("--trial", type=int, default=None)
    ap.add_argument("--select-episodes", type=int, default=100)
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--episodes", type=int, default=50)
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--targets", choices=sorted(TARGETS), default="rooms")
    ap.add_argument("--out", required=True, help="Markdown file of the tables")
    ap.add_argument("--json", default=None, help="every batch's per-episode figures")
    ap.add_argument("--contexts", default=None,
                    help="Markdown file of the learning arbiter's per-context visits, "
                    "updates and convergence over the log's trials")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    k = args.trial
    if k is None:
        k = select_trial(args.log, args.select_episodes, args.workers)
    tasks = [(args.log, w, k, s, args.episodes, arb) for w in args.worlds
             for s in range(args.seeds) for arb in (None, "cdb")]
    rows = _map(tasks, args.workers)
    worlds = [Path(w).stem if w.endswith(".toml") else w for w in args.worlds]
    for r in rows:
        r["world"] = Path(r["world"]).stem if r["world"].endswith(".toml") else r["world"]
    rates, paired, summary = tables(rows, worlds, TARGETS[args.targets], k, args.log)
    cmd = " ".join(["python", "benchmarks/learning/paired_arbiters.py", *(argv or sys.argv[1:])])
    minutes = (time.perf_counter() - t0) / 60
    doc = (f"<!-- written by benchmarks/learning/paired_arbiters.py; do not edit -->\n\n"
           f"Command: `{cmd}` ({minutes:.1f} min, {args.workers} worker(s)); learned trial "
           f"{k}" + (" (chosen by a short goal run in the learning world)"
                     if args.trial is None else "") + ".\n\n"
           f"{rates}\nPaired, learned against CDB on the same pairs (one-sided tests of "
           f"\"learned is worse\", Holm-corrected over the {len(worlds) * len(FIGURES)} "
           f"cells; α = {ALPHA}):\n\n{paired}")
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(doc)
    if args.contexts:
        from sitframe.analysis.results import contexts_table

        Path(args.contexts).write_text(
            f"<!-- written by benchmarks/learning/paired_arbiters.py; do not edit -->\n\nCommand: "
            f"`{cmd}`; the log's {len(open_log_trials(args.log))} learning trials.\n\n"
            + contexts_table(args.log).to_markdown() + "\n")
    print(doc)
    if args.json:
        Path(args.json).write_text(json.dumps({"summary": summary, "rows": rows},
                                              default=lambda o: None if isinstance(o, float)
                                              and math.isnan(o) else o))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
