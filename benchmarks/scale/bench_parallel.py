"""Wall time of ``sitframe run`` with 1 vs K workers (and a Dask cluster); identical logs?

Question: How much faster do trials run on K workers (and a Dask cluster), with identical
logs? Do logs survive kill -9 and Ctrl-C at random moments?
Output: median wall times and the speed-up, or the kill / Ctrl-C tally, printed; exit 1 on
a log that differs.

::

    python benchmarks/scale/bench_parallel.py                 # 11 trials, 1 vs 2 workers, 3 times
    python benchmarks/scale/bench_parallel.py --repeats 5 --dask  # also through a LocalCluster
    python benchmarks/scale/bench_parallel.py --kill 20       # kill -9 / --resume tally
    python benchmarks/scale/bench_parallel.py --interrupt 40  # Ctrl-C / --resume tally

Each timing is the whole ``sitframe run`` command (a fresh process: imports,
collect, cluster, trials, log writing), so the ratio is what a user sees.
The median over the repeats is reported; serial and parallel runs alternate
so a change in machine load hits both. ``--kill N`` starts N runs, kills
each with SIGKILL at a random moment (after at least one trial is in the
log), checks the log opens, resumes it and compares it bit for bit with an
uninterrupted run. ``--interrupt N`` sends SIGINT (Ctrl-C) instead, at a
random moment from start-up on (so also during collect, cluster and worker
start), and requires every run to end within 60 s with exit 130 and an
``aborted`` log (or exit 0 and a complete log), no traceback, and a resumed
log identical to the uninterrupted one.
"""

from __future__ import annotations

import argparse
import os
import signal
import statistics
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: common
import numpy as np
from common import SITFRAME, reference_run, scratch, signal_at, start_run  # noqa: E402

from sitframe.errors import InputError
from sitframe.logs.compare import compare_logs
from sitframe.logs.reader import open_log


def timed_run(args: list[str]) -> float:
    t0 = time.perf_counter()
    subprocess.run([*SITFRAME, "run", *args, "--json"], check=True, stdout=subprocess.DEVNULL)
    return time.perf_counter() - t0


def bench_workers(experiment: str, trials: int, workers: int, repeats: int, tmp: Path,
                  dask: bool, trials_only: bool = False) -> None:
    serial, parallel, dask_t = [], [], []
    reuse: list[str] = []
    if trials_only:  # fit the situations once; every timed run then reuses them
        situations = tmp / "situations.h5"
        timed_run([experiment, "--trials", "1", "--iterations", "1", "--workers", "1",
                   "--out", str(situations)])
        reuse = ["--clusters-from", str(situations)]
    identical = True
    cluster = None
    if dask:
        from distributed import LocalCluster

        cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                               host="127.0.0.1", dashboard_address=None)
    try:
        for r in range(repeats):
            a, b = tmp / f"serial{r}.h5", tmp / f"parallel{r}.h5"
            common = [experiment, "--trials", str(trials), *reuse]
            serial.append(timed_run([*common, "--workers", "1", "--out", str(a)]))
            parallel.append(timed_run([*common, "--workers", str(workers), "--out", str(b)]))
            identical &= compare_logs(a, b) == []
            if cluster is not None:
                c = tmp / f"dask{r}.h5"
                dask_t.append(timed_run([*common, "--scheduler", cluster.scheduler_address,
                                         "--out", str(c)]))
                identical &= compare_logs(a, c) == []
            print(f"repeat {r + 1}: 1 worker {serial[-1]:.2f} s, {workers} workers "
                  f"{parallel[-1]:.2f} s" + (f", dask {dask_t[-1]:.2f} s" if dask_t else ""),
                  flush=True)
    finally:
        if cluster is not None:
            cluster.close()
    s, p = statistics.median(serial), statistics.median(parallel)
    what = "trials only (situations reused)" if trials_only else "whole command"
    print(f"{experiment}, {trials} trials, {what}, median of {repeats}: 1 worker {s:.2f} s, "
          f"{workers} workers {p:.2f} s, speed-up {s / p:.2f}x" +
          (f", dask ({workers} worker processes) {statistics.median(dask_t):.2f} s"
           if dask_t else ""))
    print(f"best of {repeats} (least disturbed by other load): 1 worker {min(serial):.2f} s, "
          f"{workers} workers {min(parallel):.2f} s, speed-up {min(serial) / min(parallel):.2f}x")
    print(f"logs identical (every dataset and trial attribute): {identical}")
    print(f"load average during the benchmark: {os.getloadavg()}")


