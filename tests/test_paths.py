"""Shortest collision-free paths of a disc (the reference length of SPL)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sitframe.sim.metrics import spl
from sitframe.sim.paths import PathDistance, segment_clear, shortest_path_length
from sitframe.sim.world import load_world, parse_world

ROOM = """name = "t"
description = "a 10 m x 8 m room"
[robot]
start = [1, 1, 0]
[[walls]]
points = [[0, 0], [10, 0], [10, 8], [0, 8], [0, 0]]
"""
# a thin wall from the floor to y = 6: from (2, 4) to (8, 4) the disc turns round its end
WALL = ROOM + "[[walls]]\npoints = [[5, 0], [5, 6]]\n"
R = 0.15


def around_the_wall_end(r: float) -> float:
    """The true shortest path from (2, 4) to (8, 4) round the end (5, 6): tangents and an arc."""
    d = math.sqrt(13.0)
    phi = math.acos(-5.0 / 13.0)  # the angle at the end between the two straight pieces
    beta = math.acos(r / d)
    return 2 * math.sqrt(d * d - r * r) + r * (2 * math.pi - phi - 2 * beta)


def test_straight_line_when_it_is_clear():
    w = parse_world(ROOM)
    assert shortest_path_length(w, [1, 1], [9, 7], radius=R) == pytest.approx(10.0, abs=1e-12)


def test_round_the_end_of_a_wall_within_the_arc_bound():
    w = parse_world(WALL)
    exact = around_the_wall_end(R)
    got = shortest_path_length(w, [2, 4], [8, 4], radius=R)
    # never shorter than the truth; longer only on the arc, by <= 2.3 % of it (< 5 mm here)
    assert exact <= got <= exact + 0.023 * R * math.pi
    assert got > 6.0 + 1.0  # far from the straight line through the wall
    assert shortest_path_length(w, [8, 4], [2, 4], radius=R) == pytest.approx(got, abs=1e-9)


def test_a_wider_disc_needs_a_longer_path_and_a_door_too_narrow_closes():
    w = parse_world(WALL)
    assert shortest_path_length(w, [2, 4], [8, 4], radius=0.4) > \
        shortest_path_length(w, [2, 4], [8, 4], radius=R)
    # the gap above the wall is 2 m: a disc of radius 1.1 cannot pass
    assert shortest_path_length(w, [2, 4], [8, 4], radius=1.1) == math.inf


def test_walled_off_goal_is_unreachable_and_scores_zero():
    box = "[[walls]]\npoints = [[7, 3], [9, 3], [9, 5], [7, 5], [7, 3]]\n"
    w = parse_world(ROOM + box)
    assert shortest_path_length(w, [2, 4], [8, 4], radius=R) == math.inf
    # an unreachable reference counts 0, like a failure; a reached one counts l / max(p, l)
    assert spl(np.array([True, True]), np.array([np.inf, 4.0]), np.array([5.0, 8.0])) == 0.25


def test_doors_of_the_multi_room_world():
    w = load_world("multi-room")
    # rooms 1 and 3 are joined through a door at the top of the first wall and one at the
    # bottom of the second: the path must climb to y > 6.2 and come down to y < 1.8
    a, b = np.array([2.0, 1.0]), np.array([12.0, 7.0])
    lower = math.hypot(4.5 - 2.0, 6.2 - 1.0) + math.hypot(9.5 - 4.5, 6.2 - 1.8) \
        + math.hypot(12.0 - 9.5, 7.0 - 1.8)
    got = shortest_path_length(w, a, b, radius=R)
    assert lower <= got <= lower * 1.15
    assert got > 1.5 * math.hypot(*(b - a))


def test_segment_clear_checks_the_disc_not_the_line():
    w = parse_world(WALL)
    ends = np.array([[4.0, 7.0], [4.8, 7.0], [6.0, 6.1]])
    # (3, 6.1) -> (6, 6.1) passes 0.1 m above the wall's end: clear for a point, not the disc
    assert segment_clear(w, [3.0, 6.1], ends[2:], 0.05).tolist() == [True]
    assert segment_clear(w, [3.0, 6.1], ends[2:], R).tolist() == [False]
    assert segment_clear(w, [3.0, 7.0], ends[:2], R).tolist() == [True, True]


def test_bad_radius_is_a_value_error():
    w = parse_world(ROOM)
    for r in (0.0, -1.0, float("nan")):
        with pytest.raises(ValueError, match="radius must be > 0"):
            shortest_path_length(w, [1, 1], [2, 2], radius=r)


@pytest.mark.parametrize("name", ["goal", "multi-room", "u-trap"])
def test_segment_clear_agrees_with_dense_sampling(name):
    w = load_world(name)
    rng = np.random.default_rng(5)
    x0, y0, x1, y1 = w.bounds
    a = rng.uniform((x0, y0), (x1, y1), size=(60, 2))
    b = a + rng.normal(0.0, 1.5, size=(60, 2))
    for p, q in zip(a, b, strict=True):
        t = np.linspace(0.0, 1.0, int(np.hypot(*(q - p)) / 0.002) + 2)[:, None]
        least = float(w.clearance(p * (1 - t) + q * t).min())
        if abs(least - R) < 0.003:  # too close to call at this sampling
            continue
        assert segment_clear(w, p, q[None], R)[0] == (least >= R), (name, p, q, least)


@pytest.mark.parametrize("name", ["goal-training", "u-trap", "multi-room"])
def test_path_distance_field_agrees_with_the_graph_search(name):
    w = load_world(name)
    rng = np.random.default_rng(3)
    goal = w.random_free_pose(rng, R, margin=0.3)[:2]
    field = PathDistance(w, goal, R)
    for _ in range(40):
        p = w.random_free_pose(rng, R, margin=0.0)[:2]
        assert field(p) == pytest.approx(shortest_path_length(w, p, goal, radius=R), rel=1e-12)


def test_path_distance_round_a_wall_is_inf_in_contact_and_checks_its_radius():
    w = parse_world(WALL)
    field = PathDistance(w, np.array([8.0, 4.0]), R)
    assert around_the_wall_end(R) <= field([2.0, 4.0]) <= around_the_wall_end(R) * 1.023
    assert field([7.0, 4.0]) == pytest.approx(1.0)  # in sight: the straight line
    assert math.isinf(field([5.1, 3.0]))  # the disc would overlap the wall
    with pytest.raises(ValueError, match="radius"):
        PathDistance(w, np.array([8.0, 4.0]), 0.0)
