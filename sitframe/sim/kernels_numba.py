"""Compiled kernels of the control loop (loaded through :func:`sitframe.sim.kernels.kernels`).

Each kernel is the scalar-loop twin of numpy code kept in
:mod:`sitframe.sim.geometry`, :mod:`sitframe.sim.robot`, :mod:`sitframe.situations.fcm` and
:mod:`sitframe.learning.fcs` (the reference, and the path taken when numba is
missing or ``SITFRAME_NUMBA=0``). A kernel performs
the *same* IEEE operations in the same order as its numpy twin -- products,
sums, quotients, comparisons, ``min``/``max`` -- so its results are
bit-identical (``tests/test_kernels.py`` checks it). That rules out
``fastmath`` (which would reorder and fuse operations); a sum follows numpy's
pairwise summation (:func:`_pairwise_sum`). It is also why every ``log``, ``exp``
and power stays in numpy, between kernels: numpy takes them from its own vector
library (SVML) on AVX-512 CPUs, which differs from the C library in the last bit; a
kernel calling the C library would then change results on those CPUs. Dot products
stay in numpy too (BLAS). Sines and cosines are the exception: numpy computes
float64 ``sin`` and ``cos`` with the C library, so :func:`step_free` and
:func:`ranges_at` (the robot's step and a sensor's read fused into one call each)
compute them here, and are used only where a check at load time finds them equal to
numpy's (:func:`sitframe.sim.kernels.fused`).

Why compiled: one sonar read is 40 rays against 40 wall edges and one robot
step 31 substeps against the edges within reach; in numpy each costs some
25 small-array calls (about 1 µs of overhead each), in a kernel one call.
Kernels are compiled on first use and cached on disk in the user's cache folder
(:mod:`sitframe.sim.numba_cache`; never inside the installed package), so only the first run
after an install pays the compilation.

Why one module of this size: the kernels call each other (the sonar's, the robot's and the
fleet's share their ray and distance helpers) and are loaded, and cached by numba, together
(:func:`sitframe.sim.kernels.load`); split, every part would import the others.

Segment sets are passed as one ``(5, S)`` array :attr:`SegmentSet.packed
<sitframe.sim.geometry.SegmentSet>`: rows ``ax, ay, ex, ey, inv_len2``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numba.core import config as numba_config

__all__ = ["arc_angles", "arc_poses", "backoff", "backoffs", "cast", "cast_each", "clear_from",
           "clear_moves", "contact_points", "fcm_ratios", "first_contact", "label_strengths",
           "linspace", "near_segments", "nearest_point", "normalize", "observe",
           "point_in_polygon", "ranges", "ranges_at", "ranges_many", "refine", "step_free",
           "sweep_begin", "sweep_end", "trig"]

_EPS = 1e-12  # the hit tolerance of sitframe.sim.geometry._raycast
_INV_PI = 1.0 / math.pi
_SINC_EPS = float(np.finfo(np.float64).eps)  # numpy.sinc's stand-in for 0
_TINY = float(np.finfo(np.float64).tiny)  # SegmentSet: shorter segments are points

#: ``cache``: only where :mod:`sitframe.sim.numba_cache` pointed numba at a writable folder of
#: the user's (it sets ``CACHE_DIR`` when imported, before this module; with none, numba would
#: cache beside this file, inside the installed package, so nothing is cached).
_JIT = {"cache": bool(numba_config.CACHE_DIR), "nogil": True, "error_model": "numpy",
        "fastmath": False}


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
        elif -_EPS <= u_num <= _EPS:  # collinear: the nearest end ahead, 0 when on it
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
    """Rays from one origin ``(x, y)`` (twin of :func:`sitframe.sim.geometry._raycast`).

    ``dx, dy`` are the (n,) unit directions, ``seg`` a packed ``(5, S)``
    segment set; the (n,) distances go to ``out`` (all rays together, :func:`_nearest_hits`).
    """
    out[:] = max_range
    if _nearest_hits(x, y, dx, dy, seg, out):
        _parallel_hits(x, y, dx, dy, seg, out)


@njit(**_JIT)
def cast_each(px: np.ndarray, py: np.ndarray, dx: np.ndarray, dy: np.ndarray, seg: np.ndarray,
              max_range: float, out: np.ndarray) -> None:  # pragma: no cover - compiled
    """As :func:`cast`, with one origin ``(px[i], py[i])`` per ray."""
    for i in range(dx.size):
        out[i] = _ray(px[i], py[i], dx[i], dy[i], seg, max_range)


@njit(**_JIT)
def _parallel_hits(x: float, y: float, dx: np.ndarray, dy: np.ndarray, seg: np.ndarray,
                   best: np.ndarray) -> None:  # pragma: no cover - compiled
    """The hits of the rays parallel to a segment (:func:`_ray`'s ``denom == 0`` branch)
    folded into ``best`` (the rare case :func:`_nearest_hits` leaves out)."""
    for j in range(seg.shape[1]):
        wx = seg[0, j] - x
        wy = seg[1, j] - y
        ex, ey = seg[2, j], seg[3, j]
        for i in range(dx.size):
            if dx[i] * ey - dy[i] * ex != 0.0:
                continue
            u_num = wx * dy[i] - wy * dx[i]
            if -_EPS <= u_num <= _EPS:  # collinear: the nearest end ahead, 0 when on it
                ta = wx * dx[i] + wy * dy[i]
                tb = ta + ex * dx[i] + ey * dy[i]
                if (ta >= 0.0 or tb >= 0.0) and ta == ta and tb == tb:
                    near = ta if ta < tb else tb
                    d = near if near > 0.0 else 0.0
                    if d < best[i]:
                        best[i] = d


@njit(**_JIT)
def _nearest_hits(x: float, y: float, dx: np.ndarray, dy: np.ndarray, seg: np.ndarray,
                  best: np.ndarray) -> bool:  # pragma: no cover - compiled
    """:func:`_ray` for all rays from ``(x, y)`` at once, into ``best`` (each ray's limit on
    entry, its nearest hit on return); returns whether some ray is parallel to a segment.

    Segment by segment over all rays, without branches (so the compiler can use vector
    instructions): each quantity is :func:`_ray`'s, from the same operations on the same
    values, and a ray keeps the smallest of its hits, which does not depend on the order
    the hits come in. The parallel case is left to :func:`_parallel_hits`.
    """
    flat = False
    for j in range(seg.shape[1]):
        wx = seg[0, j] - x
        wy = seg[1, j] - y
        ex, ey = seg[2, j], seg[3, j]
        t_num = wx * ey - wy * ex
        for i in range(dx.size):
            denom = dx[i] * ey - dy[i] * ex
            t = t_num / denom
            u = (wx * dy[i] - wy * dx[i]) / denom
            d = t if t > 0.0 else 0.0
            hit = (denom != 0.0) & (t >= -_EPS) & (u >= -_EPS) & (u <= 1.0 + _EPS) \
                & (d < best[i])
            best[i] = d if hit else best[i]
            flat |= denom == 0.0
    return flat


@njit(**_JIT)
def ranges(x: float, y: float, dx: np.ndarray, dy: np.ndarray, seg: np.ndarray, max_range: float,
           radius: float, group: int, clip: bool,
           out: np.ndarray) -> None:  # pragma: no cover - compiled
    """Range-finder readings (twin of :func:`sitframe.sim.geometry.rim_ranges`) into ``out``.

    Rays of ``max_range + radius`` from ``(x, y)``; ``out[g]`` is the nearest hit of
    rays ``g * group ... (g + 1) * group - 1`` less ``radius``, or ``max_range``;
    with ``clip`` then clipped to ``[0, max_range]``. All rays are cast together
    (:func:`_nearest_hits`; each ray's distance is :func:`_ray`'s), against the segments
    within :data:`CULL` times their reach: a segment farther away is hit, if at all, beyond
    the reach, which is ignored (the nearest hit is a minimum, in any order). Rounding could
    only bring such a hit inside the reach for a ray within some 1e-13 rad of a segment
    whose line passes within some 1e-13 m of the centre. In a room a reading meets some
    quarter of the edges, and the cull costs one distance per edge.
    """
    reach = max_range + radius
    cull2 = (CULL * reach) * (CULL * reach)
    idx = np.empty(seg.shape[1], dtype=np.intp)
    near = _gather(seg, idx, near_segments(x, y, seg, cull2, idx))
    hits = np.full(dx.size, reach)
    if _nearest_hits(x, y, dx, dy, near, hits):
        _parallel_hits(x, y, dx, dy, near, hits)
    for g in range(out.size):
        best = reach
        for i in range(g * group, (g + 1) * group):
            if hits[i] < best:
                best = hits[i]
        v = max_range if best >= reach else best - radius
        if clip:  # numpy.clip's _NPY_MIN(_NPY_MAX(v, 0), max_range), NaN propagating
            v = v if (v > 0.0 or v != v) else 0.0
            v = v if (v < max_range or v != v) else max_range
        out[g] = v


@njit(**_JIT)
def ranges_at(x: float, y: float, heading: float, rel: np.ndarray, seg: np.ndarray,
              max_range: float, radius: float, group: int, clip: bool,
              out: np.ndarray) -> None:  # pragma: no cover - compiled
    """:func:`ranges` of rays at ``rel + heading`` [rad], their sines and cosines the C
    library's (used where those are numpy's: :func:`sitframe.sim.kernels.fused`)."""
    dx, dy = np.empty(rel.size), np.empty(rel.size)
    for i in range(rel.size):
        a = rel[i] + heading
        dx[i] = math.cos(a)
        dy[i] = math.sin(a)
    ranges(x, y, dx, dy, seg, max_range, radius, group, clip, out)


#: :func:`ranges` leaves out the segments farther than this many times the rays' reach.
CULL = 1.01


@njit(**_JIT)
def ranges_many(xy: np.ndarray, dx: np.ndarray, dy: np.ndarray, seg: np.ndarray,
                max_range: float, radius: float, group: int, clip: bool,
                out: np.ndarray) -> None:  # pragma: no cover - compiled
    """:func:`ranges` for N disc centres ``xy`` (N, 2) with their own (N, rays) directions
    ``dx, dy``: row ``i`` of ``out`` (N, readings) is ``ranges`` of row ``i``."""
    for i in range(out.shape[0]):
        ranges(xy[i, 0], xy[i, 1], dx[i], dy[i], seg, max_range, radius, group, clip, out[i])


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
    return _near(x, y, seg, reach2, idx)[0]


@njit(**_JIT, inline="always")
def _near(x: float, y: float, seg: np.ndarray, reach2: float,
          idx: np.ndarray) -> tuple[int, float]:  # pragma: no cover - compiled
    """:func:`near_segments`' count, and the nearest one's squared distance (``inf``: none)."""
    m, near2 = 0, np.inf
    for j in range(seg.shape[1]):
        d2 = _dist2(x, y, seg, j)
        if d2 < reach2:
            idx[m] = j
            m += 1
            near2 = d2 if d2 < near2 else near2
    return m, near2


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


@njit(**_JIT, inline="always")
def _arc(t: float, x0: float, y0: float, th0: float, v: float, omega: float, t_turn: float,
         cos_end: float, sin_end: float) -> tuple[float, float, float]:  # pragma: no cover
    """``robot._poses_at`` at one time ``t`` [s]: the arc's chord (numpy's ``sinc``) then the
    straight run, sines and cosines the C library's; ``cos_end``, ``sin_end`` are those of
    the heading at the turn's end."""
    tt = t if t < t_turn else t_turn
    half = (0.5 * omega) * tt
    y = math.pi * (half * _INV_PI)
    sarg = _SINC_EPS if y == 0.0 else y
    chord = (v * tt) * (math.sin(sarg) / sarg)
    ts = v * (t - tt)
    ang = th0 + half
    return (x0 + chord * math.cos(ang) + ts * cos_end, y0 + chord * math.sin(ang) + ts * sin_end,
            th0 + omega * tt)


