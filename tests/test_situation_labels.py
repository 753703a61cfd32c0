"""Situation labels are right on a labelled set of readings (tests/data/situations.toml)."""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import numpy as np
import pytest
from situation_set import labelled_readings

from sitframe.plugins.laser import LaserScanner
from sitframe.plugins.sonar import PIONEER_ANGLES_DEG as PIONEER
from sitframe.plugins.sonar import SonarRing
from sitframe.situations.clustering import describe_prototype
from sitframe.situations.labels import describe_prototypes


def sonar_label(ranges, **kw):
    """The label of a Pioneer sonar reading."""
    return describe_prototype(ranges, PIONEER, **kw)

SENSORS = {
    "sonar-cones": SonarRing(beam_width_deg=25, rays_per_beam=5),  # the presets' sonar
    "sonar-rays": SonarRing(),                                      # the thesis's
    "laser-180": LaserScanner(),                                    # 16 beams over 180 deg
    "laser-ring": LaserScanner(fov_deg=360, beams=16),
}


def situation(label: str) -> str:
    """The situation a description names: its head, ``"front blocked"`` is an obstacle ahead."""
    head = label.split(",")[0]
    return "obstacle ahead" if head == "front blocked" else head


@pytest.mark.parametrize("sensor", list(SENSORS))
def test_labels_are_right_on_the_labelled_set(sensor: str) -> None:
    s = SENSORS[sensor]
    readings, labels, notes = labelled_readings(s)
    assert len(labels) >= 100 and len(set(labels)) == 8
    wrong = [(n, describe_prototype(r, s.angles_deg)) for r, t, n in
             zip(readings, labels, notes, strict=True)
             if situation(describe_prototype(r, s.angles_deg)) != t]
    share = 1.0 - len(wrong) / len(labels)
    assert share >= 0.9, f"{share:.0%} right; wrong: {wrong[:10]}"
    # every situation is recognised, not only the common ones
    per_label = Counter(t for t in labels)
    for t, k in Counter(n.split(":")[0] for n, _ in wrong).items():
        assert k <= per_label[t] // 2, f"'{t}' mostly wrong: {wrong}"


def test_a_corridor_is_not_a_dead_end() -> None:
    # a prototype of the shipped obstacle-avoidance run: walls on both sides, the way
    # ahead open (the +-30 deg cones read the side walls through their outer rays)
    assert sonar_label([0.38, 0.44, 0.64, 1.24, 1.34, 0.7, 0.46, 0.39]) == "corridor"
    assert describe_prototype([0.4, 0.45, 0.6, 0.7, 0.7, 0.6, 0.45, 0.4], PIONEER) == "dead end"


# ------------------------------------------------------------ labels of a set of situations


def _alike(labels: list[str]) -> dict[str, int]:
    return {w: n for w, n in Counter(labels).items() if n > 1}


def test_labels_of_a_set_say_how_alike_situations_differ() -> None:
    """Two of one shape are told apart by what differs: an open side, where the nearest
    wall is, how close; a number only where nothing does."""
    corridors = np.array([
        [0.45, 0.5, 0.7, 1.4, 1.4, 0.7, 0.5, 0.45],   # centred
        [0.25, 0.3, 0.6, 1.4, 1.5, 0.8, 0.6, 0.65],   # nearer the left wall
        [0.65, 0.6, 0.8, 1.5, 1.4, 0.6, 0.3, 0.25],   # nearer the right wall
        [0.35, 0.4, 0.6, 1.2, 1.2, 0.6, 0.4, 0.35],   # centred, narrower
        [0.4, 1.5, 1.5, 1.4, 1.2, 0.6, 0.45, 0.35],   # the left wall ends ahead-left
        [0.4, 1.5, 1.5, 1.4, 1.2, 0.6, 0.45, 0.35],   # the same again
    ])
    assert {describe_prototype(v, PIONEER) for v in corridors} == {"corridor"}
    labels = describe_prototypes(corridors, PIONEER)
    assert labels == [
        "corridor, nearest 90° left and right at 0.45 m",
        "corridor, nearest 90° left",
        "corridor, nearest 90° right",
        "corridor, nearest 90° left and right at 0.35 m",
        "corridor, open front-left #1",
        "corridor, open front-left #2",
    ]
    # a label keeps its shape's words, and one of a kind stays as short as it was
    mixed = np.vstack([corridors[:1], [[3.0] * 8], [[0.4, 0.45, 0.6, 0.7, 0.7, 0.6, 0.45, 0.4]]])
    assert describe_prototypes(mixed, PIONEER) == ["corridor", "open space", "dead end"]


def _ring_log(tmp: Path, beams: int) -> Path:
    """A 360 deg laser ring's fitted situations: collect and cluster, c = 10."""
    from sitframe.cli.app import main

    cfg = tmp / f"ring{beams}.toml"
    cfg.write_text(f"""
[experiment]
name = "ring{beams}"
seed = 1
stages = ["collect", "cluster"]

[sensor]
component = "laser"
fov_deg = 360
beams = {beams}

[interpreter]
component = "fcm"
c = 10
trials = 10

[behaviours.avoid]
component = "fuzzy-q"
reward = "obstacle-avoidance"
""")
    out = tmp / f"ring{beams}.h5"
    assert main(["run", str(cfg), "--out", str(out), "--workers", "1"]) == 0
    return out


@pytest.mark.parametrize("beams", [24, 16])
def test_a_ring_labels_its_situations_apart(beams: int, tmp_path: Path, capsys) -> None:
    """A 360 deg ring's ten situations: several are one shape (five 'wall on left' of 16
    beams), and every label is still one of a kind and starts with the shape's words."""
    from sitframe.analysis.results import situation_labels
    from sitframe.logs.reader import open_log

    log = open_log(_ring_log(tmp_path, beams))
    capsys.readouterr()
    centers = np.asarray(log.interpreter_state()["centers"])
    shapes = [describe_prototype(v, log.sensor.angles_deg) for v in centers]
    assert _alike(shapes), "the case is not tested: no two situations share a shape"
    labels = situation_labels(log, numbered=False)
    assert len(labels) == 10 and not _alike(labels), labels
    assert all(lb.startswith(s) for lb, s in zip(labels, shapes, strict=True))
