"""Robot simulator: kinematics, no tunnelling, contact, recovery, Simulator API."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sitframe.errors import InputError
from sitframe.sim import geometry as geo
from sitframe.sim.robot import (
    Command,
    RobotParams,
    Simulator,
    StepOutcome,
    step_robot,
    trajectory,
)
from sitframe.sim.world import World, parse_world

OPEN = """
name = "open"
[robot]
start = [10, 10, 0]
[[walls]]
points = [[0, 0], [20, 0], [20, 20], [0, 20], [0, 0]]
"""

# A box with a thin free-standing wall, a thin wall ending in a tip, and a
# sharp corner (two walls meeting at 30 degrees).
THIN = """
name = "thin"
[robot]
start = [1, 1, 0]
[[walls]]
points = [[0, 0], [12, 0], [12, 12], [0, 12], [0, 0]]
[[walls]]
points = [[6, 2], [6, 10]]
[[walls]]
points = [[2, 9], [4.5, 9]]
[[walls]]
points = [[8.5, 3], [11, 3], [8.5, 4.443]]
"""


@pytest.fixture(scope="module")
def open_world() -> World:
    return parse_world(OPEN)


@pytest.fixture(scope="module")
def thin_world() -> World:
    return parse_world(THIN)


P = RobotParams()
RNG = np.random.default_rng(0)


def test_straight_motion(open_world: World) -> None:
    out = step_robot(open_world, np.array([10.0, 10.0, 0.0]), Command(0.0, 0.15), P, RNG)
    np.testing.assert_allclose(out.pose, [10.225, 10.0, 0.0], atol=1e-12)
    assert out.distance_m == pytest.approx(0.225)
    assert not out.collided and np.all(np.isnan(out.contact_xy))
    assert out.contact_pose is out.pose


def test_turn_rate_limit_and_direction(open_world: World) -> None:
    pose = np.array([10.0, 10.0, 0.0])
    times = np.array([0.0, 0.45, 0.9, 1.2, 1.5])
    traj = trajectory(pose, Command(90.0, 0.15), P, times)
    # 100 deg/s: 45 deg after 0.45 s, 90 deg after 0.9 s, then straight
    np.testing.assert_allclose(np.degrees(traj[:, 2]), [0, 45, 90, 90, 90], atol=1e-9)
    out = step_robot(open_world, pose, Command(90.0, 0.15), P, RNG)
    assert out.heading_change_deg == pytest.approx(90.0)
    rad = 0.15 / math.radians(100.0)  # quarter circle, then 0.6 s straight up
    np.testing.assert_allclose(out.pose, [10 + rad, 10 + rad + 0.09, math.pi / 2], atol=1e-12)
    out = step_robot(open_world, pose, Command(-30.0, 0.15), P, RNG)
    assert out.heading_change_deg == pytest.approx(-30.0)
    assert out.pose[1] < 10.0
    # clipping: heading to +-90, speed to [0.1, 0.3]
    out = step_robot(open_world, pose, Command(170.0, 5.0), P, RNG)
    assert out.heading_change_deg == pytest.approx(90.0)
    assert out.distance_m == pytest.approx(0.45)
    out = step_robot(open_world, pose, Command(0.0, 0.0), P, RNG)
    assert out.distance_m == pytest.approx(0.15)


def test_arc_is_exact_unicycle(open_world: World) -> None:
    # path length along the arc equals v * t: compare with a fine Euler integration
    pose = np.array([10.0, 10.0, 0.3])
    cmd = Command(-73.0, 0.27)
    t = np.linspace(0, 1.5, 30001)
    dt = t[1] - t[0]
    w = -math.radians(100.0)
    th = np.where(t < 0.73, 0.3 + w * t, 0.3 + w * 0.73)
    mid = th[:-1] + 0.5 * (th[1:] - th[:-1])
    x = 10 + np.concatenate([[0], np.cumsum(0.27 * np.cos(mid))]) * dt
    y = 10 + np.concatenate([[0], np.cumsum(0.27 * np.sin(mid))]) * dt
    out = step_robot(open_world, pose, cmd, P, RNG)
    np.testing.assert_allclose(out.pose[:2], [x[-1], y[-1]], atol=1e-6)


@pytest.mark.parametrize("speed", [0.3, 0.1])
def test_no_tunnelling_into_thin_walls_and_corners(thin_world: World, speed: float) -> None:
    targets = [(6.0, 6.0), (6.0, 2.0), (6.0, 10.0), (4.5, 9.0), (3.2, 9.0), (9.5, 3.6),
               (8.5, 3.0), (11.0, 3.0)]
    rng = np.random.default_rng(1)
    n_coll = 0
    r = P.radius
    ts = np.linspace(0, 1.5, 61)
    for tx, ty in targets:
        for ang in np.arange(0.0, 360.0, 7.5):
            for off in (0.16, 0.3, 0.45):
                a = math.radians(ang)
                start = np.array([tx - off * math.cos(a), ty - off * math.sin(a), a])
                if not thin_world.is_free(start[None, :2], r)[0]:
                    continue
                for turn in (0.0, 25.0, -60.0):
                    out = step_robot(thin_world, start, Command(turn, speed), P, rng)
                    n_coll += out.collided
                    for q in (out.contact_pose, out.pose):
                        assert thin_world.clearance(q[None, :2])[0] >= r - 1e-9, (start, turn)
                    assert thin_world.is_free(out.pose[None, :2], r - 1e-9)[0]
                    # the centre never crossed a wall (checked along the sampled path)
                    path = trajectory(start, Command(turn, speed), P, ts)[:, :2]
                    if out.collided:
                        travelled = np.linspace(0.0, speed * 1.5, ts.size)
                        path = np.vstack([path[travelled < out.distance_m],
                                          out.contact_pose[None, :2]])
                    legs = np.vstack([np.hstack([path[:-1], path[1:]]),
                                      np.r_[out.contact_pose[:2], out.pose[:2]][None, :]])
                    assert not geo.segments_intersect(legs, thin_world.segments).any(), (
                        start, turn)
    assert n_coll > 100  # the test really fires the robot into walls


def test_contact_touches_and_recovery_turns_away(thin_world: World) -> None:
    r = P.radius
    rng = np.random.default_rng(3)
    for ang in range(-80, 81, 10):
        a = math.radians(ang)
        # aim at the long thin wall x = 6 from the left
        start = np.array([6.0 - 0.15 - 0.3 * math.cos(a), 6.0 - 0.4 * math.sin(a), a])
        out = step_robot(thin_world, start, Command(0.0, 0.3), P, rng)
        assert out.collided
        c = thin_world.clearance(out.contact_pose[None, :2])[0]
        assert r - 1e-9 <= c <= r + 2e-4  # touching, never inside
        assert out.contact_xy[0] == pytest.approx(6.0)
        assert out.distance_m < 0.45
        # recovery: free, backed off along the normal, facing more away
        assert thin_world.clearance(out.pose[None, :2])[0] >= r + 0.05 - 1e-6
        assert out.backoff_m == pytest.approx(0.05)

        def bearing(q: np.ndarray, c_xy: np.ndarray = out.contact_xy) -> float:
            return abs(math.remainder(math.atan2(c_xy[1] - q[1], c_xy[0] - q[0]) - q[2], math.tau))

        assert bearing(out.pose) > bearing(out.contact_pose) + math.radians(10)
        assert abs(out.recovery_turn_deg) == pytest.approx(45.0)


def test_recovery_none_just_stalls(thin_world: World) -> None:
    params = RobotParams(recovery="none")
    out = step_robot(thin_world, np.array([5.5, 6.0, 0.0]), Command(0.0, 0.3), params, RNG)
    assert out.collided and out.pose is out.contact_pose and out.backoff_m == 0.0
    assert out.contact_pose[0] == pytest.approx(6.0 - 0.15, abs=2e-4)


def test_backoff_is_clipped_by_other_walls() -> None:
    # a slot 0.33 m wide (2 r + 0.03): after touching the upper wall, the
    # back-off along the normal (down) has only 0.03 m before the lower wall
    w = parse_world("""
