"""Which learning recipe makes fuzzy-Q obstacle avoidance generalise to unseen rooms (issue 39)?

Question: Which learning recipe (rooms learnt in, episodes, convergence rule, reward)
makes a frozen obstacle-avoidance rule base collide least and sweep most of rooms it never
saw, within one learner's budget (``sitframe run CONFIG --trials 1 --seed S``)?
Output: the ablation table (one row per recipe: collisions per 1000 iterations median
[IQR] and worst seed, coverage median and worst seed, steps, collisions while learning,
share of evaluations above 10 per 1000), printed and with ``--publish`` written to
``docs/results/tables/generalisation.md``; per-seed figures cached as JSON in ``--out``.

Every recipe is the ``obstacle-avoidance`` preset as it was before issue 39
(``benchmarks/learning/generalisation/before.toml``) with some keys changed
(:data:`RECIPES`; ``--list`` prints them, ``--write-configs DIR`` writes them as TOML
files); ``shipped`` is the preset as it is now. For each recipe and seed ``S``:
``sitframe run CONFIG --trials 1 --seed S --workers 1`` (without its evaluate stage:
judging is done here), then the frozen trial-0 policy is run 1000 iterations from the
start of each development room (``gen:2000000`` ... ``gen:2000019``, rooms no recipe
learns or collects in), which is ``sitframe evaluate LOG --world W --trial 0``
(evaluation seed 0). A seed's collisions per 1000 are pooled
over its rooms, its coverage is the mean over them. Steps are everything the learner
spends in the simulator: the collected samples, the learning iterations and the
iterations its candidates run in validation rooms.

Training rooms are ``gen:1000000`` ... ``gen:1000009`` and the shipped training and
collection rooms; test rooms (``gen:3000000`` ...) are never touched.

Usage (one core, one process; a recipe takes about 4 minutes for 10 seeds)::

    taskset -c 0 nice -n 5 python benchmarks/learning/generalisation.py --seeds 10 --publish
    python benchmarks/learning/generalisation.py --recipes base rooms --seeds 2   # a few
"""

from __future__ import annotations

import argparse
import contextlib
import copy
import hashlib
import io
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: common
from common import per_seed  # noqa: E402
from common.publish import publish  # noqa: E402

TRAIN_ROOMS = [f"gen:{1_000_000 + i}" for i in range(10)]
#: The ``obstacle-avoidance`` preset before issue 39, which every recipe but ``shipped``
#: changes.
BEFORE = Path(__file__).resolve().parent / "generalisation" / "before.toml"
DEV_ROOMS = [f"gen:{2_000_000 + i}" for i in range(20)]
COLLECT_ROOMS = ["collect-1", "collect-2", "collect-3", "collect-4", "collect-5"]
#: An evaluation above this many collisions per 1000 iterations is a bad one (the
#: "every shipped preset safe" target of issue 39).
BAD = 10.0

#: In a recipe's keys, stands for the training rooms (``--train-rooms``, default
#: :data:`TRAIN_ROOMS`) in a list of rooms; ``LEARN`` and ``VALIDATE`` for all but the last
#: two of them and those two (a recipe that chooses among candidates holds them out).
TRAIN, LEARN, VALIDATE = "@train", "@learn", "@validate"
_ROOMS = {"experiment": {"rooms": [TRAIN], "episode_iterations": 250},
          "collect": {"worlds": [*COLLECT_ROOMS, TRAIN]}}
_MU50 = {"behaviours": {"avoid": {"min_updates": 50}}}

#: The obstacle-avoidance-evolving preset's interpreter (situations created, split and
#: merged on-line), here from the preset's 8 fitted situations.
_EVOLVING = {"component": "evolving", "capacity": 48, "create_distance": 1.8,
             "create_after": 3, "prior_weight": 100.0, "adapt": True, "merge_distance": 0.4,
             "split_ratio": 4.0, "split_min_updates": 100, "split_min_distance": 0.4,
             "error_decay": 0.9, "prune_after": 0, "check_every": 50}

