"""The Pioneer sonar ring plugin."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sitframe.plugins.sonar import SonarRing, sitframe_sensors
from sitframe.sim.world import World, load_world, parse_world

BOX = """
name = "box"
[robot]
start = [2, 2, 0]
[[walls]]
points = [[0, 0], [4, 0], [4, 4], [0, 4], [0, 0]]
"""


@pytest.fixture(scope="module")
def box() -> World:
    return parse_world(BOX)


def test_exact_readings_in_a_box(box: World) -> None:
    s = SonarRing()
    rng = np.random.default_rng(0)
    r = s.read(box, np.array([2.0, 2.0, 0.0]), rng)
    assert r.shape == (8,)
    expected = []
    for a in np.radians(s.angles_deg):
        # distance from the centre to the box along bearing a
        d = min(2.0 / abs(math.cos(a)) if abs(math.cos(a)) > 1e-12 else np.inf,
                2.0 / abs(math.sin(a)) if abs(math.sin(a)) > 1e-12 else np.inf)
        expected.append(d - 0.15)
    np.testing.assert_allclose(r, expected, atol=1e-12)
    assert r[0] == pytest.approx(2.0 - 0.15)  # +90 (left)
    assert r[7] == pytest.approx(2.0 - 0.15)  # -90 (right)
    # rotated robot: the +90 sonar now points at -x
    r2 = s.read(box, np.array([1.0, 2.0, math.pi / 2]), rng)
    assert r2[0] == pytest.approx(1.0 - 0.15)
    assert r2[7] == pytest.approx(3.0 - 0.15)


def test_clips_at_max_range() -> None:
    big = parse_world(BOX.replace("4", "20").replace("start = [2, 2, 0]", "start = [2, 10, 0]"))
    s = SonarRing()
    r = s.read(big, np.array([2.0, 10.0, 0.0]), np.random.default_rng(0))
    assert r[3] == 3.0 and r[4] == 3.0  # front: 18 m away
    assert np.all((r >= 0) & (r <= 3.0))
    r = SonarRing(max_range=1.0).read(big, big.start, np.random.default_rng(0))
    assert np.all(r == 1.0)


def test_noise_and_dropout_are_reproducible(box: World) -> None:
    s = SonarRing(noise_std=0.05, dropout=0.2)
    pose = np.array([2.0, 2.0, 0.3])
    a = [s.read(box, pose, np.random.default_rng(42)) for _ in range(2)]
    np.testing.assert_array_equal(a[0], a[1])
    clean = SonarRing().read(box, pose, np.random.default_rng(0))
    rng = np.random.default_rng(7)
    many = np.array([s.read(box, pose, rng) for _ in range(400)])
    dropped = many == 3.0
    assert 0.1 < dropped.mean() < 0.3
    noise = (many - clean)[~dropped]
    assert abs(noise.mean()) < 0.01 and 0.04 < noise.std() < 0.06
    # the default sonar never touches the rng
    rng = np.random.default_rng(3)
    SonarRing().read(box, pose, rng)
    assert rng.random() == np.random.default_rng(3).random()


def test_beam_cone_sees_a_thin_obstacle_between_beams(box: World) -> None:
    # a thin pole at bearing 20 deg (between the +10 and +30 beams), 1 m away
    a = math.radians(20.0)
    px, py = 2.0 + 1.0 * math.cos(a), 2.0 + 1.0 * math.sin(a)
    corners = [[px + dx, py + dy] for dx, dy in ((-0.02, -0.02), (0.02, -0.02), (0.02, 0.02),
                                                  (-0.02, 0.02))]
    text = BOX + f"\n[[obstacles]]\npoints = {corners}\n"
    world = parse_world(text)
    pose = np.array([2.0, 2.0, 0.0])
    single = SonarRing().read(world, pose, np.random.default_rng(0))
    clean = SonarRing().read(box, pose, np.random.default_rng(0))
    np.testing.assert_array_equal(single, clean)  # missed by the single rays
    cone = SonarRing(beam_width_deg=20.0, rays_per_beam=5).read(world, pose,
                                                                np.random.default_rng(0))
    assert cone[2] < 1.0 - 0.15 and cone[3] < 1.0 - 0.15  # both neighbours see it


def test_rim_reading_is_zero_when_touching(box: World) -> None:
    s = SonarRing(angles_deg=(0.0, 10.0))
    r = s.read(box, np.array([0.15, 2.0, math.pi]), np.random.default_rng(0))
    assert r[0] == pytest.approx(0.0, abs=1e-12)
    assert r[1] == pytest.approx(0.15 / math.cos(math.radians(10)) - 0.15)


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [({"max_range": 0}, "max_range"), ({"noise_std": -1}, "noise_std"),
     ({"dropout": 1.5}, "dropout"), ({"rays_per_beam": 0}, "rays_per_beam"),
     ({"rays_per_beam": 2**63}, "rays_per_beam"),  # (found by the fuzzer: an IndexError)
     ({"beam_width_deg": "wide"}, "beam_width_deg"), ({"angles_deg": []}, "angles_deg"),
     ({"robot_radius": float("nan")}, "robot_radius")],
)
def test_bad_params_name_the_parameter(kwargs: dict, name: str) -> None:
    with pytest.raises(ValueError, match=name):
        SonarRing(**kwargs)


def test_registration_and_protocol() -> None:
    from sitframe.contract.components import Sensor

    assert sitframe_sensors() == [SonarRing]
    s = SonarRing()
    assert s.name == "pioneer-sonar" and isinstance(s, Sensor)
    assert s.angles_deg.tolist() == [90, 50, 30, 10, -10, -30, -50, -90]
    world = load_world("training")
    assert s.read(world, world.start, np.random.default_rng(0)).shape == (8,)
