"""Pool the logs of several settings and print the README's situations table (and a figure).

Question: How do fixed, automatic, evolving and on-line situations compare, pooled over
their seeds?
Output: the situations table printed as Markdown and --figure the figure; with --publish
NAME the table in docs/results/tables/NAME.md.

Each argument is ``NAME::GLOB``: a setting's name and a glob of its logs (one
per run seed). Every learning trial of every log is pooled; its frozen rule
base is judged in the rooms it never saw (``--rooms``, default the two novel
rooms), with that trial's own situations::

    python benchmarks/report/situations.py \\
        "c = 12::logs/sweeps/situations/interpreter=fcm-c=12-*_seed=*.h5" \\
        "evolving::logs/sweeps/situations/interpreter=*evolving*_seed=*.h5" \\
        --figure docs/results/figures/situations.png

Columns: trials converged; final number of situations, median [IQR] (a
fixed interpreter's c); evaluation collisions per 1000 iterations, median
[IQR] and worst, over every (trial, room) evaluation, and the median in
each room; the share of evaluations above 10 per 1000; median coverage; and
the *frontal collisions that began between prototypes*
(:func:`sitframe.sim.metrics.frontal_between_prototypes`: contact within 30 deg of
the heading, the acted-on reading's top membership below 0.5) as a share of
all evaluation collisions.
"""

from __future__ import annotations

import argparse
import glob
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: common
from common.publish import publish  # noqa: E402

from sitframe.logs.reader import open_log  # noqa: E402
from sitframe.sim.metrics import frontal_between_prototypes  # noqa: E402


def pool(paths: list[str], rooms: list[str]) -> dict[str, np.ndarray]:
    """Per-trial and per-evaluation figures of every trial in ``paths``."""
    conv, sits, coll, cov, room, fb, n_coll = [], [], [], [], [], 0, 0
    for path in paths:
        log = open_log(path)
        fixed_c = None
        for k in log.trial_indices():
            tr = log.trial(k)
            conv.append(bool(tr.summary["converged"]))
            if tr.situations:
                sits.append(int(tr.situations["count"]))
            else:
                if fixed_c is None:
                    fixed_c = len(log.interpreter_state()["centers"])
                sits.append(fixed_c)
            for w in rooms:
                coll.append(float(tr.summary[f"eval/{w}/collisions_per_1000"]))
                cov.append(float(tr.summary[f"eval/{w}/coverage"]))
                room.append(w)
                e = {key: tr.episodes[f"eval/{w}/{key}"]
                     for key in ("pose", "collision", "contact", "memberships")}
                fb += int(frontal_between_prototypes(e["pose"], e["collision"], e["contact"],
                                                     e["memberships"]).sum())
                n_coll += int(np.sum(e["collision"]))
    return {"converged": np.asarray(conv), "situations": np.asarray(sits),
            "collisions": np.asarray(coll), "coverage": np.asarray(cov),
            "room": np.asarray(room), "frontal_between": np.asarray([fb, n_coll])}


def _miq(x: np.ndarray, fmt: str = "{:.1f}") -> str:
    q1, q2, q3 = np.percentile(x, [25, 50, 75])
    return f"{fmt.format(q2)} [{fmt.format(q1)}, {fmt.format(q3)}]"


def table(results: dict[str, dict[str, np.ndarray]], rooms: list[str],
          against: str | None = None) -> str:
    """The situations table; with ``against`` a column testing whether each setting's
    evaluation collisions are worse than that setting's (Mann-Whitney U, one-sided)."""
    from scipy.stats import mannwhitneyu

    head = ["setting", "converged", "situations, median [IQR]",
            "eval coll./1000, median [IQR] (worst)",
            *[f"{w}: median" for w in rooms], "evals > 10/1000", "coverage",
            "frontal between prototypes"]
    if against:
        head.append(f"worse than {against}? (Mann-Whitney, one-sided)")
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for name, r in results.items():
        c = r["collisions"]
        fb, n = r["frontal_between"]
        row = [name, f"{r['converged'].sum()}/{r['converged'].size}",
               _miq(r["situations"], "{:g}"), f"{_miq(c)} ({c.max():g})",
               *[f"{np.median(c[r['room'] == w]):g}" for w in rooms],
               f"{np.mean(c > 10):.1%}", f"{np.median(r['coverage']):.2f}",
               f"{fb}/{n} ({fb / n:.0%})" if n else "0/0"]
        if against:
            p_value = mannwhitneyu(c, results[against]["collisions"],
                                   alternative="greater").pvalue
            row.append("--" if name == against else
                       "p < 0.001" if p_value < 0.001 else f"p = {p_value:.2f}")
        lines.append("| " + " | ".join(row) + " |")
    return "\n".join(lines)