def _reh(collect: dict[str, Any], iterations: int | None = None) -> dict[str, Any]:
    """rooms-evolving-heading's keys with another ``[collect]`` (and learning length)."""
    keys = _ROOMS | {"interpreter": _EVOLVING, "collect": collect, "behaviours": {"avoid": {
        "reward_params": {"heading_cost": 0.3}}}}
    if iterations is not None:
        keys["experiment"] = {**_ROOMS["experiment"], "iterations": iterations}
    return keys


def _mu(keys: dict[str, Any], n: int) -> dict[str, Any]:
    """``keys`` with ``min_updates = n`` for the avoid behaviour."""
    avoid = {**keys["behaviours"]["avoid"], "min_updates": n}
    return keys | {"behaviours": {"avoid": avoid}}


def _mu20_with(interpreter: dict[str, Any], avoid: dict[str, Any]) -> dict[str, Any]:
    """rooms-evolving-heading-gen200-mu20 with some interpreter and avoid keys changed."""
    keys = _mu(_reh({"worlds": [TRAIN], "wander_samples": 200}), 20)
    return keys | {"interpreter": {**keys["interpreter"], **interpreter},
                   "behaviours": {"avoid": {**keys["behaviours"]["avoid"], **avoid}}}


def _rooms_n(n: int, samples: int, episode: int) -> dict[str, Any]:
    """rooms-evolving-heading-gen200-mu20 over the first ``n`` generated training rooms."""
    rooms = [f"gen:{1_000_000 + i}" for i in range(n)]
    keys = _mu(_reh({"worlds": rooms, "wander_samples": samples}), 20)
    return keys | {"experiment": {"rooms": rooms, "episode_iterations": episode}}


