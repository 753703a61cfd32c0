"""Cost of writing a trial to the log as the log grows, and kill -9 at random moments.

Question: Does writing a trial cost more as the log grows, and does a log survive kill -9
at any moment?
Output: the write-cost ratios, or the kill tally, printed; exit 1 if a killed log does not
read or resume bit for bit.

::

    python benchmarks/logs/bench_log.py --trials 1000             # write cost, this code vs --old
    python benchmarks/logs/bench_log.py --kill 50                 # kill -9 / read / --resume tally

``--trials N`` (default 1000) writes one short real trial (obstacle
avoidance, 300 iterations, no evaluation) N times as trials 0..N-1 of
one log, after the run's collect and cluster stages, and times each
``LogWriter.trial`` call. The writer of this checkout and the writer of git
revision ``--old`` (default ``ef46ff4``, the last one that copied the whole
log per trial) write alternately, trial by trial, so a change in machine
load hits both alike. First this checkout's writer writes N trials to one
log, alternating with a control log restarted every 100 trials (never over
100 trials: its ratio is the load drift, and growing/control is the cost of
growth alone); then both writers write ``--old-trials`` trials (default 200: the old one
copies the whole log for every trial, so 1000 would take hours)
alternately, each to its own log.
Printed per writer: the median time to write one of the first 100 trials
and one of the last 100, their ratio (the target for this checkout over
1000 trials is at most 1.2), and the time of the final
``set_status("complete")`` (which packs the trial files into one file in
this checkout). ``--no-old`` skips the old writer.

``--kill N`` runs a config of many short trials (``KILL_CONFIG``, 1 or 2
workers) N times and kills each with SIGKILL at a moment drawn uniformly
from the log's creation to just past the end of an uninterrupted run (so
also while a trial file, the run file or the final packing is being
written). Each killed log must open and be read whole (``Log.check``:
every dataset with its checksum), and ``run --resume`` must bring it to
the uninterrupted run's log bit for bit (:func:`sitframe.logs.compare.compare_logs`),
packed into one file with no trial files or scratch files left beside it.
Prints figures; it is not a test.
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib.util
import os
import signal
import statistics
import subprocess
import sys
import time
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: common
from common import ROOT as REPO  # noqa: E402
from common import SITFRAME, kill_config, reference_run, scratch, start_run  # noqa: E402

from sitframe.errors import InputError  # noqa: E402
from sitframe.logs.compare import compare_logs  # noqa: E402
from sitframe.logs.layout import shard_folder
from sitframe.logs.reader import open_log
from sitframe.logs.writer import LogWriter  # noqa: E402


def old_logs_module(rev: str, tmp: Path) -> ModuleType:
    """``sitframe/logs.py`` of git revision ``rev``, imported as a separate module."""
    src = subprocess.run(["git", "-C", str(REPO), "show", f"{rev}:sitframe/logs.py"],
                         check=True, capture_output=True, text=True).stdout
    path = tmp / "old_logs.py"
    path.write_text(src)
    spec = importlib.util.spec_from_file_location("old_logs", path)
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    sys.modules["old_logs"] = mod  # (its dataclasses look their module up)
    spec.loader.exec_module(mod)
    return mod


def one_trial(tmp: Path) -> tuple[Any, dict[str, dict[str, Any]], Any]:
    """(run info, stage data, one finished trial) of a short obstacle-avoidance run."""
    from sitframe.contract.config import load_config
    from sitframe.runs.prepare import prepare_experiment

    cfg, source, _ = load_config("obstacle-avoidance")
    cfg["experiment"].update(trials=1, iterations=300, stages=["collect", "cluster", "learn"])
    exp, kwargs = prepare_experiment(cfg, source=source, out=str(tmp / "one.h5"))
    trial = exp.run(**kwargs).trials[0]
    log = open_log(tmp / "one.h5")
    stages = {s: log.stage(s) for s in ("collect", "cluster")}
    stages["cluster"]["state"] = log.interpreter_state()
    return exp.info, stages, trial


def _ratio(label: str, times: list[float]) -> float:
    first, last = statistics.median(times[:100]), statistics.median(times[-100:])
    print(f"{label}, {len(times)} trials: median write of one of the first 100 trials "
          f"{1e3 * first:.1f} ms, of the last 100 {1e3 * last:.1f} ms, ratio {last / first:.2f} "
          f"(total {sum(times):.1f} s)")
    return last / first


def _write(writers: dict[str, Any], info: Any, stages: dict[str, Any], trial: Any,
           n: int) -> dict[str, list[float]]:
    """Write ``n`` copies of ``trial`` (indices 0..n-1) with every writer, alternating
    trial by trial (so load drifts hit all alike); seconds per write, per writer."""
    times: dict[str, list[float]] = {k: [] for k in writers}
    for w in writers.values():
        w.start(info)
        for name, data in stages.items():
            w.stage(name, data)
    t_start = time.perf_counter()
    for k in range(n):
        t = dataclasses.replace(trial, index=k, seed=trial.seed + k)
        for label, w in writers.items():
            t0 = time.perf_counter()
            w.trial(t, ["avoid"])
            times[label].append(time.perf_counter() - t0)
        if (k + 1) % 100 == 0:
            print(f"  {k + 1} trials written ({time.perf_counter() - t_start:.0f} s)", flush=True)
    for label, w in writers.items():
        t0 = time.perf_counter()
        w.set_status("complete")
        t_end = time.perf_counter() - t0
        w.release()
        print(f"  {label}: end of run (in this checkout it packs the trial files) {t_end:.2f} s, "
              f"log {os.path.getsize(w.path) / 1e6:.0f} MB", flush=True)
    return times


def _grow_and_control(info: Any, stages: dict[str, Any], trial: Any, n: int,
                      tmp: Path) -> tuple[list[float], list[float]]:
    """Write trials 0..n-1 to one log and, alternately, the same trials to a control log
    started afresh every 100 trials (so it never holds more than 100): seconds per write
    of each. The control tells load drift from growth."""
    big = LogWriter(tmp / "big.h5")
    big.start(info)
    for name, data in stages.items():
        big.stage(name, data)
    grow: list[float] = []
    control: list[float] = []
    small = None
    t_start = time.perf_counter()
    for k in range(n):
        if k % 100 == 0:
            if small is not None:
                small.set_status("complete")
                small.release()
            small = LogWriter(tmp / f"control{k}.h5")
            small.start(info)
            for name, data in stages.items():
                small.stage(name, data)
        t = dataclasses.replace(trial, index=k, seed=trial.seed + k)
        for w, times in ((big, grow), (small, control)):
            t0 = time.perf_counter()
            w.trial(t, ["avoid"])
            times.append(time.perf_counter() - t0)
        if (k + 1) % 100 == 0:
            print(f"  {k + 1} trials written ({time.perf_counter() - t_start:.0f} s)", flush=True)
    t0 = time.perf_counter()
    big.set_status("complete")
    print(f"  end of the run (packs {n} trial files into the log): "
          f"{time.perf_counter() - t0:.2f} s, log {os.path.getsize(big.path) / 1e6:.0f} MB")
    big.release()
    return grow, control


def write_cost(n: int, old_rev: str | None, n_old: int, tmp: Path) -> int:
    info, stages, trial = one_trial(tmp)
    print(f"1. this checkout's writer, one log growing to {n} trials, alternating with a "
          "control log restarted every 100 trials:")
    grow, control = _grow_and_control(info, stages, trial, n, tmp)
    ratio = _ratio("growing log", grow)
    drift = _ratio("control log (never over 100 trials)", control)
    print(f"growth alone (growing-log ratio / control ratio): {ratio / drift:.2f}")
    log = open_log(tmp / "big.h5")
    log.check()
    ok = log.trial_indices() == list(range(n)) and len(log.summary()) == n \
        and not shard_folder(log.path).exists()
    print(f"the packed log reads whole with {n} trials and {n} summary rows: {ok}")
    if old_rev:
        print(f"2. this checkout's writer and the old one ({old_rev}) alternating, {n_old} trials:")
        writers = {"this checkout": LogWriter(tmp / "new2.h5"),
                   f"old ({old_rev})": old_logs_module(old_rev, tmp).LogWriter(tmp / "old.h5")}
        for label, times in _write(writers, info, stages, trial, n_old).items():
            _ratio(label, times)
    print(f"load average: {os.getloadavg()}")
    return 0 if ok and ratio <= 1.2 else 1


KILL_CONFIG = kill_config(trials=30, iterations=150, fcm_trials=2, eval_iterations=30)


def _run(args: list[str]) -> None:
    subprocess.run([*SITFRAME, "run", *args, "--json"], check=True, stdout=subprocess.DEVNULL)


def _leftovers(out: Path) -> list[str]:
    """Scratch files beside the log and in its trial folder, and that folder's files."""
    left = [p.name for p in out.parent.glob(out.name + "*.part")]
    folder = shard_folder(out)
    return left + ([f"{folder.name}/{p.name}" for p in folder.iterdir()] if folder.exists()
                   else [])


