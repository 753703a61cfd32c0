"""Vectorised 2-D geometry: ray casting, point–segment distances, polygons.

All functions work on whole arrays at once (no Python loop over segments), so
one call covers every sonar ray against every wall edge, or every substep of
a robot move against every wall edge.

Conventions
-----------
- Points are ``(k, 2)`` arrays of ``x, y`` in metres.
- Segments are ``(S, 4)`` arrays of ``x0, y0, x1, y1`` in metres. A
  zero-length segment (``x0, y0 == x1, y1``) is a valid point obstacle.
- Angles are radians, 0 = +x, counter-clockwise positive.

For repeated queries against the same segments (a world's walls), build a
:class:`SegmentSet` once; it caches the per-segment arrays and is accepted
wherever a ``segments`` array is.

The property tests check these functions against brute-force references written
with a different algorithm (plain Python loops, ``tests/geometry_reference.py``).

Why one module of this size: ray casting, distances and polygons all work on one packed
segment set (:class:`SegmentSet`) and its compiled twins.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from sitframe.sim.kernels import fused, kernels

__all__ = [
    "SegmentSet",
    "as_segments",
    "cast_rays_many",
    "min_distance",
    "nearest_on_segments",
    "point_in_polygon",
    "point_segment_distance",
    "polygon_area",
    "polygon_edges",
    "polygon_self_intersection",
    "polyline_segments",
    "raycast",
    "rim_ranges",
    "rim_ranges_many",
    "segments_intersect",
]


def as_segments(segments: np.ndarray) -> np.ndarray:
    """Return ``segments`` as a float64 ``(S, 4)`` array, or raise a clear error.

    Parameters
    ----------
    segments
        Array-like of shape (S, 4): x0, y0, x1, y1 [m].

    Raises
    ------
    TypeError
        If it is not array-like of numbers.
    ValueError
        If the shape is not (S, 4).
    """
    try:
        arr = np.asarray(segments, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"segments must be an (S, 4) array of numbers, got {segments!r}") from exc
    if arr.ndim != 2 or arr.shape[1] != 4:
        raise ValueError(f"segments must have shape (S, 4) = x0, y0, x1, y1; got shape {arr.shape}")
    return arr


def _as_points(points: np.ndarray, name: str = "points") -> np.ndarray:
    try:
        arr = np.asarray(points, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"{name} must be a (k, 2) array of numbers, got {points!r}") from exc
    if arr.ndim == 1 and arr.shape[0] == 2:
        arr = arr[None, :]
    if arr.ndim != 2 or arr.shape[1] != 2:
        raise ValueError(f"{name} must have shape (k, 2) = x, y; got shape {arr.shape}")
    return arr


class SegmentSet:
    """Segments with their derived arrays cached, for repeated fast queries.

    Parameters
    ----------
    segments
        (S, 4) array: x0, y0, x1, y1 [m].

    Attributes
    ----------
    segments
        (S, 4) read-only float64 copy.
    ax, ay
        (S,) start points.
    ex, ey
        (S,) edge vectors ``end - start``.
    inv_len2
        (S,) ``1 / |e|²``, 0 for zero-length segments.
    packed
        (5, S) read-only rows ``ax, ay, ex, ey, inv_len2`` in one array (the
        five above are views of its rows), for :mod:`sitframe.sim.kernels`.
    lo, hi
        (S, 2) lower-left and upper-right corners of each segment's bounding box.
    """

    __slots__ = ("segments", "ax", "ay", "ex", "ey", "inv_len2", "packed", "lo", "hi", "n")

    def __init__(self, segments: np.ndarray):
        seg = as_segments(segments).copy()
        seg.setflags(write=False)
        self.segments = seg
        self.n = seg.shape[0]
        packed = np.empty((5, self.n))
        packed[0] = seg[:, 0]
        packed[1] = seg[:, 1]
        packed[2] = seg[:, 2] - seg[:, 0]
        packed[3] = seg[:, 3] - seg[:, 1]
        len2 = packed[2] * packed[2] + packed[3] * packed[3]
        # Below the smallest normal float 1/len2 would overflow: such a segment
        # (shorter than ~1e-154 m) is a point.
        ok = len2 >= np.finfo(np.float64).tiny
        packed[4] = np.where(ok, 1.0 / np.where(ok, len2, 1.0), 0.0)
        packed.setflags(write=False)
        self.packed = packed
        self.ax, self.ay, self.ex, self.ey, self.inv_len2 = packed
        self.lo = np.minimum(seg[:, :2], seg[:, 2:])
        self.hi = np.maximum(seg[:, :2], seg[:, 2:])

    def subset(self, index: np.ndarray) -> SegmentSet:
        """Return the segments selected by ``index`` (bool mask or integer indices), their
        derived arrays copied from this set's, not recomputed (the robot's step uses it)."""
        sub = SegmentSet.__new__(SegmentSet)
        # (C order, as the kernels are compiled for: a column selection is Fortran-ordered)
        sub.segments, sub.packed = self.segments[index], np.ascontiguousarray(self.packed[:, index])
        sub.n = sub.segments.shape[0]
        sub.ax, sub.ay, sub.ex, sub.ey, sub.inv_len2 = sub.packed
        sub.lo, sub.hi = self.lo[index], self.hi[index]
        return sub

    def __len__(self) -> int:
        return self.n

    def __repr__(self) -> str:
        return f"SegmentSet({self.n} segments)"


def _segment_set(segments: np.ndarray | SegmentSet) -> SegmentSet:
    return segments if isinstance(segments, SegmentSet) else SegmentSet(segments)


# ----------------------------------------------------------------------------- distances


def point_segment_distance(points: np.ndarray, segments: np.ndarray | SegmentSet) -> np.ndarray:
    """Euclidean distance from every point to every segment.

    Parameters
    ----------
    points
        (k, 2) query points [m].
    segments
        (S, 4) segments [m] or a :class:`SegmentSet`.

    Returns
    -------
    numpy.ndarray
        (k, S) distances [m].
    """
    p = _as_points(points)
    s = _segment_set(segments)
    return np.sqrt(_dist2(p[:, 0:1], p[:, 1:2], s))


def _project(px: np.ndarray, py: np.ndarray, s: SegmentSet
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each point's projection on each segment, px/py shaped (k, 1): the segment parameter
    ``t`` in [0, 1] and the offset (dx, dy) from the projected point, each (k, S)."""
    wx = px - s.ax
    wy = py - s.ay
    t = (wx * s.ex + wy * s.ey) * s.inv_len2
    np.clip(t, 0.0, 1.0, out=t)
    return t, wx - t * s.ex, wy - t * s.ey


