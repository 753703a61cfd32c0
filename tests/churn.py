"""A real Dask cluster whose workers are killed and restarted while a sweep runs.

Shared by ``tests/test_faults.py`` (a churn test) and ``benchmarks/scale/bench_churn.py``
(throughput with and without churn). The scheduler runs in this process (a
``distributed.LocalCluster`` without workers); every worker is a ``dask worker``
process of its own (one thread, no nanny), so killing one with SIGKILL is what a
machine going away does to a cluster, and :meth:`Cluster.kill_one` starts a
replacement at once, as an autoscaler or a batch system would.
"""

from __future__ import annotations

import os
import random
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

BASE = """
[experiment]
name = "churn"
trials = 1
iterations = {iterations}
seed = 0
stages = ["collect", "cluster", "learn"]

[collect]
worlds = ["collect-1"]
wander_samples = 60

[interpreter]
component = "fcm"
c = 4
trials = 2

[behaviours.avoid]
component = "fuzzy-q"
reward = "obstacle-avoidance"
p = 5
"""


def write_sweep(folder: Path, settings: int, seeds: int, iterations: int = 60) -> Path:
    """A sweep of ``settings`` learning rates x ``seeds`` run seeds over a tiny run (one
    collection room, c = 4, one short trial, no evaluation): many short tasks."""
    (folder / "base.toml").write_text(BASE.format(iterations=iterations))
    alphas = ", ".join(f"{0.05 + 0.9 * i / max(settings - 1, 1):.4f}" for i in range(settings))
    (folder / "churn.toml").write_text(
        f'[sweep]\nname = "churn"\nbase = "base.toml"\n\n[grid]\n'
        f'"behaviours.avoid.alpha" = [{alphas}]\n'
        f'"experiment.seed" = {list(range(seeds))}\n')
    return folder / "churn.toml"


class Cluster:
    """A scheduler in this process and ``workers`` worker processes (context manager).

    Parameters
    ----------
    workers
        Worker processes kept running (one thread each).
    log
        File the workers' output goes to (default: discarded).
    """

    def __init__(self, workers: int, log: Path | None = None, allowed_failures: int = 50
                 ) -> None:
        self.n, self.allowed_failures = workers, allowed_failures
        self.log = log
        self.procs: list[subprocess.Popen[bytes]] = []
        self.kills = 0
        self._lock = threading.Lock()
        self.cluster: Any = None

    @property
    def address(self) -> str:
        return str(self.cluster.scheduler_address)

    def _start_worker(self) -> None:
        out = open(self.log, "ab") if self.log else subprocess.DEVNULL  # noqa: SIM115
        self.procs.append(subprocess.Popen(
            [sys.executable, "-m", "distributed.cli.dask_worker", self.address, "--nthreads",
             "1", "--no-nanny", "--no-dashboard"], stdout=out, stderr=out,
            env={**os.environ, "OMP_NUM_THREADS": "1"}))
        if self.log:
            out.close()

    def wait_for_workers(self, n: int | None = None, timeout: float = 120.0) -> None:
        """Block until ``n`` (default all) workers are connected."""
        self.cluster.scheduler_info  # noqa: B018 - (property)
        t0 = time.monotonic()
        while len(self.cluster.scheduler.workers) < (self.n if n is None else n):
            if time.monotonic() - t0 > timeout:
                raise TimeoutError(f"{n or self.n} Dask workers did not connect in {timeout} s")
            time.sleep(0.1)

    def kill_one(self, rng: random.Random) -> None:
        """SIGKILL a random worker process and start its replacement."""
        with self._lock:
            alive = [p for p in self.procs if p.poll() is None]
            if alive:
                victim = rng.choice(alive)
                victim.send_signal(signal.SIGKILL)
                victim.wait()
                self.kills += 1
            self.procs = [p for p in self.procs if p.poll() is None]
            while len(self.procs) < self.n:
                self._start_worker()

    def __enter__(self) -> Cluster:
        import dask
        from distributed import LocalCluster

        # A task whose worker is killed is run again elsewhere; under steady churn one task
        # may lose several workers in a row, more than Dask's default three.
        with dask.config.set({"distributed.scheduler.allowed-failures": self.allowed_failures}):
            # (dashboard_address=None still serves HTTP on 8787 and warns if that is taken)
            self.cluster = LocalCluster(n_workers=0, processes=False, protocol="tcp",
                                        host="127.0.0.1", dashboard_address="127.0.0.1:0")
        for _ in range(self.n):
            self._start_worker()
        self.wait_for_workers()
        return self

    def __exit__(self, *exc: Any) -> None:
        with self._lock:
            for p in self.procs:
                if p.poll() is None:
                    p.send_signal(signal.SIGKILL)
                    p.wait()
            self.procs = []
        self.cluster.close()


class Churn:
    """Kills a random worker of ``cluster`` (and starts its replacement) every ``interval``
    seconds while the ``with`` block runs."""

    def __init__(self, cluster: Cluster, interval: float, seed: int = 0) -> None:
        self.cluster, self.interval = cluster, interval
        self.rng = random.Random(seed)
        self.kills = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="churn", daemon=True)

    def _run(self) -> None:
        while not self._stop.wait(self.interval):
            self.cluster.kill_one(self.rng)
            self.kills += 1

    def __enter__(self) -> Churn:
        self._thread.start()
        return self

    def __exit__(self, *exc: Any) -> None:
        self._stop.set()
        self._thread.join(timeout=60)
