"""World files: validation errors name the key path; shipped worlds are sound."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from scipy import ndimage

from sitframe.errors import InputError
from sitframe.sim import geometry as geo
from sitframe.sim.world import World, list_worlds, load_world, parse_world

GOOD = """
name = "room"
description = "a test room"

[robot]
start = [1.0, 1.0, 90.0]

[[walls]]
points = [[0, 0], [6, 0], [6, 4], [0, 4], [0, 0]]

[[walls]]
points = [[3, 0], [3, 2]]

[[obstacles]]
points = [[4, 2.5], [5, 2.5], [5, 3.2], [4, 3.2]]

[[trajectories]]
points = [[1, 1], [1, 3], [2, 3]]

[goal]
position = [5, 1]
radius = 0.3
"""


def test_good_world_parses() -> None:
    w = parse_world(GOOD, file="room.toml")
    assert w.name == "room" and w.description == "a test room"
    np.testing.assert_allclose(w.start, [1.0, 1.0, math.pi / 2])
    assert w.segments.shape == (4 + 1 + 4, 4)
    assert w.bounds == (0.0, 0.0, 6.0, 4.0)
    assert w.goal is not None and w.goal.radius == 0.3
    assert len(w.trajectories) == 1 and w.text == GOOD
    free = w.is_free(np.array([[1, 1], [4.5, 2.8], [7, 1], [3.05, 1.0], [2, 3.5]]), 0.15)
    assert free.tolist() == [True, False, False, False, True]
    cells = w.free_cells(0.5, 0.15)
    assert cells.shape[1] == 2 and w.is_free(cells, 0.15).all()
    assert 40 < len(cells) < 96
    # computed once per (cell, radius) and shared, so a caller cannot change it for others
    assert w.free_cells(0.5, 0.15) is cells and w.free_cells(0.5, 0.3) is not cells
    with pytest.raises(ValueError, match="read-only"):
        cells[0, 0] = 0.0
    rng = np.random.default_rng(0)
    poses = np.array([w.random_free_pose(rng, 0.15, margin=0.05) for _ in range(50)])
    assert w.is_free(poses[:, :2], 0.2).all()
    assert np.all(np.abs(poses[:, 2]) <= math.pi)
    w2 = w.with_start(np.array([2.0, 3.0, 0.5]))
    assert w2.start.tolist() == [2.0, 3.0, 0.5] and w.start[0] == 1.0
    with pytest.raises(InputError, match="robot.start"):
        w.with_start(np.array([4.5, 2.8, 0.0]))
    with pytest.raises(ValueError):
        w.start[0] = 3.0  # read-only


def _bad(old: str, new: str) -> str:
    assert old in GOOD, old
    return GOOD.replace(old, new)


BAD_CASES = [
    # (text, key path in message, words in message)
    ("name = [", None, "not valid TOML"),
    ("   \n\n", None, "empty"),
    (_bad('name = "room"', 'nmae = "room"'), "nmae", "did you mean 'name'"),
    (_bad('name = "room"', ""), "name", "missing required key"),
    (_bad("start = [1.0, 1.0, 90.0]", "strat = [1.0, 1.0, 90.0]"), "robot.strat",
     "did you mean 'start'"),
    (_bad("start = [1.0, 1.0, 90.0]", "start = [1.0, 1.0]"), "robot.start", "3 numbers"),
    (_bad("start = [1.0, 1.0, 90.0]", 'start = [1.0, "a", 90.0]'), "robot.start[1]",
     "expected a number"),
    (_bad("start = [1.0, 1.0, 90.0]", "start = [1.0, nan, 90.0]"), "robot.start[1]", "finite"),
    (_bad("start = [1.0, 1.0, 90.0]", "start = [1.0, inf, 90.0]"), "robot.start[1]", "finite"),
    (_bad("points = [[3, 0], [3, 2]]", "points = [[3, 0]]"), "walls[1].points",
     "at least 2 points, got 1"),
    (_bad("points = [[3, 0], [3, 2]]", "points = [[3, 0], [3, true]]"), "walls[1].points[1][1]",
     "expected a number"),
    (_bad("points = [[3, 0], [3, 2]]", "point = [[3, 0], [3, 2]]"), "walls[1].point",
     "did you mean 'points'"),
    (_bad("points = [[4, 2.5], [5, 2.5], [5, 3.2], [4, 3.2]]", "points = [[4, 2.5], [5, 2.5]]"),
     "obstacles[0].points", "at least 3 points, got 2"),
    (_bad("points = [[4, 2.5], [5, 2.5], [5, 3.2], [4, 3.2]]",
          "points = [[4, 2.5], [5, 3.2], [5, 2.5], [4, 3.2]]"),
     "obstacles[0].points", "self-intersecting"),
    (_bad("points = [[4, 2.5], [5, 2.5], [5, 3.2], [4, 3.2]]",
          "points = [[4, 2.5], [5, 2.5], [5, 2.5], [4, 3.2]]"),
     "obstacles[0].points", "repeated point"),
    (_bad("[[obstacles]]", "[[obstacle]]"), "obstacle", "did you mean 'obstacles'"),
    (_bad("points = [[1, 1], [1, 3], [2, 3]]", "points = [[1, 1]]"), "trajectories[0].points",
     "at least 2 points"),
    (_bad("start = [1.0, 1.0, 90.0]", "start = [4.5, 2.8, 0]"), "robot.start",
     "inside an obstacle"),
    (_bad("start = [1.0, 1.0, 90.0]", "start = [2.9, 1.0, 0]"), "robot.start",
     "robot radius"),
    (_bad("start = [1.0, 1.0, 90.0]", "start = [0.1, 1.0, 0]"), "robot.start", "robot radius"),
    (_bad("start = [1.0, 1.0, 90.0]", "start = [8, 1.0, 0]"), "robot.start", "outside the walls"),
    (_bad("position = [5, 1]", "position = [9, 1]"), "goal.position", "outside the walls"),
    (_bad("position = [5, 1]", "position = [4.5, 3]"), "goal.position", "inside an obstacle"),
    (_bad("radius = 0.3", "radius = -1"), "goal.radius", "(0.0, 10000.0]"),
    (_bad("radius = 0.3", "radius = 0.3\ncolour = 'red'"), "goal.colour", "expected one of"),
    (_bad("[robot]", "robot = 3\n[robt]"), "robt", "did you mean 'robot'"),
    (GOOD.replace("[[walls]]\npoints = [[0, 0], [6, 0], [6, 4], [0, 4], [0, 0]]",
                  "[[walls]]\npoints = [[0, 0], [6, 4], [6, 0], [0, 4], [0, 0]]"),
     "walls[0].points", "self-intersecting"),
]


@pytest.mark.parametrize(("text", "key", "words"), BAD_CASES)
def test_bad_worlds_raise_input_error(text: str, key: str | None, words: str) -> None:
    with pytest.raises(InputError) as info:
        parse_world(text, file="room.toml")
    err = info.value
    assert err.file == "room.toml"
    assert words in str(err)
    if key is not None:
        assert err.key == key, str(err)
        assert key in str(err)


def test_toml_error_reports_the_line() -> None:
    with pytest.raises(InputError, match=r"line 3"):
        parse_world('name = "x"\n\nstart = [1, \n', file="x.toml")
    with pytest.raises(InputError, match=r"not valid TOML: .*line 2"):
        parse_world('name = "x"\nfoo = = 1\n[robot]\n', file="x.toml")


def test_missing_walls_and_start() -> None:
    with pytest.raises(InputError, match="walls"):
        parse_world('name = "x"\n[robot]\nstart = [0, 0, 0]\n')
    with pytest.raises(InputError) as info:
        parse_world('name = "x"\n[robot]\n[[walls]]\npoints = [[0, 0], [1, 0]]\n')
    assert info.value.key == "robot.start"


def test_load_by_name_and_path(tmp_path: Path) -> None:
    names = list_worlds()
    for expected in ["collect-1", "collect-2", "collect-3", "collect-4", "collect-5", "training",
                     "novel-1", "novel-2", "wall-following", "goal"]:
        assert expected in names
    with pytest.raises(InputError, match="did you mean 'training'") as info:
        load_world("trainig")
    assert "novel-1" in str(info.value)  # lists the available names
    p = tmp_path / "room.toml"
    p.write_text(GOOD)
    w = load_world(p)
    assert w.source == str(p) and w.name == "room"
    assert load_world(str(p)).name == "room"
    with pytest.raises(InputError, match="not found"):
        load_world(tmp_path / "missing.toml")


@pytest.mark.parametrize("name", list_worlds())
def test_shipped_world_is_sound(name: str) -> None:
    w = load_world(name)
    assert isinstance(w, World) and w.name == name and w.description
    r = 0.15
    assert w.is_free(w.start[None, :2], r)[0]
    for traj in w.trajectories:
        segs = geo.polyline_segments(traj)
        pts = np.concatenate([np.linspace(s[:2], s[2:], 25) for s in segs])
        assert w.inside(pts).all(), name
        # the path keeps >= 0.2 m from every wall: the disc stays clear
        assert w.clearance(pts).min() >= 0.2 - 1e-9, name
        assert np.allclose(traj[0], w.start[:2]), "a forced path starts at the start pose"
    if w.goal is not None:
        assert w.is_free(w.goal.position[None, :], r)[0]
    # plenty of open space, and all of it reachable from the start (one component)
    assert len(w.free_cells(0.5, r)) > 20
    x0, y0, x1, y1 = w.bounds
    h = 0.05
    gx, gy = np.meshgrid(np.arange(x0 + h / 2, x1, h), np.arange(y0 + h / 2, y1, h))
    free = w.is_free(np.stack([gx.ravel(), gy.ravel()], axis=1), r + 0.01).reshape(gx.shape)
    labels, n = ndimage.label(free)
    assert n == 1, f"{name}: {n} separate free regions"


def test_data_collection_rooms() -> None:
    total = 0.0
    for k in range(1, 6):
        w = load_world(f"collect-{k}")
        x0, y0, x1, y1 = w.bounds
        assert (x1 - x0, y1 - y0) == (3.0, 6.0)
        assert w.trajectories
        for t in w.trajectories:
            total += float(np.hypot(*np.diff(t, axis=0).T).sum())
    # ~1500 samples at 2 Hz and 0.15 m/s is ~110 m in all
    assert 90.0 < total < 130.0
