"""Brute-force references for :mod:`sitframe.sim.geometry` (plain Python loops, another method).

The property tests compare the vectorised functions with these; they are test oracles,
kept out of the package so that nothing but the tests depends on them.
"""

from __future__ import annotations

import math

import numpy as np


def point_segment_distance_reference(points: np.ndarray, segments: np.ndarray) -> np.ndarray:
    """Brute-force reference for :func:`point_segment_distance` (Python loops).

    Uses a different method: the minimum of the two end-point distances and,
    when the foot of the perpendicular falls inside the segment, the
    perpendicular distance.
    """
    pts = [(float(x), float(y)) for x, y in np.asarray(points, dtype=float).reshape(-1, 2)]
    segs = [tuple(float(v) for v in s) for s in np.asarray(segments, dtype=float).reshape(-1, 4)]
    out = np.empty((len(pts), len(segs)))
    for i, (px, py) in enumerate(pts):
        for j, (x0, y0, x1, y1) in enumerate(segs):
            best = min(math.hypot(px - x0, py - y0), math.hypot(px - x1, py - y1))
            lx, ly = x1 - x0, y1 - y0
            length = math.hypot(lx, ly)
            if length > 0.0:
                # unit direction first: products with a subnormal length would underflow
                ux, uy = lx / length, ly / length
                along = (px - x0) * ux + (py - y0) * uy
                if 0.0 <= along <= length:
                    perp = abs((px - x0) * uy - (py - y0) * ux)
                    best = min(best, perp)
            out[i, j] = best
    return out


def raycast_reference(
    origins: np.ndarray,
    angles_rad: np.ndarray,
    segments: np.ndarray,
    max_range: float,
    *,
    tol: float = 0.0,
) -> np.ndarray:
    """Brute-force reference for :func:`raycast` (Python loops, scalar math).

    Intersects each ray with each segment by solving the 2×2 system with
    Cramer's rule; collinear overlaps are handled by projecting the end points.
    ``tol`` widens (positive) or narrows (negative) what counts as a hit at
    the segment ends and the ray origin, so tests can bracket the fast result
    in floating-point edge cases: ``ref(tol=+e) <= raycast <= ref(tol=-e)``.
    """
    ang = np.asarray(angles_rad, dtype=float).reshape(-1)
    org = np.asarray(origins, dtype=float).reshape(-1, 2)
    if org.shape[0] == 1:
        org = np.repeat(org, ang.shape[0], axis=0)
    segs = [tuple(float(v) for v in s) for s in np.asarray(segments, dtype=float).reshape(-1, 4)]
    out = np.empty(ang.shape[0])
    for i in range(ang.shape[0]):
        px, py = float(org[i, 0]), float(org[i, 1])
        dx, dy = math.cos(float(ang[i])), math.sin(float(ang[i]))
        best = float(max_range)
        for x0, y0, x1, y1 in segs:
            ex, ey = x1 - x0, y1 - y0
            wx, wy = x0 - px, y0 - py
            elen = math.hypot(ex, ey)
            det = dx * ey - dy * ex
            if det != 0.0:
                t = (wx * ey - wy * ex) / det
                u = (wx * dy - wy * dx) / det
                utol = tol / elen if elen > 0 else tol
                if t >= -tol and -utol <= u <= 1.0 + utol:
                    best = min(best, max(t, 0.0))
            # parallel (or a point): hit only if the segment lies on the ray's line
            off = abs(wx * dy - wy * dx)
            exact = det == 0.0 and off == 0.0
            loose = tol > 0.0 and abs(det) <= tol * max(elen, 1.0) and off <= tol
            if exact or loose:
                ta = wx * dx + wy * dy
                tb = (x1 - px) * dx + (y1 - py) * dy
                if max(ta, tb) >= -tol:
                    best = min(best, max(min(ta, tb), 0.0))
        out[i] = min(best, float(max_range))
    return out
