"""Property tests: the vectorised geometry agrees with the brute-force references."""

from __future__ import annotations

import math
import re
import warnings

import numpy as np
import pytest
from geometry_reference import point_segment_distance_reference, raycast_reference
from hypothesis import example, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from sitframe.sim import geometry as g

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
    lo = raycast_reference(origins, a, segs, 4.0, tol=1e-9)
    hi = raycast_reference(origins, a, segs, 4.0, tol=-1e-9)
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
@example(segs=np.array([[2.0, 0.0, 0.0, -2.0], [0.0, 0.0, 0.0, 0.0]]), t=0.13889364220217407,
         ang=0.7853981633974483)
def test_ray_starting_on_segment_reads_zero(segs: np.ndarray, t: float, ang: float) -> None:
    x0, y0, x1, y1 = segs[0]
    origin = np.array([[x0 + t * (x1 - x0), y0 + t * (y1 - y0)]])
    d = g.raycast(origin, np.array([ang]), segs, 3.0)
    # numerically "on" the segment: the hit is at (essentially) zero -- unless the ray runs
    # along the segment's line (to 1e-9 rad) from a point a rounding off it, which the
    # ray's line then meets far away or never (e.g. a 45 deg ray, whose cosine and sine
    # differ in the last bit, along a 45 deg segment from 5.6e-17 m beside it)
    along = abs(math.cos(ang) * (y1 - y0) - math.sin(ang) * (x1 - x0)) <= \
        1e-9 * math.hypot(x1 - x0, y1 - y0)
    assert d[0] < 1e-6 or g.min_distance(origin, segs[:1])[0] > 1e-12 or along


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
    ref = point_segment_distance_reference(pts, segs)
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


# a room 6 x 4 m, an inner wall, a triangle and a point post: with max_range 2.5 some rays
# hit nothing, and the origins see different numbers of segments within range
SENSOR_ROOM = np.concatenate([
    g.polygon_edges(np.array([[0.0, 0.0], [6.0, 0.0], [6.0, 4.0], [0.0, 4.0]])),
    np.array([[3.0, 1.0, 3.0, 3.0], [5.2, 0.7, 5.2, 0.7]]),
    g.polygon_edges(np.array([[4.2, 2.6], [4.8, 2.6], [4.5, 3.2]])),
])


def _rim_reference(xy: np.ndarray, ang: np.ndarray, max_range: float, radius: float,
                   group: int, clip: bool) -> np.ndarray:
    """What a range finder on a disc reads, from the brute-force ray cast."""
    reach = max_range + radius
    dist = raycast_reference(xy, ang, SENSOR_ROOM, reach).reshape(-1, group).min(axis=1)
    out = np.where(dist >= reach, max_range, dist - radius)
    return np.clip(out, 0.0, max_range) if clip else out


