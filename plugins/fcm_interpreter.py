"""Situation interpreter: fuzzy c-means prototypes of sonar readings (thesis 4.4, 4.5.1).

``fit`` runs many FCM trials from random starts on the collected readings,
keeps every trial's centres and validity measures (they are logged), and
picks one trial by :func:`sitframe.situations.clustering.select_trial`. ``memberships``
then fuzzifies each live reading with the *same* formula and the *same* m as
the clustering, :func:`sitframe.situations.fcm.memberships`.

Config (``[interpreter]``)::

    component = "fcm"
    c = 8          # number of situations, or "auto" (chosen from the validity measures)
    auto_cs = [4, 6, 8, 10, 12, 14, 16, 18, 20]   # candidates for c = "auto"
    auto_trials = 10                                # FCM restarts per candidate
    auto_rule = "cardinality"  # or "rf" (below)
    auto_knee = 2.0            # "cardinality": how near the plateau counts as on it
    m = 1.2        # fuzziness (membership exponent 2/(m-1) = 10)
    trials = 50    # FCM restarts
    sweep = []     # optional list of c values for the validity-vs-c sweep (Fig. 4.5)
    transform = "range"   # feature space: "range" (thesis), "log" or "inverse"
    offset = 0.1          # metres, for "log" / "inverse"

Feature space. The thesis clusters raw ranges with the Euclidean distance, so a
2.5 m difference in a far beam weighs as much as one between touching and
2.5 m clear: a reading with one beam at 5 cm and the others open lands in
"open space". ``transform = "log"`` clusters ``ln(r + offset)`` and
``"inverse"`` clusters the proximity ``1 / (r + offset)``, which spread short
ranges apart and compress long ones. Live readings are fuzzified in the same
space. The logged state keeps ``centers`` in metres (for plots and tables)
and adds ``feature_centers``, which the memberships use.

``c = "auto"``. The thesis chose c by looking at the validity measures against
c (Fig. 4.5) and at the learned behaviour. Most measures cannot choose c on
their own: the partition coefficient and the normalised index fall and the
partition entropy rises with c for any data, and the objective J_m always
falls. Sonar readings form a continuum, not separate groups, so no index of
compactness or crispness has a stable optimum on them either (sitframe's
first rule, the smallest relative fuzziness R_f, picked anything from 6 to
20 from one run seed to the next: docs/results/evolving-situations.md).

The rule (``auto_rule = "cardinality"``, the default) reads the **minimum
cardinality** (Eq. 4.8: the readings of the smallest situation) against c.
While c is small, every added prototype carves the readings into smaller
groups and the smallest situation shrinks with it. Once every distinct
configuration of the readings (a rare one too: a corner, a touching beam)
has a situation of its own, the smallest situation stops shrinking: more
prototypes only subdivide the common situations, thinning each rule's
share of the learning updates. The rule takes the smallest c at which the
minimum cardinality has come down to that plateau and stays there: the
first c in ``auto_cs`` from which on every minimum cardinality is at most
``auto_knee`` (2) times the plateau's, the median minimum cardinality over
the larger half of ``auto_cs``. ("Stays": one unlucky clustering that
isolates a few readings early must not end the search.) Candidates with an
empty cluster do not count. On the
obstacle-avoidance readings the plateau starts at c = 10-12, which is where
the fixed-c sweep's frozen rule bases collide least
(docs/results/evolving-situations.md). On data made
of a few well-separated groups the minimum cardinality has no plateau (it
keeps falling once the groups are split); for such data
``auto_rule = "rf"`` takes the crispest partition instead: the c whose
partition has the smallest R_f (Eq. 4.9) and no empty cluster (ties, e.g.
several perfectly crisp partitions: the largest minimum hard tendency
``min_ht``, then the smaller c).

Either way the sweep runs over ``auto_cs`` (``auto_trials`` restarts each,
one trial chosen per c as usual), then the chosen c is clustered with
``trials`` restarts as for a fixed c. The sweep is logged (``auto_cs``,
``auto_min_card``, ``auto_rf``, ``auto_rule``, ``auto_plateau``,
``auto_knee``, ``auto_c``) and ``sitframe analyse`` draws it
(``auto_c.png``). Until ``fit`` has run, ``n_situations`` is ``None``.
"""

from __future__ import annotations

import math
import warnings
from typing import Any

import numpy as np

from sitframe import MembershipFunction, TaskMap, cluster_trials, hookimpl, sweep_c
from sitframe import params as P

TRANSFORMS = ("range", "log", "inverse")
AUTO_RULES = ("cardinality", "rf")
#: Upper bounds of the counts (beyond them the clustering's arrays do not fit in memory).
MAX_TRIALS = 10_000
MAX_ITER = 1_000_000


