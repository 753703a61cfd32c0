"""`sitframe compare` (intervals, rank tests), the report's replay data, DataFrames, `export`."""

from __future__ import annotations

import base64
import csv
import gzip
import json
import sys

import numpy as np
import pytest

from sitframe.analysis.compare import _compare, _holm, compare_logs, compare_sweeps, trial_metrics
from sitframe.analysis.replay_data import replay_payload
from sitframe.cli.app import main
from sitframe.logs.reader import open_log


def _summary(it: np.ndarray, coll: np.ndarray) -> np.ndarray:
    s = np.zeros(it.size, dtype=[("trial", "i4"), ("converged", "f8"),
                                 ("convergence_iteration", "f8"),
                                 ("eval.room.collisions_per_1000", "f8"),
                                 ("eval.room.coverage", "f8")])
    s["trial"] = np.arange(it.size)
    s["converged"] = 1.0
    s["convergence_iteration"] = it
    s["eval.room.collisions_per_1000"] = coll
    s["eval.room.coverage"] = 0.4
    return s


def test_statistics_two_and_three_runs():
    rng = np.random.default_rng(1)
    a = _summary(rng.normal(1000, 100, 30).round(), rng.poisson(2, 30).astype(float))
    b = _summary(rng.normal(1600, 100, 30).round(), rng.poisson(2, 30).astype(float))
    cmp = _compare(["a", "b"], ["a", "b"], [[a], [b]], seed=0)
    m = {r.key: r for r in cmp.metrics}
    it = m["convergence_iteration"]
    assert cmp.test == "Mann-Whitney U"
    assert it.p < 1e-6 and it.different
    assert it.low[0] <= np.median(a["convergence_iteration"]) == it.estimate[0] <= it.high[0]
    assert it.diff[1] > 0  # the interval of the difference excludes 0
    cov = m["eval.room.coverage"]  # identical values: no difference, a point interval
    assert cov.p == 1.0 and not cov.different and cov.low == cov.high == [0.4, 0.4]
    assert m["convergence_rate"].estimate == [1.0, 1.0]
    assert not m["eval.room.collisions_per_1000"].different  # same distribution
    # the same seed gives the same intervals; three runs use Kruskal-Wallis
    assert _compare(["a", "b"], ["a", "b"], [[a], [b]], seed=0).metrics[1].low == it.low
    three = _compare(list("abc"), list("abc"), [[a], [b], [a]], seed=0)
    assert three.test == "Kruskal-Wallis" and three.metrics[1].p < 1e-6
    assert "Difference" not in " ".join(three.table().columns)


def test_settings_pooling_seeds_use_the_run_as_unit():
    """Trials of one run share its situations: with several seeds per setting the test
    compares the runs' medians and the interval resamples whole runs."""
    rng = np.random.default_rng(2)

    def seeds(shift):  # 5 runs of 11 trials, each run offset by its own seed effect
        return [_summary(rng.normal(1000 + shift + rng.normal(0, 300), 50, 11).round(),
                         np.zeros(11)) for _ in range(5)]

    a, b = seeds(0), seeds(100)
    cmp = _compare(["a", "b"], ["a", "b"], [a, b], seed=0)
    it = next(m for m in cmp.metrics if m.key == "convergence_iteration")
    assert cmp.unit == "run" and it.runs == [5, 5] and "5 runs" in cmp.table().rows[1][1]
    med = [np.array([np.median(s["convergence_iteration"]) for s in x]) for x in (a, b)]
    from scipy.stats import mannwhitneyu

    assert it.p == pytest.approx(mannwhitneyu(*med, alternative="two-sided").pvalue)
    flat = _compare(["a", "b"], ["a", "b"], [[np.concatenate(a)], [np.concatenate(b)]], 0)
    it_flat = next(m for m in flat.metrics if m.key == "convergence_iteration")
    assert flat.unit == "trial" and it_flat.p < it.p  # trials as the unit overstate certainty
    assert it.high[0] - it.low[0] > it_flat.high[0] - it_flat.low[0]


