"""Two writers on one log, and SIGTERM at random moments: tallies (issue 19).

Question: Do two writers on one log, and SIGTERM at any moment, leave one valid log and
resumable runs?
Output: the tallies printed; exit 1 on any run that did not end cleanly.

::

    python benchmarks/scale/bench_hostile.py --concurrent 20     # two runs on one --out, 20 tries
    python benchmarks/scale/bench_hostile.py --sigterm 20        # SIGTERM / --resume, 20 runs

``--concurrent N`` starts two ``sitframe run obstacle-avoidance --trials 2
--iterations 300 --workers 1`` at the same moment on the same ``--out`` (run
seeds 1 and 2), N times, and counts the tries that end with exactly one run
exiting 0, the other exiting 2 with one stderr line saying another process
is writing the log, and one valid, complete log holding the winner's seed.

``--sigterm N`` sends SIGTERM at a random moment (from start-up on) to N
runs of the kill/interrupt config of ``bench_parallel.py`` (1 or 2 workers)
and to sweeps of it (2 points), and counts the logs that end ``aborted``
(exit 143; or ``complete`` with exit 0 when the signal came after the end)
with no traceback, and how many resume (``run --resume``) to the
uninterrupted result bit for bit (``sitframe.logs.compare.compare_logs``). A
signal that arrives while the interpreter is still starting (before any
sitframe code runs, so before its handler exists) kills the process (exit
-15); that counts as clean only if nothing was written.
Prints figures; it is not a test.
"""

from __future__ import annotations

import argparse
import json
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: common
from common import SITFRAME, reference_run, terminate_at  # noqa: E402

from sitframe.errors import InputError  # noqa: E402
from sitframe.logs.compare import compare_logs  # noqa: E402
from sitframe.logs.reader import open_log  # noqa: E402

SMALL_RUN = ["obstacle-avoidance", "--trials", "2", "--iterations", "300", "--workers", "1",
             "--json"]


def concurrent_tally(n: int, tmp: Path) -> int:
    good = 0
    for i in range(n):
        out = tmp / f"same{i}.h5"
        procs = [subprocess.Popen([*SITFRAME, "run", *SMALL_RUN, "--out", str(out), "--seed",
                                   str(seed)], stdout=subprocess.PIPE, stderr=subprocess.PIPE)
                 for seed in (1, 2)]
        res = [(p.returncode, o, e.decode()) for p in procs for o, e in [p.communicate()]]
        codes = sorted(r[0] for r in res)
        why = f"exit codes {codes}"
        if codes == [0, 2]:
            win = next(r for r in res if r[0] == 0)
            lose = next(r for r in res if r[0] == 2)
            seed = json.loads(win[1])["trials"][0]["seed"]
            try:
                log = open_log(out)
                log.check()
                valid = log.complete and log.trial(0).seed == seed
            except InputError as exc:
                valid, why = False, str(exc)
            refusal = (lose[2].count("\n") == 1 and "another sitframe process" in lose[2]
                       and "Traceback" not in lose[2])
            ok = valid and refusal
            why = "one log, one refusal" if ok else f"valid={valid} refusal={refusal}: {lose[2]}"
        else:
            ok = False
            why += "".join(f"\n  {r[2].strip()[-300:]}" for r in res)
            ok = False
        good += ok
        print(f"try {i + 1:2d}: {why}", flush=True)
    print(f"two writers on one log: {good}/{n} tries ended with one valid log from exactly one "
          "run and one clear refusal")
    return 0 if good == n else 1


SWEEP = """
[sweep]
name = "term"
base = "kill.toml"
trials = 4

[grid]
"behaviours.avoid.p" = [4, 5]
"""


def _settled(code: int | None, err: str, statuses: list[str]) -> bool:
    """Exit 143 with every log aborted or complete, or exit 0 with every log complete, or
    killed by the signal (exit -15) before sitframe's code ran, with nothing written."""
    if code is None or "Traceback" in err or "leaked" in err:
        return False
    if code == -signal.SIGTERM:  # still in interpreter start-up: no handler can exist yet
        return not statuses
    if code == 143:
        return all(s in ("aborted", "complete") for s in statuses)
    return code == 0 and all(s == "complete" for s in statuses)


def _resume(log: Path, workers: str) -> bool:
    if open_log(log).status == "complete":
        return True
    return subprocess.run([*SITFRAME, "run", "--resume", str(log), "--workers", workers,
                           "--json"], stdout=subprocess.DEVNULL,
                          stderr=subprocess.DEVNULL).returncode == 0


def sigterm_tally(n: int, tmp: Path, seed: int) -> int:
    rng = np.random.default_rng(seed)
    cfg, ref, t_ref = reference_run(tmp)
    (tmp / "term.toml").write_text(SWEEP)
    t0 = time.perf_counter()
    subprocess.run([*SITFRAME, "sweep", str(tmp / "term.toml"), "--out", str(tmp / "ref-sweep"),
                    "--workers", "2", "--json"], check=True, stdout=subprocess.DEVNULL)
    t_sweep = time.perf_counter() - t0
    aborted = settled = identical = early = 0
    for i in range(n):
        mode = ["run-1", "run-2", "sweep"][i % 3]
        if mode == "sweep":
            out = tmp / f"sweep{i}"
            at = float(rng.uniform(0.2, 1.1 * t_sweep))
            code, err = terminate_at(["sweep", str(tmp / "term.toml"), "--out", str(out),
                                    "--workers", "2", "--json"], at)
            logs = sorted(out.glob("*.h5"))
            pairs = [(p, tmp / "ref-sweep" / p.name) for p in logs]
            workers = "2"
        else:
            workers = mode[-1]
            out = tmp / f"term{i}.h5"
            at = float(rng.uniform(0.2, 1.1 * t_ref / int(workers)))
            code, err = terminate_at(["run", str(cfg), "--out", str(out), "--workers", workers,
                                    "--json"], at)
            logs = [out] if out.exists() else []
            pairs = [(out, ref)]
        statuses = [open_log(p).status for p in logs]
        ok = _settled(code, err, statuses)
        settled += ok
        aborted += ok and code == 143 and "aborted" in statuses
        early += ok and not statuses
        same = ok and all(_resume(p, workers) and compare_logs(r, p) == [] for p, r in pairs
                          if p.exists())
        identical += same
        print(f"{i + 1:2d} {mode:6s} SIGTERM at {at:5.2f} s: exit {code}, logs {statuses}; "
              f"resumed {'identical' if same else 'DIFFERENT or not clean'}"
              + ("" if ok else f"\n{err[-1500:]}"), flush=True)
    print(f"SIGTERM tally over {n} runs and sweeps (reference run {t_ref:.2f} s, sweep "
          f"{t_sweep:.2f} s): {settled}/{n} ended cleanly (exit 143 with every log 'aborted' "
          f"or 'complete', or exit 0 after completing; {aborted} mid-run with an 'aborted' log, "
          f"{early} before any log existed), "
          f"{identical}/{n} resumed bit-identically to the uninterrupted result")
    return 0 if settled == identical == n else 1


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--concurrent", type=int, metavar="N", help="two-writers tally of N tries")
    ap.add_argument("--sigterm", type=int, metavar="N", help="SIGTERM / resume tally of N runs")
    ap.add_argument("--seed", type=int, default=0, help="seed of the SIGTERM moments")
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="sitframe-hostile-"))
    status = 0
    try:
        if args.concurrent:
            status |= concurrent_tally(args.concurrent, tmp)
        if args.sigterm:
            status |= sigterm_tally(args.sigterm, tmp, args.seed)
        return status
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
