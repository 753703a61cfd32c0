"""Fuzzy c-means clustering (thesis Algorithm 1, Eqs. 3.1-3.2) and validity measures (Eqs. 4.1-4.9).

Public API (used from notebooks; names and shapes are stable)
-------------------------------------------------------------
:func:`fcm`
    One FCM run from random (or given) initial centres -> :class:`FCMResult`.
:func:`memberships`
    Eq. 3.2 for arbitrary points and centres. The live fuzzy controller uses the
    same function with the same ``m`` as the clustering (thesis 4.5.1).
:func:`validity`
    The seven validity measures of thesis 4.4 plus the objective ``J_m``.
:data:`MEASURE_DIRECTIONS`
    ``"max"``, ``"min"`` or ``"positive"`` for every validity key: the single
    source of truth for trial selection and plots.

All arrays are *samples x features*: ``X`` has shape ``(n, d)``, centres
``(c, d)``, memberships ``(n, c)`` (rows sum to 1). Distances are Euclidean, in
the units of ``X`` (metres for sonar ranges), so ``J_m`` is in units squared.

Numerics
--------
Memberships are computed from *squared*-distance ratios, scaled per point by its
smallest squared distance (``s_ij = d2_min,j / d2_ij`` in ``(0, 1]``), so that

    u_ij = s_ij**p / sum_k s_kj**p,         p = 1 / (m - 1)

which is Eq. 3.2 with the largest term equal to 1: no overflow for any ``m > 1``
or any distance. Ratios are floored at ``10**(-300 / (p + 1))`` so that no power
underflows into subnormal numbers: a membership below ``10**(-300 p / (p + 1))``
(1e-250 at ``m = 1.2``, 1e-150 at ``m = 2``, 1e-100 at ``m = 3``) is reported as
that value instead of a smaller one; it changes nothing measurable. A point
that sits exactly on a centre gets membership 1 there and exactly 0 elsewhere
(split equally between identical centres).

For the iteration the centre update needs ``u**m``; writing ``S_j = sum_k s_kj**p``
gives ``u_ij**m = s_ij**(p+1) / S_j**m``, so only the ``n`` row sums need a real
power function. When ``2p`` is an integer (``m = 1.2`` -> ``p = 5``, ``m = 2`` ->
``p = 1``, ``m = 3`` -> ``p = 0.5``) the element-wise powers are done by repeated
multiplication (and one square root) instead of ``np.power``. The objective
comes for free: ``sum_i u_ij**m d2_ij = d2_min,j * S_j**(1-m)``. Squared distances
use the expansion ``|x|^2 - 2 x.v + |v|^2`` computed by one matrix product (clamped
at 0); points within round-off of a centre are recomputed exactly.

Why one module of this size: the algorithm, its stable memberships and the validity measures
share one formula and one ``m``; apart, the measures would lose the memberships they are
defined on.
"""

from __future__ import annotations

import functools
import math
import numbers
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Literal, ParamSpec, TypeVar

import numpy as np

from sitframe import params as P
from sitframe.sim.kernels import kernels

__all__ = [
    "FCMResult",
    "MEASURE_DIRECTIONS",
    "MEASURE_LABELS",
    "fcm",
    "init_centers_from_data",
    "memberships",
    "online_update",
    "row_sq_norms",
    "partition_measures",
    "validity",
]

#: Direction in which each validity measure is "better": ``"max"`` (larger is
#: better), ``"min"`` (smaller is better) or ``"positive"`` (a constraint that
#: must be > 0; not ranked). Keys are exactly those returned by :func:`validity`.
MEASURE_DIRECTIONS: dict[str, str] = {
    "pc": "max",
    "pe": "min",
    "nfi": "max",
    "min_ht": "max",
    "mean_ht": "max",
    "min_card": "positive",
    "rf": "min",
    "objective": "min",
}

#: Short human labels (thesis notation) for tables and plot titles.
MEASURE_LABELS: dict[str, str] = {
    "pc": "Partition coefficient $V_{PC}$",
    "pe": "Partition entropy $V_{PE}$",
    "nfi": "Non-fuzzy index NFI",
    "min_ht": "Minimum hard tendency",
    "mean_ht": "Mean hard tendency",
    "min_card": "Minimum cardinality",
    "rf": "Relative fuzziness $R_f$",
    "objective": "Objective $J_m$",
}

