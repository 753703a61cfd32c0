"""Time ``sitframe analyse`` (figures, tables and ``index.html``) on a log, and size the page.

Question: How long does `sitframe analyse` take on a log, and how large is its page?
Output: median wall and CPU time and the page's size, printed.

Runs ``sitframe analyse LOG -o TMP`` in fresh processes ``--repeats`` times and
prints the median wall time, the median CPU time of the process (user + system,
which a loaded shared machine inflates less than wall time), the load average,
the size of ``index.html`` and how much of it is the replay's embedded data.
Target (issue 16): an 11-trial log's report in <= 10 s::

    sitframe run obstacle-avoidance          # in an empty folder: logs/obstacle-avoidance.h5
    python benchmarks/report/bench_report.py logs/obstacle-avoidance.h5 [--repeats 3]
"""

from __future__ import annotations

import argparse
import os
import re
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def once(log: str) -> tuple[float, float, int, int]:
    """(wall s, CPU s, page bytes, replay-data bytes) of one ``analyse`` in a fresh process."""
    with tempfile.TemporaryDirectory() as tmp:
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-m", "sitframe.cli", "analyse", log, "-o", tmp],
                       check=True, stdout=subprocess.DEVNULL)
        wall = time.perf_counter() - t0
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
        page = (Path(tmp) / "index.html").read_text(encoding="utf-8")
        data = re.search(r'<script type="application/json" id="replay-data">(.*?)</script>',
                         page, re.S)
        return wall, cpu, len(page.encode()), len(data.group(1)) if data else 0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("log")
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    runs = [once(args.log) for _ in range(args.repeats)]
    wall = statistics.median(r[0] for r in runs)
    cpu = statistics.median(r[1] for r in runs)
    print(f"analyse {args.log}: median of {args.repeats}: {wall:.1f} s wall, {cpu:.1f} s CPU "
          f"(load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores)")
    print(f"index.html: {runs[0][2] / 1e6:.2f} MB, of which replay data {runs[0][3] / 1e6:.2f} MB")


if __name__ == "__main__":
    main()
