"""The core's side of situations that change during a trial (an evolving interpreter).

The contract (what an evolving interpreter and its followers do, and when) is in
:mod:`sitframe.situations.events`. :class:`SituationTracker` carries it out for one learning
trial of the control loop: after each learning iteration it passes the learners' TD errors to
the interpreter, drains the interpreter's events, checks them at the plugin boundary
(:func:`checked_errors`, :func:`checked_events`) and hands each to every follower, in config
order; at the trial's end it returns the trial's own final situations for the log.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from sitframe.contract.checks import BoundaryError, check_flag, fault
from sitframe.errors import PLUGIN_ERRORS, InputError, PluginFault
from sitframe.sim.kernels import kernels
from sitframe.situations.events import SituationEvent, history_arrays

_F64 = np.dtype(np.float64)


def _finite_nonnegative(a: np.ndarray) -> bool:
    """Whether every value of the 1-d float64 ``a`` is finite and >= 0."""
    kern = kernels()
    if kern is not None:  # (one compiled pass instead of two reductions)
        return bool(kern.finite_nonnegative(a))
    return bool(np.minimum.reduce(a) >= 0.0 and np.maximum.reduce(a) < np.inf)


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
    converged_sources
        ``(origin, learning_converged)`` of each learning behaviour (and arbiter) that
        says when its learning converged; once all do, the interpreter's optional
        ``rules_converged()`` is called, once.
    origin, trial
        The interpreter's origin and the trial's index (to name a plugin on a fault).
    """

    def __init__(self, interpreter: Any, followers: list[tuple[Any, Any]],
                 error_sources: list[tuple[Any, Any]], origin: Any = "interpreter",
                 trial: int | None = None,
                 converged_sources: list[tuple[Any, Any]] | None = None) -> None:
        self.interp = interpreter
        self.c = int(interpreter.n_situations)
        self.followers = followers
        self.observe = getattr(interpreter, "observe_errors", None) if error_sources else None
        self.error_sources = error_sources
        self.converged_sources = converged_sources or []
        self.tell = getattr(interpreter, "rules_converged", None) if self.converged_sources \
            else None
        self.origin, self.trial = origin, trial
        self.log: list[tuple[int, SituationEvent]] = []

    @classmethod
    def start(cls, interpreter: Any, learning: bool, components: list[tuple[str, Any]],
              origins: dict[str, Any], trial: int) -> SituationTracker | None:
        """The tracker of a learning trial with an evolving interpreter (else ``None``).

        ``components`` are ``(config key, component)`` of the trial; behaviours
        and the arbiter with ``situations_changed`` follow the events, those
        with ``situation_errors`` feed the interpreter's ``observe_errors``, and those
        with ``learning_converged`` decide when its ``rules_converged`` is called.
        """
        if not (learning and getattr(interpreter, "evolving", False)):
            return None
        follow, errors, converged = [], [], []
        for key, comp in components:
            if not (key.startswith("behaviours.") or key == "arbiter") or key.endswith(".reward"):
                continue
            if hasattr(comp, "situations_changed"):
                follow.append((origins[key], comp.situations_changed))
            if hasattr(comp, "situation_errors"):
                errors.append((origins[key], comp.situation_errors))
            if hasattr(comp, "learning_converged"):
                converged.append((origins[key], comp.learning_converged))
        return cls(interpreter, follow, errors, origins["interpreter"], trial, converged)

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
        except (InputError, PluginFault, KeyboardInterrupt):
            raise
        except PLUGIN_ERRORS as exc:  # any fault in plugin code is reported
            raise fault(exc, origin, method, self.trial) from exc
        self.deliver(iteration)

    def deliver(self, iteration: int) -> None:
        """The rest of :meth:`step` after the TD errors: tell the interpreter once every
        learner has converged, then hand its events to the followers (the compiled trial
        calls this alone: it passes the TD errors on itself)."""
        origin, method = self.origin, "learning_converged"
        try:
            if self.tell is not None:
                for origin, done in self.converged_sources:  # noqa: B007 - names the caller
                    if not check_flag(done()):
                        break
                else:
                    origin, method = self.origin, "rules_converged"
                    tell, self.tell = self.tell, None
                    tell()
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
                            "sitframe.SituationEvent")
    out = list(events)
    for ev in out:
        if not isinstance(ev, SituationEvent):
            raise BoundaryError(f"returned a {type(ev).__name__} {ev!r:.60} in its list, "
                                "expected sitframe.SituationEvent")
        for i in (ev.id, *ev.parents, *ev.removed):
            if isinstance(i, bool) or not isinstance(i, int | np.integer) or not 0 <= i < c:
                raise BoundaryError(f"returned a '{ev.kind}' event naming situation {i!r}, "
                                    f"expected ids 0 .. {c - 1} (n_situations is the capacity)")
    return out
