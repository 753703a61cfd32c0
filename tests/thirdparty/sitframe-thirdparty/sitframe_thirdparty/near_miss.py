"""Penalise collisions and near misses, counted per trial (a reward with state)."""

from sitframe import RunContext, Transition, TrialInfo, hookimpl


class NearMiss:
    name = "near-miss"

    def __init__(self, *, collision: float = -20.0, near: float = 0.25) -> None:
        self.collision, self.near = float(collision), float(near)
        self.misses = self.hits = 0
        self.radius = 0.15

    def bind(self, run: RunContext) -> None:
        self.radius = float(run.robot.radius)

    def trial_start(self, trial: TrialInfo) -> None:
        self.misses = self.hits = 0

    def __call__(self, tr: Transition) -> float:
        if tr.collided:
            self.hits += 1
            return self.collision
        if tr.after.nearest < self.near:
            self.misses += 1
            return -2.0
        return 1.0 - 0.01 * abs(tr.command.heading_change_deg)

    def trial_end(self, trial: TrialInfo) -> dict[str, int]:
        return {"near_misses": self.misses, "collisions": self.hits}


@hookimpl
def sitframe_rewards() -> list[type]:
    return [NearMiss]