@pytest.mark.parametrize("compiled", [True, False], ids=["compiled", "numpy"])
def test_sensor_casts_match_the_reference_with_and_without_compiled_kernels(
        compiled: bool, monkeypatch: pytest.MonkeyPatch) -> None:
    """The sensors' unchecked fast paths (one origin, N origins, readings from a disc's rim)
    read what the brute-force cast reads, whether numba is there or not (SITFRAME_NUMBA=0)."""
    from sitframe.sim import kernels

    if not compiled:
        monkeypatch.setattr(kernels, "_LOADED", [None])
    elif kernels.load() is None:
        pytest.skip("compiled kernels switched off")
    rng = np.random.default_rng(5)
    s = g.SegmentSet(SENSOR_ROOM)
    # (0.6, 2.0): the inner wall is 2.4 m away, within range of the rays near 0 rad only
    xy = np.array([[0.5, 0.5], [2.9, 2.0], [5.5, 3.5], [1.0, 3.9], [4.5, 1.0], [0.6, 2.0]])
    ang = rng.uniform(-4.0, 4.0, (6, 12))
    ang[5, :3] = [0.0, 0.1, -0.1]
    pairs = list(zip(xy, ang, strict=True))
    ref = np.stack([raycast_reference(p, a, SENSOR_ROOM, 2.5) for p, a in pairs])
    assert (ref == 2.5).any() and (ref < 2.5).any()
    many = g.cast_rays_many(s, xy, ang, 2.5)
    np.testing.assert_allclose(many, ref, rtol=0, atol=1e-9)
    for i, ((x, y), a) in enumerate(pairs):
        one = g.cast_rays(s, x, y, a, 2.5)
        np.testing.assert_allclose(one, ref[i], rtol=0, atol=1e-9)
        assert np.array_equal(one, many[i])  # row i of the many-origin cast is the one cast
    for group, clip in [(1, False), (2, True), (3, True), (4, False)]:
        want = np.stack([_rim_reference(p, a, 2.5, 0.3, group, clip) for p, a in pairs])
        got = g.rim_ranges_many(s, xy, ang, 2.5, 0.3, group, clip=clip)
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-9)
        for i, ((x, y), a) in enumerate(pairs):
            assert np.array_equal(g.rim_ranges(s, x, y, a, 2.5, 0.3, group, clip=clip), got[i])
    # defaults: one ray per reading, not clipped (the disc at (1.0, 3.9) overlaps the wall)
    unclipped = g.rim_ranges_many(s, xy, ang, 2.5, 0.3)
    np.testing.assert_allclose(unclipped, np.stack(
        [_rim_reference(p, a, 2.5, 0.3, 1, False) for p, a in pairs]), rtol=0, atol=1e-9)
    assert unclipped.min() < 0
    for (x, y), a, row in zip(xy, ang, unclipped, strict=True):
        assert np.array_equal(g.rim_ranges(s, x, y, a, 2.5, 0.3), row)
    # a ray that hits nothing reads exactly max_range (here (1.2 + 0.13) - 0.13 != 1.2)
    assert g.rim_ranges(s, 1.5, 2.0, ang[0], 1.2, 0.13).tolist() == [1.2] * 12
    assert g.rim_ranges_many(s, np.array([[1.5, 2.0]]), ang[:1], 1.2, 0.13, 3,
                             clip=True).tolist() == [[1.2] * 4]
    assert g.rim_ranges_many(s, np.array([[1.5, 2.0]]), ang[:1], 1.2, 0.13).tolist() == [
        [1.2] * 12]
    # bad groups and shapes are refused naming what was expected
    for group in (0, 5):
        with pytest.raises(ValueError, match=rf"^rim_ranges: 12 rays do not make groups of "
                                             rf"{group}; expected a positive group size that "
                                             r"divides the number of rays$"):
            g.rim_ranges(s, 1.0, 1.0, ang[0], 2.5, 0.3, group)
    with pytest.raises(ValueError, match=r"^rim_ranges: 0 rays do not make groups of 0; "):
        g.rim_ranges(s, 1.0, 1.0, ang[0, :0], 2.5, 0.3, 0)  # (no rays, no group either)
    for bad_xy, bad_ang, group in [(xy[:, :1], ang, 1), (xy, ang, 0), (xy, ang, 5),
                                   (xy[:1], ang[0], 1), (xy, ang[:, :0], 0), (xy, ang, -3)]:
        with pytest.raises(ValueError, match=r"^rim_ranges_many: expected \(N, 2\) centres "
                                             rf"and \(N, n \* {group}\) angles, got "):
            g.rim_ranges_many(s, bad_xy, bad_ang, 2.5, 0.3, group)
    with pytest.raises(ValueError, match="^nearest_on_segments needs at least one segment, "
                                         "got 0$"):
        g.nearest_on_segments(np.zeros((1, 2)), np.zeros((0, 4)))
    # no segments at all: every ray reads the maximum range
    empty = g.SegmentSet(np.zeros((0, 4)))
    assert g.cast_rays(empty, 1.0, 1.0, ang[0], 2.5).tolist() == [2.5] * 12
    assert g.cast_rays_many(empty, xy, ang, 2.5).tolist() == [[2.5] * 12] * 6
    assert g.rim_ranges(empty, 1.0, 1.0, ang[0], 2.5, 0.3, 3).tolist() == [2.5] * 4
    assert g.raycast(np.ones((12, 2)), ang[0], empty, 2.5).tolist() == [2.5] * 12


