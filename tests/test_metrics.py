"""Coverage (reported for every evaluation and used to pick the best rule base) and the
other path metrics, on a room whose free cells are known by hand."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import ROOM

from sitframe.metrics import collisions_per_1000, coverage, heading_change_per_m, path_length, spl
from sitframe.world import parse_world

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
