"""Runs side by side with confidence intervals and a rank test (``sitframe compare``).

The unit of observation is one learning trial: every metric is read from the
logs' summary tables (one row per finished trial). Per run and metric the
page gives the median (the share, for the convergence rate) with a 95 %
bootstrap confidence interval (:func:`scipy.stats.bootstrap`, percentile
method, 2000 resamples, seeded), and across runs a rank test: Mann-Whitney U
(:func:`scipy.stats.mannwhitneyu`, two-sided) for two runs, Kruskal-Wallis
(:func:`scipy.stats.kruskal`) for more. Because a table tests a dozen metrics
at once, p-values are also given Holm-adjusted over the table's metrics; a
metric is called *different* when its Holm-adjusted p is below 0.05, so that
two runs that differ only by chance are called different in at most 5 % of
comparisons, whatever the number of metrics. For two runs the difference of
the medians (second minus first) has its own bootstrap interval.

Metrics: share of converged trials; iterations to convergence and collisions
per 1000 iterations after convergence (converged trials only); for every
evaluation world the collisions per 1000 iterations and the coverage of the
frozen rule base; for goal-episode evaluations the success rate, the share of
collision-free episodes, SPL, mean time to goal and heading change per metre.

Plugin figures: every per-trial scalar a plugin logged (the summary columns
``plugins.<plugin>.<key>`` and ``behaviours.<label>.<key>``,
:meth:`sitframe.logs.reader.Log.plugin_scalars`) is compared the same way, a
bool as a share, after the core metrics. They are a family of their own for
Holm's adjustment: the core metrics' verdicts do not depend on how much the
run's plugins log (each family holds its error rate at 5 %).

Two logs are two runs: the test asks whether *these runs'* trials differ.
Trials of one run share its situations (the clustering of its seed), so two
runs of one setting with different seeds differ more often than chance
(``benchmarks/report/compare_seeds.py``: 9 % of 270 same-setting seed pairs had a
Holm-significant metric); to compare *settings*, run each with several seeds.

A sweep folder (``sitframe sweep`` output) is compared per setting: points
that differ only in ``experiment.seed`` are pooled, each metric is drawn
against every grid axis (one line per combination of the other axes) with
its intervals, and the test runs across all settings. When settings pool
two or more seeds, the unit is the run: the intervals resample whole runs
(a cluster bootstrap over seeds, trials pooled within) and the rank test
compares the runs' medians, so the seed-to-seed spread is counted.
"""

from __future__ import annotations

import csv
import math
import os
import re
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np
from scipy import stats

from sitframe.analysis.results import Table, _col, _summary, as_log
from sitframe.contract.records import summary_key
from sitframe.errors import InputError

__all__ = ["Comparison", "MetricResult", "compare_logs", "compare_sweep", "trial_metrics"]

#: Confidence level of the intervals and resamples of the bootstrap.
LEVEL, RESAMPLES, ALPHA = 0.95, 2000, 0.05
_GOAL = {"success_rate": "success rate", "collision_free_rate": "collision-free episodes",
         "spl": "SPL", "spl_shortest": "SPL (shortest path)",
         "mean_time_s": "mean time to goal [s]",
         "heading_change_per_m": "heading change [deg/m]"}


@dataclass
class MetricResult:
    """One metric across the compared runs.

    Attributes
    ----------
    key, label : str
        Summary column (or derived name) and its readable label.
    statistic : str
        ``"median"`` or ``"share"`` (the mean of a 0/1 value).
    values : list of ndarray
        Per run, the trial values (NaN dropped).
    estimate, low, high : list of float
        Per run, the statistic and its bootstrap interval (NaN for < 2 trials).
    p : float
        Rank-test p-value across runs (NaN if fewer than two runs have data).
    p_holm : float
        ``p`` Holm-adjusted over the metrics of its family in the comparison.
    diff : tuple of float or None
        Two runs: (median of run 2 - median of run 1, low, high).
    family : str
        ``"core"`` (the metrics above) or ``"plugin"`` (a plugin's per-trial scalar).
    """

    key: str
    label: str
    statistic: str
    values: list[np.ndarray]
    estimate: list[float] = field(default_factory=list)
    low: list[float] = field(default_factory=list)
    high: list[float] = field(default_factory=list)
    p: float = math.nan
    p_holm: float = math.nan
    diff: tuple[float, float, float] | None = None
    runs: list[int] = field(default_factory=list)  # per compared run: seeds pooled in it
    family: str = "core"  # "core" or "plugin": Holm adjusts within each

    @property
    def different(self) -> bool:
        """True when the Holm-adjusted p-value is below 0.05."""
        return bool(self.p_holm < ALPHA)


