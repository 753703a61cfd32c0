"""One learning trial end to end: simulation + FCS + fuzzy Q-learning + HDF5 logging.

Question: How long does one 5000-iteration learning trial take end to end, with and
without writing the log?
Output: the median time per trial and the logging overhead printed (and the ratio to
--against REV's).

Prints the median wall time of a 5000-iteration obstacle-avoidance trial
(situations fitted once beforehand and reused), with the HDF5 logger writing
the trial and without a log, and the logging overhead as a ratio measured in
the same run. Target (issue 4): <= 2.5 s per trial, logging <= 10 %.

``--against REV`` instead times the learning trial of this checkout and of git
revision ``REV`` (exported to a temporary folder; both with REV's obstacle-avoidance
preset) in one run, alternating
fresh processes of each so that load drifts on a shared machine hit both
alike, and prints the medians and their ratio (issue 11: the checked plugin
boundary must cost nothing measurable, within 5 % of the previous commit)::

    python benchmarks/learning/bench_trial.py [--repeats 5] [--iterations 5000]
    python benchmarks/learning/bench_trial.py --against HEAD~1 [--repeats 7]
"""

from __future__ import annotations

import argparse
import importlib
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: common
from common import against  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
#: The built-in plugin modules a learning trial needs (loaded by module, so a
#: revision without a newer entry point still runs; one a revision does not have
#: yet, such as the evaluation protocols', is skipped).
PLUGINS = ("sonar", "fcm_interpreter", "fuzzy_q", "rewards", "arbiters", "frozen_evaluation")


def _time_trials(iterations: int, repeats: int, config: str = "obstacle-avoidance"
                 ) -> list[float]:
    """Seconds per learning trial of ``config`` (a preset name or a .toml path) with this
    process's sitframe."""
    from sitframe.contract.config import load_config, validate_config
    from sitframe.contract.pluginmanager import get_plugin_manager

    try:
        from sitframe.runs.experiment import Experiment
    except ImportError:  # a revision from before Experiment moved (--against)
        from sitframe.scheduler import Experiment

    mods = []
    for m in PLUGINS:
        try:
            mods.append(importlib.import_module(f"sitframe.plugins.{m}"))
        except ModuleNotFoundError:  # an older revision (--against) without it
            pass
    cfg, source, _ = load_config(config)
    cfg["experiment"].update(trials=1, iterations=iterations, stages=["collect", "cluster"])
    cfg = validate_config(cfg, file=source)

    def experiment() -> Experiment:
        return Experiment(cfg, source=source, pm=get_plugin_manager(autoload=False, plugins=mods))

    state = experiment().run().interpreter_state
    cfg["experiment"]["stages"] = ["learn"]
    out = []
    for _ in range(repeats):
        exp = experiment()
        t0 = time.perf_counter()
        exp.run(interpreter_state=state)
        out.append(time.perf_counter() - t0)
    return out


def _against(rev: str, iterations: int, repeats: int) -> None:
    # Both time the same config: the obstacle-avoidance preset as REV has it (a preset whose
    # settings changed since would otherwise time another learning run).
    times = against(rev, Path(__file__), lambda _tree, old: (
        f"m._time_trials({iterations}, 3, "
        f"{str(old / 'sitframe/presets/obstacle-avoidance.toml')!r})"), repeats,
        env={"SITFRAME_DISABLE_PLUGIN_AUTOLOAD": "1"})
    med = {k: statistics.median(v) for k, v in times.items()}
    for k, v in med.items():
        print(f"{k:>14}: median {v:.3f} s per {iterations}-iteration learning trial "
              f"({len(times[k])} trials in {repeats} processes)")
    print(f"ratio this checkout / {rev}: {med['this checkout'] / med[rev]:.3f}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--iterations", type=int, default=5000)
    ap.add_argument("--against", metavar="REV",
                    help="compare this checkout's learning trial with git revision REV")
    args = ap.parse_args()
    if args.against:
        _against(args.against, args.iterations, args.repeats)
        return

    from sitframe.contract.config import load_config
    from sitframe.logs.writer import LogWriter
    from sitframe.runs.prepare import prepare_experiment

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
