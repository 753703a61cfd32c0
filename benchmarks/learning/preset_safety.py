"""Is every shipped preset safe in rooms it never saw (issue 39)?

Question: For each shipped preset whose frozen policies drive alone (obstacle avoidance,
wall following, speed), in what share of evaluations in unseen rooms does a frozen policy
exceed 10 collisions per 1000 iterations, over 10 run seeds x the preset's trials?
Output: a Markdown table (one row per preset: evaluations, share above 10 per 1000 with
its 95 % interval over seeds (:func:`seed_interval`), share of learners (frozen rule bases)
with any evaluation above it, median and worst collisions per 1000, median coverage, share
of trials converged), printed and with ``--publish`` written to
``docs/results/tables/preset-safety.md``; per-seed figures cached as JSON in ``--out``.
Candidate presets (``benchmarks/learning/preset_candidates/*.toml``: a base and the keys
changed, :func:`candidate_config`; the first line says why) are judged the same way and
published with ``--publish preset-safety-candidates``.

For each preset and seed ``S``: ``sitframe run PRESET --seed S --workers 1`` (the
preset as shipped, its own prerequisites made first in ``--out``), then every trial's
frozen policy runs 1000 iterations from the start of each judging room (default the 20
development rooms ``gen:2000000`` ... ``gen:2000019``; evaluation seed 0), which is
``sitframe evaluate LOG --world W --trial K``. The goal presets are judged in goal
episodes (their own results pages) and are not listed.

Usage (one core, one process)::

    taskset -c 0 nice -n 5 python benchmarks/learning/preset_safety.py --seeds 10 --publish
    python benchmarks/learning/preset_safety.py --presets obstacle-avoidance --seeds 2 \\
        --rooms gen:2000000 gen:2000001
    python benchmarks/learning/preset_safety.py --seeds 10 \\
        --presets benchmarks/learning/preset_candidates/*.toml --publish preset-safety-candidates
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import io
import os
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: common
from common import per_seed  # noqa: E402
from common.publish import publish  # noqa: E402

DEV_ROOMS = [f"gen:{2_000_000 + i}" for i in range(20)]
#: The presets whose frozen policies drive alone (the goal presets fuse behaviours and are
#: judged in goal episodes).
PRESETS = ("obstacle-avoidance", "obstacle-avoidance-8", "obstacle-avoidance-12",
           "obstacle-avoidance-16", "obstacle-avoidance-evolving", "obstacle-avoidance-online",
           "obstacle-avoidance-thesis", "speed", "wall-following", "wall-following-12",
           "wall-following-evolving")
#: An evaluation above this many collisions per 1000 iterations is unsafe.
BAD = 10.0


def run_seed(preset: str, seed: int, out: Path, rooms: list[str],
             trials: int | None = None) -> dict[str, Any]:
    """Run ``preset`` with seed ``seed`` in ``out`` and judge every trial in ``rooms``."""
    from sitframe.cli import main as cli_main
    from sitframe.logs.reader import open_log
    from sitframe.runs.evaluation import evaluate_log

    log = out / label(preset) / f"seed-{seed}.h5"
    log.parent.mkdir(parents=True, exist_ok=True)
    cfg = candidate_config(preset)
    if cfg is not None:  # (a candidate: its config written out, paths resolving beside it)
        (log.parent / "config.toml").write_text(cfg, "utf-8")
    config = str((log.parent / "config.toml").resolve()) if cfg is not None else preset
    argv = ["run", config, "--seed", str(seed), "--workers", "1", "--out", str(log.resolve())]
    if trials is not None:
        argv += ["--trials", str(trials)]
    t0 = time.perf_counter()
    here = Path.cwd()
    work = out / "work"  # (a preset's prerequisites are made in logs/ of the working folder,
    work.mkdir(exist_ok=True)  # which must not hold a folder named like a preset)
    os.chdir(work)
    try:
        with contextlib.redirect_stdout(io.StringIO()):
            rc = cli_main(argv)
    finally:
        os.chdir(here)
    if rc:
        raise SystemExit(f"sitframe {' '.join(argv)} failed ({rc})")
    lg = open_log(str(log))
    lg.check()
    evals = {f"{k}@{w}": evaluate_log(str(log), world=w, trial=k, iterations=1000, checked=lg)
             for k in lg.trial_indices() for w in rooms}
    return {"preset": preset, "seed": seed, "seconds": time.perf_counter() - t0,
            "config": preset_key(preset),
            "rooms": rooms, "trials": trials,
            "converged": [bool(lg.trial(k).summary["converged"]) for k in lg.trial_indices()],
            "evaluations": {key: {"collisions_per_1000": float(r["collisions_per_1000"]),
                                  "coverage": float(r["coverage"])}
                            for key, r in evals.items()}}


def preset_key(preset: str) -> str:
    """A digest of the preset's (or config file's, or candidate's config) text and of its
    prerequisites' (the logs it builds on, e.g. speed on obstacle-avoidance-12): a cached
    seed is reused only while none of them changed."""
    import tomllib

    from sitframe.contract.config import preset_text

    text = preset_text(preset) if not preset.endswith(".toml") else \
        candidate_config(preset) or Path(preset).read_text("utf-8")
    needs = tomllib.loads(text).get("prerequisites", {}).values()
    if needs:  # (a preset without prerequisites keeps the key of its text alone)
        text += "".join(preset_key(str(Path(preset).parent / n) if n.endswith(".toml") else n)
                        for n in needs)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def candidate_config(path: str) -> str | None:
    """A candidate file's config as TOML text, or None for a plain config file or a
    shipped preset's name.

    A candidate (``benchmarks/learning/preset_candidates/*.toml``) names what it starts
    from, ``base = "..."`` (a shipped preset, or a config file relative to the candidate),
    and the keys it changes as tables under ``[set]`` (e.g. ``[set.behaviours.avoid]``),
    merged into the base's own: tables key by key, any other value replaced.
    """
    import tomllib

    from sitframe.contract.config import preset_text, to_toml

    if not path.endswith(".toml"):
        return None
    spec = tomllib.loads(Path(path).read_text("utf-8"))
    if "base" not in spec:
        return None
    base = spec["base"]
    if not base.endswith(".toml"):
        cfg = tomllib.loads(preset_text(base))
    else:  # (its prerequisites' config files are named relative to the base's folder)
        file = Path(path).parent / base
        cfg = tomllib.loads(file.read_text("utf-8"))
        needs = cfg.get("prerequisites", {})
        for log, name in needs.items():
            if name.endswith(".toml"):
                needs[log] = str((file.parent / name).resolve())
    _merge(cfg, spec.get("set", {}))
    return to_toml(cfg)


def _merge(into: dict[str, Any], keys: dict[str, Any]) -> None:
    for k, v in keys.items():
        if isinstance(v, dict) and isinstance(into.get(k), dict):
            _merge(into[k], v)
        else:
            into[k] = v


def label(preset: str) -> str:
    """A preset's name, or a config file's name without ``.toml`` (a candidate preset)."""
    return Path(preset).stem if preset.endswith(".toml") else preset


def row(preset: str, results: list[dict[str, Any]]) -> str:
    """One Markdown row: the preset's evaluations pooled over seeds, trials and rooms."""
    ev = [e for r in results for e in r["evaluations"].values()]
    coll = np.array([e["collisions_per_1000"] for e in ev])
    cov = np.array([e["coverage"] for e in ev])
    conv = [c for r in results for c in r["converged"]]
    return (f"| `{label(preset)}` | {len(results)} × {len(results[0]['converged'])} | {len(ev)} | "
            f"{np.mean(coll > BAD):.1%} | {seed_interval(results)} | "
            f"{unsafe_learners(results):.0%} | "
            f"{np.median(coll):.2f} | {coll.max():.1f} | {np.median(cov):.3f} | "
            f"{np.mean(conv):.1%} |")


def seed_interval(results: list[dict[str, Any]], level: float = 0.95) -> str:
    """The share above :data:`BAD`'s ``level`` interval, resampling whole seeds.

    A seed's learners share its data and situations, so its evaluations are not
    independent: the bootstrap (:func:`scipy.stats.bootstrap`, percentile, 9,999
    resamples, Generator seed 0) draws seeds with replacement and pools their
    evaluations. With 10 seeds a share near 2 % is known only to within a few per cent;
    the interval says how far.
    """
    from scipy.stats import bootstrap

    bad = np.array([sum(e["collisions_per_1000"] > BAD for e in r["evaluations"].values())
                    for r in results], dtype=float)
    n = np.array([len(r["evaluations"]) for r in results], dtype=float)
    if len(results) < 2 or bad.sum() == 0:
        return "–" if len(results) < 2 else "0.0–0.0%"
    ci = bootstrap((bad, n), lambda b, m, axis=-1: b.sum(axis=axis) / m.sum(axis=axis),
                   paired=True, vectorized=True, confidence_level=level, n_resamples=9999,
                   method="percentile", random_state=np.random.default_rng(0)).confidence_interval
    return f"{ci.low:.1%}–{ci.high:.1%}".replace("%–", "–")


def unsafe_learners(results: list[dict[str, Any]]) -> float:
    """The share of learners (seed x trial: one frozen rule base each) with at least one
    evaluation above :data:`BAD`: how the unsafe evaluations are spread over rule bases."""
    bad = [any(e["collisions_per_1000"] > BAD for key, e in r["evaluations"].items()
               if key.split("@")[0] == str(k))
           for r in results for k in range(len(r["converged"]))]
    return float(np.mean(bad))


HEADER = ("| preset | seeds × trials | evaluations | > 10 coll./1000 | its 95 % interval, seeds "
          "resampled | learners with one > 10 | coll./1000 median | worst | coverage median | "
          "trials converged |\n|---|---|---|---|---|---|---|---|---|---|")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--presets", nargs="+", default=list(PRESETS), metavar="PRESET",
                    help="shipped presets, or config files (*.toml) of candidate presets "
                         "(default every preset that drives alone)")
    ap.add_argument("--seeds", type=int, default=10, help="how many run seeds (default 10)")
    ap.add_argument("--first-seed", type=int, default=0,
                    help="the first run seed (default 0; a candidate chosen on seeds 0-9 is "
                         "confirmed on others)")
    ap.add_argument("--trials", type=int, default=None,
                    help="trials per run (default: the preset's own)")
    ap.add_argument("--rooms", nargs="+", default=DEV_ROOMS,
                    help="the rooms judged in (default the 20 development rooms)")
    ap.add_argument("--out", type=Path, default=Path("logs/preset-safety"),
                    help="logs and cached per-seed figures (default %(default)s)")
    ap.add_argument("--publish", nargs="?", const="preset-safety", default=None,
                    metavar="TABLE", help="write docs/results/tables/TABLE.md (default "
                    "preset-safety; candidates: preset-safety-candidates)")
    a = ap.parse_args(argv)
    a.presets = [str(Path(p).resolve()) if p.endswith(".toml") else p for p in a.presets]
    a.out.mkdir(parents=True, exist_ok=True)

    def results(preset: str) -> list[dict[str, Any]]:
        want = {"rooms": a.rooms, "trials": a.trials, "config": preset_key(preset)}

        def say(seed: int, r: dict[str, Any]) -> str:
            bad = np.mean([e["collisions_per_1000"] > BAD for e in r["evaluations"].values()])
            return f"{label(preset)} seed {seed}: {bad:.1%} above {BAD:g} ({r['seconds']:.0f} s)"

        return per_seed(range(a.first_seed, a.first_seed + a.seeds), a.out / label(preset),
                        lambda old: all(old.get(k) == v for k, v in want.items()),
                        lambda seed: run_seed(preset, seed, a.out, a.rooms, a.trials), say)

    rows = [row(preset, results(preset)) for preset in a.presets]
    table = "\n".join([HEADER, *rows])
    print(table)
    if a.publish:
        publish(a.publish, table)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
