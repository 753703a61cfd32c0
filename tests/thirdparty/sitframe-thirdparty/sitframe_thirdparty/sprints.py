"""Sprints: from random free starts, how often the robot gets ``distance`` metres away
without a collision (an evaluation protocol with its own config table, ``[sprints]``)."""

from typing import Any, ClassVar

import numpy as np

from sitframe import ConfigKey, ConfigTable, Context, RobotParams, World, hookimpl

SPRINTS = ConfigTable("sprints", (
    ConfigKey("episodes", "integer", 4, "sprints per world", lo=1, hi=1000),
    ConfigKey("timeout", "integer", 80, "iterations before a sprint is given up", lo=1),
    ConfigKey("distance", "number", 1.0, "how far from its start a sprint ends", unit="m",
              lo=0.0, lo_open=True),
    ConfigKey("margin", "number", 0.1, "clearance beyond the robot's radius at a start",
              unit="m", lo=0.0),
    ConfigKey("worlds", "names", ["novel-1"], "the worlds a batch of sprints runs in"),
), "Sprints from random free starts (the sitframe-thirdparty package).")


class Sprints:
    name = "sprints"
    config_table: ClassVar[ConfigTable] = SPRINTS

    def __init__(self, *, episodes: int = 4, timeout: int = 80, distance: float = 1.0,
                 margin: float = 0.1) -> None:
        self.episodes, self.iterations = int(episodes), int(timeout)
        self.distance, self.margin = float(distance), float(margin)

    def episode_starts(self, world: World, rng: np.random.Generator,
                       robot: RobotParams) -> tuple[np.ndarray, np.ndarray]:
        starts = np.array([world.random_free_pose(rng, robot.radius, margin=self.margin)
                           for _ in range(self.episodes)])
        # the "goal" of a sprint: its start, with the distance to get away as the radius
        return starts, np.column_stack([starts[:, :2], np.full(self.episodes, self.distance)])

    def terminated(self, context: Context) -> bool:
        g = context.goal
        return g is not None and float(np.hypot(*(context.pose[:2] - g.position))) >= g.radius

    def score_episode(self, arrays: dict[str, np.ndarray], start: np.ndarray,
                      goal: np.ndarray | None, robot: RobotParams) -> dict[str, Any]:
        away = float(np.hypot(*(arrays["pose"][-1, :2] - start[:2])))
        collisions = int(arrays["collision"].sum())
        return {"escaped": bool(away >= self.distance and collisions == 0),
                "away_m": away, "collisions": collisions}

    def aggregate(self, figures: dict[str, np.ndarray]) -> dict[str, float]:
        return {"escape_rate": float(np.mean(figures["escaped"])),
                "mean_away_m": float(np.mean(figures["away_m"]))}


@hookimpl
def sitframe_protocols() -> list[type]:
    return [Sprints]
