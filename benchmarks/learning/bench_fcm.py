"""Benchmark sitframe's FCM against scikit-fuzzy 0.5 ``cmeans`` (benchmark-only dependency).

Question: Is sitframe's fuzzy c-means as fast and as exact as scikit-fuzzy's?
Output: time per iteration of both and the agreement of their fixed points, printed.

Run::

    python benchmarks/learning/bench_fcm.py            # full run (~1 min)
    python benchmarks/learning/bench_fcm.py --repeats 3

For n = 1500 with c = 8, 12, 16 and n = 100,000 with c = 8 (m = 1.2, 8-D
sonar-like data clipped to [0, 3] m) it prints the time per FCM iteration of
``sitframe.situations.fcm.fcm`` and ``skfuzzy.cluster.cmeans`` (same data, same starting
point, a fixed iteration budget: skfuzzy with ``error=0``, sitframe with a
negligible ``tol``; median of the repeats, the two measured alternately), the
speed-up, and the relative difference of the objective at the fixed point
reached by both from the same initial memberships. Finally the wall time of a
50-trial ``cluster_trials`` at n = 1500, c = 12.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from sitframe.situations.clustering import cluster_trials
from sitframe.situations.fcm import FCMResult, fcm, memberships, validity

PROTOTYPES = np.array([
    [3.0, 3.0, 3.0, 3.0, 3.0, 3.0, 3.0, 3.0],  # open space
    [0.6, 0.9, 1.3, 3.0, 3.0, 3.0, 3.0, 3.0],  # wall on left
    [3.0, 3.0, 3.0, 3.0, 3.0, 1.3, 0.9, 0.6],  # wall on right
    [0.7, 1.0, 1.5, 3.0, 3.0, 1.5, 1.0, 0.7],  # corridor
    [3.0, 3.0, 1.2, 0.5, 0.5, 1.2, 3.0, 3.0],  # front blocked
    [0.5, 0.6, 0.6, 0.7, 1.5, 3.0, 3.0, 3.0],  # left corner
    [3.0, 3.0, 3.0, 1.5, 0.7, 0.6, 0.6, 0.5],  # right corner
    [0.5, 0.6, 0.7, 0.6, 0.6, 0.7, 0.6, 0.5],  # dead end
    [3.0, 1.2, 0.8, 1.5, 3.0, 3.0, 3.0, 3.0],  # obstacle front-left
    [3.0, 3.0, 3.0, 3.0, 1.5, 0.8, 1.2, 3.0],  # obstacle front-right
])


def sonar_like(n: int, seed: int = 0, noise: float = 0.35) -> np.ndarray:
    """(n, 8) ranges in metres: noisy copies of plausible situations, clipped to [0.05, 3]."""
    rng = np.random.default_rng(seed)
    lab = rng.integers(0, len(PROTOTYPES), n)
    X = PROTOTYPES[lab] + rng.normal(0.0, noise, (n, 8)) * (PROTOTYPES[lab] / 3 + 0.3)
    return np.clip(X, 0.05, 3.0)


def time_per_iteration(X, c, iters, repeats, skfuzzy, m=1.2, seed=0):
    rng = np.random.default_rng(seed)
    V0 = X[rng.choice(len(X), c, replace=False)]
    u0 = memberships(X, V0, m).T
    ours, theirs, n_ours = [], [], []
    for _ in range(repeats):  # interleaved
        t = time.perf_counter()
        r = fcm(X, c, m, tol=1e-300, max_iter=iters, init_centers=V0)
        ours.append((time.perf_counter() - t) / r.n_iter)
        n_ours.append(r.n_iter)
        t = time.perf_counter()
        out = skfuzzy.cluster.cmeans(X.T, c, m, 0.0, iters, init=u0)
        theirs.append((time.perf_counter() - t) / out[5])
    return float(np.median(ours)), float(np.median(theirs)), min(n_ours)


def fixed_point_agreement(X, c, skfuzzy, m=1.2, seed=0):
    rng = np.random.default_rng(seed + 1)
    V0 = X[rng.choice(len(X), c, replace=False)]
    ours = fcm(X, c, m, tol=1e-10, max_iter=5000, init_centers=V0)
    cntr, _, _, _, jm, p, _ = skfuzzy.cluster.cmeans(
        X.T, c, m, 1e-12, 5000, init=memberships(X, V0, m).T)
    # skfuzzy's jm[-1] is J at its previous memberships; compare J_m(U(V), V) at its centres
    theirs = validity(X, FCMResult(cntr, memberships(X, cntr, m), 0.0, 0, True, m))
    return abs(ours.objective - theirs["objective"]) / theirs["objective"], ours.n_iter, p


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeats", type=int, default=7)
    args = ap.parse_args()
    import skfuzzy

    print(f"sitframe fcm vs skfuzzy {skfuzzy.__version__} cmeans, m = 1.2, 8-D sonar-like data; "
          f"median of {args.repeats} interleaved repeats; numpy {np.__version__}")
    print(f"{'n':>7} {'c':>3} {'iters':>5} {'sitframe ms/it':>15} {'skfuzzy ms/it':>14} "
          f"{'speed-up':>9} {'rel. |dJ| at the fixed point':>30}")
    for n, c, iters in ((1500, 8, 100), (1500, 12, 100), (1500, 16, 100), (100_000, 8, 10)):
        X = sonar_like(n)
        a, b, it = time_per_iteration(X, c, iters, args.repeats, skfuzzy)
        rel, it_ours, it_theirs = fixed_point_agreement(X, c, skfuzzy)
        note = "" if it == iters else f" (sitframe converged exactly after {it})"
        print(f"{n:>7} {c:>3} {iters:>5} {a * 1e3:>15.3f} {b * 1e3:>14.3f} {b / a:>8.1f}x "
              f"{rel:>11.1e} ({it_ours}/{it_theirs} it){note}")
    X = sonar_like(1500, seed=1)
    times = []
    for _ in range(3):
        t = time.perf_counter()
        tr = cluster_trials(X, 12, n_trials=50, seed=0)
        times.append(time.perf_counter() - t)
    print(f"cluster_trials(n=1500, c=12, 50 trials): {np.median(times):.2f} s "
          f"(median of 3; mean {tr.n_iter.mean():.0f} iterations per trial, chosen trial "
          f"{tr.chosen})")


if __name__ == "__main__":
    main()
