"""Speed learning pooled over a sweep: convergence, and learned speed against clearance.

Question: Does the learned speed rise with the clearance the robot senses?
Output: convergence, the per-situation table and the per-iteration deciles, printed as
Markdown; with --publish PREFIX the tables PREFIX-convergence, PREFIX-situations and
PREFIX-clearance in docs/results/tables/.

Run::

    python benchmarks/learning/speed_openness.py logs/sweeps/speed logs/obstacle-avoidance.h5

Reads every log in the sweep folder, or every log a glob matches (all
trials pooled), and the log the
situations came from (the speed preset's ``clusters_from``). Prints:

1. **Convergence**: converged trials, median [IQR] of the iterations (trials
   not converged count as slower than any that did).
2. **Per situation** (the measure used so far): each prototype's *openness*
   -- the mean over beams of ``log(r + offset)``, the space the situations
   were clustered in (``offset`` from the ``[interpreter]`` table) -- its
   label and the mean over trials of each trial's greedy speed (the converged
   rule base, or the greedy one of its final Q), the median number of updates
   of the situation (learning stops at convergence) and the mean final Q.
   Spearman's rank correlation of that speed with the openness (with a
   95 % bootstrap interval over trials), the mean range, the nearest range and the range ahead (the
   nearest beam within 22.5 deg of the heading). Eight points, whose middle
   six lie within 0.1 of each other in openness, and greedy speeds frozen
   after a few dozen updates of each situation: a coarse measure.
3. **Per iteration of the frozen evaluations** (needs a sweep with the
   ``evaluate`` stage): the commanded speed at every iteration of every
   evaluation (each trial's frozen speed and heading rule bases driving
   1000 iterations per room), against the clearance the robot sensed at
   that iteration: the reading's openness (same formula as above), its
   nearest range and its range ahead. The learned speed *as a function of
   clearance* is the mean commanded speed in each decile of the clearance;
   Spearman of that curve against the decile tells whether speed rises
   with clearance over the readings the robot actually meets; the raw
   per-iteration Spearman (speed blends three singletons, so most of its
   spread is the fuzzy blend, not the clearance) is printed beside it.
"""

from __future__ import annotations

import argparse
import glob
import sys
from pathlib import Path

import numpy as np
from scipy.stats import spearmanr

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: common
from common.publish import publish  # noqa: E402

from sitframe.analysis import situation_labels  # noqa: E402
from sitframe.logs.reader import open_log  # noqa: E402
from sitframe.situations.clustering import SECTORS_DEG  # noqa: E402

AHEAD_DEG = SECTORS_DEG[0]
DECILES = 10


def _pooled(folder: str, behaviour: str) -> tuple[np.ndarray, dict[str, np.ndarray], list, list]:
    """Convergence iterations (inf = none); greedy speeds, updates of each situation
    and final Q (``speed`` (trials, c), ``updates`` (trials, c), ``q`` (trials, c, 3));
    the evaluations' commanded speeds and readings (one array per evaluation)."""
    conv, speeds, updates, qs, cmd, reading = [], [], [], [], [], []
    files = sorted(Path(folder).glob("*.h5")) if Path(folder).is_dir() else \
        sorted(Path(f) for f in glob.glob(folder))  # (a relative or an absolute pattern)
    for f in files:
        lg = open_log(f)
        for k in lg.trial_indices():
            tr = lg.trial(k)
            it = tr.summary.get("convergence_iteration", -1)
            conv.append(np.inf if it is None or it < 0 else float(it))
            out = tr.policies[behaviour].outputs["speed"]
            speeds.append(np.asarray(out.actions)[np.asarray(out.rules)])
            updates.append(np.asarray(tr.behaviours[behaviour]["speed/updates"]))
            qs.append(np.asarray(tr.behaviours[behaviour]["speed/q"]))
            for key, v in tr.episodes.items():
                if key.startswith("eval/") and key.endswith("/command"):
                    cmd.append(np.asarray(v)[:, 1])
                    reading.append(np.asarray(tr.episodes[key[:-len("command")] + "reading"]))
    learned = {"speed": np.array(speeds), "updates": np.array(updates), "q": np.array(qs)}
    return np.array(conv), learned, cmd, reading


def _clearances(r: np.ndarray, offset: float, angles: np.ndarray) -> dict[str, np.ndarray]:
    """Openness, mean, nearest and ahead range of readings ``r`` (n, d) [m]."""
    return {"openness": np.log(r + offset).mean(axis=1), "mean range": r.mean(axis=1),
            "nearest range": r.min(axis=1),
            "range ahead": r[:, np.abs(angles) <= AHEAD_DEG].min(axis=1)}


def _rho(x: np.ndarray, y: np.ndarray) -> float:
    return float(spearmanr(x, y).statistic)