def _touch_reference(s: tuple, t: tuple) -> bool:
    """Whether two closed segments share a point, in exact rational arithmetic (parametric
    form; a zero-length segment is a point)."""
    from fractions import Fraction as F

    px, py, qx, qy = (F(v) for v in s)
    ax, ay, bx, by = (F(v) for v in t)
    rx, ry, ux, uy = qx - px, qy - py, bx - ax, by - ay
    wx, wy = ax - px, ay - py

    def on(ox, oy, dx, dy, x, y):  # (x, y) on the segment from (ox, oy) along (dx, dy)
        if dx == dy == 0:
            return (x, y) == (ox, oy)
        if dx * (y - oy) - dy * (x - ox) != 0:
            return False
        k = ((x - ox) * dx + (y - oy) * dy) / (dx * dx + dy * dy)
        return 0 <= k <= 1

    den = rx * uy - ry * ux
    if den != 0:
        return 0 <= (wx * uy - wy * ux) / den <= 1 and 0 <= (wx * ry - wy * rx) / den <= 1
    # parallel, collinear or points: they meet iff an end of one lies on the other
    return (on(px, py, rx, ry, ax, ay) or on(px, py, rx, ry, bx, by)
            or on(ax, ay, ux, uy, px, py) or on(ax, ay, ux, uy, qx, qy))


quarter = st.integers(-8, 8).map(lambda k: k / 4)  # exact in binary: orientations are exact
seg = st.tuples(quarter, quarter, quarter, quarter)


@settings(max_examples=150, deadline=None)
@given(a=st.lists(seg, min_size=1, max_size=4), b=st.lists(seg, min_size=1, max_size=4))
@example(a=[(0, 0, 1, 0)], b=[(1, 0, 2, 0)])  # collinear, sharing an end
@example(a=[(0, 0, 1, 0)], b=[(1.25, 0, 2, 0)])  # collinear, apart
@example(a=[(0, 0, 1, 0.5)], b=[(0.5, 0.5, 1.5, 0.75)])  # orientations in (0, 1)
def test_segments_intersect_matches_exact_arithmetic(a: list, b: list) -> None:
    got = g.segments_intersect(np.array(a), np.array(b))
    assert got.shape == (len(a), len(b))
    assert got.tolist() == [[_touch_reference(s, t) for t in b] for s in a]


def test_polygon_area_sign_and_subsets():
    tri = np.array([[1.0, 1.0], [4.0, 1.0], [1.0, 5.0]])
    assert g.polygon_area(tri) == 6.0 and g.polygon_area(tri[::-1]) == -6.0
    segs = np.arange(12.0).reshape(3, 4)
    s = g.SegmentSet(segs)
    assert s.subset([0, 2]).segments.tolist() == segs[[0, 2]].tolist()
    assert s.subset(np.array([False, True, False])).segments.tolist() == [segs[1].tolist()]
    with pytest.raises(ValueError, match=r"^polygon must have shape \(k, 2\)"):
        g.point_in_polygon(np.zeros((1, 2)), np.zeros((4, 3)))


def test_point_in_polygon_with_a_tiny_vertical_edge_is_quiet():
    """A vertical edge of subnormal height: (py - y0) / dy overflows and meets a zero run."""
    poly = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 5e-324], [2.0, 2.0], [0.0, 2.0]])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        inside = g.point_in_polygon(np.array([[1.0, 1.0], [3.0, 1.0], [1.0, 3.0]]), poly)
    assert inside.tolist() == [True, False, False]


def test_polygon_self_intersection_open_closed_folds_and_edge_lengths():
    z = np.array([[0.0, 0.0], [2.0, 0.0], [0.0, 2.0], [2.0, 2.0]])
    assert g.polygon_self_intersection(z, closed=False) is None  # an open Z is simple ...
    assert g.polygon_self_intersection(z) == (1, 3)  # ... its closing edge crosses it
    for simple in ([[0, -2], [2, 0], [0, 2], [-2, 0]], [[0, -1], [2, -1], [2, 1], [0, 1]],
                   [[0, 0], [1, -1], [2, 0], [1, 1]],
                   [[0, 0], [0.5, 0], [1, 0], [1, 1], [0, 1]]):  # collinear, same direction
        assert g.polygon_self_intersection(np.array(simple, dtype=float)) is None, simple
    for fold in ([[0, 0], [2, 0], [1, 0], [1, 1]], [[0, 0], [2, 2], [1, 1], [3, 0]],
                 [[0, 0], [4, 4], [2, 2], [5, 0]], [[0, 0], [0, 2], [0, 1], [1, 1]]):
        assert g.polygon_self_intersection(np.array(fold, dtype=float)) == (0, 1), fold


@pytest.fixture(params=["compiled", "numpy"])
def kernel_path(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch) -> str:
    """Run a test with the compiled kernels and again with the numpy path (no numba)."""
    from sitframe.sim import kernels

    if request.param == "numpy":
        monkeypatch.setattr(kernels, "_LOADED", [None])
    elif kernels.load() is None:
        pytest.skip("compiled kernels switched off")
    return request.param


