"""Wall and CPU time of one preset run, for several sitframe installs, alternated.

Question: How much longer (or shorter) does a preset's run take with one version of
sitframe than with another, on the same machine at the same time?

Output: a Markdown table (per install: median wall and CPU time, ratio to the first) at
``--out`` (docs/results/tables/timing.md for the learned arbitration's page).

Runs ``SITFRAME run PRESET --workers 1 --out <scratch>`` in ``--folder`` (where the
preset's prerequisite logs are, so only the run itself is timed, its avoidance rule base
selection included) for every ``--sitframe`` executable in turn, ``--repeats`` rounds,
alternating them so that a load that comes and goes on a shared machine hits all alike.
Reports per install the median wall time and CPU time (user + system of the run's
process tree) and each one's ratio to the first install's; the table goes to ``--out``
(Markdown, written here).

An install whose preset needs other prerequisites than the others' (an older version of the
preset, e.g. the one before situation spaces) gets a folder of its own: ``NAME=EXE@FOLDER``
(its prerequisites made there once by that install, so its runs reuse them).

Usage::

    python benchmarks/scale/time_runs.py goal-finding-learned --folder RUN_FOLDER \\
        --sitframe today=/path/to/main/venv/bin/sitframe \\
        --sitframe branch=.venv/bin/sitframe --repeats 3 \\
        --out docs/results/tables/timing.md
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def one_run(exe: str, preset: str, folder: str) -> tuple[float, float]:
    """(wall [s], CPU [s]) of one run in ``folder``, its log in a scratch file."""
    with tempfile.TemporaryDirectory(dir=folder) as tmp:
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        subprocess.run([exe, "run", preset, "--workers", "1", "--out",
                        os.path.join(tmp, "run.h5")], cwd=folder, check=True,
                       stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        wall = time.perf_counter() - t0
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("preset")
    ap.add_argument("--folder", required=True)
    ap.add_argument("--sitframe", action="append", required=True, metavar="NAME=EXE[@FOLDER]")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--out", required=True)
    args = ap.parse_args(argv)
    installs = [tuple(s.split("=", 1)) for s in args.sitframe]
    folders = {name: exe.partition("@")[2] or args.folder for name, exe in installs}
    installs = [(name, exe.partition("@")[0]) for name, exe in installs]
    times: dict[str, list[tuple[float, float]]] = {name: [] for name, _exe in installs}
    for _ in range(args.repeats):
        for name, exe in installs:
            times[name].append(one_run(exe, args.preset, folders[name]))
            print(name, times[name][-1], file=sys.stderr)
    load = os.getloadavg()
    base = installs[0][0]
    med = {n: np.median(np.asarray(v), axis=0) for n, v in times.items()}
    lines = ["<!-- written by benchmarks/scale/time_runs.py; do not edit -->", "",
             f"Command: `python benchmarks/scale/time_runs.py {' '.join(argv or sys.argv[1:])}`; "
             f"{args.repeats} alternated runs each on {os.cpu_count()} cores shared with other "
             f"jobs (load average at the end {load[0]:.1f}, {load[1]:.1f}, {load[2]:.1f}).", "",
             f"| install | wall [s], median | CPU [s], median | wall / {base} | "
             f"CPU / {base} | every run: wall, CPU [s] |", "|---|---|---|---|---|---|"]
    for name, _exe in installs:
        w, c = med[name]
        runs = "; ".join(f"{a:.0f}, {b:.0f}" for a, b in times[name])
        lines.append(f"| {name} | {w:.0f} | {c:.0f} | {w / med[base][0]:.2f} | "
                     f"{c / med[base][1]:.2f} | {runs} |")
    text = "\n".join(lines) + "\n"
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