@njit(**_JIT)
def step_free(x0: float, y0: float, th0: float, v: float, omega: float, t_turn: float,
              times: np.ndarray, seg: np.ndarray, reach2: float, r2: float,
              out: np.ndarray) -> bool:  # pragma: no cover - compiled
    """One robot step that touches nothing, in one call: ``out`` (3,) the end pose (x, y,
    unwrapped theta) and ``False``; ``True`` (``out`` undefined) when the disc touches an edge
    on the way, which :func:`sitframe.sim.robot.step_robot` then handles itself.

    The steps of ``step_robot`` up to its contact test, operation by operation: the edges
    within ``sqrt(reach2)`` (:func:`near_segments`); none: the closed form at the period's end
    (``robot._pose_at``); else the poses at ``times`` (``robot._poses_at``: :func:`arc_angles`,
    the sines and cosines, :func:`arc_poses`), each tested against those edges
    (:func:`first_contact`). Its sines and cosines are the C library's, so it is used only
    where they are numpy's too (:func:`sitframe.sim.kernels.fused`).
    """
    idx = np.empty(seg.shape[1], dtype=np.intp)
    m, near2 = _near(x0, y0, seg, reach2, idx)
    th_end = th0 + omega * t_turn
    if m == 0:  # robot._pose_at(T, ...), T the period (the last of ``times``)
        t = times[times.size - 1]
        tt = t_turn if t_turn < t else t
        half = 0.5 * omega * tt
        chord = v * tt * (math.sin(half) / half if half != 0.0 else 1.0)
        ts = v * (t - tt)
        out[0] = x0 + chord * math.cos(th0 + half) + ts * math.cos(th_end)
        out[1] = y0 + chord * math.sin(th0 + half) + ts * math.sin(th_end)
        out[2] = th0 + omega * tt
        return False
    cos_end, sin_end = math.cos(th_end), math.sin(th_end)
    # A pose at time t is within |v| t of the start (its path's length), so no edge is within
    # the radius before |v| t + r reaches the nearest one: those samples are not computed
    # (1e-9 m of slack is far above the rounding of these distances). The last is, always.
    gap, first = math.sqrt(near2) - math.sqrt(r2) - 1e-9, times.size - 1
    while first > 0 and abs(v) * times[first - 1] >= gap:
        first -= 1
    for i in range(first, times.size):
        px, py, pth = _arc(times[i], x0, y0, th0, v, omega, t_turn, cos_end, sin_end)
        for jj in range(m):
            if _dist2(px, py, seg, idx[jj]) < r2:
                return True
        out[0], out[1], out[2] = px, py, pth
    return False


