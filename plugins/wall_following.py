"""Wall-following reward (thesis 6.1, Algorithm 7) and its evaluation metrics.

The thesis keeps the robot "within an allowable distance" of 15-35 cm of the
left or the right wall but never says how that distance is measured. Here it
is, precisely:

**Distance to the wall** of one reading. Only the *side* sonars count: those
whose bearing satisfies ``|angle| >= side_min_angle`` (default 50 deg, i.e.
the Pioneer's +90, +50, -50, -90 beams). A range ``r`` (metres from the
robot's rim) of a beam at bearing ``a`` is turned into the lateral clearance
between the robot's rim and a wall *parallel to the robot's heading* that
would return that echo::

    d = (R + r) * sin(|a|) - R          # R = robot radius (0.15 m)

so the +-90 beams give ``d = r`` and the +-50 beams correct for the angle (a
robot turned towards its wall sees it first with the 50-degree beam). The
distance to the wall is the smallest ``d`` over both sides (the *nearer*
wall is the one followed, left or right). Readings at the sensor's maximum
range (nothing seen) are ignored; if no side beam sees anything the distance
is infinite (no wall).

**Reward** (evaluated on the state *after* the command; ``d0``/``d1`` =
wall distance before/after, ``n0``/``n1`` = nearest of all ranges before/after):

1. collision: ``collision`` (-30);
2. ``d1 < near`` (15 cm), too close: ``too_close`` (-20);
3. ``near <= d1 <= far`` (35 cm), following: ``inside`` (+30);
4. ``d1 > far`` and ``d0 <= far``, the robot had a wall within the band (or
   closer) and lost it: ``lost`` (-20);
5. ``d1 > far``, ``d0 > far`` and ``n1 < n0 - approach_min`` with something in
   sensor range, approaching a wall (or anything it can follow): ``approach`` (+20);
6. otherwise (exploring, no wall in reach): ``explore`` (0; the thesis leaves
   this case undefined).

Positive rewards then lose ``heading_cost * |heading|`` (degrees). The
printed algorithm subtracts the *signed* crisp heading, which would favour
right turns; we use the magnitude, as for obstacle avoidance.

The "too far" case must be conditional (rule 4): read as "any wall beyond
35 cm", it would fire whenever the robot is not in the band and the
"approaching" case (rule 5) could never be reached.

**Evaluation** (:meth:`WallFollowingReward.metrics`, used by
``sitframe evaluate`` on a wall-following log): the fraction of iterations
whose wall distance is inside the band, and two RMS errors: to the band's
centre and to the band (0 inside it), both with "no wall" counted as the
sensor's maximum range.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from sitframe import RunContext, Transition, hookimpl
from sitframe import params as P


class WallFollowingReward:
    """Thesis Algorithm 7 with the wall distance defined in the module docstring.

    Parameters
    ----------
    near, far
        The allowed band of wall distances [m] (15-35 cm, Table B.1).
    collision, too_close, lost, inside, approach, explore
        Rewards of the six cases (module docstring).
    heading_cost
        Subtracted from positive rewards per degree of |heading change|.
    angles_deg
        Bearing of each sensor beam [deg], positive = left, in reading order
        (default: the run sensor's, given at :meth:`bind`).
    side_min_angle
        Beams with ``|angle| >= side_min_angle`` [deg] measure the wall distance.
    robot_radius
        Robot disc radius [m] (ranges are from the rim; default: the run's, 0.15
        when used outside a run).
    max_range
        Readings at or beyond this [m] saw nothing (default: the sensor's, 3.0 when
        used outside a run).
    approach_min
        The nearest range must shrink by more than this [m] to count as approaching.
    """

    name = "wall-following"

    def __init__(
        self,
        *,
        near: float = 0.15,
        far: float = 0.35,
        collision: float = -30.0,
        too_close: float = -20.0,
        lost: float = -20.0,
        inside: float = 30.0,
        approach: float = 20.0,
        explore: float = 0.0,
        heading_cost: float = 0.1,
        angles_deg: Sequence[float] | None = None,
        side_min_angle: float = 50.0,
        robot_radius: float | None = None,
        max_range: float | None = None,
        approach_min: float = 0.01,
    ) -> None:
        self.near = P.number("near", near, lo=0.0)
        self.far = P.number("far", far, lo=0.0)
        if self.far <= self.near:
            raise ValueError(f"far ({self.far}) must be greater than near ({self.near})")
        self.collision = P.number("collision", collision)
        self.too_close = P.number("too_close", too_close)
        self.lost = P.number("lost", lost)
        self.inside = P.number("inside", inside)
        self.approach = P.number("approach", approach)
        self.explore = P.number("explore", explore)
        self.heading_cost = P.number("heading_cost", heading_cost, lo=0.0)
        self.side_min_angle = P.number("side_min_angle", side_min_angle, lo=0.0, hi=90.0,
                                       lo_open=True, unit="deg")
        self.approach_min = P.number("approach_min", approach_min, lo=0.0)
        self.band_centre = 0.5 * (self.near + self.far)
        self._given = {"angles_deg": angles_deg, "robot_radius": robot_radius,
                       "max_range": max_range}
        self.angles_deg: np.ndarray | None = None
        if angles_deg is not None:  # else the run's sensor gives them at bind
            self._set_geometry(angles_deg, 0.15 if robot_radius is None else robot_radius,
                               3.0 if max_range is None else max_range)

    def _set_geometry(self, angles_deg: Sequence[float], robot_radius: float,
                      max_range: float) -> None:
        angles = np.asarray(P.number_list("angles_deg", list(angles_deg), lo=-180, hi=180,
                                          unit="deg"))
        self.robot_radius = P.number("robot_radius", robot_radius, lo=0.0, unit="m")
        self.max_range = P.number("max_range", max_range, lo=0.0, lo_open=True, unit="m")
        side = np.abs(angles) >= self.side_min_angle
        if not side.any():
            raise ValueError(f"no beam has |angle| >= side_min_angle ({self.side_min_angle} deg)"
                             f"; angles_deg = {angles.tolist()}")
        self.angles_deg = angles
        self._side = np.flatnonzero(side)
        self._sin = np.sin(np.radians(np.abs(angles[side])))

    def bind(self, run: RunContext) -> None:
        """Take the beam angles, max range and robot radius from the run unless given."""
        g = self._given
        self._set_geometry(
            run.sensor.angles_deg if g["angles_deg"] is None else g["angles_deg"],
            run.robot.radius if g["robot_radius"] is None else g["robot_radius"],
            run.sensor.max_range if g["max_range"] is None else g["max_range"])
        if self.angles_deg.size != run.sensor.dim:
            raise ValueError(f"angles_deg has {self.angles_deg.size} beams but the sensor "
                             f"'{run.sensor.name}' reads {run.sensor.dim}; drop angles_deg "
                             "to use the sensor's")

    # -- wall distance -----------------------------------------------------
    def wall_distances(self, readings: np.ndarray) -> np.ndarray:
        """Distance to the nearer wall [m] of each row of ``readings`` (n, d); inf = no wall."""
        r = np.atleast_2d(np.asarray(readings, dtype=float))
        if self.angles_deg is None:
            raise ValueError("the wall-following reward knows no beam angles: give angles_deg "
                             "or bind it to a run (the run's sensor gives them)")
        if r.shape[1] != self.angles_deg.size:
            raise ValueError(f"a reading has {r.shape[1]} ranges but angles_deg has "
                             f"{self.angles_deg.size}; set reward_params.angles_deg")
        rs = r[:, self._side]
        d = (self.robot_radius + rs) * self._sin - self.robot_radius
        d = np.where(rs < self.max_range - 1e-9, d, np.inf)
        return np.maximum(d.min(axis=1), 0.0)

    def wall_distance(self, reading: np.ndarray) -> float:
        """Distance to the nearer wall [m] of one (d,) reading; inf = no wall."""
        return float(self.wall_distances(reading)[0])

    # -- reward ------------------------------------------------------------
    def __call__(self, tr: Transition) -> float:
        if tr.outcome.collided:
            return self.collision
        d1 = self.wall_distance(tr.after.reading)
        if d1 < self.near:
            return self.too_close
        if d1 <= self.far:
            r = self.inside
        elif self.wall_distance(tr.before.reading) <= self.far:
            return self.lost
        elif (tr.after.nearest < self.max_range - 1e-9
              and tr.after.nearest < tr.before.nearest - self.approach_min):
            r = self.approach
        else:
            r = self.explore
        if r > 0:
            r -= self.heading_cost * abs(tr.command.heading_change_deg)
        return r

    def _fused(self) -> dict[str, Any] | None:
        """The compiled trial's reward (``sitframe.runs.fused``): its parameters, side beams
        and their sines; ``None`` before :meth:`bind` or for a subclass's own ``__call__``
        or ``wall_distances``."""
        cls = type(self)
        if self.angles_deg is None or cls.__call__ is not WallFollowingReward.__call__ or \
                cls.wall_distances is not WallFollowingReward.wall_distances:
            return None
        return {"kind": "wall-following",
                "params": [self.near, self.far, self.collision, self.too_close, self.lost,
                           self.inside, self.approach, self.explore, self.heading_cost,
                           self.robot_radius, self.max_range, self.approach_min],
                "side": self._side, "sines": self._sin}

    # -- evaluation --------------------------------------------------------
    def metrics(self, arrays: dict[str, np.ndarray]) -> dict[str, float]:
        """Wall-following quality of a trial's per-iteration arrays (``reading (L, d)``).

        Returns
        -------
        dict
            ``wall_band_fraction`` (iterations with ``near <= d <= far``),
            ``wall_distance_rmse_m`` (RMS of ``d - (near + far) / 2``),
            ``wall_band_rmse_m`` (RMS distance outside the band, 0 inside),
            ``wall_lost_fraction`` (no side beam sees anything),
            ``wall_distance_median_m``; ``d`` is clipped to ``max_range``.
        """
        d = self.wall_distances(arrays["reading"] if "reading" in arrays else arrays["sonar"])
        if d.size == 0:
            nan = float("nan")
            return {"wall_band_fraction": nan, "wall_distance_rmse_m": nan,
                    "wall_band_rmse_m": nan, "wall_lost_fraction": nan,
                    "wall_distance_median_m": nan}
        lost = ~np.isfinite(d)
        dc = np.minimum(d, self.max_range)
        outside = np.maximum(self.near - dc, 0.0) + np.maximum(dc - self.far, 0.0)
        return {
            "wall_band_fraction": float(((d >= self.near) & (d <= self.far)).mean()),
            "wall_distance_rmse_m": float(np.sqrt(np.mean((dc - self.band_centre) ** 2))),
            "wall_band_rmse_m": float(np.sqrt(np.mean(outside ** 2))),
            "wall_lost_fraction": float(lost.mean()),
            "wall_distance_median_m": float(np.median(dc)),
        }


@hookimpl
def sitframe_rewards() -> list[Any]:
    return [WallFollowingReward]