#: Recipe -> (what it changes, the keys it sets on the shipped preset, merged table by table).
RECIPES: dict[str, tuple[str, dict[str, Any]]] = {
    "base": ("the preset before issue 39: learn in `training` only", {}),
    "shipped": ("the `obstacle-avoidance` preset as shipped now "
                "(rooms-evolving-heading-gen200-mu20-merge08, its evaluation rooms aside)", {}),
    "rooms": ("collect also in the 10 generated training rooms (wander); learn in "
              "250-iteration episodes over them, room and free start pose drawn per episode",
              _ROOMS),
    "rooms-mu50": ("rooms + convergence needs 50 updates of every situation's rules "
                   "(`min_updates = 50`)", _ROOMS | _MU50),
    "rooms-mu50-progress": (
        "rooms-mu50 + reward for moving away from the position 8 iterations back "
        "(`progress = 20` per metre: +4.5 per straight step)",
        _ROOMS | {"behaviours": {"avoid": {"min_updates": 50, "reward_params": {
            "progress": 20.0, "progress_window": 8}}}}),
    "rooms-progress": (
        "rooms + the progress reward (`progress = 20`, window 8)",
        _ROOMS | {"behaviours": {"avoid": {"reward_params": {
            "progress": 20.0, "progress_window": 8}}}}),
    "rooms-mu50-heading": (
        "rooms-mu50 + turning costs 3x (`heading_cost = 0.3`)",
        _ROOMS | {"behaviours": {"avoid": {"min_updates": 50, "reward_params": {
            "heading_cost": 0.3}}}}),
    "rooms-mu50-cand3": (
        "rooms-mu50, learning in 8 of the rooms, 3 candidates of 1667 iterations, the best "
        "in the other 2 (500 iterations each) kept",
        {"experiment": {"rooms": [LEARN], "episode_iterations": 250, "candidates": 3,
                        "validation_rooms": [VALIDATE], "validation_iterations": 500},
         "collect": _ROOMS["collect"], **_MU50}),
    "rooms-cand3": (
        "rooms-mu50-cand3 without min_updates",
        {"experiment": {"rooms": [LEARN], "episode_iterations": 250, "candidates": 3,
                        "validation_rooms": [VALIDATE], "validation_iterations": 500},
         "collect": _ROOMS["collect"]}),
    "rooms-mu50-evolving": (
        "rooms-mu50 with situations evolving on-line from the 8 fitted ones (the "
        "obstacle-avoidance-evolving preset's interpreter)",
        _ROOMS | _MU50 | {"interpreter": _EVOLVING}),
    "rooms-evolving": ("rooms-mu50-evolving without min_updates", _ROOMS | {
        "interpreter": _EVOLVING}),
    "rooms-mu50-evolving-heading": (
        "rooms-mu50-evolving + turning costs 3x (`heading_cost = 0.3`)",
        _ROOMS | {"interpreter": _EVOLVING, "behaviours": {"avoid": {
            "min_updates": 50, "reward_params": {"heading_cost": 0.3}}}}),
    "rooms-evolving-heading": (
        "rooms-mu50-evolving-heading without min_updates",
        _ROOMS | {"interpreter": _EVOLVING, "behaviours": {"avoid": {
            "reward_params": {"heading_cost": 0.3}}}}),
    "rooms-mu50-evolving-heading5": (
        "rooms-mu50-evolving with turning costing 5x (`heading_cost = 0.5`)",
        _ROOMS | {"interpreter": _EVOLVING, "behaviours": {"avoid": {
            "min_updates": 50, "reward_params": {"heading_cost": 0.5}}}}),
    "rooms-mu50-evolving-heading-t": (
        "rooms-mu50-evolving-heading, the shipped training room among the rooms",
        {"experiment": {"rooms": ["training", TRAIN], "episode_iterations": 250},
         "collect": _ROOMS["collect"], "interpreter": _EVOLVING, "behaviours": {"avoid": {
             "min_updates": 50, "reward_params": {"heading_cost": 0.3}}}}),
    "rooms-mu50-evolving-progress": (
        "rooms-mu50-evolving + the progress reward (`progress = 20`, window 8)",
        _ROOMS | {"interpreter": _EVOLVING, "behaviours": {"avoid": {
            "min_updates": 50, "reward_params": {"progress": 20.0, "progress_window": 8}}}}),
    "rooms-mu50-evolving-c12": (
        "rooms-mu50-evolving starting from 12 fitted situations",
        _ROOMS | _MU50 | {"interpreter": {**_EVOLVING, "c": 12}}),
    "rooms-heading": (
        "rooms + turning costs 3x (`heading_cost = 0.3`)",
        _ROOMS | {"behaviours": {"avoid": {"reward_params": {"heading_cost": 0.3}}}}),
    "rooms-mu50-heading-cand3": (
        "rooms-mu50-heading, learning in 8 of the rooms, 3 candidates, the best in the other "
        "2 kept (as rooms-mu50-cand3)",
        {"experiment": {"rooms": [LEARN], "episode_iterations": 250, "candidates": 3,
                        "validation_rooms": [VALIDATE], "validation_iterations": 500},
         "collect": _ROOMS["collect"], "behaviours": {"avoid": {
             "min_updates": 50, "reward_params": {"heading_cost": 0.3}}}}),
    "heading": ("base + turning costs 3x (`heading_cost = 0.3`), learning in `training` "
                "only", {"behaviours": {"avoid": {"reward_params": {"heading_cost": 0.3}}}}),
    "evolving-heading": (
        "base + evolving situations + `heading_cost = 0.3`, learning in `training` only "
        "(rooms-evolving-heading without the rooms)",
        {"interpreter": _EVOLVING, "behaviours": {"avoid": {
            "reward_params": {"heading_cost": 0.3}}}}),
    "rooms-mu50-c12": ("rooms-mu50 with 12 situations", _ROOMS | _MU50 | {
        "interpreter": {"c": 12}}),
    "rooms-mu50-ep100": ("rooms-mu50 with 100-iteration episodes", {
        **_ROOMS, "experiment": {**_ROOMS["experiment"], "episode_iterations": 100},
        **_MU50}),
    "rooms-evolving-heading-w100": (
        "rooms-evolving-heading, 100 wander samples per collection room instead of 300",
        _reh({**_ROOMS["collect"], "wander_samples": 100})),
    "rooms-evolving-heading-w50": (
        "rooms-evolving-heading, 50 wander samples per collection room instead of 300",
        _reh({**_ROOMS["collect"], "wander_samples": 50})),
    "rooms-evolving-heading-gen200": (
        "rooms-evolving-heading, collecting only by wandering 200 samples in each generated "
        "training room (no forced trajectories in collect-1 ... collect-5)",
        _reh({"worlds": [TRAIN], "wander_samples": 200})),
    "rooms-evolving-heading-gen200-l5500": (
        "rooms-evolving-heading-gen200 learning 5500 iterations instead of 5000 (the duel's "
        "step bound, 8500, with the evaluate stage's 1000)",
        _reh({"worlds": [TRAIN], "wander_samples": 200}, 5500)),
    "rooms-evolving-heading-gen150-l6000": (
        "rooms-evolving-heading, 150 wander samples in each generated training room, "
        "learning 6000 iterations",
        _reh({"worlds": [TRAIN], "wander_samples": 150}, 6000)),
    "rooms-evolving-heading-gen200-mu50": (
        "rooms-evolving-heading-gen200 + convergence needs 50 updates of every live "
        "situation's rules (`min_updates = 50`): no rule base frozen while a situation is "
        "barely learnt", _mu(_reh({"worlds": [TRAIN], "wander_samples": 200}), 50)),
    "rooms-evolving-heading-gen200-mu20": (
        "rooms-evolving-heading-gen200 with `min_updates = 20`",
        _mu(_reh({"worlds": [TRAIN], "wander_samples": 200}), 20)),
    **{f"rooms-evolving-heading-gen200-mu20-{tag}": (
        f"rooms-evolving-heading-gen200-mu20 with {what}",
        _mu20_with(interp, avoid)) for tag, what, interp, avoid in [
        ("ca6", "`create_after = 6` (a situation is made from 6 poorly covered readings in a "
         "row, not 3)", {"create_after": 6}, {}),
        ("cd22", "`create_distance = 2.2` (fewer readings count as poorly covered)",
         {"create_distance": 2.2}, {}),
        ("grow3000", "`grow_until = 3000` (no situation made or split in the last 2000 "
         "iterations, so every one is learnt for at least 2000)", {"grow_until": 3000}, {}),
        ("opt0", "`new_row_optimism = 0` (a new situation's row is its parents' rows, not "
         "pulled towards the optimistic start)", {}, {"new_row_optimism": 0.0}),
        ("merge08", "`merge_distance = 0.8` (near-duplicate situations merged at twice the "
         "distance)", {"merge_distance": 0.8}, {}),
        ("c12", "12 fitted situations to start from", {"c": 12}, {}),
        ("merge06", "`merge_distance = 0.6`", {"merge_distance": 0.6}, {}),
        ("merge10", "`merge_distance = 1.0`", {"merge_distance": 1.0}, {}),
        ("merge08-mu0", "`merge_distance = 0.8` and no `min_updates` (the thesis's "
         "convergence alone)", {"merge_distance": 0.8}, {"min_updates": 0}),
    ]},
    **{f"rooms{n}-evolving-heading-w{w}-mu20": (
        f"rooms-evolving-heading-gen200-mu20 over {n} generated training rooms "
        f"(gen:1000000 ... gen:{1_000_000 + n - 1}), {w} wander samples in each, "
        f"{ep}-iteration episodes", _rooms_n(n, w, ep)) for n, w, ep in [
        (20, 100, 250), (40, 50, 125)]},
    "rooms-evolving-heading-gen200-replay4": (
        "rooms-evolving-heading-gen200 + 4 stored transitions learnt from again per "
        "iteration, rarely updated situations' first (`replay = 4`)",
        _reh({"worlds": [TRAIN], "wander_samples": 200}) | {"behaviours": {"avoid": {
            "reward_params": {"heading_cost": 0.3}, "replay": 4}}}),
    "rooms-evolving-heading-gen200-mu20-replay4": (
        "rooms-evolving-heading-gen200-mu20 + `replay = 4`", _mu20_with({}, {"replay": 4})),
    "rooms-evolving-heading-gen200-tight30": (
        "rooms-evolving-heading-gen200 with 30 % of the episodes starting in a tight place "
        "(`tight_starts = 0.3`: the free pose nearest a wall of 20 drawn), so that situations "
        "rarely met (dead ends, corners) get learnt",
        _reh({"worlds": [TRAIN], "wander_samples": 200}) | {"experiment": {
            **_ROOMS["experiment"], "tight_starts": 0.3}}),
    "rooms-evolving-heading-gen200-tight60": (
        "rooms-evolving-heading-gen200-tight30 with 60 % of the episodes starting in a tight "
        "place", _reh({"worlds": [TRAIN], "wander_samples": 200}) | {"experiment": {
            **_ROOMS["experiment"], "tight_starts": 0.6}}),
}


