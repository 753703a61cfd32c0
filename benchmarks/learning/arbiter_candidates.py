"""Which learning setting of the learned arbiter beats CDB, chosen on development rooms only?

Question: For each candidate setting of ``goal-finding-learned`` (a file in
``benchmarks/learning/arbiter_candidates/``: a base and the keys it changes, as the preset
candidates of ``preset_safety.py``), how does *every* trial's learned arbitration compare with
CDB over the same behaviours, spaces and start/goal pairs, in rooms that no results page
judges: the arbiter's learning room ``goal-training`` and the development rooms
``gen:2000000`` ... ``gen:2000004`` (the test rooms of the duel, ``gen:3000000`` on, and the
rooms of the learned-arbitration page are never used here)?
Output: a Markdown table (one row per candidate: trials converged, the per-trial SPL and
collision-free differences learned - CDB averaged over the rooms as median [IQR] (worst),
how many trials are at least CDB's SPL, and the pooled success), printed and with
``--publish`` written to ``docs/results/tables/arbiter-candidates.md``.

For each candidate: ``sitframe run CONFIG --workers 1`` (its prerequisites,
``obstacle-avoidance-12`` and ``wall-following``, made once and shared in ``--out``), then
for every trial ``K`` one paired batch per room, exactly as ``paired_arbiters.py LOG
--trial K --worlds ROOMS --seeds 1 --episodes 50`` (seed 0: 50 random pairs per room).
Judging every trial, not the one a selection run picks, says what the setting does to a
learner rather than what one lucky trial does. Per trial and room the cached figures live
in ``--out/<candidate>/trial-K.json``.

Usage (one core, about 5 minutes per candidate)::

    python benchmarks/learning/arbiter_candidates.py --publish
    python benchmarks/learning/arbiter_candidates.py \\
        --candidates benchmarks/learning/arbiter_candidates/p150.toml --episodes 20
"""

from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))  # (preset_safety: candidate files, the same format)
from preset_safety import candidate_config  # noqa: E402

ROOMS = ["goal-training"] + [f"gen:{2_000_000 + i}" for i in range(5)]
HEADER = ("| candidate | trials converged | SPL learned - CDB, per trial: median [IQR] (worst) "
          "| trials with SPL >= CDB | collision-free learned - CDB: median [IQR] (worst) "
          "| success learned / CDB |\n|---|---|---|---|---|---|")


def run(candidate: Path, out: Path) -> Path:
    """Learn the candidate's arbitration (once: a complete log is reused); return the log."""
    text = candidate_config(str(candidate)) or candidate.read_text("utf-8")
    config = out / f"{candidate.stem}.toml"  # (its prerequisites' logs resolve in out/logs)
    log = out / candidate.stem / "arbitration.h5"
    if not (log.is_file() and config.is_file() and config.read_text("utf-8") == text):
        config.write_text(text, "utf-8")
        log.parent.mkdir(parents=True, exist_ok=True)
        subprocess.run(["sitframe", "run", str(config), "--workers", "1", "--out", str(log)],
                       cwd=out, check=True)
    return log


def judge(log: Path, trial: int, episodes: int) -> dict[str, Any]:
    """Trial ``trial`` against CDB in every room (paired_arbiters.py's summary), cached."""
    cache = log.parent / f"trial-{trial}.json"
    if cache.is_file():
        old = json.loads(cache.read_text("utf-8"))
        if old.get("episodes") == episodes and old.get("log_mtime") == log.stat().st_mtime:
            return old
    tmp = log.parent / f"trial-{trial}.batches.json"
    subprocess.run([sys.executable, str(HERE / "paired_arbiters.py"), str(log), "--trial",
                    str(trial), "--worlds", *ROOMS, "--seeds", "1", "--episodes", str(episodes),
                    "--out", str(log.parent / f"trial-{trial}.md"), "--json", str(tmp)],
                   check=True, stdout=subprocess.DEVNULL)
    rooms = json.loads(tmp.read_text("utf-8"))["summary"]["rooms"]
    res = {"episodes": episodes, "log_mtime": log.stat().st_mtime,
           "rooms": {r: {a: v[a] for a in ("learned", "cdb")} for r, v in rooms.items()}}
    cache.write_text(json.dumps(res, indent=1), "utf-8")
    return res


def _spread(x: np.ndarray) -> str:
    q1, med, q3 = np.percentile(x, [25, 50, 75])
    return f"{med:+.3f} [{q1:+.3f}, {q3:+.3f}] ({x.min():+.3f})"


def row(name: str, log: Path, episodes: int) -> str:
    """One candidate's row over every trial of its log."""
    from sitframe.logs.reader import open_log

    summary = open_log(str(log)).summary()
    conv = np.asarray(summary["converged"], dtype=bool)
    per = [judge(log, int(k), episodes)["rooms"] for k in summary["trial"]]

    def gap(fig: str) -> np.ndarray:
        return np.array([np.mean([r[w]["learned"][fig] - r[w]["cdb"][fig] for w in r])
                         for r in per])

    spl, cf = gap("spl"), gap("collision_free")
    succ = {a: np.mean([r[w][a]["success"] for r in per for w in r]) for a in ("learned", "cdb")}
    return (f"| `{name}` | {conv.sum()}/{conv.size} | {_spread(spl)} | "
            f"{(spl >= 0).sum()}/{spl.size} | {_spread(cf)} | "
            f"{succ['learned']:.3f} / {succ['cdb']:.3f} |")


def _natural(path: Path) -> list[Any]:
    """Sort key: numbers in a name compare as numbers (p50 before p100)."""
    return [int(s) if s.isdigit() else s for s in re.split(r"(\d+)", path.stem)]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--candidates", nargs="+", type=Path,
                    default=sorted((HERE / "arbiter_candidates").glob("*.toml"), key=_natural))
    ap.add_argument("--episodes", type=int, default=50, help="pairs per room (default 50)")
    ap.add_argument("--out", type=Path, default=Path("logs/arbiter-candidates"))
    ap.add_argument("--publish", nargs="?", const="arbiter-candidates", default=None)
    a = ap.parse_args(argv)
    a.out.mkdir(parents=True, exist_ok=True)
    rows = [row(c.stem, run(c.resolve(), a.out.resolve()), a.episodes) for c in a.candidates]
    table = "\n".join([HEADER, *rows])
    print(table)
    if a.publish:
        sys.path.insert(0, str(HERE.parent))  # benchmarks/: common
        from common.publish import publish

        publish(a.publish, table)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
