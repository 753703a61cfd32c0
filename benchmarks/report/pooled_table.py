"""A preset's headline figures pooled over a sweep folder (every trial of every log).

Run::

    python benchmarks/report/pooled_table.py logs/sweeps/wall-following

For the README's tables: convergence (converged trials, median [IQR] of the
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
from pathlib import Path
from typing import Any

import numpy as np

from sitframe.contract.pluginmanager import Registry, get_plugin_manager
from sitframe.contract.resolve import Resolved
from sitframe.logs.reader import open_log

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


def pool(folder: str) -> dict[str, Any]:
    """Per-trial summary values and reward scores of every log in ``folder``."""
    conv: list[float] = []
    per: dict[str, dict[str, list[float]]] = {}
    scorers = None
    for f in sorted(Path(folder).glob("*.h5")):
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
    return {"conv": np.array(conv), "per": per, "runs": len(list(Path(folder).glob("*.h5")))}


def report(p: dict[str, Any]) -> None:
    """Print the pooled figures."""
    conv = p["conv"]
    if conv.size:
        ok = conv[np.isfinite(conv)]
        print(f"converged {ok.size}/{conv.size}; iterations to convergence "
              f"{_miq(ok, whole=True) if ok.size else '-'}")
    bad = []
    for world, m in p["per"].items():
        parts = []
        if "collisions_per_1000" in m and "success_rate" not in m:
            c = np.array(m["collisions_per_1000"])
            bad.append(c > BAD)
            parts.append(f"collisions/1000 {_miq(c)} ({c.max():.0f}), > {BAD:.0f}: "
                         f"{np.mean(c > BAD):.1%}, coverage {np.median(m['coverage']):.2f}")
        if "wall_band_fraction" in m:
            b = np.array(m["wall_band_fraction"])
            parts.append(f"in band {_miq(100 * b)} % (lowest {100 * b.min():.0f} %), "
                         f"below {100 * BAND_BAD:.0f} %: {np.mean(b < BAND_BAD):.1%}")
        for name in GOAL:
            if name in m:
                v = np.array(m[name])
                parts.append(f"{name} {v.mean():.3f} (runs {v.min():.2f}-{v.max():.2f})")
        print(f"{world} ({len(next(iter(m.values())))} evaluations): " + "; ".join(parts))
    if bad:
        b = np.concatenate(bad)
        print(f"evaluations > {BAD:.0f} collisions/1000: {b.mean():.1%} of {b.size}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folder", help="a sweep's output folder (its *.h5 logs are pooled)")
    report(pool(ap.parse_args().folder))


if __name__ == "__main__":
    main()
