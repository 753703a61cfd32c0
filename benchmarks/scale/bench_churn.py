"""A sweep on a Dask cluster whose workers are killed and restarted: throughput, identical logs.

Question: How much throughput does a sweep keep when its Dask workers are killed and
replaced every few seconds, and are its logs still bit-identical to a calm run's?

Output: per repeat and as medians: wall time, trials per minute calm and under churn,
their ratio, workers killed, complete and identical logs (printed).

::

    python benchmarks/scale/bench_churn.py                    # 40 settings x 2 seeds, 2 workers
    python benchmarks/scale/bench_churn.py --settings 60 --interval 2 --repeats 3

Starts a real Dask cluster (the scheduler of a ``distributed.LocalCluster`` in this
process, ``--workers`` ``dask worker`` processes of one thread each: ``tests/churn.py``),
runs one sweep of ``--settings`` grid values x ``--seeds`` run
seeds (tiny points: one collection room, c = 4, one 60-iteration trial and no
evaluation, so that the sweep is many short tasks) through ``sitframe sweep
--scheduler`` twice per repeat: calm, and under churn, while a thread kills a
random worker with SIGKILL every ``--interval`` seconds and starts a new one at once
(Dask runs the tasks the killed one held again elsewhere). Each sweep is a fresh
``sitframe sweep`` process into an empty folder.

Printed per repeat and as medians: the wall time and the throughput in trials
per minute of each sweep, their ratio (churn / calm; the target is >= 0.5),
the number of workers killed, whether every point's log is complete, and
whether every point's log is bit-identical (``compare_logs``) to the calm
run's. The figures are this machine's; the kill interval and the workers'
start-up time (a killed worker's replacement imports sitframe again) decide
the ratio. Prints figures; it is not a test (``tests/test_faults.py`` runs a
smaller churn as a test).
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tests"))
from churn import Churn, Cluster, write_sweep  # noqa: E402

SITFRAME = [sys.executable, "-m", "sitframe.cli"]


def sweep(sweep_file: Path, out: Path, cluster: Cluster, *, churn: float = 0.0,
          seed: int = 0) -> dict[str, Any]:
    """One ``sitframe sweep`` process on the cluster (under churn if ``churn`` > 0)."""
    cmd = [*SITFRAME, "sweep", str(sweep_file), "--out", str(out), "--scheduler",
           cluster.address, "--json"]
    kills = 0
    t0 = time.perf_counter()
    if churn > 0:
        with Churn(cluster, churn, seed) as c:
            proc = subprocess.run(cmd, capture_output=True, text=True)
        kills = c.kills
    else:
        proc = subprocess.run(cmd, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    cluster.wait_for_workers()  # (the next sweep starts with every worker up)
    return {"code": proc.returncode, "err": proc.stderr, "wall": wall, "kills": kills}


def check(out: Path, ref: Path) -> tuple[int, int, int]:
    """(point logs, complete, identical to ``ref``'s)."""
    from sitframe.errors import InputError
    from sitframe.logs.compare import compare_logs
    from sitframe.logs.reader import open_log

    logs = sorted(ref.glob("*.h5"))
    complete = identical = 0
    for r in logs:
        p = out / r.name
        try:
            complete += open_log(p).complete
            identical += not compare_logs(r, p)
        except InputError:
            pass
    return len(logs), complete, identical


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--settings", type=int, default=40)
    ap.add_argument("--seeds", type=int, default=2)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--interval", type=float, default=3.0, help="seconds between kills")
    ap.add_argument("--iterations", type=int, default=60)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args(argv)
    trials = args.settings * args.seeds
    rates: dict[str, list[float]] = {"calm": [], "churn": []}
    ok = True
    with tempfile.TemporaryDirectory() as tmp, Cluster(args.workers) as c:
        folder = Path(tmp)
        sweep_file = write_sweep(folder, args.settings, args.seeds, args.iterations)
        print(f"{args.settings} settings x {args.seeds} seeds = {trials} points (1 trial "
              f"each), {args.workers} worker processes, a kill every {args.interval:g} s",
              flush=True)
        for r in range(args.repeats):
            calm = sweep(sweep_file, folder / f"calm{r}", c)
            churn = sweep(sweep_file, folder / f"churn{r}", c, churn=args.interval, seed=r)
            n, complete, same = check(folder / f"churn{r}", folder / f"calm{r}")
            for name, res in (("calm", calm), ("churn", churn)):
                rates[name].append(trials / res["wall"] * 60)
                if res["code"] != 0:
                    ok = False
                    print(f"  {name} sweep exit {res['code']}: {res['err'].strip()[-400:]}")
            ok &= complete == n == same == trials
            print(f"repeat {r + 1}: calm {calm['wall']:.1f} s ({rates['calm'][-1]:.0f} trials/min)"
                  f", churn {churn['wall']:.1f} s ({rates['churn'][-1]:.0f} trials/min, "
                  f"{churn['kills']} workers killed): ratio "
                  f"{rates['churn'][-1] / rates['calm'][-1]:.2f}; {complete}/{n} points "
                  f"complete, {same}/{n} identical to calm", flush=True)
    calm_m, churn_m = statistics.median(rates["calm"]), statistics.median(rates["churn"])
    print(f"median: calm {calm_m:.0f} trials/min, churn {churn_m:.0f} trials/min, ratio "
          f"{churn_m / calm_m:.2f} (target >= 0.5); every point complete and identical: {ok}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