@njit(**_JIT)
def plan(x0: float, y0: float, th0: float, heading: float, speed: float,
         rp: np.ndarray) -> tuple[float, float, float]:  # pragma: no cover - compiled
    """``robot._plan``'s ``v``, ``omega`` [rad/s] and turn duration [s] of a command.

    ``rp`` is :data:`ROBOT`.
    """
    lo, hi, h = -rp[5], rp[5], heading
    h = lo if lo > h else h
    dh = math.radians(hi if hi < h else h)
    lo, hi, v = rp[3], rp[4], speed
    v = lo if lo > v else v
    v = hi if hi < v else v
    w = math.radians(rp[1])
    t_turn, period = abs(dh) / w, rp[2]
    t_turn = period if period < t_turn else t_turn
    omega = math.copysign(w, dh) if dh != 0.0 else 0.0
    return v, omega, t_turn


#: The robot parameters :func:`plan`, :func:`step_contact` and :func:`env_step` read, in
#: order (``sitframe.sim.robot.packed_params``; ``backoff_turn`` 1.0 for the recovery
#: ``"backoff-turn"``, 0.0 for ``"none"``).
ROBOT = ("radius", "max_turn_rate_deg_s", "control_period_s", "min_speed", "max_speed",
         "max_heading_change_deg", "recovery_backoff_m", "recovery_turn_deg", "backoff_turn")


@njit(**_JIT)
def robot_step(x0: float, y0: float, th0: float, heading: float, speed: float,
               rp: np.ndarray, times: np.ndarray, seg: np.ndarray, contact: bool,
               out: np.ndarray) -> int:  # pragma: no cover - compiled
    """``step_robot`` in one call: the command's :func:`plan`, :func:`step_free` and, when
    the disc touches a wall, :func:`step_contact` (into ``out``, (14,), and its answer;
    :data:`TIE` leaves the turn's side to the caller's draw, :func:`finish_turn`). Without
    ``contact`` (where :func:`step_contact` does not agree with Python's) a step that
    touches a wall answers :data:`TOUCH` and writes nothing: the caller steps it."""
    v, omega, t_turn = plan(x0, y0, th0, heading, speed, rp)
    reach = v * rp[2] + rp[0] + rp[6] + 1e-9
    end = np.empty(3)
    if step_free(x0, y0, th0, v, omega, t_turn, times, seg, reach * reach, rp[0] * rp[0], end):
        if not contact:
            return TOUCH
        return step_contact(x0, y0, th0, v, omega, t_turn, times, seg, rp, out)
    w = wrap(end[2])
    out[0], out[1], out[2], out[3], out[4] = end[0], end[1], w, np.nan, np.nan
    out[5], out[6], out[7], out[8] = end[0], end[1], w, v * rp[2]
    out[9], out[10], out[11] = math.degrees(end[2] - th0), 0.0, 0.0
    return FREE


@njit(**_JIT)
def env_step(x0: float, y0: float, th0: float, heading: float, speed: float, rp: np.ndarray,
             times: np.ndarray, seg: np.ndarray, contact: bool, clip: bool, rel: np.ndarray,
             max_range: float, sensor_radius: float, group: int, scale: float, lo: np.ndarray,
             hi: np.ndarray, out: np.ndarray, reading: np.ndarray,
             obs: np.ndarray) -> int:  # pragma: no cover - compiled
    """One Gym step in one call: :func:`robot_step`, the range finder's read at the end pose
    (:func:`ranges_at`) and its observation (:func:`observe`). ``out`` (15,):
    :func:`robot_step`'s fourteen figures and the reading's nearest range. Returns
    :func:`robot_step`'s answer; on :data:`TIE` (a dead-ahead contact, whose turn's side is a
    draw from the robot's generator) before reading: the caller steps that one through
    ``step_robot``. ``contact`` (robot_step's) and ``clip`` (ranges_at's; a sensor without
    noise) are both true, passed in rather than written here: numba compiles a kernel
    again for a constant argument, and robot_step costs seconds to compile.
    """
    code = robot_step(x0, y0, th0, heading, speed, rp, times, seg, contact, out)
    if code == TIE:
        return code
    ranges_at(out[0], out[1], out[2], rel, seg, max_range, sensor_radius, group, clip, reading)
    out[14] = observe(reading, scale, lo, hi, obs)
    return code


@njit(**_JIT)
def env_steps(poses: np.ndarray, headings: np.ndarray, speeds: np.ndarray, rp: np.ndarray,
              times: np.ndarray, seg: np.ndarray, contact: bool, clip: bool, rel: np.ndarray,
              max_range: float,
              sensor_radius: float, group: int, scale: float, lo: np.ndarray, hi: np.ndarray,
              reward: np.ndarray, out: np.ndarray, readings: np.ndarray, obs: np.ndarray,
              codes: np.ndarray, rewards: np.ndarray) -> None:  # pragma: no cover - compiled
    """:func:`env_step` for N robots in one world (the vector env's step): row ``i`` of
    ``out``, ``readings``, ``obs`` and ``codes`` is robot ``i``'s, from ``poses[i]`` (x, y,
    theta) under ``headings[i]`` [deg] and ``speeds[i]`` [m/s]; ``rewards[i]`` its
    ``obstacle-avoidance`` reward (``reward``: collision, base, heading cost; a
    :data:`TIE` row gets none: the caller steps it)."""
    for i in range(poses.shape[0]):
        h = headings[i]
        code = env_step(poses[i, 0], poses[i, 1], poses[i, 2], h, speeds[i], rp, times, seg,
                        contact, clip, rel, max_range, sensor_radius, group, scale, lo, hi, out[i],
                        readings[i], obs[i])
        codes[i] = code
        rewards[i] = reward[0] if code != FREE else (reward[1] - reward[2] * abs(h)) + 0.0


