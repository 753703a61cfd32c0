"""Property tests: the vectorised geometry agrees with the brute-force references."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from sitframe import geometry as g

coord = st.floats(-5.0, 5.0, allow_nan=False, allow_infinity=False, width=64)
small_int = st.integers(-4, 4).map(float)  # exact values: hits ends, parallels, on-segment
mixed = st.one_of(coord, small_int)


@st.composite
def segment_arrays(draw: st.DrawFn, min_size: int = 1, max_size: int = 8) -> np.ndarray:
    n = draw(st.integers(min_size, max_size))
    rows = []
    for _ in range(n):
        kind = draw(st.sampled_from(["free", "free", "point", "axis"]))
        x0, y0 = draw(mixed), draw(mixed)
        if kind == "point":
            rows.append([x0, y0, x0, y0])
        elif kind == "axis":
            length = draw(mixed)
            rows.append([x0, y0, x0 + length, y0] if draw(st.booleans()) else
                        [x0, y0, x0, y0 + length])
        else:
            rows.append([x0, y0, draw(mixed), draw(mixed)])
    return np.array(rows, dtype=float)


angles = st.one_of(
    st.floats(-math.pi, math.pi, allow_nan=False, width=64),
    st.sampled_from([0.0, math.pi / 2, math.pi, -math.pi / 2, math.pi / 4]),
)


@settings(max_examples=300, deadline=None)
@given(segs=segment_arrays(), ox=mixed, oy=mixed, angs=st.lists(angles, min_size=1, max_size=6))
def test_raycast_matches_reference(segs: np.ndarray, ox: float, oy: float, angs: list) -> None:
    origins = np.tile([ox, oy], (len(angs), 1))
    a = np.array(angs)
    fast = g.raycast(origins, a, segs, 4.0)
    lo = g._raycast_reference(origins, a, segs, 4.0, tol=1e-9)
    hi = g._raycast_reference(origins, a, segs, 4.0, tol=-1e-9)
    assert np.all(fast >= lo - 1e-7), (fast, lo)
    assert np.all(fast <= hi + 1e-7), (fast, hi)
    assert np.all((fast >= 0) & (fast <= 4.0))
    # the cached SegmentSet gives identical numbers
    assert np.array_equal(fast, g.raycast(origins, a, g.SegmentSet(segs), 4.0))


@settings(max_examples=200, deadline=None)
@given(segs=segment_arrays(), t=st.floats(0, 1), ang=angles)
# along the wall y = x from a point on it: cos and sin of 45 deg differ in the last bit,
# the cross product rounds to 0 (parallel) while the offset does not (1e-16)
@example(segs=np.array([[2.294921875, 2.294921875, -1.0, -1.0], [0.0, 0.0, 0.0, 0.0]]),
         t=0.1875, ang=0.7853981633974483)
def test_ray_starting_on_segment_reads_zero(segs: np.ndarray, t: float, ang: float) -> None:
    x0, y0, x1, y1 = segs[0]
    origin = np.array([[x0 + t * (x1 - x0), y0 + t * (y1 - y0)]])
    d = g.raycast(origin, np.array([ang]), segs, 3.0)
    # numerically "on" the segment: the hit is at (essentially) zero
    assert d[0] < 1e-6 or g.min_distance(origin, segs[:1])[0] > 1e-12


def test_ray_parallel_collinear_and_points() -> None:
    segs = np.array([[2.0, 0.0, 3.0, 0.0], [1.0, 1.0, 2.0, 1.0], [1.5, -1.0, 1.5, -1.0]])
    # along +x: collinear segment starts at 2 (the parallel one at y=1 is ignored)
    assert g.raycast(np.zeros((1, 2)), np.array([0.0]), segs, 5.0)[0] == pytest.approx(2.0)
    # from inside the collinear segment
    assert g.raycast(np.array([[2.5, 0.0]]), np.array([0.0]), segs, 5.0)[0] == 0.0
    # collinear but behind
    assert g.raycast(np.array([[4.0, 0.0]]), np.array([0.0]), segs, 5.0)[0] == 5.0
    # a point segment exactly on the ray
    pt = np.array([[1.5, -1.0, 1.5, -1.0]])
    assert g.raycast(np.array([[0.5, -1.0]]), np.array([0.0]), pt, 5.0)[0] == 1.0
    # empty segment set
    assert g.raycast(np.zeros((2, 2)), np.zeros(2), np.zeros((0, 4)), 3.0).tolist() == [3.0, 3.0]


@settings(max_examples=300, deadline=None)
@given(
    segs=segment_arrays(),
    pts=arrays(np.float64, st.tuples(st.integers(1, 6), st.just(2)), elements=mixed),
)
# a subnormal-length segment: the reference's cross product used to underflow to 0
@example(segs=np.array([[0.0, 0.0, 0.0, 5e-324]]), pts=np.array([[0.0, 0.5]]))
def test_point_segment_distance_matches_reference(segs: np.ndarray, pts: np.ndarray) -> None:
    fast = g.point_segment_distance(pts, segs)
    ref = g._point_segment_distance_reference(pts, segs)
    assert fast.shape == (pts.shape[0], segs.shape[0])
    np.testing.assert_allclose(fast, ref, atol=1e-9, rtol=1e-9)
    d, idx, nearest = g.nearest_on_segments(pts, segs)
    np.testing.assert_allclose(d, ref.min(axis=1), atol=1e-9)
    np.testing.assert_allclose(np.hypot(*(pts - nearest).T), d, atol=1e-9)
    np.testing.assert_allclose(g.min_distance(pts, segs), d, atol=1e-12)


def test_polygon_helpers() -> None:
    square = np.array([[0, 0], [2, 0], [2, 2], [0, 2]], dtype=float)
    inside = g.point_in_polygon(np.array([[1, 1], [3, 1], [-0.1, 1], [1, 1.9]]), square)
    assert inside.tolist() == [True, False, False, True]
    assert g.polygon_area(square) == 4.0
    assert g.polygon_self_intersection(square) is None
    bowtie = np.array([[0, 0], [2, 2], [2, 0], [0, 2]], dtype=float)
    assert g.polygon_self_intersection(bowtie) is not None
    repeated = np.array([[0, 0], [1, 0], [1, 0], [0, 1]], dtype=float)
    assert g.polygon_self_intersection(repeated) == (1, 1)
    fold = np.array([[0, 0], [2, 0], [1, 0]], dtype=float)
    assert g.polygon_self_intersection(fold) is not None
    triangle = np.array([[0, 0], [1, 0], [0, 1]], dtype=float)
    assert g.polygon_self_intersection(triangle) is None
    # an open polyline that crosses itself
    zig = np.array([[0, 0], [2, 0], [1, 1], [1, -1]], dtype=float)
    assert g.polygon_self_intersection(zig, closed=False) is not None


def test_bad_shapes_raise_clearly() -> None:
    with pytest.raises(ValueError, match=r"\(S, 4\)"):
        g.raycast(np.zeros((1, 2)), np.zeros(1), np.zeros((3, 3)), 1.0)
    with pytest.raises(ValueError, match="same n"):
        g.raycast(np.zeros((2, 2)), np.zeros(3), np.zeros((1, 4)), 1.0)
    with pytest.raises(TypeError):
        g.point_segment_distance([["a", "b"]], np.zeros((1, 4)))


def test_point_in_polygon_with_a_nearly_flat_edge_is_quiet():
    """An edge with a subnormal rise used to overflow (a RuntimeWarning; found by the fuzzer)."""
    square = np.array([[0.0, 0.0], [2.0, 5e-324], [2.0, 2.0], [0.0, 2.0]])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        inside = g.point_in_polygon(np.array([[1.0, 1.0], [3.0, 1.0], [1.0, 1e300]]), square)
    assert inside.tolist() == [True, False, False]
