"""Tests of sitframe.clustering (trials, selection, sweep, prototype descriptions) and its plots."""

from __future__ import annotations

import numpy as np
import pytest
from matplotlib.figure import Figure

from sitframe.clustering import (
    RANKED_MEASURES,
    SONAR_ANGLES_DEG,
    canonical_order,
    cluster_trials,
    describe_prototype,
    rank_trials,
    select_trial,
    sweep_c,
)
from sitframe.fcm import MEASURE_DIRECTIONS, fcm, validity

PROTOS = {
    "open space": [3.0, 3.0, 3.0, 3.0, 3.0, 3.0, 3.0, 3.0],
    "wall on left": [0.6, 0.9, 1.3, 3.0, 3.0, 3.0, 3.0, 3.0],
    "wall on right": [3.0, 3.0, 3.0, 3.0, 3.0, 1.3, 0.9, 0.6],
    "corridor": [0.7, 1.0, 1.5, 3.0, 3.0, 1.5, 1.0, 0.7],
    "front blocked": [3.0, 3.0, 1.2, 0.45, 0.45, 1.2, 3.0, 3.0],
    "left corner": [0.5, 0.6, 0.6, 0.7, 1.5, 3.0, 3.0, 3.0],
    "right corner": [3.0, 3.0, 3.0, 1.5, 0.7, 0.6, 0.6, 0.5],
    "dead end": [0.5, 0.6, 0.7, 0.6, 0.6, 0.7, 0.6, 0.5],
}


def sonar_like(n=600, seed=0):
    rng = np.random.default_rng(seed)
    P = np.array(list(PROTOS.values()))
    lab = rng.integers(0, len(P), n)
    return np.clip(P[lab] + rng.normal(0, 0.15, (n, 8)), 0.05, 3.0)


@pytest.fixture(scope="module")
def X():
    return sonar_like()


@pytest.fixture(scope="module")
def trials(X):
    return cluster_trials(X, 6, n_trials=8, seed=11)


def test_trials_shapes_and_measures(X, trials):
    T = 8
    assert trials.centers.shape == (T, 6, 8) and trials.init_centers.shape == (T, 6, 8)
    assert set(trials.measures) == set(MEASURE_DIRECTIONS)
    assert all(v.shape == (T,) for v in trials.measures.values())
    assert trials.n_iter.shape == (T,) and trials.converged.dtype == bool
    assert trials.ranks.shape == (T, len(RANKED_MEASURES))
    assert 0 <= trials.chosen < T and trials.eligible[trials.chosen]
    assert "min_card > 0" in trials.rule and not trials.fallback
    # each trial's measures are those of validity() at its final centres
    k = 3
    r = fcm(X, 6, init_centers=trials.init_centers[k])
    np.testing.assert_allclose(trials.centers[k], r.centers)
    v = validity(X, r)
    for key in MEASURE_DIRECTIONS:
        assert trials.measures[key][k] == pytest.approx(v[key], rel=1e-9)
    assert trials.chosen_centers.shape == (6, 8)
    assert set(trials.chosen_measures) == set(MEASURE_DIRECTIONS)


def test_same_seed_identical_trials(X, trials):
    again = cluster_trials(X, 6, n_trials=8, seed=11)
    np.testing.assert_array_equal(trials.centers, again.centers)
    np.testing.assert_array_equal(trials.n_iter, again.n_iter)
    for k in trials.measures:
        np.testing.assert_array_equal(trials.measures[k], again.measures[k])
    assert trials.chosen == again.chosen
    other = cluster_trials(X, 6, n_trials=8, seed=12)
    assert not np.array_equal(trials.init_centers, other.init_centers)


def _measures(**over):
    base = {k: np.array([0.5, 0.5, 0.5]) for k in MEASURE_DIRECTIONS}
    base["min_card"] = np.array([5.0, 5.0, 5.0])
    base.update({k: np.asarray(v, dtype=float) for k, v in over.items()})
    return base


def test_select_trial_prefers_best_in_every_direction():
    m = _measures(pc=[0.9, 0.95, 0.8], pe=[0.2, 0.1, 0.3], nfi=[0.8, 0.9, 0.7],
                  min_ht=[1, 2, 0.5], mean_ht=[2, 3, 1], rf=[0.1, 0.05, 0.2],
                  objective=[10, 9, 11])
    assert select_trial(m) == 1
    ranks, mean_rank, eligible, fallback = rank_trials(m)
    np.testing.assert_allclose(ranks[1], 1.0)
    np.testing.assert_allclose(ranks[2], 3.0)
    assert eligible.all() and not fallback


def test_select_trial_requires_positive_min_card():
    m = _measures(pc=[0.9, 0.95, 0.8], min_card=[3, 0, 4])
    assert select_trial(m) == 0  # trial 1 is best on pc but has an empty cluster
    _, mean_rank, eligible, _ = rank_trials(m)
    assert np.isnan(mean_rank[1]) and not eligible[1]


def test_select_trial_ties_lowest_objective_then_index():
    m = _measures(objective=[3.0, 3.0, 3.0])
    assert select_trial(m) == 0
    # trade-off: equal mean rank, trial 2 has the lower objective
    m2 = _measures(pc=[0.9, 0.5, 0.6], objective=[2.0, 3.0, 1.0])
    ranks, mean_rank, *_ = rank_trials(m2)
    assert mean_rank[0] == mean_rank[2]
    assert select_trial(m2) == 2


