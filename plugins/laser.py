"""A planar laser scanner, as a sensor plugin — the second worked example of a sensor.

A scanner is a fan of ``beams`` rays spread evenly over a field of view
``fov_deg`` centred on the heading (0 deg), each reading the range to the
first wall or obstacle edge, measured from the robot's rim like the sonar:

- ``fov_deg < 360``: beams from ``-fov/2`` (right) to ``+fov/2`` (left), both
  ends included — the default 16 beams over 180 deg are 12 deg apart,
  ``-90, -78, ..., 78, 90``;
- ``fov_deg = 360``: a full ring, beams in ``[-180, 180)`` (``-180`` is
  straight behind), ``360 / beams`` apart.

``angle_offset_deg`` turns the whole fan (a scanner mounted askew);
bearings are kept in ``[-180, 180)``. The run logs the layout
(``angles_deg``, ``max_range``) with every reading, so clustering, the
situation descriptions and ``sitframe analyse`` work with any layout.

How it is written (copy it for your own sensor; ``plugins/sonar.py`` has the
step-by-step guide):

1. ``__init__`` takes the ``[sensor]`` table's keys as keyword arguments,
   checks each with :mod:`sitframe.params` (an error names the parameter;
   the config loader adds the file and table) and lays the beams out once.
2. ``bind(run)`` learns the robot's radius from the run, unless the config
   gave ``robot_radius``.
3. ``read`` casts every beam in one :func:`sitframe.rim_ranges` call (ranges
   from the rim) against the world's cached edges and draws from the given ``rng``
   only when ``noise_std`` or ``dropout`` is on, so runs stay reproducible.

In a run config::

    [sensor]
    component = "laser"
    fov_deg = 360        # a full ring
    beams = 16
    max_range = 4.0      # m
    noise_std = 0.01     # m, Gaussian range noise
    dropout = 0.02       # chance that a beam reads max_range

>>> import numpy as np
>>> from sitframe import load_world
>>> from sitframe.plugins.laser import LaserScanner
>>> world = load_world("training")
>>> LaserScanner(fov_deg=360, beams=8).angles_deg.tolist()
[-180.0, -135.0, -90.0, -45.0, 0.0, 45.0, 90.0, 135.0]
>>> LaserScanner().read(world, world.start, np.random.default_rng(0)).shape
(16,)
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np

from sitframe import hookimpl
from sitframe import params as P

from .sonar import RimRangeSensor

__all__ = ["LaserScanner", "sitframe_sensors"]

#: More beams than this only costs time (a 360 deg scan every 0.35 deg); the
#: bound keeps a typo from allocating gigabytes.
MAX_BEAMS = 1024


class LaserScanner(RimRangeSensor):
    """Planar laser scanner: ``beams`` ranges [m] from the robot's rim over ``fov_deg``.

    Parameters
    ----------
    fov_deg
        Field of view [deg], in (0, 360]; 360 is a full ring.
    beams
        Number of beams, in [1, 1024]; one beam looks straight ahead.
    max_range
        Maximum range from the rim [m], > 0; readings clip to it.
    robot_radius
        Distance from the centre (ray origin) to the rim [m]; by default the
        run's ``robot.radius`` (given at :meth:`bind`).
    noise_std
        Standard deviation of additive Gaussian range noise [m], >= 0.
    dropout
        Probability in [0, 1] that a beam returns nothing (reads ``max_range``).
    angle_offset_deg
        Rotation of the whole fan [deg], positive = left, in [-180, 180].

    Attributes
    ----------
    angles_deg
        (beams,) read-only bearings [deg] relative to the heading, positive =
        left, in [-180, 180), in scan order (right to left).
    """

    name: ClassVar[str] = "laser"

    def __repr__(self) -> str:
        return (f"LaserScanner({self.beams} beams over {self.fov_deg:g} deg, "
                f"max_range={self.max_range:g} m)")

    def __init__(
        self,
        *,
        fov_deg: float = 180.0,
        beams: int = 16,
        max_range: float = 4.0,
        robot_radius: float | None = None,
        noise_std: float = 0.0,
        dropout: float = 0.0,
        angle_offset_deg: float = 0.0,
    ):
        self.fov_deg = P.number("fov_deg", fov_deg, lo=0, hi=360, lo_open=True, unit="deg")
        self.beams = P.number("beams", beams, lo=1, hi=MAX_BEAMS, integer=True)
        self.max_range = P.number("max_range", max_range, lo=0, lo_open=True, unit="m")
        self._radius_given = robot_radius is not None
        self.robot_radius = 0.15 if robot_radius is None else \
            P.number("robot_radius", robot_radius, lo=0, unit="m")
        self.noise_std = P.number("noise_std", noise_std, lo=0, unit="m")
        self.dropout = P.number("dropout", dropout, lo=0, hi=1)
        offset = P.number("angle_offset_deg", angle_offset_deg, lo=-180, hi=180, unit="deg")
        n = self.beams
        if self.fov_deg == 360:  # a ring: n gaps, the first beam straight behind
            fan = -180.0 + 360.0 * np.arange(n) / n
        else:  # an arc: n - 1 gaps, both edges included
            fan = np.linspace(-self.fov_deg / 2, self.fov_deg / 2, n) if n > 1 else np.zeros(1)
        self.angles_deg = (fan + offset + 180.0) % 360.0 - 180.0
        self.angles_deg.setflags(write=False)
        self._ray_rel = np.radians(self.angles_deg)  # one ray per beam
        self.rays_per_beam, self._n = 1, n


@hookimpl
def sitframe_sensors() -> list[type]:
    """Register the laser scanner as ``"laser"``."""
    return [LaserScanner]