def recipe_config(name: str, train: list[str] | None = None) -> dict[str, Any]:
    """Recipe ``name``'s config: the ``obstacle-avoidance`` preset as it was before issue 39
    (:data:`BEFORE`; ``shipped``: as it is now) with the recipe's keys set,
    ``train`` (default :data:`TRAIN_ROOMS`) as its training rooms, and no evaluate stage (the
    script judges)."""
    import tomllib

    from sitframe.contract.config import preset_text

    cfg = tomllib.loads(preset_text("obstacle-avoidance") if name == "shipped"
                        else BEFORE.read_text("utf-8"))
    _merge(cfg, copy.deepcopy(RECIPES[name][1]), TRAIN_ROOMS if train is None else train)
    cfg["experiment"]["name"] = f"generalisation-{name}"
    cfg["experiment"]["stages"] = ["collect", "cluster", "learn"]
    return cfg


def _merge(into: dict[str, Any], keys: dict[str, Any], train: list[str]) -> None:
    for k, v in keys.items():
        if isinstance(v, dict) and isinstance(into.get(k), dict):
            _merge(into[k], v, train)
        elif isinstance(v, list) and {TRAIN, LEARN, VALIDATE} & set(v):
            rooms = {TRAIN: train, LEARN: train[:-2], VALIDATE: train[-2:]}
            into[k] = [r for x in v for r in rooms.get(x, [x])]
        else:
            into[k] = v


