"""Situation labels are right on a labelled set of readings (tests/data/situations.toml)."""

from __future__ import annotations

from collections import Counter

import pytest
from situation_set import labelled_readings

from sitframe.plugins.laser import LaserScanner
from sitframe.plugins.sonar import PIONEER_ANGLES_DEG as PIONEER
from sitframe.plugins.sonar import SonarRing
from sitframe.situations.clustering import describe_prototype


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
