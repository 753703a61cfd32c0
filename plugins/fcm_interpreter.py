"""Situation interpreter: fuzzy c-means prototypes of sonar readings (thesis 4.4, 4.5.1).

``fit`` runs many FCM trials from random starts on the collected readings,
keeps every trial's centres and validity measures (they are logged), and
picks one trial by :func:`sitframe.clustering.select_trial`. ``memberships``
then fuzzifies each live reading with the *same* formula and the *same* m as
the clustering, :func:`sitframe.fcm.memberships`.

Config (``[interpreter]``)::

    component = "fcm"
    c = 8          # number of situations
    m = 1.2        # fuzziness (membership exponent 2/(m-1) = 10)
    trials = 50    # FCM restarts
    sweep = []     # optional list of c values for the validity-vs-c sweep (Fig. 4.5)
"""

from __future__ import annotations

from typing import Any

import numpy as np

from sitframe import hookimpl
from sitframe import params as P
from sitframe.clustering import cluster_trials, sweep_c
from sitframe.fcm import MembershipFunction


class FCMInterpreter:
    """Fuzzy c-means situations over the sensor's reading vector."""

    name = "fcm"

    def __init__(
        self,
        *,
        c: int = 8,
        m: float = 1.2,
        trials: int = 50,
        tol: float = 1e-5,
        max_iter: int = 300,
        sweep: list[int] | None = None,
    ) -> None:
        self.c = int(P.number("c", c, lo=2, integer=True))
        self.m = float(P.number("m", m, lo=1.0, lo_open=True))
        self.trials = int(P.number("trials", trials, lo=1, integer=True))
        self.tol = float(P.number("tol", tol, lo=0.0, lo_open=True))
        self.max_iter = int(P.number("max_iter", max_iter, lo=1, integer=True))
        self.sweep = [int(P.number(f"sweep[{i}]", v, lo=2, integer=True))
                      for i, v in enumerate(sweep or [])]
        self.centers: np.ndarray | None = None

    @property
    def n_situations(self) -> int:
        return self.c

    def fit(self, X: np.ndarray, rng: np.random.Generator) -> dict[str, Any]:
        res = cluster_trials(X, self.c, n_trials=self.trials, m=self.m, tol=self.tol,
                             max_iter=self.max_iter, seed=rng)
        self.centers = np.asarray(res.centers[res.chosen], dtype=float)
        self._u = MembershipFunction(self.centers, self.m)
        out: dict[str, Any] = {
            "trial_centers": np.asarray(res.centers),
            "trial_n_iter": np.asarray(res.n_iter),
            "trial_converged": np.asarray(res.converged),
            "chosen": int(res.chosen),
            "rule": res.rule,
            "measure_names": list(res.measures),
            "trial_measures": np.column_stack(
                [np.asarray(v, float) for v in res.measures.values()]),
        }
        if self.sweep:
            sw = sweep_c(X, self.sweep, n_trials=self.trials, m=self.m, seed=rng)
            out["sweep_c"] = np.asarray(self.sweep)
            out["sweep_measures"] = np.column_stack(
                [np.asarray(sw.measures[k], float) for k in out["measure_names"]])
        return out

    def memberships(self, reading: np.ndarray) -> np.ndarray:
        return self._u(reading)

    def state(self) -> dict[str, Any]:
        if self.centers is None:
            raise ValueError("the fcm interpreter has not been fitted (no centres)")
        return {"centers": self.centers, "m": self.m}

    def load_state(self, state: dict[str, Any]) -> None:
        centers = np.asarray(state["centers"], dtype=float)
        if centers.ndim != 2 or centers.shape[0] != self.c:
            raise ValueError(f"logged centres have shape {centers.shape}, expected ({self.c}, d) "
                             f"for c = {self.c}")
        self.centers = centers
        self.m = float(state.get("m", self.m))
        self._u = MembershipFunction(centers, self.m)


@hookimpl
def sitframe_interpreters() -> list[Any]:
    return [FCMInterpreter]
