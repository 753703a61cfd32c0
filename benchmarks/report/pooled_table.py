"""A preset's headline figures pooled over a sweep folder (every trial of every log).

Question: What are a preset's headline figures pooled over its sweep's seeds?
Output: one Markdown row per sweep folder (or NAME::GLOB setting) printed; with --publish
NAME the table in docs/results/tables/NAME.md.

Run::

    python benchmarks/report/pooled_table.py logs/sweeps/wall-following
    python benchmarks/report/pooled_table.py --publish t "A::logs/sweeps/oa12/*250*.h5"

Each argument is a sweep folder (its logs pooled, named by the folder) or ``NAME::GLOB``.
The tables, one row per argument (per argument and room for the band and goal tables):
convergence (converged trials, median [IQR] of the
iterations of those that converged), and per evaluation world the collisions
per 1000 iterations, median [IQR] (worst), the share of the evaluations above
10, the median coverage; the share of *all* evaluations above 10. When the
behaviour's reward scores its own quality (a ``metrics(arrays)`` method, e.g.
the wall-following reward's ``wall_band_fraction``), that score is computed
from each logged frozen evaluation's readings and pooled the same way (worst
= lowest; bad = in the band less than half the time). Goal episodes
(``eval.<world>.success_rate`` ...) are pooled over the runs: the mean over
runs (each run scores the same number of episodes, so this is the rate over
all episodes) and the range over runs.
"""

from __future__ import annotations

import argparse
import glob
import sys
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: common
from common.publish import publish  # noqa: E402

from sitframe.contract.pluginmanager import Registry, get_plugin_manager  # noqa: E402
from sitframe.contract.resolve import Resolved  # noqa: E402
from sitframe.logs.reader import open_log  # noqa: E402

BAD = 10.0  # collisions per 1000 iterations that make an evaluation "bad"
BAND_BAD = 0.5  # a wall-following evaluation in the band less than half the time
GOAL = ("success_rate", "collision_free_rate", "spl", "spl_shortest", "mean_time_s",
        "heading_change_per_m")


def _miq(x: np.ndarray, whole: bool = False) -> str:
    """Median [IQR]; whole numbers, or one decimal where a quartile falls between two."""
    q = np.percentile(x, [25, 50, 75])
    f = [f"{v:.0f}" if whole or float(v).is_integer() else f"{v:.1f}" for v in q]
    return f"{f[1]} [{f[0]}, {f[2]}]"


def _scorers(cfg: dict[str, Any]) -> list[Any]:
    """The ``metrics`` methods of the run's rewards (built from the logged config)."""
    res = Resolved.build(cfg, Registry.collect(get_plugin_manager()))
    return [m for _b, r in res.behaviours().values() if (m := getattr(r, "metrics", None))]


def _logs(folder: str) -> list[Path]:
    """The logs of a sweep folder, or of a glob."""
    return sorted(Path(folder).glob("*.h5")) if Path(folder).is_dir() else \
        sorted(Path(p) for p in glob.glob(folder))


def pool(folder: str) -> dict[str, Any]:
    """Per-trial summary values and reward scores of every log in ``folder`` (or a glob)."""
    conv: list[float] = []
    per: dict[str, dict[str, list[float]]] = {}
    scorers = None
    files = _logs(folder)
    for f in files:
        lg = open_log(f)
        if scorers is None:
            scorers = _scorers(lg.config)
        for k in lg.trial_indices():
            tr = lg.trial(k)
            if "learn" in lg.config["experiment"].get("stages", []):
                it = tr.summary.get("convergence_iteration", -1)
                conv.append(np.inf if it is None or it < 0 else float(it))
            for key, v in tr.summary.items():
                if key.startswith("eval/") and np.isfinite(v):
                    _w, world, name = key.split("/", 2)
                    per.setdefault(world, {}).setdefault(name, []).append(float(v))
            for key, reading in tr.episodes.items():
                world, _s, what = key.removeprefix("eval/").partition("/")
                # (logs written before the sensor contract call the readings "sonar")
                if key.startswith("eval/") and what in ("reading", "sonar") and scorers:
                    for m in scorers:
                        for name, v in m({"reading": np.asarray(reading)}).items():
                            per.setdefault(world, {}).setdefault(name, []).append(v)
    trials = len(conv) // len(files) if files and conv else 0
    return {"conv": np.array(conv), "per": per, "runs": len(files), "trials": trials}