_T27 = 134217729.0  # Veltkamp's splitting constant, 2 ** 27 + 1
_TWO_PI = 2.0 * math.pi


@njit(**_JIT)
def wrap(x: float) -> float:  # pragma: no cover - compiled
    """``math.remainder(x, 2 pi)`` (``robot._wrap``): IEEE 754's remainder, exact, from the
    exact ``fmod`` as fdlibm's ``__ieee754_remainder`` takes it (numba has no
    ``math.remainder``); ``tests/test_kernels.py`` compares it with Python's."""
    p = _TWO_PI
    if x != x or x == np.inf or x == -np.inf:
        return np.nan
    r = np.fmod(x, p + p)
    a = abs(r)
    if a == p:
        return 0.0 * r
    half = 0.5 * p
    if a > half:
        a -= p
        if a >= half:
            a -= p
    return -a if r < 0.0 or (r == 0.0 and math.copysign(1.0, r) < 0.0) else a


@njit(**_JIT)
def finish_turn(out: np.ndarray, flip: bool) -> None:  # pragma: no cover - compiled
    """End a :func:`step_contact` that answered :data:`TIE` (a dead-ahead contact): turn
    right when ``flip`` (``rng.random() < 0.5``, drawn by the caller), else left."""
    turn = -out[13] if flip else out[13]
    out[2], out[11] = wrap(out[12] + turn), math.degrees(turn)


#: :func:`step_contact`'s answers: the step touched nothing, touched a wall, or touched one
#: dead ahead (the side of the turn away is the caller's draw: :func:`finish_turn`); and
#: :func:`robot_step`'s when it is not to step a contact itself.
FREE, HIT, TIE, TOUCH = 0, 1, 2, 3


@njit(**_JIT)
def _add_square(x: float, sign: float, s: np.ndarray) -> None:  # pragma: no cover - compiled
    """Add ``sign * x**2`` to the compensated sum ``s`` (``vector_norm``'s steps: ``x``
    split in halves, ``hi**2``, ``2 hi lo`` and ``lo**2`` added with their errors)."""
    t = x * _T27
    hi = t - (t - x)
    lo = x - hi
    term = sign * hi * hi
    old = s[0]
    s[0] += term
    s[1] += (old - s[0]) + term
    term = sign * 2.0 * hi * lo
    old = s[0]
    s[0] += term
    s[2] += (old - s[0]) + term
    if sign > 0.0:
        s[3] += lo * lo
        return
    term = -lo * lo
    old = s[0]
    s[0] += term
    s[3] += (old - s[0]) + term


@njit(**_JIT)
def hypot(a: float, b: float) -> float:  # pragma: no cover - compiled
    """Python 3.11's ``math.hypot(a, b)`` (its own ``vector_norm``: Veltkamp-split squares,
    compensated sums, one corrected square root), which the C library's ``hypot`` is not;
    checked against ``math.hypot`` where used (:func:`sitframe.sim.kernels.contact`)."""
    x0, x1 = abs(a), abs(b)
    mx = 0.0
    for x in (x0, x1):  # (as math_hypot finds the largest: a NaN is never it)
        if x > mx:
            mx = x
    if mx == np.inf:
        return mx
    if x0 != x0 or x1 != x1:
        return np.nan
    if mx == 0.0:
        return mx
    if math.frexp(mx)[1] < -1023:  # (subnormals: divided by the largest, summed plainly)
        csum, frac = 1.0, 0.0
        for x in (x0 / mx, x1 / mx):
            old = csum
            csum += x * x
            frac += (old - csum) + x * x
        return mx * math.sqrt(csum - 1.0 + frac)
    scale = math.ldexp(1.0, -math.frexp(mx)[1])
    sums = np.zeros(4)  # csum - 1, and the three compensations
    sums[0] = 1.0
    _add_square(x0 * scale, 1.0, sums)
    _add_square(x1 * scale, 1.0, sums)
    h = math.sqrt(sums[0] - 1.0 + (sums[1] + sums[2] + sums[3]))
    _add_square(h, -1.0, sums)
    x = sums[0] - 1.0 + (sums[1] + sums[2] + sums[3])
    return (h + x / (2.0 * h)) / scale


@njit(**_JIT)
def _poses(ts: np.ndarray, x0: float, y0: float, th0: float, v: float, omega: float,
           t_turn: float, out: np.ndarray) -> None:  # pragma: no cover - compiled
    """``robot._poses_at``: the (3, n) poses at times ``ts`` (sines and cosines the C
    library's, as :func:`step_free`'s)."""
    th_end = th0 + omega * t_turn
    cos_end, sin_end = math.cos(th_end), math.sin(th_end)
    for i in range(ts.size):
        out[0, i], out[1, i], out[2, i] = _arc(ts[i], x0, y0, th0, v, omega, t_turn, cos_end,
                                               sin_end)


@njit(**_JIT)
def _touch(x0: float, y0: float, th0: float, v: float, omega: float, t_turn: float,
           times: np.ndarray, near: np.ndarray, r2: float,
           c: np.ndarray) -> int:  # pragma: no cover - compiled
    """Steps 2 and 3 of ``robot.step_robot``: the first substep that touches (returned; -1:
    none, ``c`` the last substep's pose) and the refined contact ``c`` = ``t_c, x, y, theta``
    (the last free pose of two rounds of :data:`_REFINE_N`-fold subdivision)."""
    p = np.empty((3, times.size))
    _poses(times, x0, y0, th0, v, omega, t_turn, p)
    k = first_contact(p[0], p[1], near, r2)
    if k < 0:
        c[0], c[1], c[2], c[3] = times[times.size - 1], p[0, -1], p[1, -1], p[2, -1]
        return k
    if k == 0:  # started inside: no forward motion
        c[0], c[1], c[2], c[3] = 0.0, x0, y0, th0
        return k
    j = k - 1
    c[0], c[1], c[2], c[3] = times[j], p[0, j], p[1, j], p[2, j]
    hi = times[k]
    ts, f = np.empty(_REFINE_N + 1), np.empty((3, _REFINE_N + 1))
    for _ in range(2):
        linspace(c[0], hi, ts)
        _poses(ts, x0, y0, th0, v, omega, t_turn, f)
        j = first_contact(f[0], f[1], near, r2)
        if j < 0:
            j = _REFINE_N
        if j == 0:
            break
        hi = ts[j]
        j -= 1
        c[0], c[1], c[2], c[3] = ts[j], f[0, j], f[1, j], f[2, j]
    return k


