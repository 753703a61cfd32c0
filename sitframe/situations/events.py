"""Situations that change during a trial: the events and the arrays that record them.

A *fixed* interpreter (``fcm``) has the same ``n_situations`` situations for
the whole run. An **evolving** interpreter (class attribute ``evolving =
True``, e.g. ``plugins/evolving.py``) creates, splits, merges and prunes
situations while a learning trial runs. The contract keeps every array of
the loop fixed-size:

* ``n_situations`` is the interpreter's **capacity**: the number of situation
  *ids* ``0 .. n_situations - 1``. Ids are given out in order and never
  reused; memberships are ``(n_situations,)`` as always, zero for every id
  that is not alive (not yet created, merged away or pruned), and sum to 1
  over the alive ones (the FCM formula over the alive prototypes).
* After each learning iteration the core drains ``interpreter.events()`` (a
  list of :class:`SituationEvent`, oldest first) and hands each event to
  every behaviour (and a learning arbiter) that has
  ``situations_changed(event)``, in config order, before the next
  ``propose``. A learning behaviour grows or combines its per-situation rows
  there (``plugins/fuzzy_q.py``: a new row from its parents' rows,
  membership-weighted and pulled towards the optimistic initial value;
  merged rows visit-weighted).
* If a learning behaviour has ``situation_errors()`` -- the (c,) absolute
  TD errors its last ``learn`` attributed to each situation (0 where it
  updated nothing) -- and the interpreter has ``observe_errors(errors)``, the
  core passes the sum over the behaviours on, each iteration, before draining
  the events: this is what lets an interpreter split situations where the
  *task* is hard, not only where the readings are new.
* A frozen evaluation (``trial_start`` with ``mode == "evaluate"``) must not
  change the situations.
* At the end of a learning trial the interpreter's ``state()`` is that
  trial's **own final situations**: the core logs it under
  ``/trials/NNNN/situations/state``, with the event history under
  ``/trials/NNNN/situations/events/`` (:func:`history_arrays`), adds the
  summary scalar ``situations`` (the number alive at the end), and evaluates
  the trial's frozen policies with those situations -- in the run, and in
  ``sitframe evaluate LOG --trial K``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from sitframe.sim.kernels import kernels

#: Event kinds, and their codes in the log (``events/kind``).
KINDS = ("create", "split", "merge", "prune")


@dataclass(frozen=True)
class SituationEvent:
    """One structural change of an evolving interpreter's situations.

    Attributes
    ----------
    kind
        ``"create"`` (a reading poorly covered by every situation),
        ``"split"`` (a situation whose TD errors stay large gets a sibling),
        ``"merge"`` (near-duplicates: ``removed`` are absorbed into ``id``) or
        ``"prune"`` (``id`` never wins and is removed).
    id
        The new situation (create, split), the survivor (merge) or the removed
        one (prune).
    parents
        Ids the new situation is initialised from (create, split: its nearest
        alive situations; merge: the survivor and the absorbed ids).
    weights
        (len(parents),) non-negative weights summing to 1: for create/split the
        FCM memberships of the new prototype among ``parents``; for merge the
        share of each merged situation's evidence (its accumulated membership).
    prototype
        (d,) the prototype of ``id`` after the event, metres (reading units).
    removed
        Ids that stop existing (merge: the absorbed ones; prune: ``(id,)``).
    """

    kind: str
    id: int
    parents: tuple[int, ...] = ()
    weights: np.ndarray = field(default_factory=lambda: np.zeros(0))
    prototype: np.ndarray = field(default_factory=lambda: np.zeros(0))
    removed: tuple[int, ...] = ()

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"situation event kind '{self.kind}', expected one of {KINDS}")
        w = np.asarray(self.weights, dtype=float)
        if w.shape != (len(self.parents),) or (w.size and (
                not np.isfinite(w).all() or (w < 0).any() or abs(w.sum() - 1.0) > 1e-6)):
            raise ValueError(f"situation event weights {w.tolist()} for parents "
                             f"{list(self.parents)}: expected one non-negative weight per "
                             "parent, summing to 1")


def accumulate_errors(errors: np.ndarray, x: np.ndarray, total: np.ndarray, count: np.ndarray,
                      weighted: np.ndarray) -> None:
    """Add one update's TD errors to per-situation statistics, in place.

    For the situations with ``errors > 0`` (the rows the update touched):
    ``total += errors``, ``count += 1`` and ``weighted += errors * x``, so that
    ``total / count`` is their mean absolute TD error and ``weighted / total``
    the error-weighted mean reading (where a split would go).

    Parameters
    ----------
    errors : ndarray, shape (c,)
        Absolute TD errors of the update (0 where it updated nothing).
    x : ndarray, shape (d,)
        The reading (features) the update acted on.
    total, count : ndarray, shape (c,)
        Float64 sums of errors and numbers of updates, updated in place.
    weighted : ndarray, shape (c, d)
        C-contiguous float64 sums of ``errors * x``, updated in place.
    """
    kern = kernels()
    if kern is not None:  # (same arithmetic, compiled)
        kern.accumulate_errors(errors, x, total, count, weighted)
        return
    hit = errors > 0
    e = np.where(hit, errors, 0.0)  # (whole rows: adding 0 leaves a row as it was)
    total += e
    count += hit
    weighted += e[:, None] * x


def history_arrays(log: list[tuple[int, SituationEvent]], pose: np.ndarray,
                   d: int) -> dict[str, np.ndarray]:
    """Events as arrays: ``iteration`` (n,), ``kind`` (n,) codes into :data:`KINDS`,
    ``id`` (n,), ``removed`` (n,) (the first removed id, -1 if none), ``prototype``
    (n, d) metres and ``pose`` (n, 3) where the robot was (x [m], y [m], theta [rad])."""
    n = len(log)
    it = np.asarray([t for t, _ in log], dtype=np.int64)
    rows = np.clip(it, 0, len(pose) - 1)
    proto = np.zeros((n, d))
    for i, (_t, ev) in enumerate(log):
        if ev.prototype.size == d:
            proto[i] = ev.prototype
    return {
        "iteration": it,
        "kind": np.asarray([KINDS.index(ev.kind) for _, ev in log], dtype=np.int8),
        "id": np.asarray([ev.id for _, ev in log], dtype=np.int64),
        "removed": np.asarray([ev.removed[0] if ev.removed else -1 for _, ev in log],
                              dtype=np.int64),
        "prototype": proto,
        "pose": np.asarray(pose, dtype=float)[rows].reshape(n, 3),
    }


def count_per_iteration(events: dict[str, np.ndarray], initial: int, iterations: int
                        ) -> np.ndarray:
    """(iterations,) number of alive situations after each iteration, from logged events."""
    delta = np.zeros(iterations + 1, dtype=np.int64)
    kinds = np.asarray(events.get("kind", []), dtype=int)
    its = np.asarray(events.get("iteration", []), dtype=int)
    step = np.where(kinds <= KINDS.index("split"), 1, -1)
    np.add.at(delta, np.clip(its, 0, iterations), step)
    return initial + np.cumsum(delta)[:iterations]