def config_key(name: str, train: list[str] | None = None) -> str:
    """A digest of recipe ``name``'s config (its name aside): a cached seed is reused only
    while its recipe's config, and so the preset or ``before.toml`` it starts from, is
    unchanged."""
    cfg = recipe_config(name, train)
    del cfg["experiment"]["name"]
    return hashlib.sha256(json.dumps(cfg, sort_keys=True).encode()).hexdigest()[:16]


def write_config(name: str, folder: Path, train: list[str] | None = None) -> Path:
    """Write recipe ``name``'s config as ``folder/NAME.toml``."""
    from sitframe.contract.config import to_toml

    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{name}.toml"
    path.write_text(f"# {RECIPES[name][0]}\n{to_toml(recipe_config(name, train))}", "utf-8")
    return path


def run_seed(name: str, seed: int, out: Path, rooms: list[str],
             train: list[str] | None = None) -> dict[str, Any]:
    """Learn recipe ``name`` with run seed ``seed`` and judge trial 0 in ``rooms``."""
    from sitframe.cli import main as cli_main
    from sitframe.logs.reader import open_log
    from sitframe.runs.evaluation import evaluate_log

    cfg_path = write_config(name, out / "configs", train)
    log = out / name / f"seed-{seed}.h5"
    log.parent.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    with contextlib.redirect_stdout(io.StringIO()):
        rc = cli_main(["run", str(cfg_path), "--trials", "1", "--seed", str(seed),
                       "--workers", "1", "--out", str(log)])
    if rc:
        raise SystemExit(f"sitframe run {cfg_path} --seed {seed} failed ({rc})")
    learn_s = time.perf_counter() - t0
    lg = open_log(str(log))
    lg.check()
    samples = int(len(lg.stage("collect")["samples"])) if lg.has("collect") else 0
    s = lg.trial(0).summary
    per_room = {w: evaluate_log(str(log), world=w, trial=0, iterations=1000, checked=lg)
                for w in rooms}
    return {"recipe": name, "seed": seed, "samples": samples,
            "iterations": int(s["iterations"]),
            "validation": int(s.get("validation_iterations", 0)),
            "steps": samples + int(s["iterations"]) + int(s.get("validation_iterations", 0)),
            "learn_collisions": int(s["collisions"]), "converged": bool(s["converged"]),
            "config": config_key(name, train), "learn_seconds": learn_s,
            "judge_seconds": time.perf_counter() - t0 - learn_s,
            "rooms": {w: {"collisions": int(r["collisions"]), "iterations": int(r["iterations"]),
                          "coverage": float(r["coverage"])} for w, r in per_room.items()}}


