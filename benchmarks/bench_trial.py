"""One learning trial end to end: simulation + FCS + fuzzy Q-learning + HDF5 logging.

Prints the median wall time of a 5000-iteration obstacle-avoidance trial
(situations fitted once beforehand and reused), with the HDF5 logger writing
the trial and without a log, and the logging overhead as a ratio measured in
the same run. Target (issue 4): <= 2.5 s per trial, logging <= 10 %.

    python benchmarks/bench_trial.py [--repeats 5] [--iterations 5000]
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

from sitframe.config import load_config
from sitframe.experiment import prepare_experiment
from sitframe.logs import LogWriter


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--iterations", type=int, default=5000)
    args = ap.parse_args()

    cfg, source, _ = load_config("obstacle-avoidance")
    cfg["experiment"].update(trials=1, iterations=args.iterations, stages=["collect", "cluster"])
    exp, _ = prepare_experiment(cfg, source=source, out=None)
    res = exp.run()
    state = res.interpreter_state
    cfg["experiment"]["stages"] = ["learn"]

    with tempfile.TemporaryDirectory() as tmp:
        timings: dict[str, list[float]] = {"no log": [], "HDF5 log": []}
        for r in range(args.repeats):
            for label in timings:  # interleaved, so load drifts hit both alike
                out = str(Path(tmp) / f"t{r}.h5") if label == "HDF5 log" else None
                exp, _ = prepare_experiment(cfg, source=source, out=out)
                t0 = time.perf_counter()
                exp.run(interpreter_state=state)
                timings[label].append(time.perf_counter() - t0)
        # The per-trial cost of logging alone: writing one finished trial
        # (open-append-flush-close), against simulating it.
        exp, _ = prepare_experiment(cfg, source=source, out=str(Path(tmp) / "w.h5"))
        result = exp.run(interpreter_state=state).trials[0]
        writer = LogWriter(Path(tmp) / "w.h5")
        writes = []
        for _ in range(args.repeats):
            t0 = time.perf_counter()
            writer.trial(result, ["avoid"])
            writes.append(time.perf_counter() - t0)
    med = {k: statistics.median(v) for k, v in timings.items()}
    for k, v in med.items():
        print(f"{k:>9}: median {v:.3f} s per {args.iterations}-iteration run of one trial "
              f"({args.iterations / v:,.0f} iterations/s) over {args.repeats} repeats")
    print(f"end-to-end difference (includes creating the file once per run): "
          f"{100 * (med['HDF5 log'] / med['no log'] - 1):+.1f} %")
    w = statistics.median(writes)
    print(f"writing one finished trial: median {1000 * w:.1f} ms = "
          f"{100 * w / med['no log']:.1f} % of simulating it")


if __name__ == "__main__":
    main()
