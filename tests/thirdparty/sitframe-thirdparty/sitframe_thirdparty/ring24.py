"""A 360 deg ring of 24 range beams, one every 15 deg (sensor)."""

import numpy as np

from sitframe import RunContext, World, hookimpl, rim_ranges
from sitframe import params as P


class Ring24:
    name = "ring24"

    def __init__(self, *, max_range: float = 3.0) -> None:
        self.max_range = P.number("max_range", max_range, lo=0.0, lo_open=True)
        self.angles_deg = np.arange(24) * 15.0 - 180.0  # -180 .. 165, one straight ahead
        self._rel = np.radians(self.angles_deg)
        self.radius = 0.15

    def bind(self, run: RunContext) -> None:
        self.radius = float(run.robot.radius)

    def read(self, world: World, pose: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        return rim_ranges(world.segment_set, pose[0], pose[1], self._rel + pose[2],
                          self.max_range, self.radius, clip=True)


@hookimpl
def sitframe_sensors() -> list[type]:
    return [Ring24]