def test_holm_adjustment():
    p = np.array([0.01, np.nan, 0.04, 0.03, 0.5])
    adj = _holm(p)
    assert np.isnan(adj[1])
    assert adj[[0, 3, 2, 4]] == pytest.approx([0.04, 0.09, 0.09, 0.5])


def _with_plugins(s: np.ndarray, near: np.ndarray, happy: np.ndarray) -> np.ndarray:
    out = np.zeros(s.size, dtype=s.dtype.descr + [("plugins.obs.near_misses", "f8"),
                                                  ("behaviours.avoid.happy", "?")])
    for n in s.dtype.names:
        out[n] = s[n]
    out["plugins.obs.near_misses"], out["behaviours.avoid.happy"] = near, happy
    return out


def test_plugin_figures_are_compared_in_a_family_of_their_own():
    """A plugin's per-trial scalars are metrics (a bool as a share), Holm-adjusted among
    themselves: the core metrics' verdicts are those of a run without the plugin."""
    rng = np.random.default_rng(3)
    a = _summary(rng.normal(1000, 100, 20).round(), rng.poisson(2, 20).astype(float))
    b = _summary(rng.normal(1100, 100, 20).round(), rng.poisson(2, 20).astype(float))
    pa = _with_plugins(a, rng.poisson(3, 20), rng.random(20) < 0.2)
    pb = _with_plugins(b, rng.poisson(9, 20), rng.random(20) < 0.9)
    core = _compare(["a", "b"], ["a", "b"], [[a], [b]], seed=0)
    both = _compare(["a", "b"], ["a", "b"], [[pa], [pb]], seed=0)
    m = {r.key: r for r in both.metrics}
    near, happy = m["plugins.obs.near_misses"], m["behaviours.avoid.happy"]
    assert near.family == happy.family == "plugin" and near.different and happy.different
    assert happy.statistic == "share" and near.statistic == "median"
    assert near.label == "plugin obs: near_misses" and happy.label == "behaviour avoid: happy"
    assert [r.key for r in both.metrics][-2:] == [near.key, happy.key]  # after the core's
    for r in core.metrics:
        assert m[r.key].family == "core"
        np.testing.assert_equal(m[r.key].p_holm, r.p_holm)  # (NaN: not tested)
    assert "2 tested plugin figures" in " ".join(both.table().notes)
    assert {x["key"]: x["family"] for x in both.to_json()["metrics"]}[near.key] == "plugin"


def test_a_behaviour_column_repeating_the_runs_own_is_not_a_second_metric():
    """One learned behaviour with one output logs its convergence again under
    ``behaviours.<label>.`` (and ``.heading.``): the same trials' values are one metric, not
    three. A behaviour's convergence that differs from the run's stays, and so does any
    other plugin figure, even one equal to a core column (a protocol's own collision count)."""
    rng = np.random.default_rng(4)
    s = _summary(rng.normal(1000, 100, 11).round(), rng.poisson(2, 11).astype(float))
    extra = [("behaviours.avoid.converged", "?"), ("behaviours.avoid.heading.converged", "?"),
             ("behaviours.avoid.convergence_iteration", "f8"),
             ("behaviours.speed.converged", "?"), ("plugins.p.convergence_iteration", "f8")]
    out = np.zeros(s.size, dtype=s.dtype.descr + extra)
    for n in s.dtype.names:
        out[n] = s[n]
    out["behaviours.avoid.converged"] = out["behaviours.avoid.heading.converged"] = s["converged"]
    out["behaviours.avoid.convergence_iteration"] = s["convergence_iteration"]
    out["plugins.p.convergence_iteration"] = s["convergence_iteration"]
    out["behaviours.speed.converged"] = ~s["converged"].astype(bool)
    keys = [k for k in trial_metrics(out) if k.startswith(("behaviours.", "plugins."))]
    assert keys == ["behaviours.speed.converged", "plugins.p.convergence_iteration"]