# Every power s**k computed in the loop stays >= 10**-_FLOOR_DECADES (no subnormals).
_FLOOR_DECADES = 300.0
# Points whose expanded squared distance to a centre is below this fraction of
# |x|^2 + |v|^2 are recomputed exactly (round-off of the expansion is ~1e-16 of that).
_REL_ZERO = 1e-12
_MAX_INT_POWER = 128
# Samples per block ~ this many (c, block) elements, so that temporaries stay in cache.
_BLOCK_ELEMENTS = 2**15


_P = ParamSpec("_P")
_R = TypeVar("_R")


def _ignore_underflow(func: Callable[_P, _R]) -> Callable[_P, _R]:
    """Run ``func`` with floating-point underflow ignored (flushing to 0 is the intended result).

    Memberships of far-away clusters legitimately underflow; without this a
    caller's ``np.errstate(all="raise")`` would turn that into an error.
    """

    @functools.wraps(func)
    def wrapper(*args: _P.args, **kwargs: _P.kwargs) -> _R:
        with np.errstate(under="ignore"):
            return func(*args, **kwargs)

    return wrapper


# --------------------------------------------------------------------------- results


@dataclass(frozen=True)
class FCMResult:
    """Outcome of one fuzzy c-means run.

    Attributes
    ----------
    centers : ndarray, shape (c, d)
        Cluster prototypes ``V`` in the units of ``X``.
    u : ndarray, shape (n, c)
        Memberships of the samples to the clusters at ``centers`` (Eq. 3.2);
        every row sums to 1.
    objective : float
        ``J_m(U, V)`` (Eq. 3.1) at the returned ``centers`` and ``u``, in units of
        ``X`` squared.
    n_iter : int
        Number of centre updates performed.
    converged : bool
        True if the last update moved every centre coordinate by less than ``tol``.
    m : float
        Fuzzifier (partition order) used.
    objective_history : ndarray, shape (n_iter,)
        ``J_m(U(V_t), V_t)`` before the ``t``-th centre update (non-increasing).
    """

    centers: np.ndarray
    u: np.ndarray
    objective: float
    n_iter: int
    converged: bool
    m: float
    objective_history: np.ndarray = field(default_factory=lambda: np.empty(0), repr=False)

    @property
    def c(self) -> int:
        """Number of clusters."""
        return int(self.centers.shape[0])

    @property
    def labels(self) -> np.ndarray:
        """(n,) index of the strongest membership of each sample (ties -> lowest index)."""
        return np.argmax(self.u, axis=1)


# ------------------------------------------------------------------------ validation


def _real(X: object, name: str) -> np.ndarray:
    """``X`` as a float64 array; complex, string and date arrays are a TypeError (not cast)."""
    try:
        arr = np.asarray(X)
        if arr.dtype.kind in "biufO":  # (bool, int, float, object holding numbers)
            return arr.astype(np.float64, copy=False)
    except (TypeError, ValueError):
        pass
    raise TypeError(f"{name} must be a real numeric array, got {type(X).__name__}"
                    f"{f' of dtype {X.dtype}' if hasattr(X, 'dtype') else ''}")


def _check_X(X: object, name: str = "X") -> np.ndarray:
    arr = _real(X, name)
    if arr.ndim != 2:
        raise ValueError(
            f"{name} must be a 2-D array (samples x features), got {arr.ndim}-D "
            f"with shape {arr.shape}"
        )
    if arr.shape[0] < 1 or arr.shape[1] < 1:
        raise ValueError(f"{name} must have at least one sample and one feature, got shape "
                         f"{arr.shape}")
    if not np.all(np.isfinite(arr)):
        bad = np.argwhere(~np.isfinite(arr))[0]
        raise ValueError(
            f"{name} must be finite, got {arr[tuple(bad)]} at index {tuple(int(b) for b in bad)}"
        )
    if np.max(np.abs(arr)) > 1e150:
        raise ValueError(f"{name} values must have magnitude <= 1e150 (squared distances must "
                         f"not overflow), got {np.max(np.abs(arr)):g}")
    return np.ascontiguousarray(arr)


def _check_m(m: object) -> float:
    return float(P.number("m", m, lo=1, lo_open=True, hint=" (m = 1 is a hard partition)"))


def _check_c(c: object, n: int) -> int:
    return int(P.number("c", c, lo=2, hi=n, integer=True, hint=" (at most n_samples)"))


def _check_tol(tol: object) -> float:
    return float(P.number("tol", tol, lo=0, lo_open=True, hint=" (centre movement, units of X)"))