@dataclass
class Comparison:
    """What :func:`compare_logs` / :func:`compare_sweep` computed."""

    names: list[str]
    sources: list[str]
    test: str
    metrics: list[MetricResult]
    axes: dict[str, list[Any]] = field(default_factory=dict)  # sweeps: setting -> axis values
    unit: str = "trial"  # what the test and intervals resample: "trial", or "run" (seed)

    def table(self) -> Table:
        """One row per metric: each run's estimate [95 % CI] (n), p, Holm p, verdict."""
        cols = ["Metric", *self.names]
        two = len(self.names) == 2
        if two:
            cols.append("Difference (2nd - 1st) [95 % CI]")
        cols += [f"p ({self.test})", "p (Holm)", "Different at 5 %"]
        rows = []
        for m in self.metrics:
            d = 0 if m.key.endswith("iteration") else 2
            cells: list[Any] = [m.label]
            for j, (v, e, lo, hi) in enumerate(zip(m.values, m.estimate, m.low, m.high,
                                                   strict=True)):
                seeds = f", {m.runs[j]} runs" if self.unit == "run" else ""
                cells.append(_interval(e, lo, hi, d) + f" (n={v.size}{seeds})")
            if two:
                cells.append(_interval(*m.diff, d) if m.diff else "–")
            cells += [_p(m.p), _p(m.p_holm), "yes" if m.different else "no"]
            rows.append(cells)
        unit = ("whole runs (seeds) resampled; the test compares the runs' medians"
                if self.unit == "run" else "trials resampled; the test compares trials")
        notes = [f"Estimate = median over trials (share for the convergence rate) with a "
                 f"{LEVEL:.0%} bootstrap interval ({RESAMPLES} resamples, percentile method, "
                 f"{unit}); n = trials with a value. p: {self.test}, "
                 f"{'two-sided' if two else 'across all runs'}; Holm-adjusted over the "
                 f"{self._tested('core')} tested metrics"
                 + (f", and the {self._tested('plugin')} tested plugin figures (the rows "
                    "named after a plugin or behaviour) among themselves."
                    if any(m.family == "plugin" for m in self.metrics) else ".")]
        return Table(f"Per run: median (share for convergence) [{LEVEL:.0%} CI] (trials); "
                     f"{self.test} across runs", cols, rows, notes=notes)

    def _tested(self, family: str) -> int:
        return int(sum(np.isfinite(m.p) for m in self.metrics if m.family == family))

    def to_json(self) -> dict[str, Any]:
        """Plain data (NaN as None) for ``--json``."""
        def f(x: float) -> float | None:
            return float(x) if math.isfinite(x) else None

        return {"runs": self.names, "sources": self.sources, "test": self.test,
                "unit": self.unit, "confidence_level": LEVEL, "metrics": [
                    {"key": m.key, "label": m.label, "statistic": m.statistic,
                     "n": [int(v.size) for v in m.values], "estimate": [f(x) for x in m.estimate],
                     "low": [f(x) for x in m.low], "high": [f(x) for x in m.high],
                     "p": f(m.p), "p_holm": f(m.p_holm), "different": m.different,
                     "family": m.family,
                     **({"difference": [f(x) for x in m.diff]} if m.diff else {})}
                    for m in self.metrics]}


def _interval(e: float, lo: float, hi: float, d: int) -> str:
    if not math.isfinite(e):
        return "–"
    if not (math.isfinite(lo) and math.isfinite(hi)):
        return f"{e:.{d}f}"
    return f"{e:.{d}f} [{lo:.{d}f}, {hi:.{d}f}]"


def _p(p: float) -> str:
    if not math.isfinite(p):
        return "–"
    return "< 0.001" if p < 0.001 else f"{p:.3f}"


