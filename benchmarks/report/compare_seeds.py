"""How often does ``sitframe compare`` call two runs of the same setting different?

Question: How often does `sitframe compare` call two runs of the same setting different?
Output: the share of same-setting seed pairs with a significant metric, printed.

For each setting of a sweep folder that was run with several seeds
(``experiment.seed`` in the grid), every pair of its seeds is compared as two
runs (:func:`sitframe.analysis.compare.compare_logs`): same config, different
seed, so any "difference" is a false positive. Prints, per metric, the share
of pairs with an unadjusted p < 0.05 and the share of pairs in which any
metric is different after the Holm adjustment over the metrics (the verdict
``compare`` prints). Were the trials of a run independent samples of the
setting, both would be about 5 %; they share the run's situations, so they
are higher (measured: 2-11 % per metric, 9 % of 270 pairs with any Holm
difference, for ``logs/sweeps/fuzzy-vs-crisp`` and ``oa12-optimism``)::

    python benchmarks/report/compare_seeds.py logs/sweeps/fuzzy-vs-crisp [more sweep folders]
"""

from __future__ import annotations

import argparse
import itertools
from collections import defaultdict

from sitframe.analysis.compare import SEED_KEY, compare_logs, read_sweep


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folders", nargs="+")
    args = ap.parse_args()
    raw: dict[str, list[bool]] = defaultdict(list)
    any_holm: list[bool] = []
    for folder in args.folders:
        keys, points = read_sweep(folder)
        if SEED_KEY not in keys:
            print(f"{folder}: no {SEED_KEY} axis, skipped")
            continue
        settings: dict[tuple[str, ...], list[str]] = defaultdict(list)
        for p in points:
            settings[tuple(p[k] for k in keys if k != SEED_KEY)].append(p["log"])
        for logs in settings.values():
            for a, b in itertools.combinations(logs, 2):
                cmp = compare_logs([a, b])
                for m in cmp.metrics:
                    if m.p == m.p:  # finite
                        raw[m.label].append(m.p < 0.05)
                any_holm.append(any(m.different for m in cmp.metrics))
    n = len(any_holm)
    print(f"{n} pairs of runs of one setting with different seeds")
    for label, hits in raw.items():
        print(f"  {label:48s} p < 0.05 in {sum(hits):3d}/{len(hits)} = {sum(hits) / len(hits):.1%}")
    print(f"any metric different (Holm-adjusted, 5 %): {sum(any_holm)}/{n} = "
          f"{sum(any_holm) / max(n, 1):.1%}")


if __name__ == "__main__":
    main()