def _check_centers(centers: object, c: int | None, d: int, name: str) -> np.ndarray:
    arr = _check_X(centers, name)
    want = (c, d) if c is not None else ("c", d)
    if arr.shape[1] != d or (c is not None and arr.shape[0] != c):
        raise ValueError(f"{name} must have shape {want} (clusters x features of X), "
                         f"got {arr.shape}")
    return arr


def _as_generator(seed: object) -> np.random.Generator:
    if isinstance(seed, np.random.Generator):
        return seed
    if seed is None or (isinstance(seed, numbers.Integral) and not isinstance(seed, bool)):
        if seed is not None and int(seed) < 0:
            raise ValueError(f"seed must be a non-negative integer, a numpy Generator or None, "
                             f"got {seed}")
        return np.random.default_rng(None if seed is None else int(seed))
    raise TypeError(f"seed must be an int, a numpy.random.Generator or None, got {seed!r} "
                    f"({type(seed).__name__})")


# ---------------------------------------------------------------------------- kernel


def _power_plan(m: float) -> tuple[float, int | None]:
    """Return ``(p, twice_p)``; ``twice_p`` is ``2p`` as an int when powers can be multiplied."""
    p = 1.0 / (m - 1.0)
    tp = round(2.0 * p)
    if 1 <= tp <= _MAX_INT_POWER and abs(2.0 * p - tp) <= 1e-9 * 2.0 * p:
        return p, int(tp)
    return p, None


def _ipow(s: np.ndarray, k: int, out: np.ndarray) -> np.ndarray:
    """``out = s**k`` for an integer ``k >= 1`` by left-to-right binary exponentiation."""
    bits = bin(k)[3:]  # bits after the leading 1
    if not bits:
        np.copyto(out, s)
        return out
    np.multiply(s, s, out=out)
    if bits[0] == "1":
        np.multiply(out, s, out=out)
    for b in bits[1:]:
        np.multiply(out, out, out=out)
        if b == "1":
            np.multiply(out, s, out=out)
    return out


