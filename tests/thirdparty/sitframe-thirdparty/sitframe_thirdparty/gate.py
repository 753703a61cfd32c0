"""The first behaviour whose activation passes a threshold, else a fallback (arbiter)."""

import numpy as np

from sitframe import Context, InputError, Proposal, RunContext, hookimpl


class Gate:
    name = "gate"

    def __init__(self, *, fallback: str = "wander", threshold: float = 0.3) -> None:
        self.fallback, self.threshold = str(fallback), float(threshold)
        self.labels: tuple[str, ...] = ()

    def bind(self, run: RunContext) -> None:
        if self.fallback not in run.labels:
            raise InputError(f"names behaviour '{self.fallback}', but the run's behaviours "
                             f"are: {', '.join(run.labels)}", key="fallback")
        self.labels = run.labels

    def combine(self, context: Context,
                proposals: dict[str, Proposal]) -> tuple[Proposal, np.ndarray]:
        w = np.zeros(len(proposals))
        for j, (label, p) in enumerate(proposals.items()):
            if label != self.fallback and (p.activation or 0.0) > self.threshold:
                w[j] = 1.0
                return p, w
        j = list(proposals).index(self.fallback)
        w[j] = 1.0
        return proposals[self.fallback], w


@hookimpl
def sitframe_arbiters() -> list[type]:
    return [Gate]
