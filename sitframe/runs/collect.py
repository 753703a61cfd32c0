"""The collect stage: record sensor readings for clustering (thesis 4.3, 5.3).

Two modes (``both`` concatenates them, trajectory samples first):

``trajectory``
    The robot is driven along each world's forced ``[[trajectories]]`` at
    ``speed`` (0.15 m/s) and the sensor is read ``rate_hz`` times per second
    (twice per second in the thesis), i.e. one sample every ``speed/rate_hz``
    metres of path. The heading is the direction of the current path segment;
    at a waypoint it turns at the robot's turn-rate limit (samples taken while
    turning on the spot are kept, as a real robot would record them).
``wander``
    Random exploration with reflexive avoidance in each world, the thesis's
    own remedy for situations its trajectories missed (5.3): every
    ``1/rate_hz`` s a new command is drawn -- a random heading change (normal,
    25 deg s.d.), or, when something is within 0.6 m ahead, a hard turn toward
    the more open side -- and executed by the simulator.

Both are deterministic for a given Generator.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from sitframe.contract.components import Sensor
from sitframe.sim.robot import Command, RobotParams, step_robot
from sitframe.sim.world import World


@dataclass(frozen=True)
class Collected:
    """Collected readings.

    Attributes
    ----------
    samples : (n, d) readings, metres.
    poses : (n, 3) x [m], y [m], theta [rad] of each sample.
    source : (n,) index into ``worlds`` of the world each sample came from.
    worlds : names of the worlds, in order.
    """

    samples: np.ndarray
    poses: np.ndarray
    source: np.ndarray
    worlds: tuple[str, ...]


def trajectory_poses(
    points: np.ndarray, spacing: float, *, turn_step_rad: float | None = None
) -> np.ndarray:
    """Poses every ``spacing`` metres along a polyline.

    Parameters
    ----------
    points
        (k, 2) waypoints, metres.
    spacing
        Path length between samples, metres.
    turn_step_rad
        Heading change per sample while turning on the spot at a waypoint
        (``None``: jump to the new heading).

    Returns
    -------
    (n, 3) poses.
    """
    pts = np.asarray(points, dtype=float)
    out: list[np.ndarray] = []
    carry = 0.0  # path length already travelled past the last sample
    prev_heading: float | None = None
    for a, b in zip(pts[:-1], pts[1:], strict=True):
        seg = b - a
        length = float(np.hypot(*seg))
        if length == 0.0:
            continue
        heading = float(np.arctan2(seg[1], seg[0]))
        if prev_heading is not None and turn_step_rad:
            delta = (heading - prev_heading + np.pi) % (2 * np.pi) - np.pi
            n_turn = int(abs(delta) // turn_step_rad)
            for k in range(1, n_turn + 1):
                theta = prev_heading + np.sign(delta) * k * turn_step_rad
                out.append(np.array([a[0], a[1], theta]))
        s = np.arange(spacing - carry if out else 0.0, length, spacing)
        xy = a + np.outer(s / length, seg)
        out.extend(np.column_stack([xy, np.full(len(s), heading)]))
        carry = length - s[-1] if len(s) else carry + length
        prev_heading = heading
    if not out:
        return np.empty((0, 3))
    poses = np.asarray(out)
    poses[:, 2] = (poses[:, 2] + np.pi) % (2 * np.pi) - np.pi
    return poses


def collect_trajectories(worlds: list[World], sensor: Sensor, rng: np.random.Generator, *,
                         speed: float = 0.15, rate_hz: float = 2.0,
                         params: RobotParams | None = None) -> Collected:
    """Drive every world's forced trajectories and read the sensor (``trajectory`` mode)."""
    params = params or RobotParams()
    spacing = speed / rate_hz
    turn_step = np.deg2rad(params.max_turn_rate_deg_s) / rate_hz
    samples, poses, source = [], [], []
    for wi, world in enumerate(worlds):
        if not world.trajectories:
            raise ValueError(f"world '{world.name}' has no [[trajectories]] to collect along "
                             "(use collect.mode = \"wander\" or a collection room)")
        for traj in world.trajectories:
            for pose in trajectory_poses(traj, spacing, turn_step_rad=turn_step):
                samples.append(sensor.read(world, pose, rng))
                poses.append(pose)
                source.append(wi)
    return Collected(np.asarray(samples), np.asarray(poses), np.asarray(source, dtype=np.int16),
                     tuple(w.name for w in worlds))


def collect_wander(
    worlds: list[World],
    sensor: Sensor,
    rng: np.random.Generator,
    *,
    n_samples: int = 300,
    speed: float = 0.15,
    rate_hz: float = 2.0,
    params: RobotParams | None = None,
) -> Collected:
    """Random exploration with reflexive avoidance (``wander`` mode)."""
    params = dataclasses.replace(params or RobotParams(), control_period_s=1.0 / rate_hz)
    # Any beam layout: the frontal beams (at least the one nearest the heading) and
    # the left and right halves; the beam straight behind (+-180 deg) is neither.
    angles = (np.asarray(sensor.angles_deg, dtype=float) + 180.0) % 360.0 - 180.0
    front = np.abs(angles) <= max(30.0, float(np.abs(angles).min()))
    left, right = angles > 0, (angles < 0) & (angles > -180.0)
    samples, poses, source = [], [], []
    for wi, world in enumerate(worlds):
        pose = world.start.copy()
        for _ in range(n_samples):
            reading = sensor.read(world, pose, rng)
            samples.append(reading)
            poses.append(pose)
            source.append(wi)
            if reading[front].min() < 0.6:
                side = 1.0 if _mean(reading, left) >= _mean(reading, right) else -1.0
                turn = side * rng.uniform(60.0, 90.0)
            else:
                turn = float(np.clip(rng.normal(0.0, 25.0), -90.0, 90.0))
            pose = step_robot(world, pose, Command(turn, speed), params, rng).pose
    return Collected(np.asarray(samples), np.asarray(poses), np.asarray(source, dtype=np.int16),
                     tuple(w.name for w in worlds))


def _mean(reading: np.ndarray, beams: np.ndarray) -> float:
    """Mean range of ``beams`` (a mask), 0 when the layout has none there."""
    return float(reading[beams].mean()) if beams.any() else 0.0


def concat_collected(parts: list[Collected]) -> Collected:
    """Concatenate collections over the same worlds (e.g. trajectory + wander samples)."""
    if len(parts) == 1:
        return parts[0]
    return Collected(np.concatenate([p.samples for p in parts]),
                     np.concatenate([p.poses for p in parts]),
                     np.concatenate([p.source for p in parts]), parts[0].worlds)
