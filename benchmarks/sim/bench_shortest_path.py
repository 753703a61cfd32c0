"""What the shortest-path reference of SPL costs a batch of goal episodes.

Question: What does the shortest-path reference of SPL cost a batch of goal episodes?
Output: the median time per episode with and without the shortest path, and its share of
the batch, printed.

A goal-only controller (no log needed) runs the same batch of ``--episodes``
random goal episodes in each world (at most 60 iterations each, about the
length of a CDB episode, so the simulation's share is not inflated by
timeouts), once as shipped and once with the
shortest path replaced by the straight line (``spl_shortest`` then equals
``spl``), alternately in this one process so load drifts on a shared machine
hit both alike. Prints, per world, the median batch times, their ratio and
the median cost per episode; and the shortest-path graph's build time (once
per world and process)::

    python benchmarks/sim/bench_shortest_path.py [--repeats 5] [--episodes 50]
"""

from __future__ import annotations

import argparse
import math
import statistics
import time

import numpy as np

WORLDS = ("goal", "novel-1", "multi-room", "u-trap")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--episodes", type=int, default=50)
    args = ap.parse_args()

    import sitframe.plugins.goal_episodes as ge
    from sitframe.contract.config import validate_config
    from sitframe.contract.pluginmanager import Registry, get_plugin_manager
    from sitframe.contract.resolve import Resolved
    from sitframe.runs.loop import TrialSpec, simulate
    from sitframe.sim import paths
    from sitframe.sim.world import load_world

    cfg = validate_config({"interpreter": {"component": "fcm", "c": 2},
                           "behaviours": {"goal": {"component": "goal"}},
                           "arbiter": {"component": "single"},
                           "goal": {"episodes": args.episodes, "timeout": 60}})
    res = Resolved.build(cfg, Registry.collect(get_plugin_manager()))
    state = {"centers": np.array([[0.5] * 8, [3.0] * 8]), "m": 1.2}
    shipped = ge.shortest_path_length

    def straight(world, a, b, *, radius):  # noqa: ANN001, ANN202 - the patched reference
        return float(math.hypot(b[0] - a[0], b[1] - a[1]))

    print("| world | graph build [s] | batch, straight line [s] | batch, shortest path [s] "
          "| ratio | per episode [ms] |\n|---|---|---|---|---|---|")
    for wname in WORLDS:
        t0 = time.perf_counter()
        paths.route_graph(load_world(wname), 0.15)
        build = time.perf_counter() - t0
        spec = TrialSpec(index=0, seed=3, world=wname, iterations=60, learn=False,
                         interpreter_state=state, protocol="goal-episodes")
        times: dict[str, list[float]] = {"straight": [], "shortest": []}
        for _ in range(args.repeats):
            for label, fn in (("straight", straight), ("shortest", shipped)):
                ge.shortest_path_length = fn
                paths._QUERIES.clear()  # each batch of a run draws new pairs: no answer kept
                t0 = time.perf_counter()
                simulate(res, spec)
                times[label].append(time.perf_counter() - t0)
        ge.shortest_path_length = shipped
        a, b = (statistics.median(times[k]) for k in ("straight", "shortest"))
        print(f"| {wname} | {build:.2f} | {a:.3f} | {b:.3f} | {b / a:.2f} | "
              f"{1000 * (b - a) / args.episodes:.1f} |")


if __name__ == "__main__":
    main()