def _stale(out: Path) -> list[str]:
    """What a write in progress left: scratch files, and trial files the log does not link."""
    linked = {f"{shard_folder(out).name}/{t:04d}.h5" for t in open_log(out).trial_indices()}
    return [p for p in _leftovers(out) if p.endswith(".part") or p not in linked]


def kill_tally(n: int, tmp: Path, seed: int) -> int:
    rng = np.random.default_rng(seed)
    cfg, ref, t_ref = reference_run(tmp, KILL_CONFIG)
    readable = identical = mid = dirty = 0
    for i in range(n):
        out = tmp / f"killed{i}.h5"
        workers = str(rng.choice([1, 2]))
        proc = start_run(cfg, out, workers)
        t0 = time.perf_counter()
        while proc.poll() is None and not out.exists():
            time.sleep(0.005)
        at = float(rng.uniform(0.0, 1.05 * t_ref / int(workers)))
        time.sleep(at)
        proc.send_signal(signal.SIGKILL)
        proc.wait()
        at = time.perf_counter() - t0
        try:
            log = open_log(out)
            log.check()
            status, have = log.status, log.trial_indices()
            left = _stale(out)
            dirty += bool(left)
            readable += 1
            mid += status == "running"
        except InputError as exc:
            print(f"{i + 1:2d}: killed at {at:.2f} s: the log does NOT read: {exc}", flush=True)
            continue
        subprocess.run([*SITFRAME, "run", "--resume", str(out), "--workers", workers, "--json"],
                       stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        diff = compare_logs(ref, out)
        ok = not diff and open_log(out).status == "complete" and not _leftovers(out)
        identical += ok
        print(f"{i + 1:2d} (workers {workers}): killed at {at:5.2f} s, status {status!r}, "
              f"{len(have):2d}/30 trials, stale: {left[:2] if left else 'nothing'}; "
              f"resumed -> {'identical, one file' if ok else f'DIFFERS {diff[:3]}'}", flush=True)
    print(f"kill -9 tally over {n} runs (uninterrupted run {t_ref:.2f} s): {readable}/{n} logs "
          f"read whole ({mid} killed mid-run; {dirty} killed inside a write, leaving a scratch "
          f"file or an unlinked trial file), {identical}/{n} resumed bit-identically to the "
          "uninterrupted run")
    return 0 if readable == identical == n else 1


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=1000, help="trials of the write-cost run")
    ap.add_argument("--old", default="ef46ff4", metavar="REV",
                    help="git revision whose LogWriter is timed alongside (default ef46ff4)")
    ap.add_argument("--old-trials", type=int, default=200, metavar="M",
                    help="trials the old writer writes (it copies the whole log per trial, "
                    "so 1000 would take hours; default 200)")
    ap.add_argument("--no-old", action="store_true", help="time this checkout's writer only")
    ap.add_argument("--kill", type=int, metavar="N", help="kill -9 / resume tally of N runs "
                    "(instead of the write cost)")
    ap.add_argument("--seed", type=int, default=0, help="seed of the kill moments")
    args = ap.parse_args()
    with scratch("sitframe-bench-log-") as tmp:
        if args.kill:
            return kill_tally(args.kill, tmp, args.seed)
        return write_cost(args.trials, None if args.no_old else args.old, args.old_trials, tmp)


if __name__ == "__main__":
    sys.exit(main())