def trial_metrics(summary: np.ndarray) -> dict[str, tuple[str, str, np.ndarray]]:
    """Per-trial values of every comparison metric in a summary table.

    Returns
    -------
    dict
        key -> (label, statistic, values (n,) float, NaN where a trial has none).
    """
    names = summary.dtype.names or ()
    col = partial(_col, summary)
    conv = col("converged") > 0.5
    out: dict[str, tuple[str, str, np.ndarray]] = {
        "convergence_rate": ("Converged trials (share)", "share", conv.astype(np.float64)),
        "convergence_iteration": ("Iterations to convergence",
                                  "median", np.where(conv, col("convergence_iteration"), np.nan)),
        "collisions_per_1000_after_convergence": (
            "Collisions /1000 after convergence (learning)", "median",
            np.where(conv, col("collisions_per_1000_after_convergence"), np.nan)),
    }
    worlds = list(dict.fromkeys(m.group(1) for n in names
                                if (m := re.fullmatch(r"eval\.(.+)\.[^.]+", n))))
    for w in worlds:
        coll, cov = (summary_key("eval", w, k, sep=".") for k in ("collisions_per_1000",
                                                                     "coverage"))
        if coll in names:
            out[coll] = (f"{w}: collisions /1000 (evaluation)", "median", col(coll))
            out[cov] = (f"{w}: coverage (evaluation)", "median", col(cov))
        for k, lab in _GOAL.items():
            if (key := summary_key("eval", w, k, sep=".")) in names:
                out[key] = (f"{w}: {lab} (goal episodes)", "median", col(key))
    for name in names:  # plugins' per-trial scalars (Log.summary(plugins=True))
        if name.startswith(PLUGIN_PREFIXES) and not _repeats_run_column(summary, name):
            kind, owner, key = name.split(".", 2)
            share = summary[name].dtype.kind == "b"
            out[name] = (f"{kind[:-1]} {owner}: {key}", "share" if share else "median",
                         col(name))
    return out


#: Summary columns that are plugins' per-trial scalars (the plugin family of metrics).
PLUGIN_PREFIXES = ("plugins.", "behaviours.")
#: The run's convergence columns, which a learned behaviour also reports for itself.
_CONVERGENCE = ("converged", "convergence_iteration")


def _repeats_run_column(summary: np.ndarray, name: str) -> bool:
    """Whether the behaviour column ``name`` (e.g. ``behaviours.avoid.heading.converged``) is
    a learner's convergence that holds, trial for trial, the run's own (``converged``,
    ``convergence_iteration``): the run's convergence is its learners', so a run of one
    learned behaviour with one output repeats it there, and a metric shown twice tells the
    reader nothing new. Other plugin columns stay, whatever their values."""
    leaf = name.rsplit(".", 1)[-1]
    names = summary.dtype.names or ()
    return name.startswith("behaviours.") and leaf in _CONVERGENCE and leaf in names and \
        np.array_equal(np.asarray(summary[name], dtype=np.float64),
                       np.asarray(summary[leaf], dtype=np.float64), equal_nan=True)


def _boot(runs: list[list[np.ndarray]], statistic: str,
          rng: np.random.Generator, clustered: bool) -> tuple[float, float, float]:
    """The statistic of one run, or of two runs the second's minus the first's, and its
    bootstrap interval.

    A run is a list of clusters (its seeds' trial values, NaN dropped). Clustered, and when
    every run has two or more clusters, whole clusters are resampled; otherwise the pooled
    trial values. One value gives no interval (NaN); identical values a zero-width one.
    """
    fn = np.mean if statistic == "share" else np.median
    pooled = [np.concatenate(r) if r else np.empty(0) for r in runs]
    if min(p.size for p in pooled) == 0:
        return math.nan, math.nan, math.nan

    def stat(*xs: np.ndarray, axis: int = -1) -> Any:
        v = [fn(x, axis=axis) for x in xs]
        return v[-1] - v[0] if len(v) == 2 else v[0]

    est = float(stat(*pooled))
    allv = np.concatenate(pooled)
    if allv.size < 2:
        return est, math.nan, math.nan
    if np.all(allv == allv[0]):
        return est, est, est
    kw: dict[str, Any] = {"n_resamples": RESAMPLES, "confidence_level": LEVEL,
                          "method": "percentile", "random_state": rng}
    if clustered and all(len(r) >= 2 for r in runs):
        def resampled(*idx: np.ndarray) -> Any:
            return stat(*(np.concatenate([r[int(i)] for i in ix])
                          for r, ix in zip(runs, idx, strict=True)))

        res = stats.bootstrap(tuple(np.arange(len(r)) for r in runs), resampled,
                              vectorized=False, **kw)
    else:
        res = stats.bootstrap(tuple(pooled), stat, vectorized=True, **kw)
    return est, float(res.confidence_interval.low), float(res.confidence_interval.high)