name = "slot"
[robot]
start = [0.5, 1.165, 0]
[[walls]]
points = [[0, 0], [4, 0], [4, 3], [0, 3], [0, 0]]
[[walls]]
points = [[0.3, 1.0], [3.5, 1.0]]
[[walls]]
points = [[0.3, 1.33], [3.5, 1.33]]
""")
    rng = np.random.default_rng(0)
    for ang in (5.0, 20.0, -20.0):
        out = step_robot(w, np.array([1.0, 1.165, math.radians(ang)]), Command(0.0, 0.3), P, rng)
        assert out.collided
        assert 0.0 <= out.backoff_m <= 0.03 + 1e-9
        assert w.clearance(out.pose[None, :2])[0] >= 0.15 - 1e-9


def test_start_inside_wall_backs_off(thin_world: World) -> None:
    out = step_robot(thin_world, np.array([5.9, 6.0, 0.0]), Command(0.0, 0.3), P, RNG)
    assert out.collided and out.distance_m == 0.0
    assert out.pose[0] < 5.9  # moved away from the wall


def test_params_validation() -> None:
    with pytest.raises(InputError, match="radius") as info:  # an InputError is a ValueError
        RobotParams(radius=-1)
    assert isinstance(info.value, ValueError) and info.value.key == "radius"
    with pytest.raises(ValueError, match="recovery"):
        RobotParams(recovery="bounce")
    with pytest.raises(ValueError, match="min_speed"):
        RobotParams(min_speed=0.5, max_speed=0.3)
    with pytest.raises(ValueError, match="substep_s"):
        RobotParams(substep_s=1.0)
    with pytest.raises(TypeError, match="heading_change_deg"):
        Command("left", 0.1)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="finite"):
        Command(float("nan"), 0.1)


def test_simulator_api(thin_world: World) -> None:
    class Probe:
        def read(self, world: World, pose: np.ndarray, rng: np.random.Generator) -> np.ndarray:
            return np.array([pose[0], rng.random()])

    sim = Simulator(thin_world, sensor=Probe(), seed=5)
    r0, info = sim.reset(seed=7)
    np.testing.assert_array_equal(info["pose"], thin_world.start)
    reading, out = sim.step(Command(10.0, 0.2))
    assert isinstance(out, StepOutcome) and reading[0] == sim.pose[0]
    r0b, _ = sim.reset(seed=7)
    assert r0b[1] == r0[1]  # re-seeded
    with pytest.raises(ValueError, match="not free"):
        sim.reset(pose=np.array([6.0, 5.0, 0.0]))
    assert Simulator(thin_world).reset()[0] is None
    with pytest.raises(TypeError):
        Simulator("training")  # type: ignore[arg-type]
