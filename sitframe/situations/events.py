"""Situations that change during a trial: the events, and the core's side of them.

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
from typing import Any

import numpy as np

from sitframe.contract.checks import BoundaryError, fault
from sitframe.errors import PLUGIN_ERRORS, InputError, PluginFault
from sitframe.sim.kernels import kernels

_F64 = np.dtype(np.float64)


def _finite_nonnegative(a: np.ndarray) -> bool:
    """Whether every value of the 1-d float64 ``a`` is finite and >= 0."""
    kern = kernels()
    if kern is not None:  # (one compiled pass instead of two reductions)
        return bool(kern.finite_nonnegative(a))
    return bool(np.minimum.reduce(a) >= 0.0 and np.maximum.reduce(a) < np.inf)


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


class SituationTracker:
    """The core's side of an evolving interpreter during one learning trial.

    Parameters
    ----------
    interpreter
        The trial's interpreter (``evolving = True``).
    followers
        ``(origin, situations_changed)`` of each component that follows the events.
    error_sources
        ``(origin, situation_errors)`` of each learning behaviour that reports TD errors.
    origin, trial
        The interpreter's origin and the trial's index (to name a plugin on a fault).
    """

    def __init__(self, interpreter: Any, followers: list[tuple[Any, Any]],
                 error_sources: list[tuple[Any, Any]], origin: Any = "interpreter",
                 trial: int | None = None) -> None:
        self.interp = interpreter
        self.c = int(interpreter.n_situations)
        self.followers = followers
        self.observe = getattr(interpreter, "observe_errors", None) if error_sources else None
        self.error_sources = error_sources
        self.origin, self.trial = origin, trial
        self.log: list[tuple[int, SituationEvent]] = []

    @classmethod
    def start(cls, interpreter: Any, learning: bool, components: list[tuple[str, Any]],
              origins: dict[str, Any], trial: int) -> SituationTracker | None:
        """The tracker of a learning trial with an evolving interpreter (else ``None``).

        ``components`` are ``(config key, component)`` of the trial; behaviours
        and the arbiter with ``situations_changed`` follow the events, those
        with ``situation_errors`` feed the interpreter's ``observe_errors``.
        """
        if not (learning and getattr(interpreter, "evolving", False)):
            return None
        follow, errors = [], []
        for key, comp in components:
            if not (key.startswith("behaviours.") or key == "arbiter") or key.endswith(".reward"):
                continue
            if hasattr(comp, "situations_changed"):
                follow.append((origins[key], comp.situations_changed))
            if hasattr(comp, "situation_errors"):
                errors.append((origins[key], comp.situation_errors))
        return cls(interpreter, follow, errors, origins["interpreter"], trial)

    def step(self, iteration: int) -> None:
        """After iteration ``iteration``'s learning: pass TD errors on, deliver the events.

        One ``try`` for all the plugin calls (this runs every iteration): a raise,
        or a value outside the contract, is reported at the plugin and method it
        came from.
        """
        origin, method = self.origin, "observe_errors"
        try:
            if self.observe is not None:
                errs = None
                method = "situation_errors"
                for origin, src in self.error_sources:  # noqa: B007 - names the caller
                    e = checked_errors(src(), self.c)
                    if e is not None:
                        errs = e if errs is None else errs + e
                if errs is not None:
                    origin, method = self.origin, "observe_errors"
                    self.observe(errs)
            origin, method = self.origin, "events"
            events = self.interp.events()
            if events.__class__ is list and not events:  # (most iterations change nothing)
                return
            events = checked_events(events, self.c)
            method = "situations_changed"
            for ev in events:
                self.log.append((iteration, ev))
                for origin, follow in self.followers:  # noqa: B007 - names the caller
                    follow(ev)
        except (InputError, PluginFault, KeyboardInterrupt):
            raise
        except PLUGIN_ERRORS as exc:  # any fault in plugin code is reported
            raise fault(exc, origin, method, self.trial) from exc

    def finish(self, pose: np.ndarray, d: int) -> dict[str, Any]:
        """The trial's situations for the log: final state, events and count."""
        state = self.interp.state()
        alive = int(np.asarray(state.get("ids", state.get("centers", []))).shape[0])
        return {"state": state, "events": history_arrays(self.log, pose, d), "count": alive}


def checked_errors(errors: Any, c: int) -> np.ndarray | None:
    """A learner's ``situation_errors()``: ``None`` or a (c,) array of finite values >= 0
    (BoundaryError if not), as float64. A cheap test on the usual float64 array: it runs
    every iteration."""
    if errors is None:
        return None
    if errors.__class__ is np.ndarray and errors.shape == (c,) and errors.dtype is _F64 \
            and _finite_nonnegative(errors):
        return errors
    shape, dtype = getattr(errors, "shape", None), getattr(errors, "dtype", None)
    if isinstance(errors, np.ndarray) and shape == (c,) and (
            np.issubdtype(dtype, np.floating) or np.issubdtype(dtype, np.integer)):
        a = errors.astype(np.float64)
        bad = np.flatnonzero(~(np.isfinite(a) & (a >= 0.0)))
        if not bad.size:
            return a
        what = f"a TD error of {float(a[bad[0]])} for situation {int(bad[0])}"
    else:
        what = f"an array of shape {shape} and dtype {dtype}" if shape is not None \
            else type(errors).__name__
    raise BoundaryError(f"returned {what}, expected None or a ({c},) array of finite "
                        "absolute TD errors >= 0 (0 where the update touched nothing)")


def checked_events(events: Any, c: int) -> list[SituationEvent]:
    """An interpreter's ``events()``: ``None`` or an iterable of :class:`SituationEvent` whose
    ids (``id``, ``parents``, ``removed``) are in ``0 .. c - 1`` (BoundaryError if not)."""
    if events is None:
        return []
    if isinstance(events, SituationEvent) or not hasattr(events, "__iter__"):
        raise BoundaryError(f"returned {type(events).__name__}, expected a list of "
                            "sitframe.situations.events.SituationEvent")
    out = list(events)
    for ev in out:
        if not isinstance(ev, SituationEvent):
            raise BoundaryError(f"returned a {type(ev).__name__} {ev!r:.60} in its list, "
                                "expected sitframe.situations.events.SituationEvent")
        for i in (ev.id, *ev.parents, *ev.removed):
            if isinstance(i, bool) or not isinstance(i, int | np.integer) or not 0 <= i < c:
                raise BoundaryError(f"returned a '{ev.kind}' event naming situation {i!r}, "
                                    f"expected ids 0 .. {c - 1} (n_situations is the capacity)")
    return out


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