def _rank_test(groups: list[np.ndarray]) -> float:
    groups = [g for g in groups if g.size]
    if len(groups) < 2:
        return math.nan
    allv = np.concatenate(groups)
    if np.all(allv == allv[0]):
        return 1.0  # identical values: no evidence of a difference
    if len(groups) == 2:
        return float(stats.mannwhitneyu(groups[0], groups[1], alternative="two-sided").pvalue)
    return float(stats.kruskal(*groups).pvalue)


def _holm(p: np.ndarray) -> np.ndarray:
    """Holm's step-down adjustment of the finite entries of ``p`` (NaN stay NaN)."""
    out = np.full(p.shape, np.nan)
    ok = np.flatnonzero(np.isfinite(p))
    order = ok[np.argsort(p[ok], kind="stable")]
    m = order.size
    adj = np.minimum(1.0, np.maximum.accumulate(p[order] * (m - np.arange(m))))
    out[order] = adj
    return out


def _metric(key: str, label: str, statistic: str, runs: list[list[np.ndarray]],
            clustered: bool, rng: np.random.Generator) -> MetricResult:
    """One metric; ``runs[j]`` holds run j's trial values per seed (NaN already dropped)."""
    runs = [[c for c in r if c.size] for r in runs]
    vals = [np.concatenate(r) if r else np.empty(0) for r in runs]
    res = MetricResult(key, label, statistic, vals, runs=[len(r) for r in runs])
    for r in runs:
        e, lo, hi = _boot([r], statistic, rng, clustered)
        res.estimate.append(e)
        res.low.append(lo)
        res.high.append(hi)
    # the unit of the test: one trial, or one run (its median) when runs pool several seeds
    fn = np.mean if statistic == "share" else np.median
    res.p = _rank_test([np.array([fn(c) for c in r]) for r in runs] if clustered else vals)
    if len(vals) == 2 and all(v.size >= 2 for v in vals):
        res.diff = _boot(runs, statistic, rng, clustered)
    return res


def _compare(names: list[str], sources: list[str], tables: list[list[np.ndarray]],
             seed: int) -> Comparison:
    """Metrics of runs, each given as a list of summary tables (one per seed).

    When every run pools two or more seeds, the seed's run is the unit: the
    intervals resample whole runs (a cluster bootstrap) and the rank test
    compares the runs' medians, since trials of one run share its situations
    and are not independent samples of the setting.
    """
    rng = np.random.default_rng(seed)
    clustered = all(len(t) >= 2 for t in tables)
    per = [[trial_metrics(s) for s in t] for t in tables]
    keys = list(dict.fromkeys(k for run in per for m in run for k in m))
    keys = [k for k in keys if not k.startswith(PLUGIN_PREFIXES)] + \
        [k for k in keys if k.startswith(PLUGIN_PREFIXES)]  # the core metrics first
    metrics = []
    for k in keys:
        label, statistic = next((m[k][0], m[k][1]) for run in per for m in run if k in m)
        runs = [[m[k][2][np.isfinite(m[k][2])] for m in run if k in m] for run in per]
        metrics.append(_metric(k, label, statistic, runs, clustered, rng))
        metrics[-1].family = "plugin" if k.startswith(PLUGIN_PREFIXES) else "core"
    for family in ("core", "plugin"):
        ms = [m for m in metrics if m.family == family]
        for m, ph in zip(ms, _holm(np.array([m.p for m in ms])), strict=True):
            m.p_holm = float(ph)
    test = "Mann-Whitney U" if len(names) == 2 else "Kruskal-Wallis"
    return Comparison(names, sources, test, metrics, unit="run" if clustered else "trial")


def _run_names(paths: list[str]) -> list[str]:
    names = [Path(p).stem for p in paths]
    if len(set(names)) < len(names):
        names = [os.path.join(Path(p).parent.name, Path(p).stem) for p in paths]
    if len(set(names)) < len(names):
        names = [f"{i + 1}: {n}" for i, n in enumerate(names)]
    return names