@njit(**_JIT)
def step_contact(x0: float, y0: float, th0: float, v: float, omega: float, t_turn: float,
                 times: np.ndarray, seg: np.ndarray, rp: np.ndarray,
                 out: np.ndarray) -> int:  # pragma: no cover - compiled
    """``robot.step_robot`` for a step that may touch a wall, operation by operation: the
    substeps against the edges in reach, the refined contact, the contact point, the
    back-off along the normal and the turn away. ``rp`` is :data:`ROBOT`.

    ``out`` (14,): the end pose (x, y, wrapped theta), the contact point (x, y; NaN without
    one), the contact pose (x, y, wrapped theta), the distance [m], the heading change
    [deg], the distance backed off [m], the recovery turn [deg], and the contact heading
    (unwrapped) and the turn's size [rad] for :func:`finish_turn`. Returns :data:`FREE`,
    :data:`HIT` or :data:`TIE` (a dead-ahead contact: ``step_robot`` draws the turn's side
    from the robot's generator, which the caller does and passes to :func:`finish_turn`).
    """
    r, back, recovery = rp[0], rp[6], rp[8] != 0.0
    reach = v * rp[2] + r + back + 1e-9
    idx = np.empty(seg.shape[1], dtype=np.intp)
    near = _gather(seg, idx, near_segments(x0, y0, seg, reach * reach, idx))
    c = np.empty(4)
    k = -1 if near.shape[1] == 0 else _touch(x0, y0, th0, v, omega, t_turn, times, near,
                                             r * r, c)
    if k < 0:  # (nothing touched: the closed form at the end, as step_robot's open space)
        if near.shape[1] == 0:
            e = np.empty(3)
            step_free(x0, y0, th0, v, omega, t_turn, times, seg, 0.0, r * r, e)
            c[1], c[2], c[3] = e[0], e[1], e[2]
        w = wrap(c[3])
        out[0], out[1], out[2], out[3], out[4] = c[1], c[2], w, np.nan, np.nan
        out[5], out[6], out[7], out[8] = c[1], c[2], w, v * rp[2]
        out[9], out[10], out[11] = math.degrees(c[3] - th0), 0.0, 0.0
        return FREE
    t_c, cx, cy, cth = c[0], c[1], c[2], c[3]
    px, py = nearest_point(cx, cy, near)
    backed, bx, by = 0.0, cx, cy
    if recovery and back > 0.0:
        nx, ny = cx - px, cy - py
        norm = hypot(nx, ny)
        if norm > 0.0:
            nx, ny = nx / norm, ny / norm
        else:  # centre on the wall (only if it started there): back straight up
            nx, ny = -math.cos(cth), -math.sin(cth)
        s = np.empty(_BACKOFF_N)
        m, xx, yy = backoff(cx, cy, nx, ny, back, near, r * r, k == 0, s)
        if m > 0:
            backed, bx, by = s[m], xx, yy
    w = wrap(cth)
    out[3], out[4], out[5], out[6], out[7] = px, py, cx, cy, w
    out[8], out[9], out[10], out[11] = v * t_c, math.degrees(cth - th0), backed, 0.0
    if not recovery:
        out[0], out[1], out[2] = cx, cy, w
        return HIT
    bearing = wrap(math.atan2(py - by, px - bx) - cth)
    turn_max, room = math.radians(rp[7]), math.pi - abs(bearing)
    turn = room if room < turn_max else turn_max  # (Python's min(turn_max, room))
    out[0], out[1], out[12], out[13] = bx, by, cth, turn
    finish_turn(out, bearing > 0.0)
    return TIE if bearing == 0.0 else HIT


#: ``robot._REFINE`` and ``robot._BACKOFF_SAMPLES`` (the simulator cannot be imported here).
_REFINE_N, _BACKOFF_N = 16, 11


@njit(**_JIT)
def trig(x: np.ndarray, out: np.ndarray) -> None:  # pragma: no cover - compiled
    """``out[0] = sin(x)``, ``out[1] = cos(x)`` as compiled code computes them (the C
    library's), for :func:`sitframe.sim.kernels.fused` to compare with numpy's."""
    for i in range(x.size):
        out[0, i] = math.sin(x[i])
        out[1, i] = math.cos(x[i])


@njit(**_JIT)
def _first_touch(xs: np.ndarray, ys: np.ndarray, seg: np.ndarray, idx: np.ndarray, count: int,
                 r2: float) -> int:  # pragma: no cover - compiled
    """:func:`first_contact` against the segments ``idx[:count]`` of ``seg``."""
    for k in range(xs.size):
        for jj in range(count):
            if _dist2(xs[k], ys[k], seg, idx[jj]) < r2:
                return k
    return -1


@njit(**_JIT)
def sweep_begin(plans: np.ndarray, times: np.ndarray, period: float, margin: np.ndarray,
                seg: np.ndarray, idx: np.ndarray, count: np.ndarray, slot: np.ndarray,
                sinc_arg: np.ndarray, ang: np.ndarray) -> int:  # pragma: no cover - compiled
    """Step 1 of ``robot.step_robot`` for N robots, and step 2 up to its sines and cosines.

    ``plans`` (N, >= 6) rows start ``x0, y0, th0, v, omega, t_turn``; a robot's swept disc
    reaches ``v * period + margin[0] + margin[1] + margin[2]`` (the radius, the back-off and
    a hair, added one by one as there). Writes each robot's near segments to
    ``idx[i, :count[i]]`` (:func:`near_segments`); a robot with any gets the next free row
    ``slot[i]`` of ``sinc_arg, ang`` (B, n), where the arguments of its substeps' sines and
    cosines at ``times`` go (:func:`arc_angles`); one in open space gets ``slot[i] = -1``.
    Returns B, the number of robots near a wall, or -1 if a pose is not finite.
    """
    for i in range(plans.shape[0]):
        for j in range(3):
            if not math.isfinite(plans[i, j]):
                return -1
    b = 0
    for i in range(plans.shape[0]):
        reach = plans[i, 3] * period + margin[0] + margin[1] + margin[2]
        count[i] = near_segments(plans[i, 0], plans[i, 1], seg, reach * reach, idx[i])
        slot[i] = -1
        if count[i] > 0:
            slot[i] = b
            arc_angles(times, plans[i, 2], plans[i, 4], plans[i, 5], sinc_arg[b], ang[b])
            b += 1
    return b