def per_situation(learned: dict[str, np.ndarray], centers: np.ndarray, labels: list[str],
                  offset: float, angles: np.ndarray) -> str:
    """The per-situation table and correlations (``learned`` from :func:`_pooled`)."""
    cl = _clearances(centers, offset, angles)
    S = learned["speed"]
    mean_speed = S.mean(axis=0)
    out = ["| situation | openness (mean log range) | mean range | nearest range | "
           "learned speed, mean over trials | updates, median | mean Q of each speed |",
           "|---|---|---|---|---|---|---|"]
    for i in np.argsort(cl["openness"]):
        q = " / ".join(f"{v:.0f}" for v in learned["q"][:, i].mean(axis=0))
        out.append(f"| {labels[i]} | {cl['openness'][i]:.2f} | {centers[i].mean():.2f} m | "
                   f"{centers[i].min():.2f} m | {mean_speed[i]:.3f} m/s | "
                   f"{np.median(learned['updates'][:, i]):.0f} | {q} |")
    rng = np.random.default_rng(0)
    boot = [_rho(S[rng.integers(0, len(S), len(S))].mean(axis=0), cl["openness"])
            for _ in range(2000)]
    lo, hi = np.nanpercentile(boot, [2.5, 97.5])
    out.append("")
    for name, x in cl.items():
        extra = f" (95 % bootstrap over trials: {lo:.2f} to {hi:.2f})" if name == "openness" else ""
        out.append(f"- Spearman(learned speed, {name}) = {_rho(mean_speed, x):.2f}{extra}")
    return "\n".join(out)


def per_iteration(cmd: list, reading: list, offset: float, angles: np.ndarray) -> str:
    """The speed-against-clearance curves of the frozen evaluations, as a table."""
    if not cmd:
        return "per iteration: no evaluation in these logs (run the sweep with 'evaluate')"
    v = np.concatenate(cmd)
    cl = _clearances(np.concatenate(reading), offset, angles)
    out = [f"| clearance at the iteration ({v.size:,} iterations of {len(cmd)} evaluations) | "
           "mean commanded speed per decile, lowest clearance first (m/s) | "
           "Spearman of the curve | raw per iteration |", "|---|---|---|---|"]
    for name, x in cl.items():
        edges = np.quantile(x, np.linspace(0.0, 1.0, DECILES + 1))
        b = np.clip(np.searchsorted(edges, x, side="right") - 1, 0, DECILES - 1)
        curve = np.array([v[b == i].mean() for i in range(DECILES)])
        out.append(f"| {name} ({edges[0]:.2f} .. {edges[-1]:.2f}) | "
                   + " ".join(f"{c:.3f}" for c in curve)
                   + f" | {_rho(curve, np.arange(DECILES)):.2f} | {_rho(v, x):.2f} |")
    return "\n".join(out)


def convergence(conv: np.ndarray) -> str:
    """Converged trials and the iterations to convergence (not converged: slower than any)."""
    q25, med, q75 = np.percentile(conv, [25, 50, 75], method="lower")
    return ("| trials | converged | iterations to convergence, median [IQR] |\n"
            "|---|---|---|\n"
            f"| {len(conv)} | {np.isfinite(conv).sum()}/{len(conv)} | "
            f"{med:.0f} [{q25:.0f}, {q75:.0f}] |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folder", help="a sweep's output folder (its *.h5 logs are pooled), or a "
                    "glob of logs relative to here, e.g. 'logs/sweeps/S/activation=0.3_seed=?.h5'")
    ap.add_argument("situations", help="the log the situations came from (clusters_from)")
    ap.add_argument("--behaviour", default="avoid")
    ap.add_argument("--publish", action="append", default=[], metavar="PART=NAME",
                    help="also write a part (convergence, situations, clearance) to "
                    "docs/results/tables/NAME.md (repeatable)")
    args = ap.parse_args()
    src = open_log(args.situations)
    centers = np.asarray(src.interpreter_state()["centers"], dtype=np.float64)
    offset = float(src.config["interpreter"].get("offset", 0.1))
    angles = (np.asarray(src.sensor.angles_deg) + 180.0) % 360.0 - 180.0
    conv, learned, cmd, reading = _pooled(args.folder, args.behaviour)
    parts = {"convergence": convergence(conv),
             "situations": per_situation(learned, centers, situation_labels(src), offset,
                                         angles),
             "clearance": per_iteration(cmd, reading, offset, angles)}
    print("\n\n".join(parts.values()))
    for spec in args.publish:
        part, _, name = spec.partition("=")
        if part not in parts or not name:
            sys.exit(f"speed_openness: --publish {spec}: expected PART=NAME with PART one of "
                     f"{', '.join(parts)}")
        publish(name, parts[part])


if __name__ == "__main__":
    main()