A = 1.0  # a ray direction with both components non-zero and inexact
D = np.array([math.cos(A), math.sin(A)])
# (origin, angle, segments, expected reading with max_range 5): parallel and collinear
# segments, the 1e-12 tolerance at the ray's origin and at a segment's ends, hits beyond
# max_range; each reading is the documented one ("a ray that starts on a segment reads 0,
# a ray along a collinear segment hits its nearest end")
RAY_EDGES = [
    ((0.0, 0.0), 0.0, [[2.0, -0.5, 2.0, 0.5]], 2.0),  # square on: cross(d, e) = 1
    ((0.0, 0.0), 0.0, [[2.0, 0.0, 3.0, 0.0]], 2.0),  # collinear ahead
    ((0.0, 0.0), 0.0, [[3.0, 0.0, 2.0, 0.0]], 2.0),  # ... drawn the other way
    ((0.0, 0.0), 0.0, [[0.5, 0.0, 2.0, 0.0]], 0.5),
    ((0.0, 0.0), 0.0, [[-1.0, 0.0, 0.5, 0.0]], 0.0),  # starts on it
    ((0.0, 0.0), 0.0, [[-1.0, 0.0, 0.0, 0.0]], 0.0),  # starts on its end
    ((0.0, 0.0), 0.0, [[-3.0, 0.0, -1.0, 0.0]], 5.0),  # collinear behind
    ((0.0, 0.0), 0.0, [[1.0, 1.0, 3.0, 1.0], [-3.0, 0.0, -1.0, 0.0]], 5.0),  # parallel beside
    ((0.0, 0.0), 0.0, [[10.0, -1.0, 10.0, 1.0]], 5.0),  # beyond max_range
    ((0.0, 1e-12), 0.0, [[2.0, 0.0, 3.0, 0.0]], 2.0),  # collinear within the hair
    ((0.0, 2e-12), 0.0, [[2.0, 0.0, 3.0, 0.0]], 5.0),  # ... and just beyond it
    ((1e-12, 0.0), 0.0, [[0.0, -1.0, 0.0, 1.0]], 0.0),  # 1e-12 past a wall: on it
    ((0.0, -1e-12), 0.0, [[1.0, 0.0, 1.0, 1.0]], 1.0),  # grazing an end by 1e-12
    ((0.0, 1.0 + 1e-12), 0.0, [[1.0, 0.0, 1.0, 1.0]], 1.0),  # ... the other end
    # a wall 1e10 m long rising 1e-300 m: the quotients overflow (and are not hits)
    ((0.0, 1.0), 0.0, [[0.0, 0.0, 1e10, 1e-300]], 5.0),
    # along the inexact direction D: end points 2 D, 4 D are exact multiples of D
    ((0.0, 0.0), A, [[*(2 * D), *(4 * D)]], 2.0),
    ((0.0, 0.0), A, [[*(4 * D), *(2 * D)]], 2.0),
    ((0.0, 0.0), A, [[*(-2 * D), *(2 * D)]], 0.0),
    ((0.0, 0.0), A, [[*(-4 * D), *(-2 * D)]], 5.0),
]