def kill_tally(n: int, tmp: Path, seed: int) -> int:
    rng = np.random.default_rng(seed)
    cfg, ref, t_ref = reference_run(tmp)
    opened = reproduced = mid_run = 0
    for i in range(n):
        out = tmp / f"killed{i}.h5"
        workers = str(rng.choice([1, 2]))
        proc = start_run(cfg, out, workers)
        while proc.poll() is None:
            try:
                if out.exists() and open_log(out).trial_indices():
                    break
            except InputError:
                pass
            time.sleep(0.01)
        # a random moment in what is left of the run (~1/workers of the serial time)
        time.sleep(float(rng.uniform(0.0, 0.8 * t_ref / int(workers))))
        proc.send_signal(signal.SIGKILL)
        proc.wait()
        try:
            log = open_log(out)
            status, have = log.status, log.trial_indices()
            opened += 1
            mid_run += status == "running"
        except InputError as exc:
            print(f"run {i + 1}: log does not open: {exc}")
            continue
        subprocess.run([*SITFRAME, "run", "--resume", str(out), "--workers", workers, "--json"],
                       check=True, stdout=subprocess.DEVNULL)
        diff = compare_logs(ref, out)
        ok = not diff and open_log(out).status == "complete"
        reproduced += ok
        print(f"run {i + 1:2d} (workers {workers}): killed with status {status!r} and "
              f"{len(have)}/10 trials; resumed -> {'identical' if ok else f'DIFFERS {diff[:3]}'}",
              flush=True)
    print(f"kill -9 tally: {opened}/{n} logs opened ({mid_run} killed mid-run, the rest just "
          f"after finishing), {reproduced}/{n} resumed runs identical to the uninterrupted run")
    return 0 if opened == reproduced == n else 1


def interrupt_tally(n: int, tmp: Path, seed: int) -> int:
    rng = np.random.default_rng(seed)
    cfg, ref, t_ref = reference_run(tmp)
    good = 0
    outcomes: dict[str, int] = {}
    for i in range(n):
        out = tmp / f"interrupted{i}.h5"
        workers = str(rng.choice([1, 2]))
        at = float(rng.uniform(0.2, 1.1 * t_ref / int(workers)))
        code, err = signal_at(start_run(cfg, out, workers, stderr=subprocess.PIPE, cli=True),
                              at, signal.SIGINT)
        if code is None:
            print(f"run {i + 1}: HUNG after SIGINT at {at:.2f} s")
            outcomes["hung"] = outcomes.get("hung", 0) + 1
            continue
        status = open_log(out).status if out.exists() else "no log"
        clean = "Traceback" not in err and (code, status) in (
            (130, "aborted"), (130, "no log"), (0, "complete"))
        if clean and status == "aborted":
            subprocess.run([*SITFRAME, "run", "--resume", str(out), "--workers", workers,
                            "--json"], check=True, stdout=subprocess.DEVNULL)
            clean = compare_logs(ref, out) == []
        key = f"exit {code}, {status}" + ("" if clean else " (BAD)")
        outcomes[key] = outcomes.get(key, 0) + 1
        good += clean
        if not clean:
            print(f"run {i + 1}: SIGINT at {at:.2f} s -> {key}\n{err[-2000:]}",
                  flush=True)
    print(f"Ctrl-C tally over {n} runs (reference run {t_ref:.2f} s): {outcomes}; "
          f"{good}/{n} clean (aborted logs resumed to the uninterrupted result)")
    return 0 if good == n else 1


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--experiment", default="obstacle-avoidance")
    ap.add_argument("--trials", type=int, default=11)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--dask", action="store_true", help="also run through a Dask LocalCluster")
    ap.add_argument("--trials-only", action="store_true",
                    help="reuse situations fitted once (--clusters-from): time the trials and "
                         "their evaluations, not the serial collect and cluster stages")
    ap.add_argument("--kill", type=int, metavar="N", help="kill -9 / resume tally of N runs")
    ap.add_argument("--interrupt", type=int, metavar="N", help="Ctrl-C / resume tally of N runs")
    ap.add_argument("--seed", type=int, default=0, help="seed of the kill moments")
    args = ap.parse_args()
    with scratch("sitframe-bench-") as tmp:
        if args.kill:
            return kill_tally(args.kill, tmp, args.seed)
        if args.interrupt:
            return interrupt_tally(args.interrupt, tmp, args.seed)
        bench_workers(args.experiment, args.trials, args.workers, args.repeats, tmp, args.dask,
                      args.trials_only)
        return 0


if __name__ == "__main__":
    sys.exit(main())
