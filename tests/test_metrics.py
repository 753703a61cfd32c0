"""Coverage (reported for every evaluation and used to pick the best rule base) and the
other path metrics, on a room whose free cells are known by hand."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from helpers import ROOM

from sitframe.sim.metrics import (
    collisions_per_1000,
    coverage,
    frontal_between_prototypes,
    heading_change_per_m,
    path_length,
    spl,
)
from sitframe.sim.world import parse_world

#: 6 m x 4 m: 12 x 8 cells of 0.5 m; the obstacle [4, 5] x [2.5, 3.2] grown by the robot
#: radius (0.15 m) covers the centres of the 4 cells x in {4.25, 4.75}, y in {2.75, 3.25}.
WORLD = parse_world(ROOM)
FREE = 12 * 8 - 4
BLOCKED = np.array([[4.25, 2.75], [4.75, 2.75], [4.25, 3.25], [4.75, 3.25]])


def test_free_cells_of_the_room():
    assert len(WORLD.free_cells()) == FREE


def test_coverage_counts_each_visited_free_cell_once():
    assert coverage(WORLD, np.array([[1.1, 1.1]])) == pytest.approx(1 / FREE)
    assert coverage(WORLD, np.array([[1.1, 1.1]] * 50 + [[1.4, 1.4]])) == pytest.approx(1 / FREE)
    xs, ys = np.meshgrid(np.arange(0.25, 6, 0.5), np.arange(0.25, 4, 0.5))
    every = np.column_stack([xs.ravel(), ys.ravel()])
    assert coverage(WORLD, every) == 1.0
    # poses (x, y, theta) as logged: the heading column is ignored
    assert coverage(WORLD, np.array([[1.1, 1.1, 3.0], [2.6, 1.1, -1.0]])) == \
        pytest.approx(2 / FREE)


def test_cells_that_are_not_free_do_not_count():
    assert coverage(WORLD, BLOCKED) == 0.0
    assert coverage(WORLD, np.vstack([BLOCKED, [[0.3, 0.3]]])) == pytest.approx(1 / FREE)


def test_cells_are_anchored_at_the_lower_left_corner():
    """Corners of one cell are one cell; a step past its edge is the next one."""
    one_cell = np.array([[0.01, 0.01], [0.49, 0.49], [0.01, 0.49], [0.49, 0.01]])
    assert coverage(WORLD, one_cell) == pytest.approx(1 / FREE)
    assert coverage(WORLD, np.array([[0.49, 0.25], [0.51, 0.25]])) == pytest.approx(2 / FREE)
    assert coverage(WORLD, np.array([[1.0, 1.0], [0.99, 0.99]])) == pytest.approx(2 / FREE)
    # a coarser grid is anchored the same way
    n1 = len(WORLD.free_cells(cell=1.0))
    assert coverage(WORLD, np.array([[0.1, 0.1], [0.9, 0.9]]), cell=1.0) == pytest.approx(1 / n1)


def test_path_metrics():
    xy = np.array([[0.0, 0.0], [3.0, 4.0], [3.0, 5.0]])
    assert path_length(xy) == 6.0
    assert heading_change_per_m(np.array([0.0, np.pi / 2, 0.0]), xy) == pytest.approx(180 / 6)
    assert np.isnan(heading_change_per_m(np.zeros(2), np.zeros((2, 2))))
    assert collisions_per_1000(np.array([0, 1, 0, 1], bool)) == 500.0
    assert collisions_per_1000(np.array([1, 1, 0, 0], bool), start=2) == 0.0
    assert np.isnan(collisions_per_1000(np.array([1], bool), start=1))
    assert spl(np.array([1, 0, 1]), np.array([2.0, 2.0, 2.0]), np.array([4.0, 2.0, 1.0])) == \
        pytest.approx((0.5 + 0 + 1.0) / 3)
    assert np.isnan(spl(np.zeros(0), np.zeros(0), np.zeros(0)))


def test_path_metrics_on_logged_poses():
    """Logged poses are (x, y, theta): the heading is not a distance; turning on the spot has
    no smoothness per metre; collision flags are flags, whatever their integer type."""
    poses = np.array([[0.0, 0.0, 0.0], [3.0, 4.0, 3.0]])
    assert path_length(poses) == 5.0
    assert np.isnan(heading_change_per_m(np.array([0.0, 1.0]), np.zeros((2, 2))))
    assert collisions_per_1000(np.array([0, 2, 0, 0], dtype=np.int8)) == 250.0


def _rect(x0: float, y0: float, x1: float, y1: float) -> str:
    return (f'name = "rect"\n[robot]\nstart = [{(x0 + x1) / 2}, {(y0 + y1) / 2}, 0.0]\n'
            f"[[walls]]\npoints = [[{x0}, {y0}], [{x1}, {y0}], [{x1}, {y1}], [{x0}, {y1}], "
            f"[{x0}, {y0}]]\n")


def test_cells_are_anchored_at_the_worlds_own_corner():
    """A room whose corner is not at the origin, nor on the 0.5 m lattice: 4 x 2 cells of
    0.5 m from (0.2, 0.3); a visit just inside a cell's corner counts for that cell."""
    world = parse_world(_rect(0.2, 0.3, 2.2, 1.3))
    assert len(world.free_cells()) == 8
    assert coverage(world, np.array([[0.21, 0.31], [0.69, 1.29]])) == pytest.approx(2 / 8)
    assert coverage(world, np.array([[2.19, 0.31], [1.71, 0.79]])) == pytest.approx(1 / 8)