@njit(**_JIT)
def _refine_angles(plan: np.ndarray, state: np.ndarray, ts: np.ndarray, sinc_arg: np.ndarray,
                   ang: np.ndarray) -> None:  # pragma: no cover - compiled
    """One refinement round's samples ``ts`` between ``state``'s free time and bad time, and
    the arguments of their sines and cosines (``robot.step_robot``, step 3)."""
    linspace(state[0], state[4], ts)
    arc_angles(ts, plan[2], plan[4], plan[5], sinc_arg, ang)


@njit(**_JIT)
def sweep_end(times: np.ndarray, plans: np.ndarray, slot: np.ndarray, sinc_arg: np.ndarray,
              sin_sinc: np.ndarray, cos_ang: np.ndarray, sin_ang: np.ndarray, seg: np.ndarray,
              idx: np.ndarray, count: np.ndarray, r2: float, poses: np.ndarray,
              first: np.ndarray, hits: np.ndarray, state: np.ndarray, active: np.ndarray,
              ts: np.ndarray, ref_arg: np.ndarray,
              ref_ang: np.ndarray) -> int:  # pragma: no cover - compiled
    """The rest of step 2 of ``robot.step_robot`` for the robots of :func:`sweep_begin`, and the
    start of step 3 for those that touch a wall.

    ``plans`` (N, 8) are :func:`arc_poses`' plans; the sines and cosines (B, n) are numpy's
    of :func:`sweep_begin`'s arguments. Robot ``i`` near a wall gets its substep poses (3, n)
    in ``poses[slot[i]]`` and the first substep that touches a wall in ``first[i]`` (-1 if
    none, and for a robot in open space). The H robots that touch go to ``hits[:H]``, with
    ``state[q]`` = ``t_c, cx, cy, cth, hi`` (the last free substep's time and pose, the first
    bad one's time; ``t_c = 0`` at the start pose when it started inside, ``active[q]`` False:
    nothing to refine) and the first refinement round's samples and arguments in ``ts[q],
    ref_arg[q], ref_ang[q]`` (:func:`_refine_angles`). Returns H.
    """
    h = 0
    for i in range(plans.shape[0]):
        first[i] = -1
        b = slot[i]
        if b < 0:
            continue
        arc_poses(times, plans[i], sinc_arg[b], sin_sinc[b], cos_ang[b], sin_ang[b], poses[b])
        k = _first_touch(poses[b, 0], poses[b, 1], seg, idx[i], count[i], r2)
        first[i] = k
        if k < 0:
            continue
        hits[h] = i
        active[h] = k > 0
        if k == 0:  # started inside: no forward motion
            state[h, 0], state[h, 1], state[h, 2], state[h, 3] = 0.0, plans[i, 0], plans[i, 1], \
                plans[i, 2]
            state[h, 4] = 0.0
            ref_arg[h, :] = 0.0
            ref_ang[h, :] = 0.0
        else:
            j = k - 1
            state[h, 0], state[h, 4] = times[j], times[k]
            state[h, 1], state[h, 2], state[h, 3] = poses[b, 0, j], poses[b, 1, j], poses[b, 2, j]
            _refine_angles(plans[i], state[h], ts[h], ref_arg[h], ref_ang[h])
        h += 1
    return h


@njit(**_JIT)
def refine(plans: np.ndarray, hits: np.ndarray, h: int, ts: np.ndarray, sinc_arg: np.ndarray,
           ang: np.ndarray, sin_sinc: np.ndarray, cos_ang: np.ndarray, sin_ang: np.ndarray,
           seg: np.ndarray, idx: np.ndarray, count: np.ndarray, r2: float, state: np.ndarray,
           active: np.ndarray, poses: np.ndarray, more: bool) -> None:  # pragma: no cover
    """One refinement round of ``robot.step_robot`` (step 3) for the robots ``hits[:h]`` of
    :func:`sweep_end`: the poses (3, R) at the samples ``ts[q]`` (the sines and cosines are
    numpy's of the arguments ``sinc_arg[q], ang[q]`` of the previous call), the first that
    touches, and the narrowed ``state[q]``; with ``more``, the next round's samples and
    arguments (overwriting ``ts, sinc_arg, ang``). A robot whose first sample touches (which
    cannot happen) keeps its state and stops (``active[q]`` False), as there.
    """
    last = ts.shape[1] - 1
    for q in range(h):
        if not active[q]:
            continue
        i = hits[q]
        arc_poses(ts[q], plans[i], sinc_arg[q], sin_sinc[q], cos_ang[q], sin_ang[q], poses[q])
        j = _first_touch(poses[q, 0], poses[q, 1], seg, idx[i], count[i], r2)
        if j < 0:
            j = last  # the bad end of the interval
        if j == 0:
            active[q] = False
            continue
        state[q, 4] = ts[q, j]
        j -= 1  # the last free sample: the disc touches there
        state[q, 0], state[q, 1], state[q, 2], state[q, 3] = ts[q, j], poses[q, 0, j], \
            poses[q, 1, j], poses[q, 2, j]
        if more:
            _refine_angles(plans[i], state[q], ts[q], sinc_arg[q], ang[q])


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


@njit(**_JIT)
def _gather(seg: np.ndarray, idx: np.ndarray, count: int) -> np.ndarray:  # pragma: no cover
    """The packed segments ``idx[:count]`` of ``seg``, (5, count) (``seg[:, idx[:count]]``)."""
    sub = np.empty((5, count))
    for jj in range(count):
        for r in range(5):
            sub[r, jj] = seg[r, idx[jj]]
    return sub


@njit(**_JIT)
def contact_points(hits: np.ndarray, h: int, state: np.ndarray, seg: np.ndarray,
                   idx: np.ndarray, count: np.ndarray,
                   out: np.ndarray) -> None:  # pragma: no cover - compiled
    """:func:`nearest_point` of each contact pose ``state[q, 1:3]`` of the robots ``hits[:h]``
    (:func:`refine`) on its near segments, into ``out`` (h, 2)."""
    for q in range(h):
        i = hits[q]
        out[q, 0], out[q, 1] = nearest_point(state[q, 1], state[q, 2],
                                             _gather(seg, idx[i], count[i]))


