"""Soft nearest-prototype situations: k-means centres (interpreter)."""

from typing import Any

import numpy as np

from sitframe import hookimpl
from sitframe import params as P


class SoftKMeans:
    name = "soft-kmeans"

    def __init__(self, *, c: int = 6, width: float = 0.4, rounds: int = 15) -> None:
        self.c = int(P.number("c", c, lo=2, integer=True))
        self.width = P.number("width", width, lo=0.0, lo_open=True)
        self.rounds = int(P.number("rounds", rounds, lo=1, integer=True))
        self.centers = np.zeros((0, 0))

    @property
    def n_situations(self) -> int:
        return self.c

    def fit(self, X: np.ndarray, rng: np.random.Generator) -> dict[str, Any]:
        centers = X[rng.choice(len(X), self.c, replace=False)].copy()
        for _ in range(self.rounds):
            nearest = ((X[:, None, :] - centers[None]) ** 2).sum(-1).argmin(1)
            for j in range(self.c):
                if (nearest == j).any():
                    centers[j] = X[nearest == j].mean(0)
        self.centers = centers
        return {"sizes": np.bincount(nearest, minlength=self.c)}

    def memberships(self, reading: np.ndarray) -> np.ndarray:
        d2 = ((self.centers - reading) ** 2).sum(1)
        w = np.exp(-(d2 - d2.min()) / (2 * self.width**2))
        return w / w.sum()

    def state(self) -> dict[str, Any]:
        return {"centers": self.centers, "width": self.width}

    def load_state(self, state: dict[str, Any]) -> None:
        self.centers, self.width = np.asarray(state["centers"], float), float(state["width"])


@hookimpl
def sitframe_interpreters() -> list[type]:
    return [SoftKMeans]