def test_coverage_uses_the_robot_radius_it_is_given():
    """A 0.3 m robot cannot centre on the border cells (0.25 m from the walls) nor on the
    cells within 0.3 m of the obstacle: 60 interior cells less 10 near the obstacle."""
    assert len(WORLD.free_cells(radius=0.3)) == 50
    assert coverage(WORLD, np.array([[0.3, 0.3], [1.1, 1.1]]), radius=0.3) == \
        pytest.approx(1 / 50)


def test_coverage_of_a_world_with_one_or_no_free_cell():
    tiny = parse_world(_rect(0.0, 0.0, 0.5, 0.5))
    assert coverage(tiny, np.array([[0.25, 0.25]])) == 1.0
    assert np.isnan(coverage(tiny, np.array([[0.25, 0.25]]), radius=0.3))


def test_short_paths_and_single_episodes():
    """Metrics of a half-metre path and of one episode are values, not NaN; an empty tail
    is NaN without a numpy warning."""
    xy = np.array([[0.0, 0.0], [0.3, 0.4]])
    assert heading_change_per_m(np.array([0.0, np.pi / 4]), xy) == pytest.approx(45 / 0.5)
    assert spl(np.array([True]), np.array([3.0]), np.array([4.0])) == pytest.approx(0.75)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert np.isnan(collisions_per_1000(np.zeros(3, bool), start=3))


def test_frontal_collisions_between_prototypes():
    """Hand-made iterations away from the origin: the contact's bearing relative to the
    heading (wrapped to [-180, 180)) within the cone (bounds included), and no membership at
    or above ``top``. Collision flags are flags whatever their integer type."""
    #              ahead dominant  45  none behind wrap  29.5 30.5 -29.5 -30.5 top=.5  90/90
    heading = np.array([0, 0, 0, 0, 180, 165, 0, 0, 0, 0, 0, 90], float)
    absolute = np.array([0, 0, 45, 0, 180, -165.5, 29.5, 30.5, -29.5, -30.5, 20, 90], float)
    top = np.array([.4, .6, .4, .4, .3, .45, .4, .4, .4, .4, .5, .49])
    collision = np.array([2, 2, 1, 0, 1, 1, 1, 1, 1, 1, 1, 1], np.int8)
    frontal = [1, 0, 0, 0, 1, 1, 1, 0, 1, 0, 0, 1]
    L = heading.size
    pose = np.zeros((L + 1, 3))
    pose[:L] = np.column_stack([np.full(L, 2.0), np.full(L, -1.0), np.radians(heading)])
    pose[L] = [9.0, 9.0, 0.0]  # the pose after the last iteration: not used
    contact = pose[:L, :2] + np.column_stack([np.cos(np.radians(absolute)),
                                              np.sin(np.radians(absolute))])
    contact[3] = np.nan  # no collision there
    memberships = np.column_stack([np.minimum(top, 1 - top), top])  # the largest is top
    got = frontal_between_prototypes(pose, collision, contact, memberships)
    assert got.dtype == bool
    assert got.tolist() == [bool(f) for f in frontal]
    assert frontal_between_prototypes(pose, collision, contact, memberships, top=0.7)[1]
    # a contact exactly on the cone's edge counts (45 deg is exact in floating point)
    edge = pose[:1, :2] + [[1.0, 1.0]]
    assert frontal_between_prototypes(pose[:1], collision[:1], edge, memberships[:1],
                                      cone_deg=45.0).tolist() == [True]
