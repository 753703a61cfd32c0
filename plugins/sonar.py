"""The Pioneer 2DX front sonar ring, as a sensor plugin — and a tutorial for writing one.

A *sensor* turns ``(world, pose, rng)`` into a reading, a 1-D array of
floats. To add your own:

1. Write a class with a unique ``name``, an ``angles_deg`` array (bearing of
   each beam relative to the heading, positive = left), a ``max_range``, and a
   ``read(world, pose, rng)`` method. Take parameters as keyword arguments in
   ``__init__`` and validate them there (raise ``ValueError`` naming the
   parameter; the config loader turns it into a one-line error).
2. Use the world's cached geometry: ``world.segment_set`` holds every wall and
   obstacle edge; :func:`sitframe.cast_rays` casts all rays in one call, and
   :func:`sitframe.rim_ranges` turns them into a range finder's reading
   (ranges from the robot's rim, the nearest of each beam's rays). Both run
   compiled kernels when numba is installed (:mod:`sitframe.sim.kernels`).
   Everything a plugin needs is importable from ``sitframe`` itself.
3. Take all randomness from the ``rng`` you are given (never ``np.random``),
   and draw from it only when an option needs it, so runs stay reproducible.
4. Register the class from a hook::

       from sitframe import hookimpl

       @hookimpl
       def sitframe_sensors():
           return [MySensor]

   and declare the module as an entry point in your package's
   ``pyproject.toml``::

       [project.entry-points.sitframe]
       my_sensor = "my_package.my_sensor"

   (or drop the file in a ``--plugins-dir`` folder for a quick experiment).
   A run config then picks it with ``sensor = "my-sensor"`` and passes the
   ``[sensor]`` table's keys as keyword arguments.

The Pioneer ring
----------------
Eight front sonars at +90, +50, +30, +10, -10, -30, -50, -90 degrees, range
measured from the body's rim, at most 3.0 m. By default each sonar is a
*single ray*, as in the thesis — so thin obstacles and corners that fall
between two beams are missed (the thesis's "sonar placement" problem, kept
reproducible on purpose). Options: a beam cone of ``rays_per_beam`` rays
spread over ``beam_width_deg`` (the reading is the nearest), Gaussian range
noise ``noise_std`` [m] and a ``dropout`` probability (a dropped beam reads
``max_range``, like a lost echo).

>>> import numpy as np
>>> from sitframe import load_world
>>> from sitframe.plugins.sonar import SonarRing
>>> world = load_world("training")
>>> SonarRing().read(world, world.start, np.random.default_rng(0)).shape
(8,)
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, ClassVar

import numpy as np

from sitframe import RunContext, World, hookimpl, rim_ranges, rim_ranges_many
from sitframe import params as P

__all__ = ["PIONEER_ANGLES_DEG", "RimRangeSensor", "SonarRing", "sitframe_sensors"]

#: Bearings of the Pioneer 2DX's 8 front sonars, degrees, positive = left (the
#: project's one definition; everything else asks the run's sensor).
PIONEER_ANGLES_DEG: tuple[float, ...] = (90.0, 50.0, 30.0, 10.0, -10.0, -30.0, -50.0, -90.0)


#: More rays than this per sonar cone only costs time (a 25 deg cone is sampled
#: every 0.1 deg at 256); the bound keeps a typo from allocating gigabytes.
MAX_RAYS_PER_BEAM = 256


class RimRangeSensor:
    """Range finders on the robot's rim, read by ray casting: the shared half of
    :class:`SonarRing` and the laser scanner.

    A subclass sets, in its ``__init__``: ``max_range`` [m], ``robot_radius`` [m] (with
    ``_radius_given``: whether the config gave it), ``noise_std`` [m], ``dropout``,
    ``rays_per_beam`` (rays per reading; the reading is the nearest hit), ``_n`` (the number
    of readings) and ``_ray_rel``: the ``(_n * rays_per_beam,)`` ray bearings [rad]
    relative to the heading, reading by reading.
    """

    max_range: float
    robot_radius: float
    noise_std: float
    dropout: float
    rays_per_beam: int
    _radius_given: bool
    _n: int
    _ray_rel: np.ndarray

    def bind(self, run: RunContext) -> None:
        """Measure ranges from the run robot's rim unless ``robot_radius`` was given."""
        if not self._radius_given:
            self.robot_radius = float(run.robot.radius)

    def read(self, world: World, pose: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Read every range finder at ``pose``.

        Parameters
        ----------
        world
            The world.
        pose
            (3,) x [m], y [m], theta [rad].
        rng
            Used only for noise and dropout.

        Returns
        -------
        numpy.ndarray
            (d,) ranges [m] from the rim, in [0, max_range], one per reading (a sonar, a
            laser beam) in the sensor's order.
        """
        exact = self.noise_std == 0.0 and self.dropout == 0.0  # (then clipped in the same call)
        reading = rim_ranges(world.segment_set, pose[0], pose[1], self._ray_rel, self.max_range,
                             self.robot_radius, self.rays_per_beam, clip=exact,
                             heading=float(pose[2]))
        if exact:
            return reading
        if self.noise_std > 0.0:
            reading = reading + rng.normal(0.0, self.noise_std, self._n)
        if self.dropout > 0.0:
            reading = np.where(rng.random(self._n) < self.dropout, self.max_range, reading)
        return np.clip(reading, 0.0, self.max_range)

    def _fused(self) -> dict[str, Any] | None:
        """What the compiled trial needs of this sensor (``sitframe.runs.fused``), or ``None``
        when it cannot read for it: noise or dropout (draws), or a subclass's own ``read``."""
        if type(self).read is not RimRangeSensor.read or self.noise_std or self.dropout:
            return None
        return {"rays": self._ray_rel, "max_range": float(self.max_range),
                "radius": float(self.robot_radius), "rays_per_beam": int(self.rays_per_beam)}

    def read_many(self, world: World, poses: np.ndarray,
                  rngs: Sequence[np.random.Generator]) -> np.ndarray:
        """Read the range finders of N robots in one ray-casting call (the vector env's batch).

        Row ``i`` equals ``read(world, poses[i], rngs[i])``: the same rays and, for noise
        and dropout, the same draws from robot ``i``'s own generator.

        Parameters
        ----------
        poses
            (N, 3) x [m], y [m], theta [rad].
        rngs
            N generators, one per robot.

        Returns
        -------
        numpy.ndarray
            (N, d) ranges [m] from the rim, in [0, max_range].
        """
        poses = np.asarray(poses, dtype=np.float64)
        exact = self.noise_std == 0.0 and self.dropout == 0.0  # (as read())
        readings = rim_ranges_many(world.segment_set, poses[:, :2],
                                   self._ray_rel[None, :] + poses[:, 2:3],  # as read() adds
                                   self.max_range, self.robot_radius, self.rays_per_beam,
                                   clip=exact)
        if exact:
            return readings
        for i in range(poses.shape[0]):
            if self.noise_std > 0.0:
                readings[i] = readings[i] + rngs[i].normal(0.0, self.noise_std, self._n)
            if self.dropout > 0.0:
                readings[i] = np.where(rngs[i].random(self._n) < self.dropout, self.max_range,
                                       readings[i])
        return np.clip(readings, 0.0, self.max_range)


class SonarRing(RimRangeSensor):
    """Front sonar ring: one range per sonar, metres from the robot's rim.

    Parameters
    ----------
    angles_deg
        Bearing of each sonar relative to the heading [deg], positive = left.
    max_range
        Maximum range from the rim [m]; readings clip to it.
    robot_radius
        Distance from the centre (ray origin) to the rim [m]; by default the
        run's ``robot.radius`` (given at :meth:`bind`).
    beam_width_deg
        Full width of each beam's cone [deg] (0 = a single ray).
    rays_per_beam
        Rays spread evenly across the cone; the reading is the nearest hit.
    noise_std
        Standard deviation of additive Gaussian range noise [m].
    dropout
        Probability that a beam returns nothing (reads ``max_range``).
    """

    name: ClassVar[str] = "pioneer-sonar"

    def __init__(
        self,
        *,
        angles_deg: Sequence[float] = PIONEER_ANGLES_DEG,
        max_range: float = 3.0,
        robot_radius: float | None = None,
        beam_width_deg: float = 0.0,
        rays_per_beam: int = 1,
        noise_std: float = 0.0,
        dropout: float = 0.0,
    ):
        try:
            angles = np.array(angles_deg, dtype=np.float64).reshape(-1)
        except (TypeError, ValueError):
            raise ValueError(f"angles_deg: expected a list of numbers, got {angles_deg!r}"
                             ) from None
        if angles.size == 0 or not np.all(np.isfinite(angles)):
            raise ValueError(f"angles_deg: expected at least one finite angle, got {angles_deg!r}")
        self.angles_deg = angles
        self.angles_deg.setflags(write=False)
        self.max_range = P.number("max_range", max_range, lo=0.0, lo_open=True, unit="m")
        self.robot_radius = 0.15 if robot_radius is None else \
            P.number("robot_radius", robot_radius, lo=0.0, unit="m")
        self._radius_given = robot_radius is not None
        self.beam_width_deg = P.number("beam_width_deg", beam_width_deg, lo=0.0, hi=180.0,
                                       unit="deg")
        if isinstance(rays_per_beam, bool) or not isinstance(rays_per_beam, int | np.integer) \
                or not 1 <= rays_per_beam <= MAX_RAYS_PER_BEAM:
            raise ValueError(f"rays_per_beam: expected an integer in [1, {MAX_RAYS_PER_BEAM}], "
                             f"got {rays_per_beam!r}")
        self.rays_per_beam = int(rays_per_beam)
        self.noise_std = P.number("noise_std", noise_std, lo=0.0, unit="m")
        self.dropout = P.number("dropout", dropout, lo=0.0, hi=1.0)
        # Ray bearings relative to the heading, beam by beam: (d * rays,)
        if self.rays_per_beam > 1:
            spread = np.linspace(-0.5, 0.5, self.rays_per_beam) * self.beam_width_deg
        else:
            spread = np.zeros(1)
        self._ray_rel = np.radians((angles[:, None] + spread[None, :]).reshape(-1))
        self._n = angles.size

    def __repr__(self) -> str:
        return (f"SonarRing({self._n} beams, max_range={self.max_range:g} m, "
                f"rays_per_beam={self.rays_per_beam})")


@hookimpl
def sitframe_sensors() -> list[type]:
    """Register the Pioneer sonar ring as ``"pioneer-sonar"``."""
    return [SonarRing]
