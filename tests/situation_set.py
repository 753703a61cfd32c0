"""The labelled set of situations in ``tests/data/situations.toml``, read by a sensor.

``labelled_readings(sensor)`` builds each case's world (a 10 m x 10 m room
with the case's walls inside), reads the sensor at every pose (noise off,
a fixed seed) and returns the readings with their labels.
"""

from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np

from sitframe import load_world
from sitframe.sim.world import parse_world

DATA = Path(__file__).parent / "data" / "situations.toml"
ROOM = "[[walls]]\npoints = [[-5, -5], [5, -5], [5, 5], [-5, 5], [-5, -5]]\n"


def _world_text(case: dict, start: list[float]) -> str:
    walls = "".join(f"[[walls]]\npoints = {w['points']}\n" for w in case.get("walls", ()))
    return (f'name = "{case["label"]}: {case["note"]}"\n[robot]\nstart = {start}\n'
            f"{ROOM}{walls}")


def labelled_readings(sensor) -> tuple[np.ndarray, list[str], list[str]]:
    """Read ``sensor`` at every labelled pose.

    Returns
    -------
    readings : ndarray, shape (n, d)
        One reading per pose, metres.
    labels : list of str, length n
        The situation each pose is known to be in.
    notes : list of str, length n
        ``"label: note @ pose"``, for messages.
    """
    cases = tomllib.loads(DATA.read_text("utf-8"))["case"]
    rng = np.random.default_rng(0)
    readings, labels, notes = [], [], []
    for case in cases:
        world = load_world(parse_world(_world_text(case, case["poses"][0]), file=str(DATA)))
        for x, y, h in case["poses"]:
            pose = np.array([x, y, np.radians(h)])
            readings.append(sensor.read(world, pose, rng))
            labels.append(case["label"])
            notes.append(f"{case['label']}: {case['note']} @ {[x, y, h]}")
    return np.array(readings), labels, notes