def compare_logs(paths: list[str | os.PathLike[str]], *, seed: int = 0) -> Comparison:
    """Compare two or more logs trial by trial (see the module docstring).

    Raises
    ------
    InputError
        Fewer than two logs, a log that cannot be read, or a log without a
        finished trial.
    """
    if len(paths) < 2:
        raise InputError(f"compare needs at least two logs (or one sweep folder), got "
                         f"{len(paths)}", key="LOG")
    tables = []
    for p in paths:
        lg = as_log(p)
        s = _summary(lg, plugins=True)
        if s.size == 0:
            raise InputError("the log has no finished trial to compare", file=lg.path,
                             key="summary")
        tables.append([s])
    src = [os.fspath(p) for p in paths]
    return _compare(_run_names(src), src, tables, seed)


SEED_KEY = "experiment.seed"


def compare_sweeps(folders: list[str | os.PathLike[str]], *, seed: int = 0) -> Comparison:
    """Compare two or more sweep folders, each one run pooled over all its points.

    The use: the same preset swept over the same seeds with two settings that
    no grid can pair (e.g. a Q start *and* a temperature changed together),
    one sweep file each. Each folder's points are its runs (the cluster
    bootstrap and the run-median rank test of :func:`_compare`).

    Raises
    ------
    InputError
        Fewer than two folders, or a folder that is not a sweep output.
    """
    if len(folders) < 2:
        raise InputError(f"compare needs at least two sweep folders, got {len(folders)}",
                         key="LOG")
    tables = [[_summary(as_log(p["log"]), plugins=True) for p in read_sweep(f)[1]]
              for f in folders]
    src = [os.fspath(f) for f in folders]
    names = _run_names(src)
    sources = [f"{len(t)} point(s) of {s}, pooled" for t, s in zip(tables, src, strict=True)]
    return _compare(names, sources, tables, seed)


def read_sweep(folder: str | os.PathLike[str]) -> tuple[list[str], list[dict[str, Any]]]:
    """The grid keys and the points (``point``, key values, ``log`` path) of a sweep folder.

    Reads ``summary.csv``; each point's log is looked up in the folder by the
    file name the CSV gives (so a moved folder still works).
    """
    path = Path(folder) / "summary.csv"
    try:
        with open(path, newline="", encoding="utf-8") as fh:
            rows = list(csv.DictReader(fh))
    except OSError as exc:
        raise InputError(f"cannot read the sweep summary: {exc.strerror or exc} (expected "
                         "the output folder of `sitframe sweep`)", file=str(path)) from None
    head = list(rows[0]) if rows else []
    if not rows or "point" not in head or "trials" not in head or "log" not in head:
        raise InputError("not a sweep summary (expected columns point, <grid keys>, trials, "
                         "..., log and one row per point)", file=str(path))
    keys = head[head.index("point") + 1:head.index("trials")]
    points = []
    for r in rows:
        log = Path(folder) / Path(r["log"]).name
        if not log.exists():
            raise InputError(f"the log of point '{r['point']}' is missing", file=str(log))
        points.append({"point": r["point"], "log": str(log), **{k: r[k] for k in keys}})
    return keys, points


def compare_sweep(folder: str | os.PathLike[str], *, seed: int = 0) -> Comparison:
    """Compare the settings of a sweep, each pooled over its seeds.

    The returned :class:`Comparison` has one run per setting (named
    ``key=value, ...`` with the last part of each key) and ``axes``: setting
    name -> its value on each non-seed grid key.
    """
    keys, points = read_sweep(folder)
    axes = [k for k in keys if k != SEED_KEY]
    groups: dict[tuple[str, ...], list[np.ndarray]] = {}
    for p in points:
        s = _summary(as_log(p["log"]), plugins=True)
        groups.setdefault(tuple(p[k] for k in axes), []).append(s)
    names = [", ".join(f"{k.rsplit('.', 1)[-1]}={v}" for k, v in zip(axes, g, strict=True))
             or "all" for g in groups]
    sources = [f"{len(t)} point(s) of {folder}" + (f", pooled over {SEED_KEY}"
                                                    if len(t) > 1 else "")
               for t in groups.values()]
    cmp = _compare(names, sources, list(groups.values()), seed)
    cmp.axes = {n: dict(zip(axes, g, strict=True)) for n, g in zip(names, groups, strict=True)}
    return cmp
