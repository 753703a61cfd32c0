"""Issue 41 (speed): a learning trial and the simulator, this checkout against a git revision.

Question: How much faster are a 5000-iteration learning trial (HDF5 log included) and the
simulator than at git revision REV, how much faster does today's preset (evolving situations)
run compiled than on the Python loop, where does a trial's time go before and after, and
does a long trial's memory stay flat?
Output: printed: the medians of both in alternating fresh processes and their ratios (and
today's preset's on both paths of this checkout, alternating too); a
profile of one trial of each (seconds per part of the step); the peak RSS of trials of
10k, 50k and 100k iterations (REV's preset, as timed, and today's, in the process and in a
pool's worker); with ``--publish NAME``
the same as a Markdown table in
``docs/results/tables/NAME.md``.

Every figure is measured in one run, the revision's code and this checkout's alternating
in fresh processes (each imports its own tree's sitframe: REV is exported to a temporary
folder), so a change of the shared machine's load hits both; both run REV's
``obstacle-avoidance`` preset, its situations fitted once per process beforehand, and a
warm-up trial first (the compiled kernels loaded, as in any run longer than a few hundred
iterations). The simulator is ``benchmarks/sim/bench_sim.py``'s wander loop (one 8-ray
sonar read and one 1.5 s step per iteration). The profile is cProfile's (its overhead
inflates Python-heavy parts; compare the shares, not the seconds, with the timings).
Peak RSS is that of a fresh process running one trial with its log (this checkout), and of
one whose trial a pool's worker runs (and the worker's)::

    python benchmarks/learning/bench_speed.py --against main --repeats 5
    python benchmarks/learning/bench_speed.py --against main --repeats 5 --publish speed-41
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: common
# (the compiled trial timed, never the Python loop while its kernel compiles in the
# background: compiled here when the cache lacks it; the processes started inherit it)
os.environ.setdefault("SITFRAME_FUSED", "wait")
from common import BENCHMARKS, against  # noqa: E402

#: Parts of a learning step, and the source files (or compiled kernels, ``k:``, or functions,
#: ``f:``) whose own time (cProfile's ``tottime``; a C function's counts for its caller) is
#: that part; anything else is "loop and other": the loop's own code in
#: ``sitframe/runs/loop.py``, which builds the step's records (``Context``, ``Transition``,
#: ``StepRecord``: their ``__init__`` is not seen by cProfile on Python 3.11), the compiled
#: trial's driver (``sitframe/runs/fused.py``), and the trial's set-up and summary. A trial
#: that runs compiled spends its per-iteration time in the first part (one entry: cProfile
#: cannot see inside a kernel).
PARTS: dict[str, tuple[str, ...]] = {  # (the first that matches: motion's subset before sensing)
    "compiled loop (sensing to learning, one call per 100 iterations)": (
        "runs/fused_kernels.py",),
    "motion and collisions": ("sim/robot.py", "f:subset", "k:arc_angles", "k:arc_poses",
                              "k:near_segments", "k:first_contact", "k:linspace",
                              "k:nearest_point", "k:backoff"),
    "sensing": ("plugins/sonar.py", "sim/geometry.py", "k:ranges", "k:cast"),
    "memberships": ("plugins/fcm_interpreter.py", "situations/fcm.py", "k:fcm_ratios",
                    "k:normalize"),
    "action choice": ("learning/fcs.py", "plugins/arbiters.py", "k:label_strengths",
                      "f:propose", "f:record_rules"),
    "fuzzy-Q update": ("learning/fuzzy_q.py", "f:learn"),
    "reward": ("plugins/rewards.py",),
    "recorder and log": ("f:record", "logs/", "h5py/"),
    "boundary checks": ("contract/checks.py",),
    "observers (pluggy)": ("pluggy/", "plugins/progress.py", "f:step_hook"),
}


def _setup(config: str, iterations: int) -> tuple[Any, Any, Any, Any]:
    """Fit the situations of ``config`` once; ``(cfg, source, state, prepare)``."""
    from sitframe.contract.config import load_config
    from sitframe.runs.prepare import prepare_experiment

    cfg, source, _ = load_config(config)
    cfg["experiment"].update(trials=1, iterations=iterations, stages=["collect", "cluster"])
    exp, _ = prepare_experiment(cfg, source=source, out=None)
    state = exp.run().interpreter_state
    cfg["experiment"]["stages"] = ["learn"]
    return cfg, source, state, prepare_experiment


def trial_times(config: str, iterations: int = 5000, trials: int = 3) -> list[float]:
    """Seconds per learning trial of ``config`` with its HDF5 log, after a warm-up trial
    (this process's sitframe)."""
    cfg, source, state, prepare = _setup(config, iterations)
    out = []
    with tempfile.TemporaryDirectory() as tmp:
        for k in range(trials + 1):
            exp, _ = prepare(cfg, source=source, out=str(Path(tmp) / f"t{k}.h5"))
            t0 = time.perf_counter()
            exp.run(interpreter_state=state)
            out.append(time.perf_counter() - t0)
    return out[1:]


def sim_rates(iterations: int = 2000, runs: int = 3) -> list[float]:
    """Control iterations per second of ``bench_sim``'s wander loop (this process's sitframe)."""
    sys.path.insert(0, str(BENCHMARKS / "sim"))
    import bench_sim

    return bench_sim._rates("training", iterations, runs, 0)


def _part(filename: str, func: str) -> str:
    """The part of the step a profiled function's own time belongs to (:data:`PARTS`)."""
    for part, keys in PARTS.items():
        for key in keys:
            kind, _, name = key.partition(":")
            if (kind == "k" and name and func == name and "kernels_numba" in filename) or \
                    (kind == "f" and name and func == name) or (not name and key in filename):
                return part
    return "loop and other"


def trial_profile(config: str, iterations: int = 5000) -> dict[str, float]:
    """cProfile's seconds per part (:data:`PARTS`) of one logged learning trial, and its
    ``total`` (this process's sitframe)."""
    import cProfile
    import pstats

    cfg, source, state, prepare = _setup(config, iterations)
    parts: dict[str, float] = dict.fromkeys([*PARTS, "loop and other"], 0.0)
    with tempfile.TemporaryDirectory() as tmp:
        prepare(cfg, source=source, out=str(Path(tmp) / "w.h5"))[0].run(interpreter_state=state)
        exp, _ = prepare(cfg, source=source, out=str(Path(tmp) / "p.h5"))
        prof = cProfile.Profile()
        prof.enable()
        exp.run(interpreter_state=state)
        prof.disable()
    stats = pstats.Stats(prof).stats  # type: ignore[attr-defined]
    for (filename, _line, func), (_cc, _nc, tottime, _ct, callers) in stats.items():
        if filename != "~":
            parts[_part(filename.replace(os.sep, "/"), func)] += tottime
            continue
        for (cfile, _cline, cfunc), (*_, c_tottime, _c_cumtime) in callers.items():
            parts[_part(cfile.replace(os.sep, "/"), cfunc)] += c_tottime  # (a C call: its caller's)
    parts["total"] = sum(parts.values())
    return parts


_RSS = """
import json, resource, sys, tempfile
sys.path.insert(0, {bench!r})
import bench_speed as m
cfg, source, state, prepare = m._setup({config!r}, {iterations})
before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
worker = None
with tempfile.TemporaryDirectory() as tmp:
    exp, _ = prepare(cfg, source=source, out=tmp + "/t.h5")
    if {pool}:
        from sitframe.runs.parallel import ProcessExecutor
        exp.executor = ProcessExecutor(1)
    exp.run(interpreter_state=state)
    if {pool}:
        worker = exp.executor.submit(resource.getrusage, resource.RUSAGE_SELF).result().ru_maxrss
        exp.executor.shutdown()
after = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
print(json.dumps([before, after, worker]))
"""


def peak_rss(config: str, iterations: int, pool: bool = False
             ) -> tuple[float, float, float | None]:
    """Peak RSS [MiB] of a fresh process (this checkout) before and after one logged trial of
    ``iterations``, and with ``pool`` (the trial run by a pool's one worker) the worker's."""
    code = _RSS.format(bench=str(Path(__file__).parent), config=config, iterations=iterations,
                       pool=pool)
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, env=dict(os.environ, SITFRAME_NUMBA="1"))
    before, after, worker = json.loads(res.stdout.strip().splitlines()[-1])
    return before / 1024, after / 1024, None if worker is None else worker / 1024