class FCMInterpreter:
    """Fuzzy c-means situations over the sensor's reading vector."""

    name = "fcm"

    def __init__(
        self,
        *,
        c: int | str = 8,
        m: float = 1.2,
        trials: int = 50,
        tol: float = 1e-5,
        max_iter: int = 300,
        sweep: list[int] | None = None,
        transform: str = "range",
        offset: float = 0.1,
        auto_cs: list[int] = (4, 6, 8, 10, 12, 14, 16, 18, 20),  # type: ignore[assignment]
        auto_trials: int = 10,
        auto_rule: str = "cardinality",
        auto_knee: float = 2.0,
    ) -> None:
        # (upper bounds keep the trials' arrays in memory; c is bounded by the samples)
        self.auto = isinstance(c, str)
        if self.auto and c != "auto":
            raise ValueError(f"c = '{c}': expected an integer >= 2 or \"auto\"")
        self.c: int | None = None if self.auto else int(P.number("c", c, lo=2, integer=True))
        self.auto_cs = [int(P.number(f"auto_cs[{i}]", v, lo=2, integer=True))
                        for i, v in enumerate(auto_cs)]
        if not self.auto_cs or len(set(self.auto_cs)) != len(self.auto_cs):
            raise ValueError(f"auto_cs = {list(auto_cs)}: expected distinct integers >= 2")
        self.auto_trials = int(P.number("auto_trials", auto_trials, lo=1, hi=MAX_TRIALS,
                                        integer=True))
        self.auto_rule = P.choice("auto_rule", auto_rule, AUTO_RULES)
        self.auto_knee = float(P.number("auto_knee", auto_knee, lo=1.0))
        self.m = float(P.number("m", m, lo=1.0, lo_open=True))
        self.trials = int(P.number("trials", trials, lo=1, hi=MAX_TRIALS, integer=True))
        self.tol = float(P.number("tol", tol, lo=0.0, lo_open=True))
        self.max_iter = int(P.number("max_iter", max_iter, lo=1, hi=MAX_ITER, integer=True))
        self.sweep = [int(P.number(f"sweep[{i}]", v, lo=2, integer=True))
                      for i, v in enumerate(sweep or [])]
        self.transform = P.choice("transform", transform, TRANSFORMS)
        self.offset = float(P.number("offset", offset, lo=0.0, lo_open=True))
        self.centers: np.ndarray | None = None
        self.feature_centers: np.ndarray | None = None

    @property
    def n_situations(self) -> int | None:
        return self.c

    def features(self, X: np.ndarray) -> np.ndarray:
        """Map ranges (metres) to the feature space the clustering works in."""
        if self.transform == "log":
            return np.log(X + self.offset)
        if self.transform == "inverse":
            return 1.0 / (X + self.offset)
        return X

    def ranges(self, F: np.ndarray) -> np.ndarray:
        """Inverse of :meth:`features`: feature-space points back to metres."""
        if self.transform == "log":
            return np.exp(F) - self.offset
        if self.transform == "inverse":
            return 1.0 / F - self.offset
        return F

    def fit(self, X: np.ndarray, rng: np.random.Generator,
            pmap: TaskMap | None = None) -> dict[str, Any]:
        """Cluster ``X (n, d)`` [m]: ``trials`` FCM runs, one chosen by the validity measures.

        ``pmap`` (given by the run when it has a worker pool) spreads the FCM
        trials over the workers; the result is the same without it. When no
        trial fills every situation, the rule in the result says so (``[fallback``)
        and the run says it in one line naming the config key, instead of the
        clustering's Python warning (raised in a worker, it would reach the
        terminal as two raw lines).
        """
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", message=r".*no trial .*has min_card > 0",
                                    category=RuntimeWarning)
            return self._fit(X, rng, pmap)

    def _fit(self, X: np.ndarray, rng: np.random.Generator,
             pmap: TaskMap | None) -> dict[str, Any]:
        auto: dict[str, Any] = {}
        if self.auto:
            auto = self.choose_c(X, rng)
            self.c = auto["auto_c"]
        res = cluster_trials(self.features(X), self.c, n_trials=self.trials, m=self.m,
                             tol=self.tol, max_iter=self.max_iter, seed=rng, pmap=pmap)
        self.feature_centers = np.asarray(res.centers[res.chosen], dtype=float)
        self.centers = self.ranges(self.feature_centers)
        self._u = MembershipFunction(self.feature_centers, self.m)
        out: dict[str, Any] = {
            "transform": self.transform,
            "trial_centers": self.ranges(np.asarray(res.centers)),
            "trial_n_iter": np.asarray(res.n_iter),
            "trial_converged": np.asarray(res.converged),
            "chosen": int(res.chosen),
            "rule": res.rule,
            "measure_names": list(res.measures),
            "trial_measures": np.column_stack(
                [np.asarray(v, float) for v in res.measures.values()]),
            **auto,
        }
        if self.sweep:
            sw = sweep_c(self.features(X), self.sweep, n_trials=self.trials, m=self.m, seed=rng)
            out["sweep_c"] = np.asarray(self.sweep)
            out["sweep_measures"] = np.column_stack(
                [np.asarray(sw.measures[k], float) for k in out["measure_names"]])
        return out

    def choose_c(self, X: np.ndarray, rng: np.random.Generator) -> dict[str, Any]:
        """The ``c = "auto"`` rule (module docstring) over ``auto_cs``."""
        cs = sorted(c for c in self.auto_cs if c <= len(X))
        if not cs:
            raise ValueError(f"auto_cs {self.auto_cs}: every candidate exceeds the {len(X)} "
                             "collected samples")
        sw = sweep_c(self.features(X), cs, n_trials=self.auto_trials, m=self.m, tol=self.tol,
                     max_iter=self.max_iter, seed=rng)
        card = np.asarray(sw.measures["min_card"], float)
        ok = card > 0
        plateau = float(np.median(card[ok][ok.sum() // 2:])) if ok.any() else 0.0
        if self.auto_rule == "rf":
            rf = np.asarray(sw.measures["rf"], float)
            rf = np.where(ok, rf, np.inf) if ok.any() else rf
            tied = np.isclose(rf, rf.min())  # (e.g. several perfectly crisp partitions)
            best = int(np.argmax(np.where(tied, sw.measures["min_ht"], -np.inf)))
        elif ok.any():
            near = ok & (card <= self.auto_knee * plateau)
            stays = np.logical_and.accumulate((near | ~ok)[::-1])[::-1]  # (and every larger c)
            best = int(np.argmax(near & stays)) if (near & stays).any() else int(np.argmax(near))
        else:  # (every candidate has an empty cluster: the fewest situations)
            best = 0
        return {"auto_c": int(sw.cs[best]), "auto_cs": np.asarray(sw.cs),
                "auto_min_card": card, "auto_rf": np.asarray(sw.measures["rf"], float),
                "auto_rule": self.auto_rule, "auto_plateau": plateau,
                "auto_knee": self.auto_knee}

    def memberships(self, reading: np.ndarray) -> np.ndarray:
        if self.transform == "range":
            return self._u(reading)
        return self._u(self.features(reading))

    def _fused(self) -> dict[str, Any] | None:
        """What the compiled trial needs of these situations (``sitframe.runs.fused``), or
        ``None`` (not fitted, or a subclass's own ``memberships`` or ``features``)."""
        cls = type(self)
        if self.centers is None or cls.memberships is not FCMInterpreter.memberships or \
                cls.features is not FCMInterpreter.features or \
                type(self._u) is not MembershipFunction:
            return None
        return {"centers": self._u.centers, "p": self._u.p, "floor": self._u.floor,
                "transform": TRANSFORMS.index(self.transform), "offset": self.offset}

    def state(self) -> dict[str, Any]:
        if self.centers is None:
            raise ValueError("the fcm interpreter has not been fitted (no centres)")
        return {"centers": self.centers, "feature_centers": self.feature_centers, "m": self.m,
                "transform": self.transform, "offset": self.offset}

    def _check_space(self, state: dict[str, Any]) -> None:
        """A logged state's feature space (transform, offset) must be this config's."""
        transform = str(state.get("transform", "range"))
        if transform != self.transform or float(state.get("offset", self.offset)) != self.offset:
            raise ValueError(f"logged situations use transform '{transform}' (offset "
                             f"{state.get('offset', self.offset)}), this config "
                             f"'{self.transform}' (offset {self.offset})")

    def load_state(self, state: dict[str, Any]) -> None:
        self._check_space(state)
        centers = np.asarray(state["centers"], dtype=float)
        if self.auto and centers.ndim == 2 and centers.shape[0] >= 1:
            self.c = centers.shape[0]  # (c = "auto": the logged clustering's c)
        if centers.ndim != 2 or centers.shape[0] != self.c:
            raise ValueError(f"logged centres have shape {centers.shape}, expected ({self.c}, d) "
                             f"for c = {self.c}")
        feat = state.get("feature_centers")
        feat = np.asarray(feat, dtype=float) if feat is not None else self.features(centers)
        m = float(state.get("m", self.m))
        if feat.shape != centers.shape or not (np.isfinite(centers).all()
                                               and np.isfinite(feat).all()):
            raise ValueError(f"logged centres are not finite or their feature_centers have shape "
                             f"{feat.shape}, expected finite arrays of shape {centers.shape}")
        if not (math.isfinite(m) and m > 1.0):
            raise ValueError(f"logged fuzzifier m = {m}, expected a number > 1")
        self.m = m
        self.centers = centers
        self.feature_centers = feat
        self._u = MembershipFunction(self.feature_centers, self.m)


@hookimpl
def sitframe_interpreters() -> list[Any]:
    return [FCMInterpreter]