def _row(cells: list[str]) -> str:
    return "| " + " | ".join(cells) + " |"


def tables(pooled: dict[str, dict[str, Any]]) -> str:
    """The pooled figures as Markdown tables: collisions and convergence (one row per
    setting), the wall band (one row per setting and room) and goal episodes (likewise)."""
    worlds = list(dict.fromkeys(w for p in pooled.values() for w, m in p["per"].items()
                                if "collisions_per_1000" in m and "success_rate" not in m))
    out = []
    if worlds:
        out += [_row(["setting", "runs × trials", "converged", "iterations to convergence",
                      *worlds, f"evaluations > {BAD:.0f}", "coverage: " + ", ".join(worlds)]),
                "|" + "---|" * (6 + len(worlds))]
        for name, p in pooled.items():
            conv = p["conv"]
            ok = conv[np.isfinite(conv)]
            coll = [np.array(p["per"][w]["collisions_per_1000"]) for w in worlds]
            out.append(_row([
                name, f"{p['runs']} × {p['trials']}",
                f"{ok.size}/{conv.size}" if conv.size else "–",
                _miq(ok, whole=True) if ok.size else "–",
                *[f"{_miq(c)} ({c.max():.0f})" for c in coll],
                f"{np.mean(np.concatenate(coll) > BAD):.1%}",
                ", ".join(f"{np.median(p['per'][w]['coverage']):.2f}" for w in worlds)]))
        out.append("")
    band = [(n, w, np.array(m["wall_band_fraction"]), np.array(m["collisions_per_1000"]),
             np.median(m["coverage"])) for n, p in pooled.items() for w, m in p["per"].items()
            if "wall_band_fraction" in m]
    if band:
        out += [_row(["setting", "room", "in the band, median [IQR] (lowest)",
                      f"evaluations in the band < {100 * BAND_BAD:.0f} %",
                      "collisions / 1000, median [IQR] (worst)", f"evaluations > {BAD:.0f}",
                      "coverage"]), "|---|---|---|---|---|---|---|"]
        out += [_row([n, w, f"{_miq(100 * b)} % ({100 * b.min():.0f} %)",
                      f"{np.mean(b < BAND_BAD):.1%}", f"{_miq(c)} ({c.max():.0f})",
                      f"{np.mean(c > BAD):.1%}", f"{cov:.2f}"]) for n, w, b, c, cov in band]
        out.append("")
    goal = [(n, w, m) for n, p in pooled.items() for w, m in p["per"].items()
            if "success_rate" in m]
    if goal:
        names = [g for g in GOAL if any(g in m for _n, _w, m in goal)]
        out += [_row(["setting", "room", *names]), "|---|---|" + "---|" * len(names)]
        for n, w, m in goal:
            cells = []
            for g in names:
                v = np.array(m.get(g, [np.nan]))
                whole = g in ("mean_time_s", "heading_change_per_m")
                cells.append(f"{v.mean():.0f} ({v.min():.0f}–{v.max():.0f})" if whole else
                             f"{v.mean():.3f} ({v.min():.2f}–{v.max():.2f})")
            out.append(_row([n, w, *cells]))
        out.append("")
    return "\n".join(out).strip()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("settings", nargs="+", metavar="FOLDER|NAME::GLOB",
                    help="a sweep's output folder (its *.h5 logs are pooled) or NAME::GLOB")
    ap.add_argument("--publish", metavar="NAME",
                    help="also write the tables to docs/results/tables/NAME.md")
    args = ap.parse_args()
    pooled = {}
    for arg in args.settings:
        name, sep, pattern = arg.partition("::")
        if not sep:
            name, pattern = Path(arg).name, arg
        if not _logs(pattern):
            sys.exit(f"pooled_table: no logs in '{pattern}'")
        pooled[name] = pool(pattern)
    text = tables(pooled)
    print(text)
    if args.publish:
        publish(args.publish, text)


if __name__ == "__main__":
    main()