def test_raycast_edge_cases_with_and_without_compiled_kernels(kernel_path: str) -> None:
    """Every edge reads what the docstring says, quietly (no RuntimeWarning), on both paths."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for origin, angle, segs, want in RAY_EDGES:
            got = g.raycast(np.array([origin]), np.array([angle]), np.array(segs), 5.0)
            assert got.shape == (1,)
            assert got[0] == pytest.approx(want, abs=1e-12), (origin, angle, segs)
        # several origins, one per ray; a single (2,) origin for all rays; a scalar angle
        walls = g.polygon_edges(np.array([[-1.0, -2.0], [3.0, -2.0], [3.0, 4.0], [-1.0, 4.0]]))
        got = g.raycast(np.array([[0.0, 0.0], [1.0, 1.0], [2.0, 3.0]]),
                        np.array([0.0, math.pi, -math.pi / 2]), walls, 10.0)
        np.testing.assert_allclose(got, [3.0, 2.0, 5.0], rtol=0, atol=1e-12)
        got = g.raycast(np.array([1.0, 1.0]), np.array([0.0, math.pi, -math.pi / 2]), walls, 10.0)
        np.testing.assert_allclose(got, [2.0, 2.0, 3.0], rtol=0, atol=1e-12)
        assert g.raycast(np.array([1.0, 1.0]), 0.0, walls, 10.0).tolist() == [2.0]
        # max_range 0 (the documented edge) reads 0; an int max_range is a number
        assert g.raycast(np.zeros((2, 2)), np.zeros(2), walls, 0).tolist() == [0.0, 0.0]
        assert g.raycast(np.zeros((1, 2)), np.zeros(1), walls[:0], 3).tolist() == [3.0]


def test_inputs_of_any_float_precision_are_read_as_float64(kernel_path: str) -> None:
    """float32 angles, segments and vertices (a policy's or a file's) give the readings of
    their float64 values: the arithmetic is float64 whatever the input's precision."""
    rng = np.random.default_rng(7)
    ang = rng.uniform(-4.0, 4.0, 24).astype(np.float32)
    xy = rng.uniform(0.5, 5.5, (3, 2)).astype(np.float32)
    room = SENSOR_ROOM.astype(np.float32)
    a64, xy64, room64 = ang.astype(np.float64), xy.astype(np.float64), room.astype(np.float64)
    s = g.SegmentSet(room)
    assert s.segments.dtype == np.float64
    assert np.array_equal(s.packed, g.SegmentSet(room64).packed)
    assert np.array_equal(g.raycast(xy[0], ang, room, 2.5), g.raycast(xy64[0], a64, room64, 2.5))
    assert np.array_equal(g.cast_rays(s, *xy64[0], ang, 2.5), g.cast_rays(s, *xy64[0], a64, 2.5))
    assert np.array_equal(g.rim_ranges(s, *xy64[0], ang, 2.5, 0.3, 2),
                          g.rim_ranges(s, *xy64[0], a64, 2.5, 0.3, 2))
    many = ang.reshape(3, 8)
    assert np.array_equal(g.cast_rays_many(s, xy, many, 2.5),
                          g.cast_rays_many(s, xy64, many.astype(np.float64), 2.5))
    assert np.array_equal(g.rim_ranges_many(s, xy, many, 2.5, 0.3, 2),
                          g.rim_ranges_many(s, xy64, many.astype(np.float64), 2.5, 0.3, 2))
    tri = rng.uniform(-3.0, 3.0, (5, 2)).astype(np.float32)
    assert g.polygon_area(tri) == g.polygon_area(tri.astype(np.float64))
    pts = rng.uniform(-3.0, 3.0, (40, 2))
    assert np.array_equal(g.point_in_polygon(pts, tri),
                          g.point_in_polygon(pts, tri.astype(np.float64)))
    assert g.polygon_edges(tri).dtype == g.polyline_segments(tri).dtype == np.float64


def test_geometry_refuses_bad_input_naming_it() -> None:
    segs = np.array([[0.0, 0.0, 1.0, 0.0]])
    with pytest.raises(ValueError, match=r"^origins must have shape \(k, 2\) = x, y; "
                                         r"got shape \(2, 3\)$"):
        g.raycast(np.zeros((2, 3)), np.zeros(2), segs, 1.0)
    with pytest.raises(TypeError, match=r"^origins must be a \(k, 2\) array of numbers, "
                                        r"got \[\['a', 'b'\]\]$"):
        g.raycast([["a", "b"]], np.zeros(1), segs, 1.0)
    with pytest.raises(ValueError, match=r"^origins \(n, 2\) and angles_rad \(n,\) must have "
                                         r"the same n; got 3 and 2$"):
        g.raycast(np.zeros((3, 2)), np.zeros(2), segs, 1.0)
    for bad in (-1.0, -1e-300, float("nan"), "5", None, [1.0]):
        with pytest.raises(ValueError, match=rf"^max_range must be a number >= 0, "
                                             rf"got {re.escape(repr(bad))}$"):
            g.raycast(np.zeros((1, 2)), np.zeros(1), segs, bad)
    with pytest.raises(ValueError, match=r"^segments must have shape \(S, 4\) = x0, y0, x1, y1; "
                                         r"got shape \(3, 3\)$"):
        g.raycast(np.zeros((1, 2)), np.zeros(1), np.zeros((3, 3)), 1.0)
    with pytest.raises(TypeError, match=r"^segments must be an \(S, 4\) array of numbers, "
                                        r"got \[\[0, 0, 1, 'x'\]\]$"):
        g.SegmentSet([[0, 0, 1, "x"]])
    with pytest.raises(TypeError, match=r"^points must be a \(k, 2\) array of numbers, "
                                        r"got \[\['a', 'b'\]\]$"):
        g.point_segment_distance([["a", "b"]], segs)
    for bad in (np.zeros(3), np.zeros((2, 3)), np.zeros((2, 2, 2))):
        with pytest.raises(ValueError, match=r"^points must have shape \(k, 2\) = x, y; "
                                             rf"got shape {re.escape(str(bad.shape))}$"):
            g.min_distance(bad, segs)
    # the documented edges: a single (2,) point is one point; no segments, no nearest one
    assert g.min_distance([3.0, 4.0], segs).tolist() == [np.hypot(2.0, 4.0)]
    assert g.point_segment_distance((1.0, 2.0), segs).tolist() == [[2.0]]
    assert g.min_distance(np.zeros((3, 2)), segs[:0]).tolist() == [math.inf] * 3