def test_select_trial_fallback_warns():
    m = _measures(min_card=[0, 0, 0], pc=[0.5, 0.7, 0.6])
    with pytest.warns(RuntimeWarning, match="min_card"):
        assert select_trial(m) == 1


def test_select_trial_bad_input():
    with pytest.raises(ValueError, match="measures is missing"):
        select_trial({"pc": [1.0]})
    bad = _measures()
    bad["pe"] = np.array([1.0, 2.0])
    with pytest.raises(ValueError, match="same length"):
        select_trial(bad)


def test_cluster_trials_bad_arguments(X):
    with pytest.raises(ValueError, match=r"c must be an integer >= 2 and <= n_samples \(600\), "
                                         r"got 1"):
        cluster_trials(X, 1, seed=0)
    with pytest.raises(ValueError, match="n_trials must"):
        cluster_trials(X, 3, n_trials=0, seed=0)
    with pytest.raises(ValueError, match="tol must"):
        cluster_trials(X, 3, tol=0, seed=0)
    with pytest.raises(TypeError, match="seed"):
        cluster_trials(X, 3, seed=1.5)
    with pytest.raises(TypeError):
        cluster_trials(X, 3)  # seed is a required keyword


def test_sweep_c(X):
    sw = sweep_c(X, [2, 4, 8], n_trials=3, seed=0)
    np.testing.assert_array_equal(sw.cs, [2, 4, 8])
    assert all(v.shape == (3,) for v in sw.measures.values())
    assert sw.at(4).c == 4 and sw.centers(8).shape == (8, 8)
    assert sw.measures["pc"][1] == sw.at(4).measures["pc"][sw.chosen[1]]
    again = sweep_c(X, [2, 4, 8], n_trials=3, seed=0)
    np.testing.assert_array_equal(sw.measures["objective"], again.measures["objective"])
    with pytest.raises(ValueError, match="cs must not repeat"):
        sweep_c(X, [2, 2], seed=0)
    with pytest.raises(ValueError, match="swept values"):
        sw.at(5)


def test_cluster_trials_recovers_the_situations(X):
    tr = cluster_trials(X, 8, n_trials=10, seed=1)
    names = sorted(describe_prototype(v) for v in tr.chosen_centers)
    assert names == sorted(PROTOS)


@pytest.mark.parametrize("name, ranges", list(PROTOS.items()))
def test_describe_prototype(name, ranges):
    assert describe_prototype(np.array(ranges), SONAR_ANGLES_DEG) == name


def test_describe_prototype_more():
    assert describe_prototype([3, 1.2, 0.8, 1.5, 3, 3, 3, 3]) == "obstacle front-left"
    assert describe_prototype([3, 3, 3, 1.2, 0.4, 0.4, 0.9, 3]).startswith("obstacle front-right")
    assert describe_prototype([0.9, 1.0, 1.5, 0.45, 0.45, 3, 3, 3]) == "left corner"
    assert describe_prototype([3, 3, 3, 1.0, 1.0, 3, 3, 3]) == "obstacle ahead"
    assert describe_prototype([3, 3, 3, 0.4, 0.4, 2.0, 1.6, 1.6]) == "front blocked, left open"
    with pytest.raises(ValueError, match="same length"):
        describe_prototype([1.0, 2.0], SONAR_ANGLES_DEG)
    with pytest.raises(ValueError, match="near and far"):
        describe_prototype(PROTOS["dead end"], near=2.0, far=1.0)


def test_canonical_order_is_a_stable_permutation():
    P = np.array(list(PROTOS.values()))
    rng = np.random.default_rng(0)
    perm = rng.permutation(len(P))
    o1 = canonical_order(P)
    o2 = canonical_order(P[perm])
    np.testing.assert_array_equal(P[o1], P[perm][o2])
    assert describe_prototype(P[o1[0]]) == "open space"
    assert describe_prototype(P[o1[-1]]) == "dead end"


def test_clustering_is_fast_enough():
    # 1500 samples, c = 12, 50 trials: < 2 s on 2 cores (typically ~0.4 s)
    import time

    X = sonar_like(1500, seed=3)
    t = time.perf_counter()
    tr = cluster_trials(X, 12, n_trials=50, seed=0)
    assert time.perf_counter() - t < 4.0  # slack for a loaded CI machine
    assert tr.n_trials == 50


# ---------------------------------------------------------------------------- plots


def test_plots_build_figures(X, trials, tmp_path):
    from sitframe.analysis.clustering_plots import (
        plot_measures_by_c,
        plot_measures_by_trial,
        plot_prototypes,
    )

    f1 = plot_prototypes(trials.chosen_centers, SONAR_ANGLES_DEG)
    assert isinstance(f1, Figure) and len(f1.axes) == 6
    assert f1.axes[0].get_title().startswith("S1: ")
    f2 = plot_measures_by_trial(trials)
    titles = [ax.get_title() for ax in f2.axes if ax.get_visible()]
    assert any("(max)" in t for t in titles) and any("(min)" in t for t in titles)
    sw = sweep_c(X, [2, 3], n_trials=2, seed=0)
    f3 = plot_measures_by_c(sw)
    for i, f in enumerate((f1, f2, f3)):
        f.savefig(tmp_path / f"f{i}.png", dpi=50)
    with pytest.raises(ValueError, match="labels"):
        plot_prototypes(trials.chosen_centers, SONAR_ANGLES_DEG, labels=["a"])