def loop_or_compiled(repeats: int) -> dict[str, list[float]]:
    """Seconds per trial of today's ``obstacle-avoidance`` preset in this checkout, the Python
    loop (``SITFRAME_FUSED=0``) and compiled alternating in fresh processes."""
    code = (f"import json, sys; sys.path.insert(0, {str(Path(__file__).parent)!r}); "
            "import bench_speed as m; "
            "print(json.dumps(m.trial_times('obstacle-avoidance')))")
    out: dict[str, list[float]] = {"Python loop": [], "compiled": []}
    for _ in range(repeats):
        for name, mode in (("Python loop", "0"), ("compiled", "wait")):
            res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                                 check=True, env=dict(os.environ, SITFRAME_FUSED=mode,
                                                      SITFRAME_NUMBA="1"))
            out[name] += json.loads(res.stdout.strip().splitlines()[-1])
    return out


def _profiles(rev: str) -> dict[str, dict[str, float]]:
    """One profiled trial of each tree (REV's preset), alternating: name -> seconds per part."""
    got = against(rev, Path(__file__), lambda _tree, old: (
        f"[m.trial_profile({str(old / 'sitframe/presets/obstacle-avoidance.toml')!r})]"), 1)
    return {name: v[0] for name, v in got.items()}


def _table(rev: str, med: dict[str, dict[str, float]], prof: dict[str, dict[str, float]],
           rss: list[tuple[str, int, float, float]]) -> str:
    """The Markdown table of the timings, the profile and the peak RSS."""
    new, old = "this checkout", rev
    today = med["today"]
    lines = [f"| | {rev} | this checkout | ratio |", "|---|---:|---:|---:|",
             f"| learning trial, 5000 iterations with its log (median s) | "
             f"{med['trial'][old]:.3f} | {med['trial'][new]:.3f} | "
             f"{med['trial'][old] / med['trial'][new]:.2f}x faster |",
             f"| simulator (median control iterations/s) | {med['sim'][old]:,.0f} | "
             f"{med['sim'][new]:,.0f} | {med['sim'][new] / med['sim'][old]:.2f}x the rate |",
             "", "| today's obstacle-avoidance preset (evolving situations, ten rooms), this "
             "checkout | Python loop | compiled | ratio |", "|---|---:|---:|---:|",
             f"| learning trial, 5000 iterations with its log (median s) | "
             f"{today['Python loop']:.3f} | {today['compiled']:.3f} | "
             f"{today['Python loop'] / today['compiled']:.2f}x faster |",
             "", f"| profile of one trial (cProfile, s) | {rev} | share | this checkout | "
             "share |", "|---|---:|---:|---:|---:|"]
    for part in sorted(prof[old], key=lambda p: -prof[old][p]):
        if part == "total":
            continue
        a, b = prof[old][part], prof[new][part]
        lines.append(f"| {part} | {a:.3f} | {a / prof[old]['total']:.0%} | {b:.3f} | "
                     f"{b / prof[new]['total']:.0%} |")
    lines.append(f"| **total** | {prof[old]['total']:.3f} | | {prof[new]['total']:.3f} | |")
    lines += ["", "| one logged trial of | iterations | peak RSS before the trial (MiB) | "
              "after (MiB) | its worker's (MiB) |", "|---|---:|---:|---:|---:|"]
    lines += [f"| {name} | {n:,} | {b:.0f} | {a:.0f} | {'–' if w is None else f'{w:.0f}'} |"
              for name, n, b, a, w in rss]
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--against", metavar="REV", default="main")
    ap.add_argument("--repeats", type=int, default=5, help="processes per tree and figure")
    ap.add_argument("--rss", default="10000,50000,100000",
                    help="trial lengths whose peak RSS is measured ('' for none)")
    ap.add_argument("--publish", metavar="NAME", help="write the table to the docs' tables")
    args = ap.parse_args()
    rev = args.against
    env = {"SITFRAME_NUMBA": "1"}
    trial = against(rev, Path(__file__), lambda _t, o: (
        f"m.trial_times({str(o / 'sitframe/presets/obstacle-avoidance.toml')!r})"),
        args.repeats, env=env)
    sim = against(rev, Path(__file__), lambda _t, _o: "m.sim_rates()", args.repeats, env=env)
    today = loop_or_compiled(args.repeats)
    med = {"trial": {k: statistics.median(v) for k, v in trial.items()},
           "sim": {k: statistics.median(v) for k, v in sim.items()},
           "today": {k: statistics.median(v) for k, v in today.items()}}
    for k, v in med["today"].items():
        print(f"today's preset, {k}: learning trial median {v:.3f} s")
    for k, v in med["trial"].items():
        print(f"{k:>14}: learning trial median {v:.3f} s ({len(trial[k])} trials in "
              f"{args.repeats} processes)")
    for k, v in med["sim"].items():
        print(f"{k:>14}: simulator median {v:,.0f} control iterations/s")
    print(f"trial: {med['trial'][rev] / med['trial']['this checkout']:.2f}x faster; simulator: "
          f"{med['sim']['this checkout'] / med['sim'][rev]:.2f}x the rate")
    prof = _profiles(rev)
    with tempfile.TemporaryDirectory() as tmp:  # (REV's preset: the trials timed above)
        old = Path(tmp) / "rev.toml"
        old.write_text(subprocess.run(["git", "show", f"{rev}:sitframe/presets/"
                                       "obstacle-avoidance.toml"], capture_output=True,
                                      text=True, check=True, cwd=BENCHMARKS.parent).stdout)
        rss = [(name, n, *peak_rss(cfg, n, pool))
               for name, cfg, pool in (
                   (f"{rev}'s obstacle-avoidance (compiled)", str(old), False),
                   ("today's obstacle-avoidance (evolving, compiled)", "obstacle-avoidance",
                    False),
                   ("the same in a pool's worker", "obstacle-avoidance", True))
               for n in (int(v) for v in args.rss.split(",") if v.strip())]
    table = _table(rev, med, prof, rss)
    print(table)
    if args.publish:
        from common.publish import publish

        publish(args.publish, table)


if __name__ == "__main__":
    main()