def figure(results: dict[str, dict[str, np.ndarray]], path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(results)
    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 3.8), layout="constrained",
                               gridspec_kw={"width_ratios": [3, 2]})
    rng = np.random.default_rng(0)  # jitter of the dots only
    for i, n in enumerate(names):
        c = results[n]["collisions"]
        a.scatter(i + rng.uniform(-0.18, 0.18, c.size), c, s=6, alpha=0.35, color="tab:blue")
        a.plot([i - 0.3, i + 0.3], [np.median(c)] * 2, color="black", lw=2)
        s = results[n]["situations"]
        b.scatter(i + rng.uniform(-0.18, 0.18, s.size), s, s=8, alpha=0.4, color="tab:green")
        b.plot([i - 0.3, i + 0.3], [np.median(s)] * 2, color="black", lw=2)
    a.axhline(10, color="tab:red", lw=0.8, ls="--", label="10 per 1000")
    a.set_yscale("symlog", linthresh=1)
    top = max(float(r["collisions"].max()) for r in results.values())
    a.set_ylim(-0.15, max(20.0, top * 10))  # (headroom: the legend sits above every dot)
    a.set_ylabel("Evaluation collisions per 1000 it.")
    a.set_title("Frozen rule bases in the evaluation rooms (bar = median)")
    a.legend(fontsize=8, loc="upper right")
    b.set_ylabel("Situations at the end of the trial")
    b.set_title("Number of situations")
    for ax in (a, b):
        ax.set_xticks(range(len(names)), names, rotation=20, ha="right", fontsize=8)
        ax.grid(axis="y", alpha=0.3)
    fig.savefig(path, dpi=150)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("settings", nargs="+", metavar="NAME::GLOB")
    ap.add_argument("--rooms", nargs="+", default=["novel-1", "novel-2"])
    ap.add_argument("--figure", metavar="PNG")
    ap.add_argument("--against", metavar="NAME",
                    help="add a column: is each setting worse than setting NAME?")
    ap.add_argument("--publish", metavar="NAME",
                    help="also write the table to docs/results/tables/NAME.md")
    args = ap.parse_args()
    results: dict[str, dict[str, np.ndarray]] = {}
    owner: dict[str, str] = {}  # log -> the setting that matched it first
    for arg in args.settings:
        name, _, pattern = arg.partition("::")
        paths = sorted(glob.glob(pattern))
        if not paths:
            print(f"situations_report: no logs match '{pattern}' ({name})", file=sys.stderr)
            return 2
        # A glob that also matches another setting's logs (``*c=12-*`` matches the
        # evolving logs of sweeps/situations.toml too) would pool two settings in one row.
        twice = [p for p in paths if p in owner]
        if twice:
            print(f"situations_report: '{pattern}' ({name}) matches {twice[0]}, already pooled "
                  f"in '{owner[twice[0]]}'; expected each log in one setting (narrow the glob)",
                  file=sys.stderr)
            return 2
        owner.update(dict.fromkeys(paths, name))
        results[name] = pool(paths, args.rooms)
        print(f"{name}: {len(paths)} logs", file=sys.stderr)
    if args.against and args.against not in results:
        print(f"situations_report: --against {args.against}: no such setting", file=sys.stderr)
        return 2
    text = table(results, args.rooms, args.against)
    print(text)
    if args.publish:
        publish(args.publish, text)
    if args.figure:
        figure(results, args.figure)
    return 0


if __name__ == "__main__":
    sys.exit(main())