def _dist2(px: np.ndarray, py: np.ndarray, s: SegmentSet) -> np.ndarray:
    """Squared distances, px/py shaped (k, 1) → (k, S)."""
    _t, dx, dy = _project(px, py, s)
    return dx * dx + dy * dy


def nearest_on_segments(
    points: np.ndarray, segments: np.ndarray | SegmentSet
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Nearest segment and the nearest point on it, for every point.

    Parameters
    ----------
    points
        (k, 2) query points [m].
    segments
        (S, 4) segments [m] (S ≥ 1) or a :class:`SegmentSet`.

    Returns
    -------
    distance : numpy.ndarray
        (k,) distance to the nearest segment [m].
    index : numpy.ndarray
        (k,) int index of the nearest segment.
    nearest : numpy.ndarray
        (k, 2) nearest point on that segment [m] (e.g. a contact point; the
        contact normal is ``points - nearest``).
    """
    p = _as_points(points)
    s = _segment_set(segments)
    if s.n == 0:
        raise ValueError("nearest_on_segments needs at least one segment, got 0")
    t, dx, dy = _project(p[:, 0:1], p[:, 1:2], s)
    d2 = dx * dx + dy * dy
    idx = np.argmin(d2, axis=1)
    rows = np.arange(p.shape[0])
    tt = t[rows, idx]
    nearest = np.stack([s.ax[idx] + tt * s.ex[idx], s.ay[idx] + tt * s.ey[idx]], axis=1)
    return np.sqrt(d2[rows, idx]), idx, nearest


def min_distance(points: np.ndarray, segments: np.ndarray | SegmentSet) -> np.ndarray:
    """Distance from every point to the nearest segment: (k,) [m], the row minimum of
    :func:`point_segment_distance` (same parameters); with no segment (S = 0) ``inf``."""
    p = _as_points(points)
    s = _segment_set(segments)
    if s.n == 0:
        return np.full(p.shape[0], np.inf)
    return np.sqrt(_dist2(p[:, 0:1], p[:, 1:2], s).min(axis=1))


# ----------------------------------------------------------------------------- ray casting


def raycast(
    origins: np.ndarray,
    angles_rad: np.ndarray,
    segments: np.ndarray | SegmentSet,
    max_range: float,
) -> np.ndarray:
    """Distance along each ray to the first segment it hits.

    A ray that starts on a segment reads 0. A ray running along a collinear
    segment hits the segment's nearest end (or reads 0 when it starts on it).
    Zero-length segments are points and are hit when the ray passes through
    them exactly.

    Parameters
    ----------
    origins
        (n, 2) ray origins [m]; a single (2,) origin is broadcast to all rays.
    angles_rad
        (n,) world-frame ray directions [rad].
    segments
        (S, 4) segments [m] or a :class:`SegmentSet`.
    max_range
        Rays that hit nothing within ``max_range`` [m] read ``max_range``.

    Returns
    -------
    numpy.ndarray
        (n,) distances [m] in ``[0, max_range]``.
    """
    ang = np.asarray(angles_rad, dtype=np.float64).reshape(-1)
    o = _as_points(origins, "origins")
    if o.shape[0] == 1:
        o = np.broadcast_to(o, (ang.shape[0], 2))
    elif o.shape[0] != ang.shape[0]:
        raise ValueError(
            f"origins (n, 2) and angles_rad (n,) must have the same n; "
            f"got {o.shape[0]} and {ang.shape[0]}"
        )
    if not (isinstance(max_range, int | float | np.floating) and max_range >= 0):
        raise ValueError(f"max_range must be a number >= 0, got {max_range!r}")
    s = _segment_set(segments)
    if s.n == 0 or ang.shape[0] == 0:
        return np.full(ang.shape[0], float(max_range))
    k = kernels()
    if k is None:
        return _raycast(o[:, 0:1], o[:, 1:2], np.cos(ang)[:, None], np.sin(ang)[:, None], s,
                        float(max_range))
    out = np.empty(ang.shape[0])
    k.cast_each(np.ascontiguousarray(o[:, 0]), np.ascontiguousarray(o[:, 1]), np.cos(ang),
                np.sin(ang), s.packed, float(max_range), out)
    return out


_finite = math.isfinite


def _check_rays(segments: Any, x: float, y: float, ang: np.ndarray, max_range: float,
                radius: float = 0.0) -> None:
    """Refuse, in words, what a sensor plugin may pass :func:`cast_rays` or :func:`rim_ranges`
    wrong (a few scalar tests: they run in the loop). A NaN origin read ``max_range`` on
    every ray and a negative range gave negative distances."""
    if segments.__class__ is SegmentSet and ang.ndim == 1 and _finite(x) and _finite(y) \
            and 0.0 < max_range < math.inf and 0.0 <= radius < math.inf:
        return
    if segments.__class__ is not SegmentSet:
        raise TypeError(f"segments: expected world.segment_set (a SegmentSet), got "
                        f"{type(segments).__name__}")
    if ang.ndim != 1:
        raise ValueError(f"angles_rad: expected a 1-D array of ray directions [rad], got shape "
                         f"{ang.shape}")
    if not (math.isfinite(x) and math.isfinite(y)):
        raise ValueError(f"x, y: expected a finite ray origin [m], got ({x!r}, {y!r})")
    if not (0.0 < max_range < math.inf and 0.0 <= radius < math.inf):
        raise ValueError(f"max_range = {max_range!r}, radius = {radius!r}: expected a finite "
                         "max_range > 0 and radius >= 0 [m]")


def cast_rays(segments: SegmentSet, x: float, y: float, angles_rad: np.ndarray,
              max_range: float) -> np.ndarray:
    """Fast ray casting from one point ``(x, y)`` [m], for sensors in the control loop.

    The unchecked core of :func:`raycast` (same ``angles_rad``, ``max_range`` and result)
    for the common case of a sensor: every ray starts at the robot's centre, and
    ``segments`` is a :class:`SegmentSet` (pass ``world.segment_set``: every wall and
    obstacle edge, cached by the world).
    """
    ang = np.asarray(angles_rad, dtype=np.float64)
    _check_rays(segments, x, y, ang, max_range)
    if segments.n == 0:
        return np.full(ang.shape[0], float(max_range))
    k = kernels()
    if k is None:
        return _raycast(np.array([[float(x)]]), np.array([[float(y)]]), np.cos(ang)[:, None],
                        np.sin(ang)[:, None], segments, float(max_range))
    out = np.empty(ang.shape[0])
    k.cast(float(x), float(y), np.cos(ang), np.sin(ang), segments.packed, float(max_range), out)
    return out


def rim_ranges(segments: SegmentSet, x: float, y: float, angles_rad: np.ndarray,
               max_range: float, radius: float, group: int = 1, *,
               clip: bool = False, heading: float | None = None) -> np.ndarray:
    """What a range finder on a disc reads: ranges from the rim, for sensors in the loop.

    Rays of ``max_range + radius`` from the disc's centre ``(x, y)``; a ray
    that hits nothing reads exactly ``max_range``, one that hits reads the
    distance from the rim (``hit - radius``, negative when the disc overlaps
    a segment). With ``group > 1`` each reading is the nearest of ``group``
    consecutive rays (a beam's cone sampled by several rays).

    Parameters
    ----------
    segments
        The world's :class:`SegmentSet` (``world.segment_set``).
    x, y
        The disc's centre [m].
    angles_rad
        (n * group,) world-frame ray directions [rad], beam by beam.
    max_range
        Largest reading [m], > 0.
    radius
        Distance from the centre to the rim [m], >= 0.
    group
        Rays per reading.
    clip
        Clip the readings to ``[0, max_range]`` as well (a sensor without
        noise: ``numpy.clip`` of the result, in the same call).
    heading
        When given [rad], ``angles_rad`` are relative to it (a sensor's own ray angles, the
        robot's heading): the rays point at ``angles_rad + heading``, the sum and the rays'
        sines and cosines then computed in the compiled call (the same numbers).

    Returns
    -------
    numpy.ndarray
        (n,) readings [m] in ``[-radius, max_range]`` (``[0, max_range]`` with ``clip``).
    """
    ang = np.asarray(angles_rad, dtype=np.float64)
    _check_rays(segments, x, y, ang, max_range, radius)
    if not group >= 1 or ang.shape[0] % group:
        raise ValueError(f"rim_ranges: {ang.shape[0]} rays do not make groups of {group!r}; "
                         "expected a positive group size that divides the number of rays")
    n = ang.shape[0] // group
    k = kernels()
    fast = None if k is None or heading is None else fused()
    if fast is not None:
        out = np.empty(n)
        fast.ranges_at(float(x), float(y), float(heading), ang, segments.packed,
                       float(max_range), float(radius), int(group), bool(clip), out)
        return out
    if heading is not None:
        ang = ang + float(heading)
    if k is None:
        return _rim(cast_rays(segments, x, y, ang, max_range + radius), max_range, radius,
                    group, clip)
    out = np.empty(n)
    k.ranges(float(x), float(y), np.cos(ang), np.sin(ang), segments.packed, float(max_range),
             float(radius), int(group), bool(clip), out)
    return out


def cast_rays_many(segments: SegmentSet, xy: np.ndarray, angles_rad: np.ndarray,
                   max_range: float) -> np.ndarray:
    """:func:`cast_rays` for N origins at once (N robots' sensors in one call).

    Each origin's rays meet only the segments within ``max_range`` of it (the
    others cannot be hit nearer), padded with repeats of its first one, so the
    (N, K, n) arrays are a fraction of (N, S, n). Element by element the
    arithmetic is :func:`cast_rays`' own: row ``i`` is bit-identical to
    ``cast_rays(segments, *xy[i], angles_rad[i], max_range)``: ``xy`` is (N, 2) ray
    origins [m], ``angles_rad`` (N, n) world-frame directions [rad], one row per origin,
    and the result (N, n) distances [m] in ``[0, max_range]``.
    """
    ang = np.asarray(angles_rad, dtype=np.float64)
    xy = np.asarray(xy, dtype=np.float64)
    n = xy.shape[0]
    if segments.n == 0:
        return np.full(ang.shape, float(max_range))
    near = _dist2(xy[:, 0:1], xy[:, 1:2], segments) <= (max_range * (1.0 + 1e-9) + 1e-12) ** 2
    count = near.sum(axis=1)
    k = max(int(count.max()), 1)
    order = np.argsort(~near, axis=1, kind="stable")[:, :k]  # near segments first
    idx = np.where(np.arange(k) < count[:, None], order, order[:, :1])
    sub = SegmentSet.__new__(SegmentSet)  # (N, K, 1) columns: the kernel broadcasts them
    sub.ax, sub.ay = segments.ax[idx][..., None], segments.ay[idx][..., None]
    sub.ex, sub.ey = segments.ex[idx][..., None], segments.ey[idx][..., None]
    return _raycast(xy[:, 0].reshape(n, 1, 1), xy[:, 1].reshape(n, 1, 1),
                    np.cos(ang)[:, None, :], np.sin(ang)[:, None, :], sub, float(max_range))



def rim_ranges_many(segments: SegmentSet, xy: np.ndarray, angles_rad: np.ndarray,
                    max_range: float, radius: float, group: int = 1, *,
                    clip: bool = False) -> np.ndarray:
    """:func:`rim_ranges` for N discs at once (N robots' range finders in one call).

    Row ``i`` is bit-identical to ``rim_ranges(segments, *xy[i], angles_rad[i], max_range,
    radius, group, clip=clip)``: one compiled call for all N when the kernels are there
    (:mod:`sitframe.sim.kernels`), else :func:`cast_rays_many`.

    Parameters
    ----------
    segments
        The world's :class:`SegmentSet`.
    xy
        (N, 2) disc centres [m].
    angles_rad
        (N, n * group) world-frame ray directions [rad], one row per disc, beam by beam.
    max_range, radius, group, clip
        As :func:`rim_ranges`.

    Returns
    -------
    numpy.ndarray
        (N, n) readings [m] in ``[-radius, max_range]`` (``[0, max_range]`` with ``clip``).
    """
    ang = np.asarray(angles_rad, dtype=np.float64)
    xy = np.asarray(xy, dtype=np.float64)
    if (ang.ndim != 2 or not group >= 1 or ang.shape[1] % group
            or xy.shape != (ang.shape[0], 2)):
        raise ValueError(f"rim_ranges_many: expected (N, 2) centres and (N, n * {group!r}) "
                         f"angles, got {xy.shape} and {ang.shape}")
    n = ang.shape[1] // group
    k = kernels()
    if k is None:
        return _rim(cast_rays_many(segments, xy, ang, max_range + radius), max_range, radius,
                    group, clip)
    out = np.empty((xy.shape[0], n))
    k.ranges_many(xy, np.cos(ang), np.sin(ang), segments.packed, float(max_range),
                  float(radius), int(group), bool(clip), out)
    return out


def _rim(dist: np.ndarray, max_range: float, radius: float, group: int,
         clip: bool) -> np.ndarray:
    """Readings from the rim: the (..., n * group) ray distances from the centre, each
    group's nearest, less ``radius``; ``max_range`` where nothing was hit (numpy fallback)."""
    reach = max_range + radius
    if group > 1:
        dist = dist.reshape(*dist.shape[:-1], -1, group).min(axis=-1)
    out = np.where(dist >= reach, max_range, dist - radius)
    return np.clip(out, 0.0, max_range) if clip else out


_EPS = 1e-12


def _raycast(
    px: np.ndarray,
    py: np.ndarray,
    dx: np.ndarray,
    dy: np.ndarray,
    s: SegmentSet,
    max_range: float,
) -> np.ndarray:
    """Core of :func:`raycast`; px, py, dx, dy are (n, 1) or (1, 1) columns."""
    wx = s.ax - px  # (n|1, S)
    wy = s.ay - py
    denom = dx * s.ey - dy * s.ex  # (n, S)  cross(d, e)
    t_num = wx * s.ey - wy * s.ex  # cross(w, e)
    u_num = wx * dy - wy * dx  # cross(w, d)
    # Near-parallel rays give huge quotients (overflow to inf) and exactly
    # parallel ones 0/0: both are filtered out by ``hit`` below.
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        t = t_num / denom
        u = u_num / denom
    # A hair of tolerance (1e-12) so rays starting on, or grazing the end of,
    # a segment are not lost to rounding.
    hit = (denom != 0.0) & (t >= -_EPS) & (u >= -_EPS) & (u <= 1.0 + _EPS)
    dist = np.where(hit, np.maximum(t, 0.0), max_range)
    parallel = denom == 0.0
    if parallel.any():
        # Collinear segments (and points lying on the ray's line, within the same
        # hair: a ray along a wall from a point on it can round to parallel with
        # an offset of 1e-16): the ray meets the nearest end ahead of it, or 0 if
        # it starts on the segment.
        coll = parallel & (np.abs(u_num) <= _EPS)
        if coll.any():
            ta = wx * dx + wy * dy  # projection of the start point
            tb = ta + s.ex * dx + s.ey * dy  # projection of the end point
            near = np.minimum(ta, tb)
            far = np.maximum(ta, tb)
            tc = np.maximum(near, 0.0)
            dist = np.where(coll & (far >= 0.0), np.minimum(dist, tc), dist)
    out = dist.min(axis=1)
    np.minimum(out, max_range, out=out)
    return out


# ----------------------------------------------------------------------------- polygons


def polyline_segments(points: np.ndarray) -> np.ndarray:
    """(k, 2) polyline → (k-1, 4) segments between consecutive points."""
    p = _as_points(points)
    return np.concatenate([p[:-1], p[1:]], axis=1)


def polygon_edges(points: np.ndarray) -> np.ndarray:
    """(k, 2) closed polygon (first point not repeated) → (k, 4) edges, closing edge last."""
    p = _as_points(points)
    return np.concatenate([p, np.roll(p, -1, axis=0)], axis=1)


def polygon_area(points: np.ndarray) -> float:
    """Signed area [m²] of a closed polygon (positive = counter-clockwise)."""
    p = _as_points(points)
    x, y = p[:, 0], p[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def point_in_polygon(points: np.ndarray, polygon: np.ndarray) -> np.ndarray:
    """Even–odd test: which points lie strictly inside a closed polygon.

    Points exactly on an edge may go either way; callers that care use a
    clearance test as well.

    Parameters
    ----------
    points
        (k, 2) query points [m].
    polygon
        (m, 2) polygon vertices, first point not repeated (a repeated closing
        point is harmless).

    Returns
    -------
    numpy.ndarray
        (k,) bool.
    """
    p = _as_points(points)
    poly = _as_points(polygon, "polygon")
    k = kernels()
    if k is not None:
        out = np.empty(p.shape[0], dtype=np.bool_)
        k.point_in_polygon(np.require(p, np.float64, ["C", "W"]),  # (one compiled type)
                           np.require(poly, np.float64, ["C", "W"]), out)
        return out
    x0, y0 = poly[:, 0], poly[:, 1]
    x1, y1 = np.roll(x0, -1), np.roll(y0, -1)
    py = p[:, 1:2]
    px = p[:, 0:1]
    straddle = (y0 > py) != (y1 > py)  # (k, m)
    dy = np.where(y1 != y0, y1 - y0, 1.0)
    # t = (py - y0) / dy is in [0, 1] on every edge that straddles py, so x_cross
    # is finite there; elsewhere it may overflow, and is masked by ``straddle``.
    with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
        x_cross = x0 + ((py - y0) / dy) * (x1 - x0)
    crossings = np.count_nonzero(straddle & (px < x_cross), axis=1)
    return (crossings % 2) == 1


def _orient(ax, ay, bx, by, cx, cy):  # noqa: ANN001, ANN202 - internal, arrays
    return (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)


def segments_intersect(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Which segments of ``a`` touch or cross which segments of ``b``.

    Parameters
    ----------
    a
        (m, 4) segments.
    b
        (n, 4) segments.

    Returns
    -------
    numpy.ndarray
        (m, n) bool, True when the closed segments share at least one point.
    """
    a = as_segments(a)
    b = as_segments(b)
    p1x, p1y, p2x, p2y = (a[:, i : i + 1] for i in range(4))
    q1x, q1y, q2x, q2y = (b[None, :, i] for i in range(4))
    d1 = _orient(q1x, q1y, q2x, q2y, p1x, p1y)
    d2 = _orient(q1x, q1y, q2x, q2y, p2x, p2y)
    d3 = _orient(p1x, p1y, p2x, p2y, q1x, q1y)
    d4 = _orient(p1x, p1y, p2x, p2y, q2x, q2y)
    proper = (((d1 > 0) & (d2 < 0)) | ((d1 < 0) & (d2 > 0))) & (
        ((d3 > 0) & (d4 < 0)) | ((d3 < 0) & (d4 > 0))
    )

    def on_seg(ox, oy, ex, ey, px, py):  # noqa: ANN001, ANN202
        return (
            (np.minimum(ox, ex) <= px)
            & (px <= np.maximum(ox, ex))
            & (np.minimum(oy, ey) <= py)
            & (py <= np.maximum(oy, ey))
        )

    touch = (
        ((d1 == 0) & on_seg(q1x, q1y, q2x, q2y, p1x, p1y))
        | ((d2 == 0) & on_seg(q1x, q1y, q2x, q2y, p2x, p2y))
        | ((d3 == 0) & on_seg(p1x, p1y, p2x, p2y, q1x, q1y))
        | ((d4 == 0) & on_seg(p1x, p1y, p2x, p2y, q2x, q2y))
    )
    return proper | touch


def polygon_self_intersection(points: np.ndarray, *, closed: bool = True) -> tuple[int, int] | None:
    """Find two edges of a polygon (or polyline) that touch where they should not.

    Non-adjacent edges must not share any point; adjacent edges may share only
    their common vertex (no zero-length edges, no fold-backs).

    Parameters
    ----------
    points
        (k, 2) vertices; for ``closed=True`` the first point is not repeated.
    closed
        Whether the last vertex connects back to the first.

    Returns
    -------
    tuple of int or None
        Indices ``(i, j)`` of the first offending pair of edges (edge ``i``
        runs from vertex ``i`` to vertex ``i + 1``), or None if the polygon
        is simple.
    """
    p = _as_points(points)
    edges = polygon_edges(p) if closed else polyline_segments(p)
    m = edges.shape[0]
    length2 = (edges[:, 2] - edges[:, 0]) ** 2 + (edges[:, 3] - edges[:, 1]) ** 2
    zero = np.flatnonzero(length2 == 0.0)
    if zero.size:
        i = int(zero[0])
        return (i, i)
    hits = segments_intersect(edges, edges)
    i_idx, j_idx = np.triu_indices(m, k=1)
    adjacent = (j_idx == i_idx + 1) | (closed & (i_idx == 0) & (j_idx == m - 1))
    # Adjacent edges always share their vertex; they are bad only if they fold
    # back on each other (collinear and pointing in opposite directions).
    ex, ey = edges[:, 2] - edges[:, 0], edges[:, 3] - edges[:, 1]
    cross = ex[i_idx] * ey[j_idx] - ey[i_idx] * ex[j_idx]
    dot = ex[i_idx] * ex[j_idx] + ey[i_idx] * ey[j_idx]
    fold = adjacent & (cross == 0.0) & (dot < 0.0)
    bad = np.where(adjacent, fold, hits[i_idx, j_idx])
    if m == 3 and closed:
        bad = fold  # a triangle's edges are all adjacent
    k = np.flatnonzero(bad)
    if k.size == 0:
        return None
    return int(i_idx[k[0]]), int(j_idx[k[0]])
