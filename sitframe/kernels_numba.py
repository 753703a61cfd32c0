"""Compiled kernels of the control loop (loaded through :func:`sitframe.kernels.kernels`).

Each kernel is the scalar-loop twin of numpy code kept in
:mod:`sitframe.geometry`, :mod:`sitframe.robot`, :mod:`sitframe.fcm` and
:mod:`sitframe.fuzzy` (the reference, and the path taken when numba is
missing or ``SITFRAME_NUMBA=0``). A kernel performs
the *same* IEEE operations in the same order as its numpy twin -- products,
sums, quotients, comparisons, ``min``/``max`` -- so its results are
bit-identical (``tests/test_kernels.py`` checks it). That rules out
``fastmath`` (which would reorder and fuse operations); a sum follows numpy's
pairwise summation (:func:`_pairwise_sum`). It is also why every ``sin``,
``cos``, ``log`` and power stays in numpy, between kernels: numpy takes them
from the C library on some CPUs and from its own vector library (SVML) on
others (AVX-512), and the two differ in the last bit; a kernel calling the C
library would then change results on those CPUs. Dot products stay in numpy
too (BLAS).

Why compiled: one sonar read is 40 rays against 40 wall edges and one robot
step 31 substeps against the edges within reach; in numpy each costs some
25 small-array calls (about 1 µs of overhead each), in a kernel one call.
Kernels are compiled on first use and cached on disk (``cache=True``), so only
the first run after an install pays the compilation.

Segment sets are passed as one ``(5, S)`` array :attr:`SegmentSet.packed
<sitframe.geometry.SegmentSet>`: rows ``ax, ay, ex, ey, inv_len2``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["arc_angles", "arc_poses", "backoff", "cast", "cast_each", "fcm_ratios",
           "first_contact", "label_strengths", "linspace", "near_segments", "nearest_point",
           "normalize", "ranges"]

_EPS = 1e-12  # the hit tolerance of sitframe.geometry._raycast
_INV_PI = 1.0 / math.pi
_SINC_EPS = float(np.finfo(np.float64).eps)  # numpy.sinc's stand-in for 0

_JIT = {"cache": True, "nogil": True, "error_model": "numpy", "fastmath": False}


@njit(**_JIT)
def _ray(ox: float, oy: float, ddx: float, ddy: float, seg: np.ndarray,
         max_range: float) -> float:  # pragma: no cover - compiled
    """Distance along one ray to the first segment (``max_range`` if none)."""
    ax, ay, ex, ey = seg[0], seg[1], seg[2], seg[3]
    best = max_range
    for j in range(ax.size):
        wx = ax[j] - ox
        wy = ay[j] - oy
        denom = ddx * ey[j] - ddy * ex[j]
        u_num = wx * ddy - wy * ddx
        if denom != 0.0:
            t = (wx * ey[j] - wy * ex[j]) / denom
            u = u_num / denom
            if t >= -_EPS and u >= -_EPS and u <= 1.0 + _EPS:
                d = t if t > 0.0 else 0.0
                if d < best:
                    best = d
        elif u_num == 0.0:  # collinear: the nearest end ahead, 0 when on it
            ta = wx * ddx + wy * ddy
            tb = ta + ex[j] * ddx + ey[j] * ddy
            # (numpy's max/min propagate NaN: a NaN end never hits)
            if (ta >= 0.0 or tb >= 0.0) and ta == ta and tb == tb:
                near = ta if ta < tb else tb
                d = near if near > 0.0 else 0.0
                if d < best:
                    best = d
    return best


@njit(**_JIT)
def cast(x: float, y: float, dx: np.ndarray, dy: np.ndarray, seg: np.ndarray,
         max_range: float, out: np.ndarray) -> None:  # pragma: no cover - compiled
    """Rays from one origin ``(x, y)`` (twin of :func:`sitframe.geometry._raycast`).

    ``dx, dy`` are the (n,) unit directions, ``seg`` a packed ``(5, S)``
    segment set; the (n,) distances go to ``out``.
    """
    for i in range(dx.size):
        out[i] = _ray(x, y, dx[i], dy[i], seg, max_range)


@njit(**_JIT)
def cast_each(px: np.ndarray, py: np.ndarray, dx: np.ndarray, dy: np.ndarray, seg: np.ndarray,
              max_range: float, out: np.ndarray) -> None:  # pragma: no cover - compiled
    """As :func:`cast`, with one origin ``(px[i], py[i])`` per ray."""
    for i in range(dx.size):
        out[i] = _ray(px[i], py[i], dx[i], dy[i], seg, max_range)


@njit(**_JIT)
def ranges(x: float, y: float, dx: np.ndarray, dy: np.ndarray, seg: np.ndarray, max_range: float,
           radius: float, group: int, clip: bool,
           out: np.ndarray) -> None:  # pragma: no cover - compiled
    """Range-finder readings (twin of :func:`sitframe.geometry.rim_ranges`) into ``out``.

    Rays of ``max_range + radius`` from ``(x, y)``; ``out[g]`` is the nearest hit of
    rays ``g * group ... (g + 1) * group - 1`` less ``radius``, or ``max_range``;
    with ``clip`` then clipped to ``[0, max_range]``.
    """
    reach = max_range + radius
    for g in range(out.size):
        best = reach
        for i in range(g * group, (g + 1) * group):
            d = _ray(x, y, dx[i], dy[i], seg, reach)
            if d < best:
                best = d
        v = max_range if best >= reach else best - radius
        if clip:  # numpy.clip's _NPY_MIN(_NPY_MAX(v, 0), max_range), NaN propagating
            v = v if (v > 0.0 or v != v) else 0.0
            v = v if (v < max_range or v != v) else max_range
        out[g] = v


@njit(**_JIT)
def _foot(px: float, py: float, seg: np.ndarray,
          j: int) -> tuple[float, float, float]:  # pragma: no cover
    """Segment ``j``'s parameter ``t`` of the point's foot (clamped to [0, 1]) and the offset
    ``(dx, dy)`` from that foot to the point (twin of ``geometry._dist2``'s steps)."""
    wx = px - seg[0, j]
    wy = py - seg[1, j]
    t = (wx * seg[2, j] + wy * seg[3, j]) * seg[4, j]
    if t < 0.0:
        t = 0.0
    elif t > 1.0:
        t = 1.0
    return t, wx - t * seg[2, j], wy - t * seg[3, j]


@njit(**_JIT)
def _dist2(px: float, py: float, seg: np.ndarray, j: int) -> float:  # pragma: no cover
    """Squared distance of a point to segment ``j`` (twin of ``geometry._dist2``)."""
    _t, dx, dy = _foot(px, py, seg, j)
    return dx * dx + dy * dy


@njit(**_JIT)
def near_segments(x: float, y: float, seg: np.ndarray, reach2: float,
                  idx: np.ndarray) -> int:  # pragma: no cover - compiled
    """Indices (into ``idx``) of the segments closer than ``sqrt(reach2)``; returns their count."""
    m = 0
    for j in range(seg.shape[1]):
        if _dist2(x, y, seg, j) < reach2:
            idx[m] = j
            m += 1
    return m


@njit(**_JIT)
def first_contact(xs: np.ndarray, ys: np.ndarray, seg: np.ndarray,
                  r2: float) -> int:  # pragma: no cover - compiled
    """The first point ``(xs[k], ys[k])`` closer than ``sqrt(r2)`` to a segment; -1 if none."""
    for k in range(xs.size):
        for j in range(seg.shape[1]):
            if _dist2(xs[k], ys[k], seg, j) < r2:
                return k
    return -1


@njit(**_JIT)
def nearest_point(x: float, y: float, seg: np.ndarray) -> tuple[float, float]:  # pragma: no cover
    """The point nearest ``(x, y)`` on the segments (twin of ``geometry.nearest_on_segments``)."""
    best, bx, by = np.inf, np.nan, np.nan
    for j in range(seg.shape[1]):
        t, dx, dy = _foot(x, y, seg, j)
        d2 = dx * dx + dy * dy
        if d2 < best or j == 0:  # (argmin: the first of equal minima)
            best, bx, by = d2, seg[0, j] + t * seg[2, j], seg[1, j] + t * seg[3, j]
    return bx, by


@njit(**_JIT)
def linspace(start: float, stop: float, out: np.ndarray) -> None:  # pragma: no cover - compiled
    """``numpy.linspace(start, stop, out.size)`` into ``out``, the same operations."""
    num = out.size
    div = num - 1
    delta = stop - start
    step = delta / div if div > 0 else np.nan
    for i in range(num):
        if div <= 0:
            v = i * delta
        elif step == 0.0:
            v = (i / div) * delta
        else:
            v = i * step
        out[i] = v + start
    if num > 1:
        out[num - 1] = stop


@njit(**_JIT)
def arc_angles(t: np.ndarray, th0: float, omega: float, t_turn: float, sinc_arg: np.ndarray,
               ang: np.ndarray) -> None:  # pragma: no cover - compiled
    """First half of ``robot._poses_at``: the arguments of its ``sinc`` and ``cos``/``sin``."""
    for i in range(t.size):
        tt = t[i] if t[i] < t_turn else t_turn
        half = (0.5 * omega) * tt
        y = math.pi * (half * _INV_PI)  # numpy.sinc(half / pi) = sin(y) / y
        sinc_arg[i] = _SINC_EPS if y == 0.0 else y
        ang[i] = th0 + half


@njit(**_JIT)
def arc_poses(t: np.ndarray, plan: np.ndarray, sinc_arg: np.ndarray, sin_sinc: np.ndarray,
              cos_ang: np.ndarray, sin_ang: np.ndarray,
              out: np.ndarray) -> None:  # pragma: no cover - compiled
    """Second half of ``robot._poses_at``: poses (3, n) from the sines and cosines.

    ``plan`` is ``x0, y0, th0, v, omega, t_turn, cos(th_end), sin(th_end)``.
    """
    x0, y0, th0, v, omega, t_turn, cos_end, sin_end = plan
    for i in range(t.size):
        tt = t[i] if t[i] < t_turn else t_turn
        chord = (v * tt) * (sin_sinc[i] / sinc_arg[i])
        ts = v * (t[i] - tt)
        out[0, i] = x0 + chord * cos_ang[i] + ts * cos_end
        out[1, i] = y0 + chord * sin_ang[i] + ts * sin_end
        out[2, i] = th0 + omega * tt


@njit(**_JIT)
def backoff(cx: float, cy: float, nx: float, ny: float, length: float, seg: np.ndarray,
            r2: float, inside: bool, s: np.ndarray) -> tuple[int, float, float]:  # pragma: no cover
    """The back-off of ``robot.step_robot`` (step 4) along ``(nx, ny)``, ``s.size`` samples.

    Returns ``(m, x, y)``: the last sample ``m`` of the free prefix and its point.
    """
    linspace(0.0, length, s)
    m = -1
    x = y = 0.0
    floor = 0.0
    for i in range(s.size):
        bx = cx + s[i] * nx
        by = cy + s[i] * ny
        d2 = np.inf
        for j in range(seg.shape[1]):
            d = _dist2(bx, by, seg, j)
            if d < d2:
                d2 = d
        if i == 0:
            floor = (d2 if d2 < r2 else r2) - 1e-15
        if not (d2 >= (floor if inside else r2)):
            break
        m, x, y = i, bx, by
    return m, x, y


#: Longest array :func:`_pairwise_sum` sums (numpy's block; longer ones it splits
#: recursively, which the callers leave to numpy).
PAIRWISE_MAX = 128


@njit(**_JIT)
def _pairwise_sum(a: np.ndarray, n: int) -> float:  # pragma: no cover - compiled
    """``a[:n].sum()`` in numpy's order (``pairwise_sum`` of ``add.reduce``), n <= 128."""
    if n < 8:
        res = -0.0
        for i in range(n):
            res += a[i]
        return res
    r0, r1, r2, r3, r4, r5, r6, r7 = a[0], a[1], a[2], a[3], a[4], a[5], a[6], a[7]
    i = 8
    while i < n - n % 8:
        r0 += a[i]
        r1 += a[i + 1]
        r2 += a[i + 2]
        r3 += a[i + 3]
        r4 += a[i + 4]
        r5 += a[i + 5]
        r6 += a[i + 6]
        r7 += a[i + 7]
        i += 8
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        res += a[i]
        i += 1
    return res


@njit(**_JIT)
def fcm_ratios(d2: np.ndarray, floor: float, out: np.ndarray) -> float:  # pragma: no cover
    """``out = maximum(d2.min() / d2, floor)``; returns ``d2.min()`` (NaN propagates)."""
    dmin = d2[0]
    for i in range(1, d2.size):
        v = d2[i]
        if v < dmin or v != v:
            if dmin == dmin:
                dmin = v
    for i in range(d2.size):
        r = dmin / d2[i]
        out[i] = r if (r >= floor or r != r) else floor
    return dmin


@njit(**_JIT)
def normalize(w: np.ndarray) -> None:  # pragma: no cover - compiled
    """``w /= w.sum()`` in place (``w.size <= PAIRWISE_MAX``)."""
    total = _pairwise_sum(w, w.size)
    for i in range(w.size):
        w[i] /= total


@njit(**_JIT)
def label_strengths(onehot: np.ndarray, u: np.ndarray,
                    out: np.ndarray) -> float:  # pragma: no cover - compiled
    """``out = (onehot * u[:, None]).max(axis=0)`` (c, A) -> (A,); returns ``out.sum()``.

    ``A <= PAIRWISE_MAX``.
    """
    c, n = onehot.shape
    for a in range(n):
        best = onehot[0, a] * u[0]
        for i in range(1, c):
            v = onehot[i, a] * u[i]
            if (v > best or v != v) and best == best:
                best = v
        out[a] = best
    return _pairwise_sum(out, n)


def _warm() -> None:
    """Load (or, the first time, compile) every kernel now, with the types the loop uses.

    Run at import, so a process importing this module -- a worker pool's
    forkserver preloads it -- has them all, and its forked workers inherit them.
    """
    seg = np.array([[0.0], [1.0], [1.0], [0.0], [1.0]])  # one segment (0, 1)-(1, 1)
    one = np.ones(2)
    out, idx = np.empty(2), np.empty(1, dtype=np.intp)
    cast(0.0, 0.0, one, one, seg, 3.0, out)
    cast_each(one, one, one, one, seg, 3.0, out)
    ranges(0.0, 0.0, one, one, seg, 3.0, 0.1, 1, True, out)
    near_segments(0.0, 0.0, seg, 1.0, idx)
    first_contact(one, one, seg, 0.01)
    nearest_point(0.0, 0.0, seg)
    linspace(0.0, 1.0, out)
    arc_angles(one, 0.0, 1.0, 0.5, out, np.empty(2))
    arc_poses(one, np.ones(8), one, one, one, one, np.empty((3, 2)))
    backoff(0.0, 0.0, 1.0, 0.0, 0.05, seg, 0.01, False, np.empty(3))
    fcm_ratios(one, 1e-9, out)
    normalize(out)
    label_strengths(np.ones((2, 2)), one, out)


_warm()
