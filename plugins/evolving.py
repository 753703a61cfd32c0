"""Evolving situations: on-line clustering with a learned number of situations (thesis ch. 7).

The thesis fixes the situations before learning (off-line FCM, c chosen by
the designer) and names as future work "an on-line incremental clustering
system that would create models of new situations as they arise" and a
number of situations learned "with respect to the environment and goal".
This interpreter does both, during each learning trial, with the FCM
membership formula and m of the off-line clustering
(:class:`sitframe.situations.fcm.MembershipFunction`):

Start
    From nothing (the run has no collect/cluster stage: the first reading
    becomes situation 0), or from the off-line FCM prototypes (the cluster
    stage runs this class's ``fit``, which is the ``fcm`` interpreter's, with
    ``c`` situations; or ``experiment.clusters_from`` names an ``fcm`` log).

Create (coverage)
    FCM memberships always sum to 1, so they cannot say a reading is *far
    from every* situation. Coverage is judged from the distance ``d`` (in the
    feature space, e.g. log ranges) to the nearest alive prototype, i.e. by
    the firing strength ``exp(-d^2 / (2 sigma^2))`` of an RBF rule with
    ``sigma = create_distance / sqrt(2 ln 2)``: a reading is *poorly covered*
    when that strength is below 1/2 (``d > create_distance``). After
    ``create_after`` consecutive poorly covered readings a situation is
    created at their mean (consecutive: one odd echo does not make a
    situation; the mean: the robot moves, so the k readings span the new
    region). This is epsilon-completeness rule growth with epsilon = 1/2.

Adapt
    Every prototype follows its data by the incremental form of the FCM
    centre update (batch: ``v_i = sum u_i^m x / sum u_i^m``):
    ``N_i += u_i^m``, ``v_i += (u_i^m / N_i) (x - v_i)``. A seeded prototype
    starts with ``N_i = prior_weight`` readings of evidence (so the off-line
    clustering is not forgotten in the first few hundred iterations); a
    created one with the ``create_after`` readings it was made from.
    ``adapt = false`` keeps prototypes where they were made.

Split (task)
    The learner reports, per situation, the absolute TD error of its last
    update (``situation_errors`` of ``fuzzy-q``/``crisp-q``). A situation
    whose mean absolute TD error over at least ``split_min_updates`` updates
    is more than ``split_ratio`` times the median over the situations with
    that many updates is *hard for the task*: the blend of its rule does not
    fit every reading it covers (the collisions that start between
    prototypes, say). It gets a sibling at the TD-error-weighted mean of the
    readings it was updated on, if that point is at least
    ``split_min_distance`` from it (otherwise the errors are spread over the
    situation and a sibling would not separate them). Statistics decay by
    ``error_decay`` at every check, so old errors (before the rule base was
    learned) fade.

Merge, prune
    Two alive prototypes closer than ``merge_distance`` are near-duplicates
    (their memberships are then nearly equal on every reading, so their
    rules cannot differ usefully): the younger is merged into the older, at
    the evidence-weighted mean. ``prune_after > 0`` removes a situation that
    has not been the dominant one for that many iterations (never below 2
    alive); 0 (default) never prunes: a situation that rarely wins still
    shapes the blend near it.

Checks (merge, prune, split) run every ``check_every`` iterations, at most
one of each kind per check. Ids are ``0 .. capacity - 1``, given in order and
never reused; ``n_situations`` is ``capacity`` (the contract in
:mod:`sitframe.situations`). When every id is used, no more situations are
created or split (counted as ``refused`` in the trial's data).

In a frozen evaluation (``trial_start`` with kind ``"evaluate"``) nothing
changes: the situations are the trial's final ones, as logged.

Config (``[interpreter]``)::

    component = "evolving"
    c = 12                # off-line FCM situations to start from (cluster stage), or "auto"
    m = 1.2               # the fuzzifier (as fcm)
    transform = "log"     # feature space (as fcm) and its offset
    offset = 0.1
    capacity = 48         # ids available in a trial
    create_distance = 1.8 # feature-space distance of "poorly covered"
    create_after = 3      # consecutive poorly covered readings
    prior_weight = 100.0  # evidence of a seeded prototype (readings)
    adapt = true
    merge_distance = 0.4
    split_ratio = 4.0     # 0 = never split
    split_min_updates = 100
    split_min_distance = 0.4
    error_decay = 0.9
    prune_after = 0       # 0 = never prune
    check_every = 50
    grow_until = 0        # readings of a learning trial after which nothing is created
                          # or split (0 = no limit); merges, prunes and adaptation go on
    freeze_with_rules = false  # true: the situations stop changing (no adaptation, merge,
                          # prune, creation or split) once every learner has converged

``freeze_with_rules``: a learner that converged keeps its rule base for the rest of the
trial, but by default its situations go on adapting, merging and pruning until the trial
ends, so the frozen rules are finally judged over situations that moved away from those
they were learnt on (the longer the trial after convergence, the farther:
docs/results/generalisation.md). With ``true`` the core's ``rules_converged()`` call, made
once every learning behaviour reports ``learning_converged()``, freezes the situations
too, as a frozen evaluation does.
"""

