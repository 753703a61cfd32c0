"""What the benchmarks share: the command line to start, a short run to interrupt, a
process signalled at a moment, another git revision to time against.

The benchmarks are grouped by what they measure: ``sim/`` (the simulator and the
environments), ``learning/`` (learning trials, clustering, what the results pages' learning
figures come from), ``logs/`` (writing logs), ``scale/`` (workers, kills, signals, hostile
input), ``duel/`` (fuzzy Q against deep RL in unseen rooms), ``report/`` (analysis and the
results tables). Each script's module docstring says its question and its output. A script puts this
folder on ``sys.path`` (``sys.path.insert(0, str(Path(__file__).resolve().parents[1]))``)
and imports ``common``; :mod:`common.publish` writes the results tables of the docs.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import tarfile
import tempfile
import time
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

#: The repository (benchmarks/ is in it).
ROOT = Path(__file__).resolve().parents[2]
#: The benchmarks' folder, the one ``common`` is imported from.
BENCHMARKS = ROOT / "benchmarks"
#: ``sitframe`` in a fresh process of this interpreter.
SITFRAME = [sys.executable, "-m", "sitframe.cli"]
#: Starts the CLI with Python's SIGINT handler even if the benchmark was started with SIGINT
#: ignored (as a shell's background jobs are): ``[sys.executable, "-c", CLI, *argv]``.
CLI = ("import signal, sys; signal.signal(signal.SIGINT, signal.default_int_handler); "
       "from sitframe.cli.app import console_main; sys.exit(console_main(sys.argv[1:]))")


def kill_config(trials: int = 10, iterations: int = 3000, fcm_trials: int = 4,
                eval_iterations: int = 100) -> str:
    """The run the kill, interrupt and SIGTERM tallies stop: ``trials`` short
    obstacle-avoidance trials over 6 situations."""
    return f"""
[experiment]
name = "kill"
trials = {trials}
iterations = {iterations}
seed = 21

[collect]
worlds = ["collect-1", "collect-2"]

[interpreter]
component = "fcm"
c = 6
trials = {fcm_trials}

[behaviours.avoid]
component = "fuzzy-q"
reward = "obstacle-avoidance"
p = 5

[evaluate]
worlds = ["novel-1"]
iterations = {eval_iterations}
"""


def reference_run(tmp: Path, config: str | None = None) -> tuple[Path, Path, float]:
    """Write ``config`` (default :func:`kill_config`) and run it uninterrupted with one
    worker: ``(config path, log, seconds)``, what an interrupted run must reproduce."""
    cfg = tmp / "kill.toml"
    cfg.write_text(config or kill_config())
    ref = tmp / "reference.h5"
    t0 = time.perf_counter()
    subprocess.run([*SITFRAME, "run", str(cfg), "--out", str(ref), "--workers", "1", "--json"],
                   check=True, stdout=subprocess.DEVNULL)
    return cfg, ref, time.perf_counter() - t0


def start_run(cfg: Path, out: Path, workers: str, *, stderr: int = subprocess.DEVNULL,
              cli: bool = False) -> subprocess.Popen[bytes]:
    """``sitframe run CFG --out OUT --workers K --json`` started in a fresh process (with
    ``cli``: through :data:`CLI`, so that SIGINT is Ctrl-C)."""
    cmd = [sys.executable, "-c", CLI] if cli else SITFRAME
    return subprocess.Popen([*cmd, "run", str(cfg), "--out", str(out), "--workers", workers,
                             "--json"], stdout=subprocess.DEVNULL, stderr=stderr)


def signal_at(proc: subprocess.Popen[bytes], at: float, sig: int,
              timeout: float = 60) -> tuple[int | None, str]:
    """Send ``sig`` to ``proc`` ``at`` seconds from now and wait: ``(exit status, stderr)``,
    or ``(None, "HUNG")`` when it has not ended ``timeout`` seconds later (then killed)."""
    time.sleep(at)
    proc.send_signal(sig)
    try:
        _, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.communicate()
        return None, "HUNG"
    return proc.returncode, (err or b"").decode()


def terminate_at(argv: list[str], at: float) -> tuple[int | None, str]:
    """``sitframe ARGV`` started, SIGTERM-ed ``at`` seconds later (:func:`signal_at`)."""
    proc = subprocess.Popen([sys.executable, "-c", CLI, *argv], stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE)
    return signal_at(proc, at, signal.SIGTERM)


@contextmanager
def scratch(prefix: str) -> Iterator[Path]:
    """A scratch folder for a benchmark's runs, removed afterwards."""
    import shutil

    tmp = Path(tempfile.mkdtemp(prefix=prefix))
    try:
        yield tmp
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


@contextmanager
def revision_tree(rev: str) -> Iterator[Path]:
    """The repository's tree at git revision ``rev``, extracted in a temporary folder."""
    with tempfile.TemporaryDirectory() as tmp:
        old = Path(tmp) / "rev"
        old.mkdir()
        tar = Path(tmp) / "rev.tar"
        tar.write_bytes(subprocess.run(["git", "-C", str(ROOT), "archive", rev], check=True,
                                       capture_output=True).stdout)
        with tarfile.open(tar) as tf:
            tf.extractall(old, filter="data")
        yield old


def against(rev: str, script: Path, call: Callable[[Path, Path], str], repeats: int,
            env: dict[str, str] | None = None) -> dict[str, list[float]]:
    """A measurement of this checkout against git revision ``rev``, in alternating fresh
    processes (so a change in the machine's load hits both).

    ``call(tree, old)`` is the Python expression (in ``script``'s module, imported as ``m``)
    that returns a list of numbers for the sitframe of ``tree`` (``old``: the revision's
    tree, e.g. to time both on its preset); each process imports that tree's sitframe.
    Returns ``{rev: [...], "this checkout": [...]}``.
    """
    import json

    with revision_tree(rev) as old:
        trees = {rev: old, "this checkout": ROOT}
        values: dict[str, list[float]] = {k: [] for k in trees}
        for _ in range(repeats):
            for name, tree in trees.items():
                code = (f"import json, sys; sys.path.insert(0, {str(tree)!r}); "
                        f"sys.path.insert(1, {str(script.parent)!r}); "
                        f"sys.path.insert(2, {str(BENCHMARKS)!r}); "
                        f"import {script.stem} as m; print(json.dumps({call(tree, old)}))")
                res = subprocess.run([sys.executable, "-c", code], cwd=old.parent,
                                     capture_output=True, text=True,
                                     env=dict(os.environ, PYTHONPATH=str(tree), **(env or {})))
                if res.returncode:
                    sys.exit(f"{name}: {res.stderr.strip().splitlines()[-1]}")
                values[name] += json.loads(res.stdout)
    return values


def per_seed(seeds: Iterable[int], folder: Path, fresh: Callable[[dict[str, Any]], bool],
             run: Callable[[int], dict[str, Any]],
             say: Callable[[int, dict[str, Any]], str]) -> list[dict[str, Any]]:
    """Each seed's results: read from ``folder/seed-<seed>.json`` when ``fresh`` accepts what
    is there (the same config and rooms), else ``run(seed)``, written there and said in one
    line on stderr (``say``). A long measurement so resumes where it stopped."""
    out = []
    for seed in seeds:
        path = folder / f"seed-{seed}.json"
        old = json.loads(path.read_text()) if path.is_file() else {}
        if old and fresh(old):
            out.append(old)
            continue
        result = run(seed)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(result, indent=1))
        print(say(seed, result), file=sys.stderr)
        out.append(result)
    return out
