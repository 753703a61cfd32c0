"""Speed learning pooled over a sweep: convergence, and learned speed against openness.

Run::

    python benchmarks/speed_openness.py logs/sweeps/speed-convergence logs/obstacle-avoidance.h5

Reads every log in the sweep folder (all trials pooled) and the log the
situations came from (the speed preset's ``clusters_from``). Prints the
convergence (converged trials, median [IQR] of the iterations, trials not
converged counted as slower than any that did) and, per situation, the
prototype's *openness* -- the mean over beams of ``log(r + offset)``, the
same log ranges the situations were clustered on (``offset`` from the
``[interpreter]`` table) -- its nearest range, its label and the mean learned
speed over all trials (each trial's greedy speed: the converged rule base, or
the greedy one of its final Q). Spearman's rank correlation of the learned
speed with the openness, with the mean range [m], the nearest range and the
range ahead (the nearest of the beams within 22.5 deg of the heading, the
ahead sector of the situation labels) closes the table.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from scipy.stats import spearmanr

from sitframe.analysis import situation_labels
from sitframe.clustering import SECTORS_DEG
from sitframe.logs import open_log


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folder", help="a sweep's output folder (its *.h5 logs are pooled)")
    ap.add_argument("situations", help="the log the situations came from (clusters_from)")
    ap.add_argument("--behaviour", default="avoid")
    args = ap.parse_args()
    src = open_log(args.situations)
    centers = np.asarray(src.interpreter_state()["centers"], dtype=np.float64)
    offset = float(src.config["interpreter"].get("offset", 0.1))
    labels = situation_labels(src)
    conv, speeds = [], []
    for f in sorted(Path(args.folder).glob("*.h5")):
        lg = open_log(f)
        for k in lg.trial_indices():
            tr = lg.trial(k)
            it = tr.summary.get("convergence_iteration", -1)
            conv.append(np.inf if it is None or it < 0 else float(it))
            out = tr.policies[args.behaviour].outputs["speed"]
            speeds.append(np.asarray(out.actions)[np.asarray(out.rules)])
    conv_a, S = np.array(conv), np.array(speeds)
    q25, med, q75 = np.percentile(conv_a, [25, 50, 75], method="lower")
    print(f"{len(conv_a)} trials, {np.isfinite(conv_a).sum()} converged; iterations to "
          f"convergence median {med:.0f} [IQR {q25:.0f}, {q75:.0f}]")
    openness = np.log(centers + offset).mean(axis=1)
    mean_speed = S.mean(axis=0)
    print("| situation | openness (mean log range) | mean range | nearest range | "
          "learned speed, mean over trials |")
    print("|---|---|---|---|---|")
    for i in np.argsort(openness):
        print(f"| {labels[i]} | {openness[i]:.2f} | {centers[i].mean():.2f} m | "
              f"{centers[i].min():.2f} m | {mean_speed[i]:.3f} m/s |")
    angles = (np.asarray(src.sensor.angles_deg) + 180.0) % 360.0 - 180.0
    ahead = centers[:, np.abs(angles) <= SECTORS_DEG[0]].min(axis=1)
    for name, x in (("openness", openness), ("mean range", centers.mean(axis=1)),
                    ("nearest range", centers.min(axis=1)), ("range ahead", ahead)):
        print(f"Spearman(learned speed, {name}) = {spearmanr(mean_speed, x).statistic:.2f}")


if __name__ == "__main__":
    main()