def test_segment_set_is_read_only_with_its_documented_arrays() -> None:
    """A SegmentSet (a world's walls, shared by every sensor) cannot be written to through
    its arrays; its bounding boxes and 1/|e|² are the documented ones, 0 for a point and for
    a segment too short for 1/|e|² (|e|² below the smallest normal float, 2**-1022)."""
    segs = np.array([[0.0, 3.0, 2.0, 1.0], [-1.0, -2.0, -4.0, 5.0], [1.0, 1.0, 1.0, 1.0],
                     [0.0, 0.0, 2.0**-512, 0.0], [0.0, 0.0, 0.0, 2.0**-511]])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        s = g.SegmentSet(segs)
    for arr in (s.segments, s.packed, s.ax, s.inv_len2):
        with pytest.raises(ValueError, match="read-only"):
            arr[0] = 7.0
    segs[0, 0] = 9.0  # (a copy: the caller's array stays the caller's)
    assert s.segments[0, 0] == 0.0
    assert s.lo.tolist() == [[0.0, 1.0], [-4.0, -2.0], [1.0, 1.0], [0.0, 0.0], [0.0, 0.0]]
    assert s.hi.tolist() == [[2.0, 3.0], [-1.0, 5.0], [1.0, 1.0], [2.0**-512, 0.0],
                             [0.0, 2.0**-511]]
    assert s.inv_len2.tolist() == [1 / 8, 1 / 58, 0.0, 0.0, 2.0**1022]


def test_many_origins_cast_as_one_next_to_max_range() -> None:
    """Row i of cast_rays_many is cast_rays from origin i (documented), also for a wall a
    hair inside max_range and for short ranges, where the walls each origin's rays are
    tested against are chosen by distance."""
    for max_range in (1e-4, 0.5, 2.0):
        x = max_range * (1.0 - 5e-10) if max_range > 1e-3 else max_range - 5e-13
        # (a far wall first: a row without near walls is padded with the first segment)
        s = g.SegmentSet(np.array([[0.8 * x, 5.0, 0.8 * x, 6.0], [x, -1.0, x, 1.0]]))
        xy = np.array([[0.0, 0.0], [0.0, 0.5], [0.1 * x, 0.0]])
        ang = np.tile([0.0, 0.1, math.pi], (3, 1))
        many = g.cast_rays_many(s, xy, ang, max_range)
        for i, (ox, oy) in enumerate(xy):
            assert np.array_equal(many[i], g.cast_rays(s, ox, oy, ang[i], max_range)), max_range
        assert 0.0 < many[0, 0] < max_range  # the wall is within range, and hit


@pytest.mark.parametrize("args, error, match", [  # a sensor plugin's mistakes: each was a
    # silently wrong reading (every ray at max_range, negative distances) or an AttributeError
    ((math.nan, 1.0, [0.0], 2.0), ValueError, "x, y: expected a finite ray origin"),
    ((1.0, 1.0, [0.0], -2.0), ValueError, "expected a finite max_range > 0"),
    ((1.0, 1.0, np.zeros((2, 2)), 2.0), ValueError, "angles_rad: expected a 1-D array"),
])
def test_cast_rays_and_rim_ranges_refuse_what_a_sensor_gets_wrong(args, error, match):
    from sitframe import cast_rays, load_world, rim_ranges

    segs = load_world("training").segment_set
    with pytest.raises(error, match=match):
        cast_rays(segs, *args)
    with pytest.raises(error, match=match):
        rim_ranges(segs, *args, 0.1)
    with pytest.raises(TypeError, match="expected world.segment_set"):
        cast_rays(np.zeros((3, 4)), 1.0, 1.0, [0.0], 2.0)
