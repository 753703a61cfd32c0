"""The room generator: the same seed gives the same room; every seed gives a valid room
(closed outline, obstacles apart, every free place reachable, the robot fits at its start);
bad parameters get one line naming the key and the limit; a run learns in, and is judged
in, generated rooms by name."""

from __future__ import annotations

import hashlib
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from helpers import run_config, run_json, small_config
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import ndimage

from sitframe.errors import InputError
from sitframe.sim import geometry as geo
from sitframe.sim.roomgen import GENERATOR, START_MARGIN
from sitframe.sim.world import generate_room, load_world

GAP = GENERATOR.key("gap").default


def test_the_same_seed_gives_the_same_room_bit_for_bit_in_another_process():
    here = load_world("gen:1234").text
    code = "from sitframe.sim.world import load_world; print(load_world('gen:1234').text, end='')"
    there = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                           check=True).stdout
    assert hashlib.sha256(here.encode()).hexdigest() == hashlib.sha256(there.encode()).hexdigest()
    assert load_world("gen:1235").text != here


def _obstacle_distance(a: np.ndarray, b: np.ndarray) -> float:
    """Least distance between two polygons' boundaries (corners to edges, both ways)."""
    return float(min(geo.min_distance(a, geo.polygon_edges(b)).min(),
                     geo.min_distance(b, geo.polygon_edges(a)).min()))


def _components(world, radius: float) -> int:
    """Connected regions of the disc's free space on a 0.1 m grid (the world's own cells)."""
    cells = world.free_cells(0.1, radius)
    ij = np.rint((cells - np.array(world.bounds[:2])) / 0.1 - 0.5).astype(int)
    grid = np.zeros(ij.max(axis=0) + 1, bool)
    grid[ij[:, 0], ij[:, 1]] = True
    return ndimage.label(grid)[1]


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**63 - 1))
def test_every_seed_gives_a_valid_room(seed):
    w = generate_room(seed)
    outline = w.walls[0]
    assert np.array_equal(outline[0], outline[-1]) and len(outline) == 5  # closed
    for i, ob in enumerate(w.obstacles):
        assert w.inside(ob.mean(axis=0)[None])[0] is np.False_  # solid: inside an obstacle
        assert geo.min_distance(ob, np.concatenate([geo.polyline_segments(x)
                                                    for x in w.walls])).min() >= GAP - 1e-9
        for other in w.obstacles[i + 1:]:
            assert _obstacle_distance(ob, other) >= GAP - 1e-9
    assert w.is_free(w.start[None, :2], w.robot_radius + START_MARGIN - 1e-9)[0]
    assert _components(w, w.robot_radius) == 1  # every free place reachable from the start


def test_a_generator_file_gives_its_parameters_and_names_the_room(tmp_path: Path):
    f = tmp_path / "wide.toml"
    f.write_text('[generator]\nseed = 7\nwidth = [12, 12]\nheight = [3, 3]\n'
                 'obstacles = [0, 0]\ndividers = [0, 0]\n')
    w = load_world(f)
    assert w.name == "gen:7" and w.bounds == (0.0, 0.0, 12.0, 3.0) and not w.obstacles
    assert w.source == str(f)
    f.write_text('name = "corridor"\n[generator]\nseed = 7\nobstacles = [12, 12]\n')
    w = load_world(f)
    assert w.name == "corridor" and len(w.obstacles) == 12


@pytest.mark.parametrize(("table", "key", "words"), [
    ("seed = 1\nwidth = [0.4, 8]", "generator.width", "cannot hold the robot"),
    ("seed = 1\nheight = [9, 6]", "generator.height", "lo <= hi"),
    ("seed = 1\nobstacles = [5, 400]", "generator.obstacles[1]", "in [0, 200], got 400"),
    ("seed = 1\nwidth = [3, 3]\nheight = [3, 3]\nobstacles = [40, 40]",
     "generator.obstacles", "cannot fit in a 3 m x 3 m room; expected at most"),
    ("seed = 1\ngap = 0.2", "generator.gap", "expected more than 0.3 m"),
    ("seed = 1\ndoor = 0.25", "generator.door", "does not let the robot"),
    ("seed = 1\nobstacles = [1.5, 3]", "generator.obstacles", "whole numbers"),
    ("width = [6, 8]", "generator.seed", "missing"),
    ("seed = -3", "generator.seed", "in [0, inf), got -3"),
    ("seed = 1\nobstacle = [2, 3]", "generator.obstacle", "obstacles"),
])
def test_bad_generator_parameters_name_the_key_and_the_limit(tmp_path, capsys, table, key, words):
    from sitframe.cli.app import main

    f = tmp_path / "bad.toml"
    f.write_text(f"[generator]\n{table}\n")
    assert main(["world", "show", str(f), "-o", str(tmp_path / "x.png")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"sitframe: error: {f}: {key}: "), err
    assert words in err[0]
    assert not (tmp_path / "x.png").exists()


@pytest.mark.parametrize("name", ["gen:x", "gen:", "gen:-1", "gen:99999999999999999999"])
def test_a_bad_generated_name_says_what_a_name_looks_like(name):
    with pytest.raises(InputError, match=r"expected gen:SEED with SEED a whole number"):
        load_world(name)


def test_a_run_learns_in_a_generated_room_and_is_judged_in_another(tmp_path, capsys):
    cfg = small_config(trials=1, iterations=200, eval_worlds=("gen:3000000",)).replace(
        "iterations = 200\n", 'iterations = 200\nworld = "gen:1000000"\n', 1)
    _cfg, log = run_config(tmp_path, cfg, "gen.h5")
    capsys.readouterr()
    doc = run_json(capsys, "evaluate", str(log), "--world", "gen:2000000", "--trial", "0",
                   "--iterations", "100", "--json")
    assert doc["iterations"] == 100 and 0 < doc["coverage"] <= 1
    from sitframe.logs.reader import open_log

    assert load_world("gen:1000000").text in open_log(log).worlds.values()