@njit(**_JIT)
def backoffs(hits: np.ndarray, h: int, state: np.ndarray, normals: np.ndarray, length: float,
             seg: np.ndarray, idx: np.ndarray, count: np.ndarray, r2: float, first: np.ndarray,
             s: np.ndarray, out: np.ndarray) -> None:  # pragma: no cover - compiled
    """:func:`backoff` of the robots ``hits[:h]`` from their contact poses along ``normals``
    (h, 2) into ``out`` (h, 3): distance backed off, x, y (``robot._backoff``'s result; a
    robot that started inside, ``first[i] == 0``, may back off from inside)."""
    for q in range(h):
        i = hits[q]
        cx, cy = state[q, 1], state[q, 2]
        m, x, y = backoff(cx, cy, normals[q, 0], normals[q, 1], length,
                          _gather(seg, idx[i], count[i]), r2, first[i] == 0, s)
        if m > 0:
            out[q, 0], out[q, 1], out[q, 2] = s[m], x, y
        else:
            out[q, 0], out[q, 1], out[q, 2] = 0.0, cx, cy


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
def observe(reading: np.ndarray, scale: float, lo: np.ndarray, hi: np.ndarray,
            out: np.ndarray) -> float:  # pragma: no cover - compiled
    """``out[:] = clip(float32(reading / scale), lo, hi)``; returns ``reading.min()``.

    The Gym env's observation of one reading (:meth:`sitframe.gym.task.Task.observe`) and
    its nearest range, in one call; NaN propagates as in numpy's ``maximum``, ``minimum``
    and ``min``.
    """
    nearest = reading[0]
    for i in range(reading.size):
        r = reading[i]
        if (r < nearest or r != r) and nearest == nearest:
            nearest = r
        v = np.float32(r / scale)
        if v < lo[i]:
            v = lo[i]
        if v > hi[i]:
            v = hi[i]
        out[i] = v
    return nearest


@njit(**_JIT)
def point_in_polygon(p: np.ndarray, poly: np.ndarray, out: np.ndarray
                     ) -> None:  # pragma: no cover - compiled
    """``out[i]``: whether point ``p[i]`` lies inside polygon ``poly`` (m, 2), even-odd, as
    :func:`sitframe.sim.geometry.point_in_polygon` (the same crossing, operation by operation)."""
    m = poly.shape[0]
    for i in range(p.shape[0]):
        px, py = p[i, 0], p[i, 1]
        crossings = 0
        for j in range(m):
            x0, y0 = poly[j, 0], poly[j, 1]
            x1, y1 = poly[(j + 1) % m, 0], poly[(j + 1) % m, 1]
            if (y0 > py) != (y1 > py):
                dy = y1 - y0 if y1 != y0 else 1.0
                if px < x0 + ((py - y0) / dy) * (x1 - x0):
                    crossings += 1
        out[i] = crossings % 2 == 1


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


@njit(**_JIT)
def fcm_online_update(centers: np.ndarray, evidence: np.ndarray, diff: np.ndarray,
                      um: np.ndarray) -> None:  # pragma: no cover - compiled
    """``evidence += um; centers -= (um / evidence)[:, None] * diff`` in place."""
    c, d = centers.shape
    for i in range(c):
        evidence[i] += um[i]
        r = um[i] / evidence[i]
        for j in range(d):
            centers[i, j] -= r * diff[i, j]


@njit(**_JIT)
def accumulate_errors(errors: np.ndarray, x: np.ndarray, total: np.ndarray, count: np.ndarray,
                      weighted: np.ndarray) -> None:  # pragma: no cover - compiled
    """Where ``errors > 0``: ``total += errors``, ``count += 1``, ``weighted += errors * x``."""
    for i in range(errors.size):
        e = errors[i]
        if e > 0.0:
            total[i] += e
            count[i] += 1.0
            for j in range(x.size):
                weighted[i, j] += e * x[j]


@njit(**_JIT)
def finite_nonnegative(a: np.ndarray) -> bool:  # pragma: no cover - compiled
    """Whether every value of the 1-d ``a`` is finite and >= 0 (``0 <= a < inf``)."""
    for i in range(a.size):
        v = a[i]
        if not (0.0 <= v < np.inf):
            return False
    return True


@njit(**_JIT)
def frozen_td(u: np.ndarray, activation: float, thesis: bool, reward: float, gamma: float,
              v_next: float, q: np.ndarray, rules: np.ndarray,
              td: np.ndarray) -> None:  # pragma: no cover - compiled
    """``td[i] = |w r + gamma w V' - Q[i, rules[i]]|`` where ``u[i] >= activation`` (``w =
    u[i]`` if ``thesis`` else 1), 0 elsewhere: the TD errors a frozen rule base would get."""
    for i in range(u.size):
        if u[i] >= activation:
            w = u[i] if thesis else 1.0
            td[i] = abs(w * reward + gamma * w * v_next - q[i, rules[i]])
        else:
            td[i] = 0.0


def _warm() -> None:
    """Load (or, the first time, compile) the kernels of a trial now, with the types the loop
    uses.

    Run at import, so a process importing this module -- a worker pool's forkserver
    preloads it -- has them all, and its forked workers inherit them. The vector env's
    (:mod:`sitframe.sim.fleet`: ``ranges_many``, ``sweep_*``, ``refine``, ``contact_points``,
    ``backoffs``), the route planner's (``clear_moves``, ``clear_from``), and ``cast`` and
    ``cast_each`` (rays without a heading: ``cast_rays``; sensors read through
    :func:`ranges_at`) are compiled (or loaded) on their first call instead: most runs never
    call them, and compiling them would add some 3 s to the first run after an install.
    """
    seg = np.array([[0.0], [1.0], [1.0], [0.0], [1.0]])  # one segment (0, 1)-(1, 1)
    one = np.ones(2)
    # (a world's packed segments and the substep times are read-only, and so a kernel's
    # type differs from one compiled for writable arrays: compiled here as passed there)
    seg_ro, one_ro = seg.copy(), one.copy()
    seg_ro.setflags(write=False)
    one_ro.setflags(write=False)
    out, idx = np.empty(2), np.empty(1, dtype=np.intp)
    ranges(0.0, 0.0, one, one, seg_ro, 3.0, 0.1, 1, True, out)
    two = np.ones((2, 2))
    act = np.zeros(2, dtype=np.bool_)
    near_segments(0.0, 0.0, seg_ro, 1.0, idx)
    first_contact(one, one, seg, 0.01)
    nearest_point(0.0, 0.0, seg)
    linspace(0.0, 1.0, out)
    arc_angles(one, 0.0, 1.0, 0.5, out, np.empty(2))
    arc_poses(one, np.ones(8), one, one, one, one, np.empty((3, 2)))
    backoff(0.0, 0.0, 1.0, 0.0, 0.05, seg, 0.01, False, np.empty(3))
    fcm_ratios(one, 1e-9, out)
    normalize(out)
    label_strengths(np.ones((2, 2)), one, out)
    fcm_online_update(np.ones((2, 2)), np.ones(2), two, one)
    accumulate_errors(one, one, np.ones(2), np.ones(2), np.ones((2, 2)))
    finite_nonnegative(one)
    ro = np.ones(2)
    ro.setflags(write=False)  # (memberships reach the learner read-only)
    frozen_td(ro, 0.3, True, -1.0, 0.9, 0.5, two, np.zeros(2, dtype=np.intp), out)
    step_free(0.0, 0.0, 0.0, 0.1, 0.0, 0.0, one_ro, seg_ro, 1.0, 0.01, np.empty(3))
    robot_step(0.0, 0.0, 0.0, 10.0, 0.1, np.array([0.15, 100.0, 1.5, 0.1, 0.3, 90.0, 0.05, 45.0,
                                                   1.0]), one_ro, seg_ro, True, np.empty(14))
    hypot(3.0, 4.0)
    wrap(7.0)
    ranges_at(0.0, 0.0, 0.0, one, seg_ro, 3.0, 0.1, 1, True, out)
    trig(one, two)
    observe(one, 3.0, np.ones(2, dtype=np.float32), np.ones(2, dtype=np.float32),
            np.empty(2, dtype=np.float32))
    point_in_polygon(two, two, act)