def test_compare_command_on_two_logs(two_runs, tmp_path, capsys):
    a, b = two_runs
    out = tmp_path / "cmp"
    assert main(["compare", str(a), str(b), "-o", str(out)]) == 0
    text = capsys.readouterr().out
    assert "p (Mann-Whitney U)" in text and "novel-1: collisions /1000" in text
    for name in ("index.html", "compare.md", "compare.csv", "metrics.png"):
        assert (out / name).stat().st_size > 0
    rows = list(csv.DictReader(open(out / "compare.csv")))
    assert {r["run"] for r in rows} == {"a", "b"} and all(r["p"] for r in rows
                                                          if r["metric"] != "convergence_rate")
    data = json.loads(json.dumps(compare_logs([a, b]).to_json()))  # what --json prints
    assert data["runs"] == ["a", "b"] and data["test"] == "Mann-Whitney U"
    first = data["metrics"][0]
    assert {"estimate", "low", "high", "p", "p_holm", "different", "difference"} <= set(first)


def test_compare_bad_input_is_one_line(two_runs, tmp_path, capsys):
    a, _b = two_runs
    assert main(["compare", str(a)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "at least two logs" in err
    assert main(["compare", str(a), str(tmp_path / "missing.h5")]) == 2
    assert "log file not found" in capsys.readouterr().err
    assert main(["compare", str(tmp_path)]) == 2
    assert "summary.csv" in capsys.readouterr().err


def test_compare_sweep_folder(two_runs, tmp_path, capsys):
    a, b = two_runs
    folder = tmp_path / "sweep"
    folder.mkdir()
    rows = [("p=5_seed=5", 5, 5, a), ("p=5_seed=6", 5, 6, b), ("p=9_seed=5", 9, 5, a)]
    with open(folder / "summary.csv", "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["point", "behaviours.avoid.p", "experiment.seed", "trials", "status", "log"])
        for name, p, seed, log in rows:
            (folder / f"{name}.h5").write_bytes(log.read_bytes())
            w.writerow([name, p, seed, 2, "complete", f"elsewhere/{name}.h5"])
    assert main(["compare", str(folder), "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["runs"] == ["p=5", "p=9"]  # pooled over the seed axis
    assert data["metrics"][0]["n"] == [4, 2] and data["unit"] == "trial"  # p=9 has one seed
    assert (folder / "report" / "axis_p.png").exists()
    assert (folder / "report" / "index.html").exists()



def _sweep_folder(folder, logs):
    """A sweep output folder with one point per (seed, log)."""
    folder.mkdir()
    with open(folder / "summary.csv", "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["point", "experiment.seed", "trials", "status", "log"])
        for seed, log in enumerate(logs):
            (folder / f"seed={seed}.h5").write_bytes(log.read_bytes())
            w.writerow([f"seed={seed}", seed, 2, "complete", f"seed={seed}.h5"])
    return folder


def test_compare_two_sweep_folders(two_runs, tmp_path, capsys):
    """Two sweeps of one preset (settings no grid can pair) compared as one run each,
    pooled over their seeds: the run is the unit; a log and a folder do not mix."""
    a, b = two_runs
    one = _sweep_folder(tmp_path / "one", [a, a])
    two = _sweep_folder(tmp_path / "two", [b, b, a])
    cmp = compare_sweeps([one, two])
    assert cmp.names == ["one", "two"] and cmp.unit == "run"
    assert [v.size for v in cmp.metrics[0].values] == [4, 6]
    assert main(["compare", str(one), str(a)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "cannot be mixed" in err


def test_same_log_twice_is_not_different(two_runs):
    a, _b = two_runs
    cmp = compare_logs([a, a])
    assert cmp.names[0] != cmp.names[1] or len(set(cmp.names)) == 2
    assert not any(m.different for m in cmp.metrics)


def test_replay_payload_round_trip(two_runs):
    a, _b = two_runs
    lg = open_log(a)
    trials = {k: lg.trial(k) for k in lg.trial_indices()}
    data = replay_payload(lg, trials)
    buf = gzip.decompress(base64.b64decode(data["blob"]))
    assert len(buf) == data["raw_bytes"]
    kinds = [(e["trial"], e["kind"], e["world"]) for e in data["episodes"]]
    assert kinds == [(0, "learning", "training"), (0, "evaluation", "novel-1"),
                     (1, "learning", "training"), (1, "evaluation", "novel-1")]

    def get(ep, key):
        d = ep[key]
        dtype = np.dtype(d["type"].replace("Array", "").lower()).newbyteorder("<")
        n = int(np.prod(d["shape"]))
        return np.frombuffer(buf, dtype, n, d["offset"]).reshape(d["shape"]) / d["scale"]

    ep, tr = data["episodes"][2], trials[1]
    assert np.abs(get(ep, "xy") - tr.arrays["pose"][:, :2]).max() <= 0.0005
    assert np.abs(get(ep, "memberships") - tr.arrays["memberships"]).max() <= 0.005
    assert np.abs(get(ep, "heading") - tr.arrays["command"][:, 0]).max() <= 0.05
    assert get(ep, "collision").sum() == tr.arrays["collision"].sum()
    assert get(ep, "contact").shape == (int(tr.arrays["collision"].sum()), 2)
    assert np.array_equal(get(ep, "rules"), tr.behaviours["avoid"]["heading/rule_base"])
    assert data["labels"] and set(data["worlds"]) >= {"training", "novel-1"}


def test_dataframes_and_export(two_runs, tmp_path, capsys, monkeypatch):
    pd = pytest.importorskip("pandas")
    a, _b = two_runs
    lg = open_log(a)
    s = lg.summary_frame()
    assert list(s["trial"]) == [0, 1] and s["converged"].dtype == bool
    # a behaviour's per-trial scalars (its trial_data), namespaced, bools as bools
    assert s["behaviours.avoid.converged"].dtype == bool
    assert list(s["behaviours.avoid.heading.convergence_iteration"]) == \
        [lg.trial(k).behaviours["avoid"]["heading/convergence_iteration"] for k in (0, 1)]
    it = lg.iterations_frame()
    assert len(it) == 600 and list(it.columns[:6]) == ["trial", "world", "iteration", "x", "y",
                                                       "theta"]
    rules = lg.trial(1).behaviours["avoid"]["heading/rule_base"]  # a per-iteration series
    assert np.array_equal(it[it.trial == 1]["behaviours.avoid.heading.rule_base.2"], rules[:, 2])
    assert np.allclose(it[it.trial == 1][["x", "y"]], lg.trial(1).arrays["pose"][:300, :2])
    assert main(["export", str(a), "--out", str(tmp_path / "csv")]) == 0
    assert capsys.readouterr().out.split() == [str(tmp_path / "csv" / f"{n}.csv") for n in
                                               ("summary", "iterations", "evaluations")]
    ev = pd.read_csv(tmp_path / "csv" / "evaluations.csv")
    assert len(ev) == 200 and set(ev.world) == {"novel-1"} and "membership_3" in ev
    pytest.importorskip("pyarrow")
    assert main(["export", str(a), "--format", "parquet", "--out", str(tmp_path / "pq")]) == 0
    capsys.readouterr()
    back = pd.read_parquet(tmp_path / "pq" / "iterations.parquet")
    assert back.shape == it.shape
    monkeypatch.setitem(sys.modules, "pyarrow", None)
    assert main(["export", str(a), "--format", "parquet", "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "pyarrow" in err and "sitframe[parquet]" in err
    monkeypatch.setitem(sys.modules, "pandas", None)
    with pytest.raises(ImportError, match=r"sitframe\[pandas\]"):
        lg.summary_frame()
    assert main(["export", str(a), "--out", str(tmp_path / "y")]) == 2
    assert "sitframe[pandas]" in capsys.readouterr().err