def seed_figures(r: dict[str, Any]) -> tuple[float, float, list[float]]:
    """A seed's collisions per 1000 pooled over its rooms, mean coverage, per-room rates."""
    rooms = r["rooms"].values()
    coll = sum(x["collisions"] for x in rooms) / sum(x["iterations"] for x in rooms) * 1000
    per = [x["collisions"] / x["iterations"] * 1000 for x in rooms]
    return coll, float(np.mean([x["coverage"] for x in rooms])), per


def row(name: str, results: list[dict[str, Any]]) -> str:
    """One Markdown row of the ablation table."""
    figs = [seed_figures(r) for r in results]
    coll = np.array([f[0] for f in figs])
    cov = np.array([f[1] for f in figs])
    per = np.concatenate([f[2] for f in figs])
    q1, med, q3 = np.percentile(coll, [25, 50, 75])
    steps = np.median([r["steps"] for r in results])
    learn = np.median([r["learn_collisions"] for r in results])
    conv = sum(r["converged"] for r in results)
    return (f"| `{name}` | {RECIPES[name][0]} | {len(results)} | {med:.2f} [{q1:.2f}–{q3:.2f}] "
            f"| {coll.max():.2f} | {np.median(cov):.3f} | {cov.min():.3f} | "
            f"{np.mean(per > BAD):.1%} | {steps:.0f} | {learn:.0f} | {conv}/{len(results)} |")


HEADER = ("| recipe | what it changes | seeds | coll./1000 median [IQR] | worst seed | "
          "coverage median | worst seed | evaluations > 10 | steps | collisions learning | "
          "converged |\n|---|---|---|---|---|---|---|---|---|---|---|")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--recipes", nargs="+", default=list(RECIPES), choices=list(RECIPES))
    ap.add_argument("--seeds", type=int, default=10, help="run seeds 0..N-1 (default 10)")
    ap.add_argument("--rooms", nargs="+", default=DEV_ROOMS,
                    help="the rooms judged in (default the 20 development rooms)")
    ap.add_argument("--train-rooms", nargs="+", default=TRAIN_ROOMS,
                    help="the generated training rooms of the recipes that learn over rooms "
                         "(default gen:1000000 ... gen:1000009)")
    ap.add_argument("--out", type=Path, default=Path("logs/generalisation"),
                    help="logs, configs and cached per-seed figures (default %(default)s)")
    ap.add_argument("--publish", action="store_true",
                    help="write docs/results/tables/generalisation.md")
    ap.add_argument("--list", action="store_true", help="print the recipes and stop")
    ap.add_argument("--write-configs", type=Path, metavar="DIR",
                    help="write every recipe's config as DIR/NAME.toml and stop")
    a = ap.parse_args(argv)
    if a.list:
        for name, (what, _k) in RECIPES.items():
            print(f"{name}: {what}")
        return 0
    if a.write_configs:
        for name in a.recipes:
            print(write_config(name, a.write_configs, a.train_rooms))
        return 0

    def results(name: str) -> list[dict[str, Any]]:
        key, rooms = config_key(name, a.train_rooms), set(a.rooms)

        def say(seed: int, r: dict[str, Any]) -> str:
            c, v, _p = seed_figures(r)
            return (f"{name} seed {seed}: {c:.2f} coll/1000, coverage {v:.3f} "
                    f"({r['learn_seconds']:.0f} + {r['judge_seconds']:.0f} s)")

        return per_seed(range(a.seeds), a.out / name,
                        lambda old: old.get("config") == key and old["rooms"].keys() == rooms,
                        lambda seed: run_seed(name, seed, a.out, a.rooms, a.train_rooms), say)

    rows = [row(name, results(name)) for name in a.recipes]
    table = "\n".join([HEADER, *rows])
    print(table)
    if a.publish:
        publish("generalisation", table)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