@njit(**_JIT)
def _seg_d2(px: float, py: float, ax: float, ay: float, ex: float, ey: float,
            inv: float) -> float:  # pragma: no cover - compiled
    wx, wy = px - ax, py - ay
    t = min(max((wx * ex + wy * ey) * inv, 0.0), 1.0)
    dx, dy = wx - t * ex, wy - t * ey
    return dx * dx + dy * dy


@njit(**_JIT)
def _seg_dist(px: float, py: float, ax: float, ay: float, ex: float, ey: float,
              inv: float) -> float:  # pragma: no cover - compiled
    """:func:`sitframe.sim.geometry.point_segment_distance` of one point and a segment given
    by its start, its vector and ``1 / |e|²`` (a move, which no packed set holds), operation
    by operation (``t`` clipped as ``numpy.clip``: NaN stays)."""
    wx, wy = px - ax, py - ay
    t = (wx * ex + wy * ey) * inv
    if t == t:
        t = t if t > 0.0 else 0.0
        t = t if t < 1.0 else 1.0
    dx, dy = wx - t * ex, wy - t * ey
    return math.sqrt(dx * dx + dy * dy)


@njit(**_JIT)
def _orient(ax: float, ay: float, bx: float, by: float, cx: float,
            cy: float) -> float:  # pragma: no cover - compiled
    return (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)


@njit(**_JIT)
def clear_moves(a: np.ndarray, b: np.ndarray, seg: np.ndarray, packed: np.ndarray, r: float,
                out: np.ndarray) -> None:  # pragma: no cover - compiled
    """``out[i]``: whether the disc moved straight from ``a[i]`` to ``b[i]`` (k, 2) is clear
    of the edges ``seg`` (E, 4) (``packed``: their :attr:`SegmentSet.packed
    <sitframe.sim.geometry.SegmentSet>`), ``r`` the radius less its rounding allowance: the
    bit twin of :func:`sitframe.sim.paths._clear_chunk`, which shortest paths and goal pairs
    (figures of a log) depend on."""
    for i in range(a.shape[0]):
        px, py, qx, qy = a[i, 0], a[i, 1], b[i, 0], b[i, 1]
        mx, my = qx - px, qy - py
        ml2 = mx * mx + my * my
        minv = 1.0 / ml2 if ml2 >= _TINY else 0.0
        ok = True
        for j in range(seg.shape[0]):
            ax, ay, bx, by = seg[j, 0], seg[j, 1], seg[j, 2], seg[j, 3]
            if (_orient(ax, ay, bx, by, px, py) * _orient(ax, ay, bx, by, qx, qy) < 0.0
                    and _orient(px, py, qx, qy, ax, ay) * _orient(px, py, qx, qy, bx, by) < 0.0) \
                    or math.sqrt(_dist2(px, py, packed, j)) < r \
                    or math.sqrt(_dist2(qx, qy, packed, j)) < r \
                    or _seg_dist(ax, ay, px, py, mx, my, minv) < r \
                    or _seg_dist(bx, by, px, py, mx, my, minv) < r:
                ok = False
                break
        out[i] = ok


@njit(**_JIT)
def clear_from(px: float, py: float, targets: np.ndarray, seg: np.ndarray, r: float,
               out: np.ndarray) -> None:  # pragma: no cover - compiled
    """Whether a disc of radius ``r`` moved straight from (px, py) to each target (k, 2)
    touches no edge of ``seg`` (S, 4): the test of :func:`sitframe.sim.paths._clear_chunk`
    for one start (no crossing; no endpoint of either within ``r`` of the other), on
    squared distances. Not bit-twinned: only the route planner and the path-distance
    reward use it (never a figure of a preset's log)."""
    r2 = r * r
    for i in range(targets.shape[0]):
        qx, qy = targets[i, 0], targets[i, 1]
        mx, my = qx - px, qy - py
        ml2 = mx * mx + my * my
        minv = 1.0 / ml2 if ml2 > 0.0 else 0.0
        ok = True
        for j in range(seg.shape[0]):
            ax, ay, bx, by = seg[j, 0], seg[j, 1], seg[j, 2], seg[j, 3]
            ex, ey = bx - ax, by - ay
            el2 = ex * ex + ey * ey
            einv = 1.0 / el2 if el2 > 0.0 else 0.0
            o1 = ex * (py - ay) - ey * (px - ax)
            o2 = ex * (qy - ay) - ey * (qx - ax)
            o3 = mx * (ay - py) - my * (ax - px)
            o4 = mx * (by - py) - my * (bx - px)
            if (o1 * o2 < 0.0 and o3 * o4 < 0.0) or \
                    _seg_d2(px, py, ax, ay, ex, ey, einv) < r2 or \
                    _seg_d2(qx, qy, ax, ay, ex, ey, einv) < r2 or \
                    _seg_d2(ax, ay, px, py, mx, my, minv) < r2 or \
                    _seg_d2(bx, by, px, py, mx, my, minv) < r2:
                ok = False
                break
        out[i] = ok


_warm()
