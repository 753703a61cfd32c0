"""A learning trial with evolving situations against one with the fixed FCM.

Question: How much longer does a learning trial take with evolving situations than with
the fixed FCM?
Output: the median time of each and their ratio, printed.

Both start from the same off-line c = 12 clustering (``obstacle-avoidance-evolving``
with its interpreter replaced by ``fcm`` for the fixed one), learn one
obstacle-avoidance trial of ``--iterations`` iterations without a log, and
are timed alternately in this one process (so load drifts on a shared
machine hit both alike). Prints the medians and their ratio; target (issue
13): evolving / fixed <= 1.5::

    python benchmarks/learning/bench_evolving.py [--repeats 5] [--iterations 5000]
"""

from __future__ import annotations

import argparse
import statistics
import time
from typing import Any


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--iterations", type=int, default=5000)
    args = ap.parse_args()

    from sitframe.contract.config import load_config, validate_config
    from sitframe.runs.prepare import prepare_experiment

    cfg, source, _ = load_config("obstacle-avoidance-evolving")
    cfg["experiment"].update(trials=1, iterations=args.iterations,
                             stages=["collect", "cluster"])
    exp, _ = prepare_experiment(validate_config(cfg, file=source), source=source, out=None)
    state = exp.run().interpreter_state  # the evolving interpreter's start: the c = 12 FCM
    fixed_table = {k: cfg["interpreter"][k] for k in ("c", "m", "trials", "transform", "offset")}
    configs: dict[str, dict[str, Any]] = {}
    for label, table in (("fixed fcm", {"component": "fcm", **fixed_table}),
                         ("evolving", cfg["interpreter"])):
        c = {**cfg, "interpreter": table, "experiment": {**cfg["experiment"], "stages": ["learn"]}}
        configs[label] = validate_config(c, file=source)
    fcm_state = {k: v for k, v in state.items() if k in ("centers", "feature_centers", "m",
                                                         "transform", "offset")}
    times: dict[str, list[float]] = {k: [] for k in configs}
    counts = []
    for _ in range(args.repeats):
        for label, c in configs.items():  # interleaved
            exp, _ = prepare_experiment(c, source=source, out=None)
            t0 = time.perf_counter()
            res = exp.run(interpreter_state=fcm_state)
            times[label].append(time.perf_counter() - t0)
            if label == "evolving":
                counts.append(int(res.trials[0].situations["count"]))
    med = {k: statistics.median(v) for k, v in times.items()}
    for k, v in med.items():
        print(f"{k:>10}: median {v:.3f} s per {args.iterations}-iteration learning trial "
              f"({args.repeats} trials)")
    print(f"evolving situations at the end: {counts}")
    print(f"ratio evolving / fixed fcm: {med['evolving'] / med['fixed fcm']:.3f}")


if __name__ == "__main__":
    main()
