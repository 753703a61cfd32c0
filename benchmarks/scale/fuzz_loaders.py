"""Fuzz the input loaders and the FCM API with many generated inputs and tally the outcomes.

Question: Do the world and config loaders, component parameters and fcm answer every
generated input with a documented error?
Output: a tally of outcomes per target, printed; exit 1 on an undocumented exception.

Run::

    python benchmarks/scale/fuzz_loaders.py                  # 10,000 inputs per target (~2-4 min)
    python benchmarks/scale/fuzz_loaders.py -n 500 --target parse_world --show 3

It runs the hypothesis strategies of ``tests/test_fuzz.py`` (the world and
config TOML loaders on random text, near-miss edits of a valid file and
plausible documents with bad values; ``fcm``, ``memberships`` and
``validity`` on arrays of random shapes and dtypes with NaN/inf/empty and bad
parameters) and prints, per target, how many inputs were generated, how many
loaded, how many raised the documented error (``InputError`` for files,
``ValueError``/``TypeError`` for the FCM functions) and how many raised
anything else or broke a result invariant (target: 0), with the first
examples of each such failure. Exit status 1 if any input raised anything
else.
"""

from __future__ import annotations

import argparse
import collections
import sys
import time
import traceback
from pathlib import Path
from typing import Any

from hypothesis import HealthCheck, Phase, given, settings

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tests"))
import test_fuzz as F  # noqa: E402  (the strategies live with the tests)


def run_target(name: str, n: int, show: int) -> tuple[collections.Counter, list[str]]:
    strategy, classify = F.TARGETS[name]
    tally: collections.Counter = collections.Counter()
    examples: list[str] = []

    @settings(max_examples=n, deadline=None, database=None,
              phases=[Phase.generate],  # count every generated input once (no shrinking)
              suppress_health_check=list(HealthCheck))
    @given(strategy)
    def run(value: Any) -> None:
        tally["inputs"] += 1
        try:
            tally[classify(value)] += 1
        except Exception as exc:  # noqa: BLE001 - that is what we count
            tally["other"] += 1
            kind = f"{type(exc).__name__}: {str(exc)[:160]}"
            tally[f"other:{type(exc).__name__}"] += 1
            if len(examples) < show:
                tb = traceback.format_exc().strip().splitlines()
                examples.append(f"{kind}\n    input: {value!r:.400}\n    at: "
                                + " | ".join(line.strip() for line in tb[-4:-1]))

    run()
    return tally, examples


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("-n", "--examples", type=int, default=10_000,
                    help="generated inputs per target (default 10000)")
    ap.add_argument("--target", action="append", choices=sorted(F.TARGETS),
                    help="fuzz only this target (repeatable)")
    ap.add_argument("--show", type=int, default=3, help="failing examples to print per target")
    args = ap.parse_args(argv)
    names = args.target or list(F.TARGETS)
    print(f"{'target':16} {'inputs':>7} {'loaded':>7} {'documented error':>17} "
          f"{'other':>6} {'seconds':>8}")
    total_other = 0
    details = []
    for name in names:
        t0 = time.perf_counter()
        tally, examples = run_target(name, args.examples, args.show)
        dt = time.perf_counter() - t0
        total_other += tally["other"]
        print(f"{name:16} {tally['inputs']:7d} {tally['loaded']:7d} {tally['documented']:17d} "
              f"{tally['other']:6d} {dt:8.1f}", flush=True)
        kinds = {k[6:]: v for k, v in tally.items() if k.startswith("other:")}
        if kinds:
            details.append(f"{name}: {kinds}\n  " + "\n  ".join(examples))
    for d in details:
        print(d)
    print("no other exception type" if not total_other else
          f"{total_other} inputs raised something other than the documented error")
    return 1 if total_other else 0


if __name__ == "__main__":
    sys.exit(main())