from __future__ import annotations

import inspect
import math
from typing import Any

import numpy as np

from sitframe import (
    MembershipFunction,
    SituationEvent,
    accumulate_errors,
    hookimpl,
    online_update,
    row_sq_norms,
)
from sitframe import params as P

from .fcm_interpreter import TRANSFORMS, FCMInterpreter

_min = np.minimum.reduce  # (the ufunc's own reduce: ndarray.min adds a Python layer)

#: Most ids a trial may use (the loop logs (L, capacity) memberships).
MAX_CAPACITY = 256


class EvolvingInterpreter(FCMInterpreter):
    """FCM situations that are created, split, merged and pruned during a learning trial."""

    name = "evolving"
    evolving = True

    def __init__(self, *, capacity: int = 48, create_distance: float = 1.8,
                 create_after: int = 3, prior_weight: float = 100.0, adapt: bool = True,
                 merge_distance: float = 0.4, split_ratio: float = 4.0,
                 split_min_updates: int = 100, split_min_distance: float = 0.4,
                 error_decay: float = 0.9, prune_after: int = 0, check_every: int = 50,
                 grow_until: int = 0, freeze_with_rules: bool = False, **fcm: Any) -> None:
        super().__init__(**fcm)
        self.capacity = int(P.number("capacity", capacity, lo=2, hi=MAX_CAPACITY, integer=True))
        self.create_d2 = float(P.number("create_distance", create_distance, lo=0.0,
                                        lo_open=True)) ** 2
        self.create_after = int(P.number("create_after", create_after, lo=1, integer=True))
        self.prior_weight = float(P.number("prior_weight", prior_weight, lo=0.0, lo_open=True))
        self.adapt = P.boolean("adapt", adapt)
        self.merge_d2 = float(P.number("merge_distance", merge_distance, lo=0.0)) ** 2
        self.split_ratio = float(P.number("split_ratio", split_ratio, lo=0.0))
        self.split_min_updates = int(P.number("split_min_updates", split_min_updates, lo=1,
                                              integer=True))
        self.split_min_d2 = float(P.number("split_min_distance", split_min_distance,
                                           lo=0.0)) ** 2
        self.error_decay = float(P.number("error_decay", error_decay, lo=0.0, hi=1.0))
        self.prune_after = int(P.number("prune_after", prune_after, lo=0, integer=True))
        self.check_every = int(P.number("check_every", check_every, lo=1, integer=True))
        self.grow_until = int(P.number("grow_until", grow_until, lo=0, integer=True))
        self.freeze_with_rules = P.boolean("freeze_with_rules", freeze_with_rules)
        self.dim: int | None = None
        self._set_prototypes(np.zeros((0, 0)), np.zeros(0, dtype=np.int64), np.zeros(0), 0)
        self.frozen = False

    # -- the contract --------------------------------------------------------
    @property
    def n_situations(self) -> int:
        return self.capacity

    def bind(self, run: Any) -> None:
        """Learn the reading's dimension (a state with no prototypes still has its shape)."""
        self.dim = int(run.sensor.dim)
        if self.F.shape[1] == 0:
            self._set_prototypes(np.zeros((0, self.dim)), np.zeros(0, dtype=np.int64),
                                 np.zeros(0), 0)

    def fit(self, X: np.ndarray, rng: np.random.Generator, pmap: Any = None) -> dict[str, Any]:
        """The off-line FCM of ``fcm`` (``c`` prototypes, ids 0..c-1) to start from."""
        out = super().fit(X, rng, pmap=pmap)
        c = self.feature_centers.shape[0]
        if c > self.capacity:
            raise ValueError(f"c = {c} starting situations exceed capacity = {self.capacity}; "
                             "expected capacity >= c")
        self._set_prototypes(self.feature_centers, np.arange(c), np.full(c, self.prior_weight), c)
        return out

    def trial_start(self, trial: Any) -> None:
        self.frozen = trial.kind != "learn"

    def rules_converged(self) -> None:
        """Every learner of the trial has converged: with ``freeze_with_rules``, stop
        changing the situations for the rest of the trial."""
        if self.freeze_with_rules:
            self.frozen = True

    def memberships(self, reading: np.ndarray) -> np.ndarray:
        x = reading if self.transform == "range" else self.features(reading)
        if self.F.shape[1] != x.size and not self.ids.size:  # (not bound: learn d here)
            self._set_prototypes(np.zeros((0, x.size)), self.ids, np.zeros(0), self.next_id)
        self.t += 1
        diff = self.Fa - x  # (the alive prototypes, kept contiguous: this is the hot loop)
        d2 = row_sq_norms(diff)
        if not self.frozen and self._growing() and (
                self.streak or not d2.size or _min(d2) > self.create_d2) and self._cover(x, d2):
            diff = self.Fa - x
            d2 = row_sq_norms(diff)
        ids = self.ids
        u = self._u.from_d2(d2)
        out = np.zeros(self.capacity)
        out[ids] = u
        if not self.frozen:
            self.x_prev, self.x_last = self.x_last, x
            if self.prune_after:  # (only pruning asks when a situation last won)
                self.last_win[ids[int(u.argmax())]] = self.t
            if self.adapt:
                online_update(self.Fa, self.Na, diff, u ** self.m)
            if self.t % self.check_every == 0:
                self._checks()
        return out

    def observe_errors(self, errors: np.ndarray) -> None:
        """Accumulate the learners' (capacity,) absolute TD errors of the last update.

        The update acted on the reading *before* the last one (the transition's
        first reading), so that is where the errors are placed.
        """
        if self.frozen or self.x_prev is None:
            return
        accumulate_errors(errors, self.x_prev, self.err_sum, self.err_n, self.err_x)

    def _fused(self) -> dict[str, Any] | None:
        """What the compiled trial needs of these situations (``sitframe.runs.fused``): the
        ``fcm`` answer over the alive prototypes (none, when it starts from nothing), and
        this interpreter (the kernel changes its arrays in place and hands it the iterations
        that create, check or find no prototype); or ``None`` for a subclass."""
        if type(self) is not EvolvingInterpreter or type(self._u) is not MembershipFunction:
            return None
        return {"centers": self.Fa, "p": self._u.p, "floor": self._u.floor,
                "transform": TRANSFORMS.index(self.transform), "offset": self.offset,
                "evolving": self}

    def events(self) -> list[SituationEvent]:
        """The structural events since the last call (oldest first)."""
        ev, self.pending = self.pending, []
        return ev

    def trial_end(self, trial: Any) -> dict[str, Any] | None:
        if trial.kind != "learn":
            return None
        return {"refused": int(self.refused)}

    def state(self) -> dict[str, Any]:
        self._sync()
        ids = self.ids
        return {"ids": ids.astype(np.int64), "centers": self.ranges(self.F[ids]),
                "feature_centers": self.F[ids].copy(), "evidence": self.N[ids].copy(),
                "next_id": int(self.next_id), "capacity": int(self.capacity), "m": self.m,
                "transform": self.transform, "offset": self.offset}

    def load_state(self, state: dict[str, Any]) -> None:
        """Restore this interpreter's own state, or start from an ``fcm`` state (ids 0..c-1)."""
        own = "ids" in state
        if not own:
            self._load_fcm(state)
            feat = np.asarray(self.feature_centers)
            c = feat.shape[0]
            self._set_prototypes(feat, np.arange(c), np.full(c, self.prior_weight), c)
            return
        self._check_space(state)
        ids = np.asarray(state["ids"]).astype(np.int64).reshape(-1)
        feat = np.asarray(state["feature_centers"], dtype=float)
        evidence = np.asarray(state.get("evidence", np.full(ids.size, self.prior_weight)), float)
        next_id = int(state.get("next_id", ids.max() + 1 if ids.size else 0))
        if int(state.get("capacity", self.capacity)) != self.capacity:
            raise ValueError(f"logged situations have capacity {state.get('capacity')}, this "
                             f"config {self.capacity}; configure the same capacity")
        if (feat.ndim != 2 or feat.shape[0] != ids.size or evidence.shape != ids.shape
                or not np.isfinite(feat).all() or (ids < 0).any() or (ids >= next_id).any()
                or next_id > self.capacity or np.unique(ids).size != ids.size):
            raise ValueError(f"logged situations are inconsistent: ids {ids.tolist()}, "
                             f"feature_centers of shape {feat.shape}, next_id {next_id}; "
                             f"expected distinct ids below next_id <= capacity {self.capacity} "
                             "and one finite prototype per id")
        m = float(state.get("m", self.m))
        if not (math.isfinite(m) and m > 1.0):
            raise ValueError(f"logged fuzzifier m = {m}, expected a number > 1")
        self.m = m
        self._set_prototypes(feat, ids, evidence, next_id)

    # -- internals -----------------------------------------------------------
    def _load_fcm(self, state: dict[str, Any]) -> None:
        """Load an ``fcm`` state whatever its c (the start of an evolving run)."""
        c_cfg, self.c = self.c, np.asarray(state.get("centers", np.zeros((0, 0)))).shape[0]
        try:
            FCMInterpreter.load_state(self, state)
        finally:
            self.c = c_cfg

    def _set_prototypes(self, feat: np.ndarray, ids: np.ndarray, evidence: np.ndarray,
                        next_id: int) -> None:
        """(Re)build the per-trial arrays from prototypes ``feat`` (n, d) with ``ids``."""
        d = feat.shape[1] if feat.ndim == 2 and feat.shape[1] else (self.dim or 0)
        if ids.size and ids.max() >= self.capacity:
            raise ValueError(f"situation id {int(ids.max())} is beyond capacity "
                             f"{self.capacity}; configure a larger capacity")
        K = self.capacity
        self.F = np.zeros((K, d))
        self.F[ids] = feat
        self.N = np.zeros(K)
        self.N[ids] = evidence
        self.alive = np.zeros(K, dtype=bool)
        self.alive[ids] = True
        self.ids = np.flatnonzero(self.alive)
        self._compact()
        self.next_id = int(next_id)
        self.last_win = np.zeros(K, dtype=np.int64)
        self.err_sum = np.zeros(K)
        self.err_n = np.zeros(K)
        self.err_x = np.zeros((K, d))
        self.t = 0
        self.streak = 0
        self.streak_sum = np.zeros(d)
        self.x_prev: np.ndarray | None = None
        self.x_last: np.ndarray | None = None
        self.pending: list[SituationEvent] = []
        self.refused = 0
        self._u = MembershipFunction(np.zeros((1, max(d, 1))), self.m)
        self.feature_centers = self.F[self.ids]
        self.centers = self.ranges(self.feature_centers) if self.ids.size else None

    def _compact(self) -> None:
        """Copy the alive prototypes and evidence into contiguous arrays (after a change)."""
        self.Fa = self.F[self.ids]
        self.Na = self.N[self.ids]

    def _sync(self) -> None:
        """Write the contiguous prototypes and evidence back (before a change or ``state``)."""
        self.F[self.ids] = self.Fa
        self.N[self.ids] = self.Na

    def _cover(self, x: np.ndarray, d2: np.ndarray) -> bool:
        """Count poorly covered readings (``d2``: squared distances to the alive prototypes);
        create a situation after ``create_after`` in a row. Returns whether one was made."""
        if d2.size:
            if _min(d2) <= self.create_d2:
                if self.streak:
                    self.streak = 0
                    self.streak_sum[:] = 0.0
                return False
            self.streak += 1
            self.streak_sum += x
            if self.streak < self.create_after:
                return False
            at, weight = self.streak_sum / self.streak, float(self.streak)
        else:  # nothing yet: the first reading is the first situation
            at, weight = np.array(x, dtype=float), 1.0
        self.streak = 0
        self.streak_sum[:] = 0.0
        return self._new("create", at, weight) is not None

    def _new(self, kind: str, at: np.ndarray, weight: float) -> int | None:
        """Add a prototype at ``at`` (features) with ``weight`` evidence; queue its event."""
        if self.next_id >= self.capacity:
            self.refused += 1
            return None
        self._sync()
        parents, w = self._parents(at)
        i = self.next_id
        self.next_id += 1
        self.F[i] = at
        self.N[i] = weight
        self.alive[i] = True
        self.ids = np.flatnonzero(self.alive)
        self._compact()
        self.last_win[i] = self.t
        self.pending.append(SituationEvent(kind, i, parents, w, self.ranges(at)))
        return i

    def _parents(self, at: np.ndarray) -> tuple[tuple[int, ...], np.ndarray]:
        """The alive situations a new one at ``at`` inherits from: its FCM memberships among
        them (the few that carry weight above 1e-3, renormalised)."""
        ids = self.ids
        if ids.size == 0:
            return (), np.zeros(0)
        diff = self.F[ids] - at
        u = self._u.from_d2(row_sq_norms(diff))
        keep = u >= 1e-3
        return tuple(int(i) for i in ids[keep]), u[keep] / u[keep].sum()

    def _growing(self) -> bool:
        """Whether situations may still be created or split (``grow_until``)."""
        return self.grow_until == 0 or self.t <= self.grow_until

    def _checks(self) -> None:
        """Merge, prune and split: at most one of each per check."""
        self._sync()
        self._merge()
        self._prune()
        if self._growing():
            self._split()
        self._compact()
        self.err_sum *= self.error_decay
        self.err_n *= self.error_decay
        self.err_x *= self.error_decay

    def _merge(self) -> None:
        ids = self.ids
        if ids.size < 2 or self.merge_d2 <= 0:
            return
        F = self.F[ids]
        d2 = ((F[:, None, :] - F[None, :, :]) ** 2).sum(axis=2)
        d2[np.tri(ids.size, dtype=bool)] = np.inf  # (each pair once, not with itself)
        a, b = np.unravel_index(int(d2.argmin()), d2.shape)
        if d2[a, b] >= self.merge_d2:
            return
        keep, gone = int(ids[a]), int(ids[b])  # (ids ascending: keep is the older)
        w = self.N[[keep, gone]] / self.N[[keep, gone]].sum()
        self.F[keep] = w[0] * self.F[keep] + w[1] * self.F[gone]
        self.N[keep] += self.N[gone]
        for arr in (self.err_sum, self.err_n):
            arr[keep] += arr[gone]
        self.err_x[keep] += self.err_x[gone]
        self._remove(gone)
        self.pending.append(SituationEvent("merge", keep, (keep, gone), w,
                                           self.ranges(self.F[keep]), removed=(gone,)))

    def _prune(self) -> None:
        if self.prune_after == 0 or self.ids.size <= 2:
            return
        idle = self.t - self.last_win[self.ids]
        j = int(idle.argmax())
        if idle[j] > self.prune_after:
            i = int(self.ids[j])
            proto = self.ranges(self.F[i])
            self._remove(i)
            self.pending.append(SituationEvent("prune", i, (), np.zeros(0), proto, removed=(i,)))

    def _split(self) -> None:
        if self.split_ratio <= 0 or self.next_id >= self.capacity:
            return
        ids = self.ids
        ok = ids[self.err_n[ids] >= self.split_min_updates]
        if ok.size < 2:
            return
        mean = self.err_sum[ok] / self.err_n[ok]
        j = int(mean.argmax())
        if mean[j] <= self.split_ratio * _median(mean):
            return
        i = int(ok[j])
        at = self.err_x[i] / self.err_sum[i]
        if float(((at - self.F[i]) ** 2).sum()) < self.split_min_d2:
            return
        if self._new("split", at, float(self.err_n[i])) is not None:
            self.err_sum[i] = self.err_n[i] = 0.0
            self.err_x[i] = 0.0

    def _remove(self, i: int) -> None:
        self.alive[i] = False
        self.ids = np.flatnonzero(self.alive)
        self.N[i] = 0.0
        self._compact()
        self.err_sum[i] = self.err_n[i] = 0.0
        self.err_x[i] = 0.0


def _median(a: np.ndarray) -> float:
    """``float(np.median(a))`` of a 1-d array without NaN, bit for bit, without its Python layers
    (the mean of the two middle values is ``(a + b) / 2``, as ``np.mean`` computes it)."""
    s = np.sort(a)
    h = s.size // 2
    return float(s[h]) if s.size % 2 else float((s[h - 1] + s[h]) / 2.0)


def _signature() -> inspect.Signature:
    """The parameters of this class and of ``fcm`` in one signature (so a misspelt key
    in ``[interpreter]`` is refused with the closest name, as for any component)."""
    own = inspect.signature(EvolvingInterpreter.__init__)
    base = inspect.signature(FCMInterpreter.__init__)
    params = [p for p in own.parameters.values() if p.kind is not p.VAR_KEYWORD]
    return own.replace(parameters=params + [p for n, p in base.parameters.items()
                                            if n != "self"])


EvolvingInterpreter.__init__.__signature__ = _signature()  # type: ignore[attr-defined]


@hookimpl
def sitframe_interpreters() -> list[Any]:
    return [EvolvingInterpreter]
