"""Compiled kernels of the control loop: ray casting and the robot's swept disc.

Each kernel is the scalar-loop twin of numpy code kept in
:mod:`sitframe.geometry` and :mod:`sitframe.robot` (the reference, and the
path taken when numba is missing or ``SITFRAME_NUMBA=0``). A kernel performs
the *same* IEEE operations in the same order as its numpy twin -- products,
sums, quotients, comparisons, ``min``/``max``, and ``cos``/``sin`` from the C
library -- so its results are bit-identical (``tests/test_kernels.py`` checks
it). That rules out ``fastmath`` (which would reorder and fuse operations),
and it is why the trigonometry of the ray directions stays in numpy.

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

__all__ = ["cast", "cast_each", "sweep_disc"]

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
def _pose(t: float, x0: float, y0: float, th0: float, v: float, omega: float, t_turn: float,
          cos_end: float, sin_end: float) -> tuple[float, float, float]:  # pragma: no cover
    """One sample of :func:`sitframe.robot._poses_at`, the same operations."""
    tt = t if t < t_turn else t_turn
    half = (0.5 * omega) * tt
    y = math.pi * (half * _INV_PI)  # numpy.sinc(half / pi)
    if y == 0.0:
        y = _SINC_EPS
    chord = (v * tt) * (math.sin(y) / y)
    ang = th0 + half
    ts = v * (t - tt)
    return (x0 + chord * math.cos(ang) + ts * cos_end,
            y0 + chord * math.sin(ang) + ts * sin_end,
            th0 + omega * tt)


@njit(**_JIT)
def _dist2(px: float, py: float, seg: np.ndarray, j: int) -> float:  # pragma: no cover
    """Squared distance of a point to segment ``j`` (twin of ``geometry._dist2``)."""
    wx = px - seg[0, j]
    wy = py - seg[1, j]
    t = (wx * seg[2, j] + wy * seg[3, j]) * seg[4, j]
    if t < 0.0:
        t = 0.0
    elif t > 1.0:
        t = 1.0
    dx = wx - t * seg[2, j]
    dy = wy - t * seg[3, j]
    return dx * dx + dy * dy


@njit(**_JIT)
def sweep_disc(plan: np.ndarray, times: np.ndarray, seg: np.ndarray, near: np.ndarray,
               out: np.ndarray) -> tuple[int, int]:  # pragma: no cover - compiled
    """The swept-disc test of :func:`sitframe.robot.step_robot` (steps 1 and 2).

    Parameters
    ----------
    plan
        ``x0, y0, th0, v, omega, t_turn, cos(th_end), sin(th_end), reach², r²``.
    times
        (n,) substep times [s].
    seg
        Packed ``(5, S)`` segment set.
    near
        (S,) int scratch: receives the indices of the segments within reach.
    out
        (3,) receives the pose at ``times[-1]`` when no substep collides.

    Returns
    -------
    (k, n_near)
        ``n_near`` segments within reach (their indices in ``near[:n_near]``);
        ``k`` the first substep whose disc touches one of them, -1 if none.
    """
    x0, y0, th0, v, omega, t_turn = plan[0], plan[1], plan[2], plan[3], plan[4], plan[5]
    cos_end, sin_end, reach2, r2 = plan[6], plan[7], plan[8], plan[9]
    m = 0
    for j in range(seg.shape[1]):
        if _dist2(x0, y0, seg, j) < reach2:
            near[m] = j
            m += 1
    if m == 0:
        return -1, 0
    x = y = th = 0.0
    for k in range(times.size):
        x, y, th = _pose(times[k], x0, y0, th0, v, omega, t_turn, cos_end, sin_end)
        for i in range(m):
            if _dist2(x, y, seg, near[i]) < r2:
                return k, m
    out[0], out[1], out[2] = x, y, th
    return -1, m
