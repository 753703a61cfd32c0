"""Tests of sitframe.situations.fcm: Eq. 3.2 memberships, Algorithm 1, validity measures
(Eqs. 4.1-4.9)."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from sitframe.errors import InputError
from sitframe.situations.fcm import (
    MEASURE_DIRECTIONS,
    FCMResult,
    fcm,
    memberships,
    partition_measures,
    validity,
)

KEYS = ["pc", "pe", "nfi", "min_ht", "mean_ht", "min_card", "rf", "objective"]


def blobs(n=300, d=8, k=4, seed=0, spread=0.2):
    rng = np.random.default_rng(seed)
    protos = rng.uniform(0.3, 3.0, size=(k, d))
    lab = rng.integers(0, k, n)
    return np.clip(protos[lab] + rng.normal(0, spread, (n, d)), 0, 3)


def naive_memberships(X, V, m):
    D = np.sqrt(((X[:, None, :] - V[None, :, :]) ** 2).sum(-1))
    ratio = (D[:, :, None] / D[:, None, :]) ** (2 / (m - 1))
    return 1.0 / ratio.sum(axis=2)


# ----------------------------------------------------------------------- memberships


def test_memberships_match_eq_3_2():
    rng = np.random.default_rng(1)
    X, V = rng.normal(size=(50, 3)), rng.normal(size=(4, 3))
    for m in (1.2, 1.5, 2.0, 2.7, 3.0):
        np.testing.assert_allclose(memberships(X, V, m), naive_memberships(X, V, m),
                                   rtol=1e-10, atol=1e-300)


finite = st.floats(-50, 50, allow_nan=False, allow_infinity=False)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    X=arrays(np.float64, st.tuples(st.integers(1, 30), st.just(3)), elements=finite),
    V=arrays(np.float64, st.tuples(st.integers(1, 6), st.just(3)), elements=finite),
    m=st.floats(1.01, 3.0),
)
def test_memberships_are_a_fuzzy_partition(X, V, m):
    with np.errstate(all="raise"), warnings.catch_warnings():
        warnings.simplefilter("error")
        u = memberships(X, V, m)
    assert u.shape == (X.shape[0], V.shape[0])
    assert np.all(np.isfinite(u))
    assert np.all(u >= 0) and np.all(u <= 1)
    np.testing.assert_allclose(u.sum(axis=1), 1.0, atol=1e-12)


@pytest.mark.parametrize("m", [1.01, 1.05, 1.2, 2.0])
def test_memberships_far_points_no_overflow(m):
    V = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    X = np.array([[1e6, 1e6], [-3e7, 2.0], [0.5, 0.5], [1e-9, 0.0]])
    with np.errstate(all="raise"):
        u = memberships(X, V, m)
    np.testing.assert_allclose(u.sum(axis=1), 1.0, atol=1e-12)
    assert u[3, 0] == pytest.approx(1.0)
    assert u[2, 1] == pytest.approx(u[2, 2])


def test_point_on_a_centre_gets_membership_one():
    V = np.array([[0.0, 0.0], [2.0, 1.0], [5.0, 5.0]])
    X = np.array([[2.0, 1.0], [0.0, 0.0], [1.0, 1.0]])
    with np.errstate(all="raise"):
        u = memberships(X, V, 1.2)
    np.testing.assert_array_equal(u[0], [0.0, 1.0, 0.0])
    np.testing.assert_array_equal(u[1], [1.0, 0.0, 0.0])
    # identical centres share equally
    V2 = np.array([[1.0, 1.0], [1.0, 1.0], [3.0, 0.0]])
    with np.errstate(all="raise"):
        u2 = memberships(np.array([[1.0, 1.0], [2.0, 2.0]]), V2, 1.2)
    np.testing.assert_array_equal(u2[0], [0.5, 0.5, 0.0])
    assert u2[1, 0] == pytest.approx(u2[1, 1])


def test_memberships_single_reading():
    V = np.array([[0.0, 0.0], [1.0, 1.0]])
    u = memberships(np.array([0.1, 0.1]), V, 1.2)
    assert u.shape == (2,)
    assert u[0] > 0.99


# ------------------------------------------------------------------------------- fcm


def test_fcm_result_shapes_and_consistency():
    X = blobs()
    r = fcm(X, 4, seed=0)
    assert r.centers.shape == (4, 8) and r.u.shape == (300, 4)
    assert r.converged and 1 <= r.n_iter <= 300 and r.m == 1.2
    assert r.objective_history.shape == (r.n_iter,)
    np.testing.assert_allclose(r.u, memberships(X, r.centers, 1.2), atol=1e-12)
    assert validity(X, r)["objective"] == pytest.approx(r.objective, rel=1e-9)


@pytest.mark.parametrize("m", [1.2, 1.5, 2.0, 2.3])
def test_objective_is_non_increasing(m):
    X = blobs(n=400, k=6, spread=0.5, seed=3)
    r = fcm(X, 6, m, tol=1e-9, max_iter=200, seed=5)
    h = np.append(r.objective_history, r.objective)
    assert np.all(np.diff(h) <= 1e-10 * h[0])


def test_fcm_is_deterministic_for_a_seed_and_accepts_generators():
    X = blobs()
    a, b = fcm(X, 5, seed=7), fcm(X, 5, seed=7)
    np.testing.assert_array_equal(a.centers, b.centers)
    g1, g2 = np.random.default_rng(3), np.random.default_rng(3)
    np.testing.assert_array_equal(fcm(X, 5, seed=g1).centers, fcm(X, 5, seed=g2).centers)


def test_fcm_c_equals_n_each_point_its_own_cluster():
    X = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 2.0], [3.0, 3.0]])
    with np.errstate(all="raise"):
        r = fcm(X, 4, seed=0)
    assert np.all(np.isfinite(r.u)) and r.objective == 0.0
    np.testing.assert_array_equal(np.sort(r.u, axis=1)[:, -1], 1.0)
    assert validity(X, r)["min_card"] == 1


def test_fcm_identical_points():
    X = np.ones((10, 3))
    with np.errstate(all="raise"):
        r = fcm(X, 2, seed=0)
    assert np.all(np.isfinite(r.centers)) and np.all(np.isfinite(r.u))
    np.testing.assert_allclose(r.u, 0.5)
    assert r.objective == 0.0
    v = validity(X, r)
    assert v["min_card"] == 0 and v["pc"] == pytest.approx(0.5)


def test_fcm_duplicate_rows_get_distinct_initial_centres():
    rng = np.random.default_rng(0)
    X = np.vstack([np.full((900, 8), 3.0), rng.uniform(0, 3, (100, 8))])
    for s in range(5):
        r = fcm(X, 6, seed=s, max_iter=1)
        assert np.unique(r.centers, axis=0).shape[0] == 6


def test_init_centers_used():
    X = blobs()
    V0 = X[[0, 50, 100]]
    a = fcm(X, 3, init_centers=V0)
    b = fcm(X, 3, init_centers=V0, seed=123)
    np.testing.assert_array_equal(a.centers, b.centers)


# ------------------------------------------------------------------------ bad inputs


_C = "c: expected an integer in [2, 300] (at most n_samples), got "
_M = "m: expected a number in (1, inf) (m = 1 is a hard partition), got "
_TOL = "tol: expected a number in (0, inf) (centre movement, units of X), got "


@pytest.mark.parametrize(
    "kwargs, exc, message",
    [
        (dict(c=1), ValueError, _C + "1"),
        (dict(c=0), ValueError, _C + "0"),
        (dict(c=301), ValueError, _C + "301"),
        (dict(c=2.5), TypeError, _C + "2.5"),
        (dict(c=True), TypeError, _C + "bool True"),
        (dict(c=3, m=1.0), ValueError, _M + "1.0"),
        (dict(c=3, m=0.5), ValueError, _M + "0.5"),
        (dict(c=3, m=float("nan")), ValueError, _M + "non-finite nan"),
        (dict(c=3, tol=0.0), ValueError, _TOL + "0.0"),
        (dict(c=3, tol=-1e-3), ValueError, _TOL + "-0.001"),
        (dict(c=3, max_iter=0), ValueError, "max_iter: expected an integer in [1, inf), got 0"),
        (dict(c=3, max_iter=2.5), TypeError, "max_iter: expected an integer in [1, inf), got 2.5"),
    ],
)
def test_bad_scalar_arguments_are_named(kwargs, exc, message):
    """A bad scalar argument is refused by sitframe.params (an InputError, and a TypeError
    for a wrong type) naming the argument, what was expected and what was given."""
    with pytest.raises(exc) as info:
        fcm(blobs(), **kwargs)
    assert isinstance(info.value, InputError) and str(info.value) == message


@pytest.mark.parametrize(
    "kwargs, exc, words",
    [
        (dict(c=3, init_centers=np.zeros((2, 8))), ValueError, ["init_centers", "(3, 8)",
                                                                "(2, 8)"]),
        (dict(c=3, init_centers=np.zeros((3, 7))), ValueError, ["init_centers"]),
        (dict(c=3, init_centers=np.full((3, 8), np.nan)), ValueError, ["init_centers",
                                                                       "finite"]),
        (dict(c=3, seed="x"), TypeError, ["seed"]),
    ],
)
def test_bad_arguments_are_named(kwargs, exc, words):
    X = blobs()
    with pytest.raises(exc) as info:
        fcm(X, **kwargs)
    for w in words:
        assert w in str(info.value)


@pytest.mark.parametrize(
    "X, words",
    [
        (np.zeros(8), ["X must be a 2-D", "1-D"]),
        (np.zeros((2, 3, 4)), ["X must be a 2-D", "3-D"]),
        (np.array([[0.0, np.nan], [1.0, 1.0], [2.0, 2.0]]), ["X must be finite", "nan"]),
        (np.array([[0.0, np.inf], [1.0, 1.0], [2.0, 2.0]]), ["X must be finite", "inf"]),
        (np.zeros((1, 3)), ["c: expected an integer in [2, 1] (at most n_samples), got 2"]),
        (np.array([["a", "b"]]), ["X must be a real numeric array"]),
    ],
)
def test_bad_X(X, words):
    with pytest.raises((ValueError, TypeError)) as info:
        fcm(X, 2)
    for w in words:
        assert w in str(info.value)


def test_memberships_bad_arguments():
    with pytest.raises(ValueError, match=r"^m: expected a number in \(1, inf\) \(m = 1 is a "
                                         r"hard partition\), got 1\.0$"):
        memberships(np.zeros((2, 2)), np.ones((2, 2)), 1.0)
    with pytest.raises(ValueError, match="centers must have shape"):
        memberships(np.zeros((2, 2)), np.ones((2, 3)), 1.2)


# --------------------------------------------------------------------------- validity


def test_hard_partition_measures():
    u = np.array([[1, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [0, 0, 1]], dtype=float)
    v = partition_measures(u)
    assert v["pc"] == 1.0 and v["pe"] == 0.0 and v["nfi"] == 1.0
    assert v["rf"] == 0.0
    assert v["min_ht"] == math.inf and v["mean_ht"] == math.inf  # every T_s = 0
    assert v["min_card"] == 1.0


def test_uniform_partition_measures():
    c, n = 4, 10
    u = np.full((n, c), 1 / c)
    v = partition_measures(u)
    assert v["pc"] == pytest.approx(1 / c)
    assert v["pe"] == pytest.approx(math.log(c))
    assert v["nfi"] == pytest.approx(0.0, abs=1e-12)
    assert v["rf"] == math.inf  # no point reaches the threshold (1+c)/(2c)
    # argmax ties -> cluster 0 gets every point, the others are empty
    assert v["min_card"] == 0.0
    assert v["min_ht"] == 0.0  # T_s = 1 for cluster 0 (r = 1) and for the empty clusters
    assert v["mean_ht"] == 0.0


def test_hand_computed_fuzzy_partition():
    # c = 2: threshold (1+c)/(2c) = 0.75
    u = np.array([[0.9, 0.1], [0.8, 0.2], [0.6, 0.4], [0.3, 0.7]])
    v = partition_measures(u)
    n = 4
    pc = (0.81 + 0.01 + 0.64 + 0.04 + 0.36 + 0.16 + 0.09 + 0.49) / n
    assert v["pc"] == pytest.approx(pc)
    pe = -sum(a * math.log(a) for a in u.ravel()) / n
    assert v["pe"] == pytest.approx(pe)
    assert v["nfi"] == pytest.approx((2 * pc - 1) / 1)
    # cluster 0: points 0,1,2 with r = 1/9, 2/8, 4/6; cluster 1: point 3 with r = 3/7
    T0 = (1 / 9 + 2 / 8 + 4 / 6) / 3
    T1 = 3 / 7
    ht = [-math.log10(T0), -math.log10(T1)]
    assert v["min_ht"] == pytest.approx(min(ht))  # the MINIMUM over clusters
    assert v["mean_ht"] == pytest.approx(sum(ht) / 2)
    assert v["min_card"] == 1.0
    # max memberships 0.9, 0.8 >= 0.75 (non-fuzzy); 0.6, 0.7 fuzzy -> Rf = 2/2
    assert v["rf"] == pytest.approx(1.0)
    # "entries" reading: fuzzy = 8 - 2 = 6 entries -> 3 = c (rf + 1) - 1
    assert partition_measures(u, rf_count="entries")["rf"] == pytest.approx(3.0)


def test_empty_cluster_min_ht_zero():
    u = np.array([[0.9, 0.05, 0.05], [0.1, 0.85, 0.05]])
    v = partition_measures(u)
    assert v["min_card"] == 0.0 and v["min_ht"] == 0.0 and v["mean_ht"] > 0


def test_validity_keys_and_directions():
    X = blobs()
    v = validity(X, fcm(X, 4, seed=0))
    assert list(v) == KEYS
    assert set(MEASURE_DIRECTIONS) == set(KEYS)
    assert set(MEASURE_DIRECTIONS.values()) == {"max", "min", "positive"}
    assert all(isinstance(x, float) for x in v.values())
    assert 0.25 <= v["pc"] <= 1 and v["min_ht"] <= v["mean_ht"]


def test_validity_objective_by_hand():
    X = np.array([[0.0, 0.0], [2.0, 0.0]])
    V = np.array([[0.0, 0.0], [2.0, 1.0]])
    u = np.array([[0.7, 0.3], [0.4, 0.6]])
    r = FCMResult(centers=V, u=u, objective=0.0, n_iter=0, converged=True, m=2.0)
    J = 0.3**2 * 5 + 0.4**2 * 4 + 0.6**2 * 1
    assert validity(X, r)["objective"] == pytest.approx(J)


def test_validity_rejects_mismatched_result():
    X = blobs()
    r = fcm(X, 3, seed=0)
    with pytest.raises(ValueError, match="result.u"):
        validity(X[:10], r)
    with pytest.raises(ValueError, match="u rows must sum to 1"):
        partition_measures(np.array([[0.5, 0.2], [0.5, 0.5]]))


# ------------------------------------------------------------------ skfuzzy agreement


@pytest.mark.parametrize("c", [3, 6])
def test_same_fixed_point_as_skfuzzy(c):
    import skfuzzy  # (in the test extra: this check must run, never skip)
    X = blobs(n=400, k=5, spread=0.4, seed=2)
    rng = np.random.default_rng(c)
    V0 = X[rng.choice(len(X), c, replace=False)]
    m = 1.2
    ours = fcm(X, c, m, tol=1e-10, max_iter=3000, init_centers=V0)
    u0 = memberships(X, V0, m).T  # skfuzzy takes (c, n) initial memberships
    cntr, *_ = skfuzzy.cluster.cmeans(X.T, c, m, 1e-12, 3000, init=u0)
    # like with like: J_m(U(V), V) at skfuzzy's final centres (its own jm is J at the previous
    # memberships), with the same Eq. 3.2
    theirs = FCMResult(cntr, memberships(X, cntr, m), 0.0, 0, True, m)
    J_theirs = validity(X, theirs)["objective"]
    assert ours.objective == pytest.approx(J_theirs, rel=1e-6)
    # same prototypes (up to order)
    order = [int(np.argmin(((cntr - v) ** 2).sum(1))) for v in ours.centers]
    np.testing.assert_allclose(ours.centers, cntr[order], atol=1e-5)


@given(st.integers(2, 16), st.floats(1.01, 3.0), st.integers(0, 10_000))
@settings(max_examples=150, deadline=None)
def test_membership_function_matches_memberships(c, m, seed):
    from sitframe.situations.fcm import MembershipFunction

    rng = np.random.default_rng(seed)
    V = rng.uniform(0, 3, (c, 8))
    X = np.vstack([rng.uniform(0, 3, (20, 8)), V[:2]])  # includes readings on centres
    f = MembershipFunction(V, m)
    expected = memberships(X, V, m)
    got = np.array([f(x) for x in X])
    np.testing.assert_allclose(got, expected, atol=1e-9)
    np.testing.assert_allclose(got.sum(axis=1), 1.0)


def test_huge_max_iter_allocates_nothing_up_front():
    """max_iter bounds the loop; memory grows with the iterations actually run."""
    X = np.array([[0.0], [0.0], [1.0]])
    r = fcm(X, 2, max_iter=3_159_563_044, seed=0)  # found by the fuzzer: 23.5 GiB before
    assert r.converged and r.objective_history.shape == (r.n_iter,)


@pytest.mark.parametrize(("u", "message"), [
    (np.array([0.5, 0.5]), r"2-D \(n, c\) membership array with c >= 2, got shape \(2,\)"),
    (np.ones((3, 1)), r"c >= 2, got shape \(3, 1\)"),
    (np.zeros((0, 2)), r"got shape \(0, 2\)"),
    (np.array([[np.nan, 1.0]]), r"^u must hold finite memberships in \[0, 1\]$"),
    (np.array([[-0.1, 1.1]]), r"^u must hold finite memberships in \[0, 1\]$"),
    (np.array([[0.0, 1.0 + 1e-6]]), r"^u must hold finite memberships in \[0, 1\]$"),
    (np.array([[0.5, 0.75], [0.45, 0.45]]), r"row 0 sums to 1\.25"),  # the row farthest from 1
    (np.array([[0.5, 0.5], [0.25, 0.5]]), r"rows must sum to 1 .*row 1 sums to 0\.75"),
    (np.array([[0.5, 0.5], [0.5, 0.5 - 2e-6]]), "row 1 sums to"),
])
def test_partition_measures_refuse_what_is_not_a_fuzzy_partition(u, message):
    """A membership matrix that is not a fuzzy c-partition is refused, naming what is wrong
    (the shape, the entry range, the first row that does not sum to 1)."""
    with pytest.raises(ValueError, match=message):
        partition_measures(u)
    with pytest.raises(TypeError, match=r"^u must be a real numeric array, got ndarray of dtype"):
        partition_measures(np.array([["a", "b"]]))


def test_partition_measures_accept_a_partition_within_rounding():
    """Rows summing to 1 within 1e-6 and entries a hair above 1 (1e-9) are a partition."""
    u = np.array([[0.5, 0.5 + 5e-7], [1.0 + 1e-9, 0.0]])
    assert math.isfinite(partition_measures(u)["pc"])


_X = np.array([[0.0, 1.0], [1.0, 0.0], [2.0, 2.0]])


@pytest.mark.parametrize(("call", "error", "message"), [
    (lambda: fcm(np.zeros((0, 2)), 2), ValueError,
     r"^X must have at least one sample and one feature, got shape \(0, 2\)$"),
    (lambda: fcm(np.zeros((3, 0)), 2), ValueError,
     r"^X must have at least one sample and one feature, got shape \(3, 0\)$"),
    (lambda: fcm(_X * 1e151, 2), ValueError,
     r"^X values must have magnitude <= 1e150 \(squared distances must not overflow\), "
     r"got 2e\+151$"),
    (lambda: fcm(_X, 2, m=True), TypeError,
     r"^m: expected a number in \(1, inf\) \(m = 1 is a hard partition\), got bool True$"),
    (lambda: fcm(_X, 2, m="2"), TypeError,
     r"^m: expected a number in \(1, inf\) \(m = 1 is a hard partition\), got str '2'$"),
    (lambda: fcm(_X, "2"), TypeError,
     r"^c: expected an integer in \[2, 3\] \(at most n_samples\), got str '2'$"),
    (lambda: fcm(_X, 2, max_iter=1.5), TypeError,
     r"^max_iter: expected an integer in \[1, inf\), got 1\.5$"),
    (lambda: fcm(_X, 2, max_iter=0), ValueError,
     r"^max_iter: expected an integer in \[1, inf\), got 0$"),
    (lambda: fcm(_X, 2, seed=-1), ValueError,
     r"^seed must be a non-negative integer, a numpy Generator or None, got -1$"),
    (lambda: fcm(_X, 2, seed="x"), TypeError,
     r"^seed must be an int, a numpy.random.Generator or None, got 'x' \(str\)$"),
    (lambda: fcm(_X, 2, init_centers=np.zeros((3, 2))), ValueError,
     r"^init_centers must have shape \(2, 2\) \(clusters x features of X\), got \(3, 2\)$"),
    (lambda: memberships(_X, np.zeros((2, 3)), 1.5), ValueError,
     r"^centers must have shape \('c', 2\) \(clusters x features of X\), got \(2, 3\)$"),
])
def test_fcm_refuses_bad_input_naming_the_argument_and_the_value(call, error, message):
    """Each bad argument of fcm / memberships is refused with a message that names the
    argument, what was expected and what was given (its type for a wrong type)."""
    with pytest.raises(error, match=message):
        call()


def test_fcm_accepts_its_bounds():
    """The largest magnitude allowed (1e150) and seed None (fresh entropy) are accepted."""
    big = np.array([[0.0, 1e150], [1.0, 0.0], [2.0, 2.0]])
    assert memberships(big, big[:2], 1.5).shape == (3, 2)
    assert fcm(_X, 2, seed=None).centers.shape == (2, 2)


# ------------------------------------------------------ the arithmetic behind Eq. 3.2


def naive_objective(X, V, m):
    """Eq. 3.1: sum_ij u_ij**m |x_j - v_i|**2 with the memberships of Eq. 3.2."""
    d2 = ((X[:, None, :] - V[None, :, :]) ** 2).sum(-1)
    return float((naive_memberships(X, V, m) ** m * d2).sum())


def naive_update(X, V, m):
    """The FCM centre update: v_i = sum_j u_ij**m x_j / sum_j u_ij**m."""
    um = naive_memberships(X, V, m) ** m
    return (um.T @ X) / um.sum(axis=0)[:, None]


# 2/(m-1) an integer (products), a half-integer (products and a square root) or neither
# (np.power): 1.2 -> 10, 1.25 -> 8, 4/3 -> 6, 1.4 -> 5, 1.5 -> 4, 5/3 -> 3, 2 -> 2, 3 -> 1.
@pytest.mark.parametrize("m", [1.2, 1.25, 4 / 3, 1.4, 1.5, 5 / 3, 2.0, 3.0, 1.3, 2.7])
def test_every_fuzzifier_gives_eq_3_2_the_objective_and_the_centre_update(m):
    """Whatever m, memberships are Eq. 3.2, the objective history starts at J_m of the
    initial centres (Eq. 3.1) and one iteration moves the centres by the FCM update."""
    rng = np.random.default_rng(2)
    X, V = rng.normal(size=(60, 3)), rng.normal(size=(5, 3))
    np.testing.assert_allclose(memberships(X, V, m), naive_memberships(X, V, m),
                               rtol=1e-10, atol=1e-300)
    r = fcm(X, 5, m, init_centers=V, max_iter=1)
    assert r.objective_history[0] == pytest.approx(naive_objective(X, V, m), rel=1e-10)
    np.testing.assert_allclose(r.centers, naive_update(X, V, m), rtol=1e-10)
    assert r.objective == pytest.approx(naive_objective(X, r.centers, m), rel=1e-10)


def test_large_data_sets_give_the_same_results_as_small_ones():
    """5000 samples and 20 centres (processed in several cache-sized blocks) give the
    memberships, objective and centre updates of the whole data set, and a sample on a
    centre far down the data still gets membership 1 there."""
    rng = np.random.default_rng(4)
    X, V = rng.uniform(0, 3, (5000, 4)), rng.uniform(0, 3, (20, 4))
    X[4500] = V[3]
    rest = np.arange(5000) != 4500
    u = memberships(X, V, 1.2)
    np.testing.assert_array_equal(u[4500], np.eye(20)[3])
    np.testing.assert_allclose(u[rest], naive_memberships(X[rest], V, 1.2), rtol=1e-9,
                               atol=1e-300)
    r = fcm(X[rest], 20, 1.2, init_centers=V, max_iter=2, tol=1e-12)
    assert r.n_iter == 2 and r.converged is False
    V1 = naive_update(X[rest], V, 1.2)
    assert r.objective_history[0] == pytest.approx(naive_objective(X[rest], V, 1.2), rel=1e-9)
    assert r.objective_history[1] == pytest.approx(naive_objective(X[rest], V1, 1.2), rel=1e-9)
    np.testing.assert_allclose(r.centers, naive_update(X[rest], V1, 1.2), rtol=1e-9)
    assert r.objective == pytest.approx(naive_objective(X[rest], r.centers, 1.2), rel=1e-9)


def test_samples_on_and_within_round_off_of_centres():
    """A sample on a centre gets membership 1 there; one 1e-9 from another centre gets
    Eq. 3.2 (its distance recomputed exactly, not from the expansion's round-off)."""
    V = np.array([[1.0, 2.0], [3.0, 1.0], [0.0, 0.0]])
    X = np.array([[1.0, 2.0], [3.0 + 1e-9, 1.0], [2.0, 2.0]])
    u = memberships(X, V, 2.0)
    np.testing.assert_array_equal(u[0], [1.0, 0.0, 0.0])
    np.testing.assert_allclose(u[1:], naive_memberships(X[1:], V, 2.0), rtol=1e-9)


def _far_cluster(s):
    """1-D samples whose squared-distance ratio to centre 0 vs centre 1 is ``s``."""
    r = np.sqrt(s)
    return (r / (1.0 + r))[:, None]


def test_tiny_memberships_are_exact_down_to_1e_295_and_floored_at_1e_300_below():
    """m = 1.01: a membership down to ~1e-295 is Eq. 3.2; a smaller one is reported as
    ~1e-300, never as 0 or a subnormal number -- also in a batch with a sample on a centre."""
    V = np.array([[0.0], [1.0]])
    s = 10.0 ** np.array([-1.0, -2.0, -2.9, -2.95])
    X = _far_cluster(s)
    np.testing.assert_allclose(memberships(X, V, 1.01), naive_memberships(X, V, 1.01),
                               rtol=1e-8, atol=0)
    far = np.vstack([[0.0], _far_cluster(10.0 ** np.array([-5.0, -40.0]))])
    u = memberships(far, V, 1.01)
    np.testing.assert_array_equal(u[0], [1.0, 0.0])
    assert np.all((u[1:, 1] >= 1e-301) & (u[1:, 1] <= 1e-296))


def test_a_centre_no_sample_belongs_to_stays_where_it_is():
    """When every sample sits on another centre, a centre with no membership at all keeps
    its place (no 0/0) and the others stay on their samples."""
    X = np.array([[0.0], [0.0], [1.0], [1.0]])
    with np.errstate(all="raise"):
        r = fcm(X, 3, init_centers=np.array([[0.0], [1.0], [5.0]]))
    np.testing.assert_array_equal(r.centers, [[0.0], [1.0], [5.0]])
    np.testing.assert_array_equal(r.u, [[1, 0, 0], [1, 0, 0], [0, 1, 0], [0, 1, 0]])
    assert r.converged is True and r.n_iter == 1 and r.objective == 0.0


def test_an_unconverged_run_says_so_after_exactly_max_iter_updates():
    X = blobs()
    r = fcm(X, 4, seed=0, tol=1e-14, max_iter=3)
    assert r.converged is False and r.n_iter == 3 and r.objective_history.shape == (3,)


def test_convergence_needs_a_move_strictly_below_tol():
    """Stop when max |V_t+1 - V_t| < tol: a move of exactly tol is not convergence."""
    X, V0 = blobs(), blobs()[[0, 100, 200]]
    first = fcm(X, 3, init_centers=V0, max_iter=1)
    move = float(np.max(np.abs(first.centers - V0)))
    assert fcm(X, 3, init_centers=V0, tol=move, max_iter=2).n_iter == 2
    assert fcm(X, 3, init_centers=V0, tol=np.nextafter(move, np.inf), max_iter=2).n_iter == 1


def test_a_centre_whose_weights_underflow_keeps_its_place_and_the_others_move():
    """m = 60 and a centre 1e145 away: its weights underflow to exactly 0 (Eq. 3.2 would
    divide 0 by 0) and it stays where it is; the other centres, whose weights are tiny
    (~1e-70) but not 0, move by the FCM update."""
    rng = np.random.default_rng(5)
    C = rng.uniform(0, 1, (19, 2))
    X = C[rng.integers(0, 19, 60)] + rng.normal(0, 1e-4, (60, 2))
    V = np.vstack([C, [[1e145, 1e145]]])
    with np.errstate(all="raise"):
        r = fcm(X, 20, 60.0, init_centers=V, max_iter=1)
    np.testing.assert_array_equal(r.centers[19], V[19])
    with np.errstate(invalid="ignore"):  # (the naive update of the far centre is 0 / 0)
        want = naive_update(X, V, 60.0)[:19]
    np.testing.assert_allclose(r.centers[:19], want, rtol=0, atol=1e-9)
    assert np.max(np.abs(r.centers[:19] - C)) > 1e-5


def test_fcm_accepts_lists_ints_bools_and_object_arrays_as_numbers():
    """Any real numeric array-like is data: a list, an int, bool or object array (as
    pandas may give) clusters exactly like its float64 version."""
    Xf = np.array([[0.0, 1.0], [1.0, 0.0], [1.0, 1.0], [0.0, 0.0], [1.0, 1.0]])
    want = fcm(Xf, 2, seed=1)
    for X in (Xf.tolist(), Xf.astype(int), Xf.astype(bool), Xf.astype(object)):
        got = fcm(X, 2, seed=1)
        np.testing.assert_array_equal(got.centers, want.centers)
        np.testing.assert_array_equal(got.u, want.u)
        np.testing.assert_array_equal(memberships(X, want.centers, 1.2), want.u)
    with pytest.raises(TypeError, match=r"^X must be a real numeric array, got list$"):
        fcm([["a", "b"], ["c", "d"]], 2)
    with pytest.raises(TypeError,
                       match=r"^X must be a real numeric array, got ndarray of dtype complex128$"):
        fcm(Xf.astype(complex), 2)


@pytest.fixture(params=["numpy", "compiled"])
def membership_path(request, monkeypatch):
    """Run MembershipFunction on the numpy code or on the compiled kernels."""
    from sitframe.sim import kernels

    if request.param == "compiled":
        pytest.importorskip("numba")
        k = kernels.load()
        if k is None:
            pytest.skip("compiled kernels switched off (SITFRAME_NUMBA=0)")
        monkeypatch.setattr(kernels, "_LOADED", [k])
    else:
        monkeypatch.setattr(kernels, "_LOADED", [None])
    return request.param


def test_membership_function_is_eq_3_2_on_either_path(membership_path):
    """The controller's per-reading memberships: Eq. 3.2 near and far (squared distances
    below and above 1), 1 on a centre, shared equally between identical centres, a single
    centre gets everything, and ~1e-300 (not 0 or subnormal) at m = 1.01."""
    from sitframe.situations.fcm import MembershipFunction

    V = np.array([[0.0, 0.0], [0.5, 0.0], [3.0, 1.0]])
    f = MembershipFunction(V, 1.5)
    X = np.array([[0.1, 0.1], [0.25, 0.3], [2.0, 2.0], [-4.0, 1.0]])
    np.testing.assert_allclose([f(x) for x in X], naive_memberships(X, V, 1.5), rtol=1e-12)
    np.testing.assert_array_equal(f(np.array([0.5, 0.0])), [0.0, 1.0, 0.0])
    twin = MembershipFunction(np.array([[1.0, 1.0], [1.0, 1.0], [1.5, 1.0]]), 1.2)
    np.testing.assert_array_equal(twin(np.array([1.0, 1.0])), [0.5, 0.5, 0.0])
    np.testing.assert_array_equal(MembershipFunction(V[:1], 1.2)(np.array([7.0, 1.0])), [1.0])
    for table in (V.astype(object), V.tolist()):  # (as pandas or a config may give them)
        np.testing.assert_array_equal(MembershipFunction(table, 1.5)(X[1]), f(X[1]))
    fine = MembershipFunction(np.array([[0.0], [1.0]]), 1.01)
    x = _far_cluster(10.0 ** np.array([-2.95, -5.0, -40.0]))
    np.testing.assert_allclose(fine(x[0]), naive_memberships(x[:1], fine.centers, 1.01)[0],
                               rtol=1e-8)
    for xi in x[1:]:
        assert 1e-301 <= fine(xi)[1] <= 1e-299


@pytest.mark.parametrize(("centers", "shape"), [
    (np.zeros(3), r"\(3,\)"), (np.zeros((0, 3)), r"\(0, 3\)"),
    (np.array([[0.0, np.nan]]), r"\(1, 2\)"), (np.array([[0.0, np.inf], [1.0, 1.0]]), r"\(2, 2\)"),
])
def test_membership_function_refuses_centres_that_are_not_a_finite_table(centers, shape):
    from sitframe.situations.fcm import MembershipFunction

    with pytest.raises(ValueError, match=rf"^centers must be a finite \(c, d\) array, got shape "
                                         rf"{shape}$"):
        MembershipFunction(centers, 1.2)