class _Workspace:
    """Precomputed data layouts and reusable buffers for one ``(X, c, m)``.

    Samples are processed in contiguous blocks of ``block`` columns so that the
    (c, block) temporaries stay in cache for large ``n``; for ``n <= block``
    there is a single block.
    """

    def __init__(self, X: np.ndarray, c: int, m: float):
        n, d = X.shape
        self.X, self.n, self.d, self.c, self.m = X, n, d, c, m
        self.p, self.twice_p = _power_plan(m)
        self.floor = 10.0 ** (-_FLOOR_DECADES / (self.p + 1.0))
        block = max(2048, _BLOCK_ELEMENTS // c)
        xsq = np.einsum("ij,ij->i", X, X)
        self.xzero = _REL_ZERO * xsq
        self.starts = list(range(0, n, block))
        # per block: B = [X^T; |x|^2; 1] (d+2, nb) so that A @ B = squared distances with
        # A = [-2V | 1 | |v|^2]; XT1 = [X^T; 1] (d+1, nb) so that (XT1 * a) @ w.T gives
        # the weighted sums and the weight totals at once.
        self.Bs, self.XT1s = [], []
        for a in self.starts:
            b = min(a + block, n)
            B = np.empty((d + 2, b - a))
            B[:d] = X[a:b].T
            B[d] = xsq[a:b]
            B[d + 1] = 1.0
            self.Bs.append(B)
            self.XT1s.append(B[: d + 1].copy())
            self.XT1s[-1][d] = 1.0
        nb = min(block, n)
        self.A = np.empty((c, d + 2))
        self._d2 = np.empty((c, nb))
        self._s = np.empty((c, nb))
        self._w = np.empty((c, nb))
        self._w1 = np.empty((c, nb))
        self._tmp = np.empty((c, nb)) if self.twice_p is not None and self.twice_p % 2 else None
        self._YT = np.empty((d + 1, nb))
        self.dmin = np.empty(n)
        self.S = np.empty(n)

    def _prepare(self, V: np.ndarray) -> float:
        """Fill ``A`` from the centres; return the zero-distance threshold term of the centres."""
        d, A = self.d, self.A
        np.multiply(V, -2.0, out=A[:, :d])
        A[:, d] = 1.0
        csq = np.einsum("ij,ij->i", V, V)
        A[:, d + 1] = csq
        return _REL_ZERO * float(csq.max())

    def _block(self, k: int, V: np.ndarray, czero: float) -> tuple[np.ndarray, ...]:
        """Weights of block ``k``: returns views ``(w = s**p, w1 = s**(p+1), S, dmin)``.

        ``s_ij = d2_min,j / d2_ij`` (1 at the nearest centre); ``S_j = sum_i w_ij``.
        Distances use the expansion (one matrix product), not clamped: an entry can
        only be (slightly) negative where it is its column's minimum, and columns
        within round-off of a centre are recomputed exactly.
        """
        a = self.starts[k]
        B = self.Bs[k]
        nb = B.shape[1]
        d2, s = self._d2[:, :nb], self._s[:, :nb]
        w, w1 = self._w[:, :nb], self._w1[:, :nb]
        dmin, S = self.dmin[a : a + nb], self.S[a : a + nb]
        np.matmul(self.A, B, out=d2)
        np.min(d2, axis=0, out=dmin)
        near = dmin <= self.xzero[a : a + nb] + czero
        zero_cols = on = exact = None
        if near.any():
            cols = np.flatnonzero(near)
            diff = self.X[a + cols][None, :, :] - V[:, None, :]
            exact = np.einsum("ijk,ijk->ij", diff, diff)  # (c, k) exact squared distances
            d2[:, cols] = exact
            dmin[cols] = exact.min(axis=0)
            on = dmin[cols] == 0.0
            if on.any():
                zero_cols = cols[on]
                d2[:, zero_cols] = 1.0  # placeholders so that the division is defined
                dmin[zero_cols] = 1.0
        np.divide(dmin, d2, out=s)
        if s.min() < self.floor:  # (np.maximum is slow; the floor is rarely needed)
            np.maximum(s, self.floor, out=s)
        if zero_cols is not None:
            # a point on a centre: membership 1 there (shared by identical centres), 0 elsewhere
            s[:, zero_cols] = exact[:, on] == 0.0
            dmin[zero_cols] = 0.0
        tp = self.twice_p
        if tp is None:
            np.power(s, self.p, out=w)
        elif tp % 2:  # half-integer p: s**k * sqrt(s)
            tmp = self._tmp[:, :nb]
            np.sqrt(s, out=tmp)
            if tp // 2:
                _ipow(s, tp // 2, out=w)
                np.multiply(w, tmp, out=w)
            else:
                np.copyto(w, tmp)
        else:
            _ipow(s, tp // 2, out=w)
        np.multiply(w, s, out=w1)
        np.sum(w, axis=0, out=S)
        return w, w1, S, dmin

    # -- one FCM step ----------------------------------------------------------------
    def step(self, V: np.ndarray) -> tuple[np.ndarray, float]:
        """Memberships from ``V``, then new centres. Returns ``(V_new, J_m(U(V), V))``.

        ``u_ij**m = s_ij**(p+1) / S_j**m`` and ``sum_i u_ij**m d2_ij = d2_min,j S_j**(1-m)``.
        """
        czero = self._prepare(V)
        d = self.d
        num = np.zeros((self.c, d + 1))
        objective = 0.0
        for k in range(len(self.starts)):
            _, w1, S, dmin = self._block(k, V, czero)
            Sm = np.power(S, -self.m)
            objective += float(np.dot(dmin * S, Sm))
            YT = self._YT[:, : S.shape[0]]
            np.multiply(self.XT1s[k], Sm, out=YT)
            num += (YT @ w1.T).T  # (c, d+1): weighted sums | weight totals
        # a centre whose weights are all 0 (every point on another centre, or underflow at
        # a large m) stays where it is
        ok = num[:, d] > 0.0
        Vn = V.copy()
        Vn[ok] = num[ok, :d] / num[ok, d:]
        return Vn, objective

    def finalize(self, V: np.ndarray) -> tuple[np.ndarray, float]:
        """``(u (n, c), J_m(u, V))`` at centres ``V``."""
        czero = self._prepare(V)
        u = np.empty((self.n, self.c))
        objective = 0.0
        for k, a in enumerate(self.starts):
            w, _, S, dmin = self._block(k, V, czero)
            np.divide(w, S, out=u[a : a + S.shape[0]].T)
            objective += float(np.dot(dmin * S, np.power(S, -self.m)))
        return u, objective


# ------------------------------------------------------------------------ public API


@_ignore_underflow
def memberships(X: np.ndarray, centers: np.ndarray, m: float) -> np.ndarray:
    """Fuzzy memberships of samples to clusters, Eq. 3.2.

    ``u_ij = 1 / sum_k (D_ij / D_ik)**(2 / (m - 1))`` with Euclidean ``D``,
    evaluated stably from squared-distance ratios scaled by each sample's
    smallest distance (see the module docstring): no overflow, NaN or warning
    for any ``m > 1`` (tested down to 1.01) or any distance. A sample exactly on
    a centre gets membership 1 there and 0 elsewhere; on ``k`` identical
    centres it gets ``1/k`` on each.

    Parameters
    ----------
    X : array_like, shape (n, d) or (d,)
        Samples (e.g. sonar ranges in metres). A single (d,) reading returns (c,).
    centers : array_like, shape (c, d)
        Cluster prototypes in the units of ``X``; ``c >= 1``.
    m : float
        Fuzzifier, ``m > 1`` (the thesis uses 1.2). Must be the clustering's ``m``.

    Returns
    -------
    ndarray, shape (n, c) (or (c,) for a single reading)
        Memberships in [0, 1]; every row sums to 1.
    """
    single = np.ndim(X) == 1
    Xa = _check_X(np.atleast_2d(X) if single else X)
    mf = _check_m(m)
    V = _check_centers(centers, None, Xa.shape[1], "centers")
    u, _ = _Workspace(Xa, V.shape[0], mf).finalize(V)
    return u[0] if single else u


_min, _sum = np.minimum.reduce, np.add.reduce


class MembershipFunction:
    """Memberships of one reading at a time, for a controller's hot loop.

    The same formula as :func:`memberships` (Eq. 3.2 from squared-distance
    ratios scaled by the smallest distance), with the argument checks and the
    centres' preparation done once here instead of on every call; distances
    are computed directly (no expansion), so a reading on a centre is exact.

    Parameters
    ----------
    centers : array_like, shape (c, d)
        Cluster prototypes.
    m : float
        Fuzzifier, ``m > 1``: the clustering's m.

    Examples
    --------
    >>> f = MembershipFunction(np.array([[0.0, 0.0], [1.0, 1.0]]), 1.2)
    >>> f(np.array([0.0, 0.0]))
    array([1., 0.])
    """

    def __init__(self, centers: np.ndarray, m: float) -> None:
        self.m = _check_m(m)
        V = np.asarray(centers, dtype=float)
        if V.ndim != 2 or V.shape[0] < 1 or not np.all(np.isfinite(V)):
            raise ValueError(f"centers must be a finite (c, d) array, got shape {V.shape}")
        self.centers = V.copy()
        self.p = 1.0 / (self.m - 1.0)
        # s = d2_min / d2 in (0, 1]; flooring s keeps s**p at or above 1e-300 (no subnormals).
        self.floor = 10.0 ** (-_FLOOR_DECADES / self.p)

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """Return the (c,) memberships of one (d,) reading; they sum to 1."""
        diff = self.centers - x
        return self.from_d2(_c_einsum("ij,ij->i", diff, diff))  # (row_sq_norms, inlined)

    def from_d2(self, d2: np.ndarray) -> np.ndarray:
        """Memberships from the (c,) squared distances of one reading to the centres.

        For a caller that already has the distances (e.g. an interpreter whose
        centres change on-line): the same formula and floor as :meth:`__call__`.
        """
        kern = kernels()
        if kern is not None and d2.size <= kern.PAIRWISE_MAX:  # (same arithmetic, compiled)
            w = np.empty(d2.size)
            if kern.fcm_ratios(d2, self.floor, w) <= 0.0:
                on = d2 <= 0.0
                return on / on.sum()
            w **= self.p
            kern.normalize(w)
            return w
        dmin = _min(d2)  # (the ufuncs' own reduce: ndarray.min/sum add a Python layer)
        if dmin <= 0.0:
            on = d2 <= 0.0
            return on / on.sum()
        w = np.maximum(dmin / d2, self.floor)
        w **= self.p
        w /= _sum(w)
        return w


try:  # np.einsum without ``optimize`` calls this C function behind a Python layer (~3 us)
    from numpy._core.multiarray import c_einsum as _c_einsum
except ImportError:  # pragma: no cover - numpy < 2
    _c_einsum = np.einsum


def row_sq_norms(diff: np.ndarray) -> np.ndarray:
    """``np.einsum("ij,ij->i", diff, diff)``: the (c,) squared norms of the rows of the
    (c, d) ``diff`` (e.g. centres minus one reading), bit for bit, for a hot loop."""
    return _c_einsum("ij,ij->i", diff, diff)


def online_update(centers: np.ndarray, evidence: np.ndarray, diff: np.ndarray,
                  um: np.ndarray) -> None:
    """The incremental FCM centre update for one reading, in place.

    The batch update ``v_i = sum_j u_ij^m x_j / sum_j u_ij^m`` taken one reading
    at a time: ``N_i += u_i^m``, ``v_i -= (u_i^m / N_i) (v_i - x)``.

    Parameters
    ----------
    centers : ndarray, shape (c, d)
        Prototypes ``v_i``, C-contiguous float64, updated in place.
    evidence : ndarray, shape (c,)
        Accumulated ``N_i`` (readings' worth of membership), updated in place.
    diff : ndarray, shape (c, d)
        ``centers - x`` for the reading ``x``.
    um : ndarray, shape (c,)
        The reading's memberships raised to m.
    """
    kern = kernels()
    if kern is not None:  # (same arithmetic, compiled)
        kern.fcm_online_update(centers, evidence, diff, um)
        return
    evidence += um
    centers -= (um / evidence)[:, None] * diff


@_ignore_underflow
def init_centers_from_data(X: np.ndarray, c: int, rng: np.random.Generator) -> np.ndarray:
    """Pick ``c`` distinct samples of ``X`` as initial centres (Algorithm 1, step 4).

    Samples are visited in the order of ``rng.permutation(n)`` and the first ``c``
    pairwise-distinct rows are taken, so frequent readings (e.g. the all-3 m
    "open space" reading) are as likely as their frequency but never chosen
    twice. If ``X`` has fewer than ``c`` distinct rows, the remaining centres
    repeat rows (identical centres then share memberships equally).

    Parameters
    ----------
    X : ndarray, shape (n, d)
    c : int
        Number of centres, ``1 <= c <= n``.
    rng : numpy.random.Generator
        The only source of randomness (one ``permutation`` call).

    Returns
    -------
    ndarray, shape (c, d)
    """
    n = X.shape[0]
    perm = rng.permutation(n)
    first = X[perm[:c]]
    if np.unique(first, axis=0).shape[0] == c:
        return first.copy()
    _, idx = np.unique(X[perm], axis=0, return_index=True)
    idx.sort()
    if idx.size >= c:
        return X[perm[idx[:c]]].copy()
    rest = np.setdiff1d(np.arange(n), idx, assume_unique=True)[: c - idx.size]
    return X[perm[np.concatenate([idx, rest])]].copy()


@_ignore_underflow
def fcm(
    X: np.ndarray,
    c: int,
    m: float = 1.2,
    *,
    tol: float = 1e-5,
    max_iter: int = 300,
    init_centers: np.ndarray | None = None,
    seed: int | np.random.Generator | None = None,
) -> FCMResult:
    """Fuzzy c-means clustering, thesis Algorithm 1.

    Starting from initial centres ``V_0``, repeat: memberships ``U(V_t)`` by
    Eq. 3.2; centres ``V_{t+1} = sum_j u_ij^m x_j / sum_j u_ij^m`` (the standard
    FCM update that minimises Eq. 3.1; Algorithm 1's printed update omits the
    exponent ``m``). Stop when ``max |V_{t+1} - V_t| < tol`` (largest absolute
    change of any centre coordinate) or after ``max_iter`` updates. The
    returned memberships and objective are recomputed at the final centres.

    Parameters
    ----------
    X : array_like, shape (n, d)
        Samples x features (e.g. 8 sonar ranges in metres). Finite.
    c : int
        Number of clusters, ``2 <= c <= n``. ``c == n`` is allowed (each sample
        its own cluster).
    m : float, default 1.2
        Fuzzifier (partition order), ``m > 1``.
    tol : float, default 1e-5
        Convergence threshold on the centre movement, in units of ``X``; > 0.
    max_iter : int, default 300
        Maximum number of centre updates, >= 1.
    init_centers : array_like, shape (c, d), optional
        Initial centres. If omitted, ``c`` distinct samples of ``X`` chosen by
        the generator (:func:`init_centers_from_data`). To reproduce
        ``skfuzzy.cluster.cmeans`` from the same start, feed it
        ``memberships(X, init_centers, m).T``: its first centre update then
        equals ours and both reach the same fixed point.
    seed : int, numpy.random.Generator or None
        Source of the random initial centres (ignored when ``init_centers`` is
        given). An int makes the run reproducible; a Generator is advanced
        (one ``permutation`` call); None draws fresh OS entropy. The global
        ``np.random`` state is never used.

    Returns
    -------
    FCMResult

    Raises
    ------
    ValueError, TypeError
        For a non-2-D or non-finite ``X``, ``c`` outside ``[2, n]``, ``m <= 1``,
        non-positive ``tol`` or ``max_iter``, or ``init_centers`` not ``(c, d)``.
    """
    Xa = _check_X(X)
    n, d = Xa.shape
    c = _check_c(c, n)
    mf = _check_m(m)
    tol = _check_tol(tol)
    max_iter = int(P.number("max_iter", max_iter, lo=1, integer=True))
    if init_centers is None:
        V0 = init_centers_from_data(Xa, c, _as_generator(seed))
    else:
        V0 = _check_centers(init_centers, c, d, "init_centers")
    return _fcm_core(_Workspace(Xa, c, mf), V0, tol, max_iter)


def _fcm_core(ws: _Workspace, V0: np.ndarray, tol: float, max_iter: int) -> FCMResult:
    V = V0  # (validated float64; never written to: each step returns new centres)
    history: list[float] = []  # grows with the iterations run, not max_iter (may be huge)
    converged = False
    it = 0
    while it < max_iter:
        Vn, j = ws.step(V)
        history.append(float(j))
        it += 1
        delta = float(np.max(np.abs(Vn - V)))
        V = Vn
        if delta < tol:
            converged = True
            break
    u, objective = ws.finalize(V)
    return FCMResult(
        centers=V, u=u, objective=objective, n_iter=it, converged=converged, m=ws.m,
        objective_history=np.array(history),
    )


# --------------------------------------------------------------------------- validity


def _check_u(u: object) -> np.ndarray:
    ua = _real(u, "u")
    if ua.ndim != 2 or ua.shape[1] < 2 or ua.shape[0] < 1:
        raise ValueError(f"u must be a 2-D (n, c) membership array with c >= 2, got shape "
                         f"{ua.shape}")
    if not np.all(np.isfinite(ua)) or ua.min() < 0.0 or ua.max() > 1.0 + 1e-9:
        raise ValueError("u must hold finite memberships in [0, 1]")
    rs = ua.sum(axis=1)
    if not np.allclose(rs, 1.0, rtol=0, atol=1e-6):
        j = int(np.argmax(np.abs(rs - 1.0)))
        raise ValueError(f"u rows must sum to 1 (a fuzzy c-partition), row {j} sums to {rs[j]}")
    return ua


@_ignore_underflow
def partition_measures(
    u: np.ndarray, *, rf_count: Literal["points", "entries"] = "points"
) -> dict[str, float]:
    """The validity measures that depend on the memberships only (all but ``objective``).

    See :func:`validity` for the formulas and conventions.

    Parameters
    ----------
    u : array_like, shape (n, c)
        Fuzzy c-partition: entries in [0, 1], rows summing to 1, ``c >= 2``.
    rf_count : {"points", "entries"}
        How :math:`R_f` counts members (see :func:`validity`).

    Returns
    -------
    dict
        Keys ``pc pe nfi min_ht mean_ht min_card rf``.
    """
    ua = _check_u(u)
    if rf_count not in ("points", "entries"):
        raise ValueError(f"rf_count must be 'points' or 'entries', got {rf_count!r}")
    n, c = ua.shape
    pc = float(np.sum(ua * ua) / n)
    from scipy.special import xlogy  # here: importing scipy.special costs ~0.15 s per process

    pe = float(-np.sum(xlogy(ua, ua)) / n)
    nfi = (c * pc - 1.0) / (c - 1.0)
    # two strongest memberships of each point
    part = np.partition(ua, c - 2, axis=1)
    top2, top1 = part[:, c - 2], part[:, c - 1]
    labels = np.argmax(ua, axis=1)
    card = np.bincount(labels, minlength=c)
    r = top2 / top1  # top1 >= 1/c > 0
    rsum = np.bincount(labels, weights=r, minlength=c)
    T = np.ones(c)  # empty cluster: T_s = 1, the fuzziest value (hard tendency 0)
    nz = card > 0
    T[nz] = rsum[nz] / card[nz]
    with np.errstate(divide="ignore"):
        ht = -np.log10(T)  # +inf where T_s == 0 (every member crisp)
    ht = np.where(ht == 0.0, 0.0, ht)  # no -0.0
    threshold = (1.0 + c) / (2.0 * c)
    nonfuzzy = int(np.count_nonzero(top1 >= threshold))
    fuzzy = (n if rf_count == "points" else n * c) - nonfuzzy
    rf = fuzzy / nonfuzzy if nonfuzzy else math.inf
    return {
        "pc": pc,
        "pe": pe,
        "nfi": float(nfi),
        "min_ht": float(ht.min()),
        "mean_ht": float(ht.mean()),
        "min_card": float(card.min()),
        "rf": float(rf),
    }


@_ignore_underflow
def validity(
    X: np.ndarray, result: FCMResult, *, rf_count: Literal["points", "entries"] = "points"
) -> dict[str, float]:
    """Cluster validity measures of thesis 4.4 (Eqs. 4.1-4.9) and the objective (Eq. 3.1).

    With ``u`` the (n, c) memberships of ``result`` and ``lbl_i = argmax_s u_is``
    (ties -> lowest index):

    ``pc`` (maximise), Eq. 4.1
        ``sum_is u_is**2 / n``; 1 for a hard partition, ``1/c`` for the uniform one.
    ``pe`` (minimise), Eq. 4.2
        ``-sum_is u_is ln u_is / n`` with natural log and ``0 ln 0 = 0``;
        0 (hard) ... ``ln c`` (uniform).
    ``nfi`` (maximise), Eq. 4.3
        ``(c * sum_is u_is**2 - n) / (n (c - 1)) = (c pc - 1)/(c - 1)``; 1 (hard) ... 0.
    ``min_ht``, ``mean_ht`` (maximise), Eqs. 4.4-4.7
        For each point ``r_i = u_(2)i / u_(1)i``, its *second* strongest
        membership over its strongest (0 for a crisp point, 1 for a tie; the
        printed Eq. 4.7 is ambiguous, this is the reading that matches the
        text). ``T_s`` is the mean of ``r_i`` over the points whose strongest
        cluster is ``s`` (``Y_s``, Eq. 4.6); an empty cluster gets ``T_s = 1``
        (the fuzziest value). ``HT_s = -log10 T_s`` (>= 0, ``+inf`` if all of
        ``Y_s`` is crisp). ``min_ht = min_s HT_s``: the printed Eq. 4.4 says
        ``max`` but the text defines MinHT as "the least favourable hard
        tendency", i.e. the minimum over clusters, which is what is computed.
        ``mean_ht = mean_s HT_s`` (Eq. 4.5 writes ``log`` without a base; base 10
        is used for both so that ``min_ht <= mean_ht``).
    ``min_card`` (must be > 0), Eq. 4.8
        ``min_s #{i : lbl_i = s}``: the smallest number of points whose strongest
        membership is cluster ``s``; 0 means an empty cluster.
    ``rf`` (minimise), Eq. 4.9
        ``#fuzzy / #non-fuzzy`` members with threshold ``(1 + c)/(2c)``. A point
        is a non-fuzzy member if its strongest membership is >= the threshold
        (at most one membership per point can be, since the threshold is > 1/2),
        otherwise fuzzy; 0 for a hard partition, ``inf`` if no point is
        non-fuzzy. ``rf_count="entries"`` instead counts every ``u_is`` below
        the threshold as a fuzzy member (the literal "for all u_ij" reading):
        ``rf_entries = c (rf_points + 1) - 1``, the same ranking for a fixed c.
    ``objective`` (minimise), Eq. 3.1
        ``J_m = sum_is u_is**m |x_i - v_s|**2``, in units of ``X`` squared.

    Parameters
    ----------
    X : array_like, shape (n, d)
        The clustered samples.
    result : FCMResult
        Output of :func:`fcm` (or any object with ``u (n, c)``, ``centers (c, d)``, ``m``).
    rf_count : {"points", "entries"}, default "points"
        Counting convention of ``rf``.

    Returns
    -------
    dict[str, float]
        Keys exactly ``pc pe nfi min_ht mean_ht min_card rf objective``
        (see :data:`MEASURE_DIRECTIONS`).
    """
    Xa = _check_X(X)
    if not all(hasattr(result, a) for a in ("u", "centers", "m")):
        raise TypeError(f"result must be an FCMResult (or have u, centers and m), got "
                        f"{type(result).__name__}")
    u = _real(result.u, "result.u")
    V = _real(result.centers, "result.centers")
    if u.ndim != 2 or u.shape[0] != Xa.shape[0]:
        raise ValueError(f"result.u must have shape (n_samples = {Xa.shape[0]}, c), "
                         f"got {u.shape}")
    V = _check_centers(V, u.shape[1], Xa.shape[1], "result.centers")
    mf = _check_m(result.m)
    out = partition_measures(u, rf_count=rf_count)
    diff2 = np.maximum(
        np.einsum("ij,ij->i", Xa, Xa)[:, None] - 2.0 * Xa @ V.T
        + np.einsum("ij,ij->i", V, V)[None, :], 0.0)
    out["objective"] = float(np.sum(np.power(u, mf) * diff2))
    return out
