"""The plugin contract enforced: protocol checks at creation, value checks at the boundary.

Every component a run creates is checked against its protocol
(:mod:`sitframe.contract.components`) as soon as it exists, and every value that
crosses from plugin code into the core is checked where it crosses: a reading
has the sensor's declared shape and is finite, memberships are ``c``
non-negative numbers summing to 1, a proposal is a :class:`Proposal` with a
finite heading, a reward is a finite real number. Any exception raised inside
plugin code during a run becomes one :class:`~sitframe.errors.PluginFault`
naming the plugin, the component, the method, the trial and the iteration.

The per-iteration checks are a type test, a shape test and one
``math.isfinite`` per value (the reading's and memberships' full range checks
run once per trial, vectorised, on the logged arrays), so they cost nothing
measurable in the loop (``benchmarks/learning/bench_trial.py``).
"""

from __future__ import annotations

import inspect
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from sitframe.contract.records import LearnedPolicy, Proposal
from sitframe.errors import PLUGIN_ERRORS, InputError, PluginError, PluginFault

#: Methods (and attributes) each component kind must have, checked at creation.
REQUIRED: dict[str, tuple[str, ...]] = {
    "sensor": ("read", "angles_deg", "max_range"),
    "interpreter": ("fit", "memberships", "state", "load_state", "n_situations"),
    "reward": ("__call__",),
    "behaviour": ("reset", "propose"),
    "arbiter": ("combine",),
    "protocol": ("episode_starts", "terminated", "iterations"),
}

#: The members of :data:`REQUIRED` that are attributes (the rest are methods).
ATTRIBUTES = ("angles_deg", "max_range", "n_situations", "table", "iterations")

#: Why a run needs a method beyond the protocol (the ``needs`` of :func:`check_protocol`).
NEEDED_BY: dict[str, str] = {
    "learn": "the config gives it a reward to learn from",
    "load_policy": "it has policy() or policy_from: the evaluate stage, sitframe evaluate "
                   "and policy_from freeze it with a learned policy",
    "events": "it is evolving (evolving = True): the core drains its events() after each "
              "learning iteration",
    "policy": "it learns from a reward and the run has an evaluate stage, which evaluates "
              "what policy() returns, frozen",
}

#: Optional lifecycle methods any component may define (called when present).
LIFECYCLE = ("bind", "trial_start", "trial_end")

#: The arguments sitframe passes each method it calls on a component of each kind (besides
#: :data:`LIFECYCLE`'s one, ``run`` or ``trial``), checked against the method's signature.
CALLS: dict[str, dict[str, tuple[str, ...]]] = {
    "sensor": {"read": ("world", "pose", "rng")},
    "interpreter": {"fit": ("X", "rng"), "memberships": ("reading",), "state": (),
                    "load_state": ("state",), "events": (), "observe_errors": ("errors",),
                    "rules_converged": ()},
    "reward": {"__call__": ("transition",)},
    "behaviour": {"reset": ("rng", "n_situations", "iterations"), "propose": ("context",),
                  "learn": ("transition", "reward"), "policy": (), "load_policy": ("policy",),
                  "trial_data": (), "situations_changed": ("event",), "situation_errors": (),
                  "learning_converged": ()},
    "arbiter": {"combine": ("context", "proposals"), "reset": ("rng", "n_situations",
                                                              "iterations"),
                "learn": ("transition", "reward"), "policy": (), "load_policy": ("policy",),
                "trial_data": (), "situations_changed": ("event",), "situation_errors": (),
                "learning_converged": ()},
    "protocol": {"episode_starts": ("world", "rng", "robot"),
                 "training_starts": ("world", "rng", "robot"), "terminated": ("context",),
                 "score_episode": ("arrays", "start", "goal", "robot"),
                 "aggregate": ("figures",), "check_world": ("world",)},
}

#: Real scalar types accepted for a heading, speed, activation or reward.
_REAL = (int, float, np.integer, np.floating)

#: Tolerance on ``sum(memberships) == 1``.
MEMBERSHIP_SUM_TOL = 1e-6


@dataclass(frozen=True)
class Origin:
    """Who a component is, for messages: plugin, kind, registry name, config key."""

    plugin: str
    kind: str
    name: str
    key: str
    plugin_name: str = ""

    def __str__(self) -> str:
        return f"plugin {self.plugin}: {self.kind} '{self.name}' [{self.key}]"


def check_protocol(obj: Any, origin: Origin, *, needs: tuple[str, ...] = ()) -> None:
    """Raise a :class:`PluginError` naming the first missing or non-callable member.

    ``needs`` adds members this run needs beyond the protocol (:data:`NEEDED_BY`:
    ``learn`` for a component with a reward, ``load_policy`` for one given a
    policy or with ``policy()``, ``policy`` for a learner whose run evaluates).
    """
    if callable(getattr(obj, "policy", None)):
        needs += ("load_policy",)
    if getattr(obj, "evolving", False):
        needs += ("events",)
    for member in REQUIRED[origin.kind] + needs:
        if member in ATTRIBUTES:
            try:
                getattr(obj, member)
            except AttributeError:
                raise PluginError(f"{origin}: has no attribute '{member}' (sitframe's "
                                  f"{origin.kind} protocol requires it)") from None
            except PLUGIN_ERRORS as exc:  # a property that raises is the plugin's
                raise PluginFault(f"{type(exc).__name__}: {exc}", where=str(origin),
                                  method=member) from None
            continue
        if not callable(getattr(obj, member, None)):
            why = NEEDED_BY.get(member) if member in needs else None
            raise PluginError(f"{origin}: has no method '{member}' (" + (
                f"needed: {why}" if why else
                f"sitframe.contract.components requires it of a {origin.kind}") + ")")
    for member in LIFECYCLE:
        if hasattr(obj, member) and not callable(getattr(obj, member)):
            raise PluginError(f"{origin}: '{member}' is not a method")
    _check_signatures(obj, origin)
    if origin.kind == "protocol":
        it, table = obj.iterations, getattr(obj, "table", None)
        if isinstance(it, bool) or not isinstance(it, int | np.integer) or it < 1:
            raise PluginError(f"{origin}: iterations is {it!r}, expected an integer >= 1 (the "
                              "episodes' iteration limit)")
        if table is not None and (not isinstance(table, str) or not table):
            raise PluginError(f"{origin}: table is {table!r}, expected the name of the config "
                              "table of its parameters (or no attribute 'table': a protocol "
                              "with no table, or one declared by config_table)")


#: (class, kind, its methods) whose signatures passed :func:`_check_signatures` (a run creates
#: its components once per episode: the signatures of a class are read once per process, and
#: again if one of its methods is replaced).
_SIGNATURES_OK: set[tuple[Any, ...]] = set()


def _check_signatures(obj: Any, origin: Origin) -> None:
    """A :class:`PluginError` for a method sitframe calls that cannot take its arguments."""
    calls = {**CALLS[origin.kind], "bind": ("run",), "trial_start": ("trial",),
             "trial_end": ("trial",)}
    key = (type(obj), origin.kind, *(getattr(type(obj), m, None) for m in calls))
    own = getattr(obj, "__dict__", None)
    if key in _SIGNATURES_OK and (own is None or not own.keys() & calls.keys()):
        return  # (methods set on the instance itself are checked every time)
    for method, args in calls.items():
        fn = getattr(obj, method, None)
        if not callable(fn):
            continue
        try:
            sig = inspect.signature(fn)
        except (TypeError, ValueError):  # (a builtin without one)
            continue
        try:
            sig.bind(*args)
        except TypeError:
            sig = sig.replace(parameters=[q.replace(annotation=q.empty)
                                          for q in sig.parameters.values()],
                              return_annotation=sig.empty)
            raise PluginError(f"{origin}: {method}{sig} cannot be called as {method}("
                              f"{', '.join(args)}), as sitframe calls it") from None
    _SIGNATURES_OK.add(key)


def call(origin: Origin, method: str, fn: Callable[..., Any], *args: Any,
         trial: int | None = None, **kwargs: Any) -> Any:
    """Call plugin code outside the loop; any exception becomes one :class:`PluginFault`.

    An :class:`InputError` raised by the plugin (bad configuration it found,
    e.g. in ``bind``) stays an input error, located at the component's key.
    """
    try:
        return fn(*args, **kwargs)
    except (InputError, PluginFault, KeyboardInterrupt):
        raise
    except PLUGIN_ERRORS as exc:  # any fault in plugin code is reported
        raise fault(exc, origin, method, trial) from exc


def fault(exc: BaseException, origin: Origin | str, method: str, trial: int | None = None,
          iteration: int | None = None) -> PluginFault:
    """The :class:`PluginFault` for ``exc`` raised by ``origin.method``."""
    if isinstance(exc, PluginFault):
        return exc
    msg = str(exc) if isinstance(exc, BoundaryError) else \
        f"{type(exc).__name__}: {exc}" if str(exc) else type(exc).__name__
    if isinstance(exc, ValueError) and "read-only" in str(exc):
        msg += (" (the pose, readings and memberships sitframe hands over are read-only: "
                "copy one to change it; return a new array from each read or memberships)")
    return PluginFault(msg, where=str(origin), method=method, trial=trial, iteration=iteration)


def blame(exc: BaseException, impls: list[Any]) -> str | None:
    """The plugin name of the hook implementation (of ``impls``) that raised ``exc``.

    pluggy calls every implementation in one call, so the raiser is found on
    the traceback: the innermost frame running one of the implementations'
    functions. ``None`` if none is on it.
    """
    codes = {}
    for impl in impls:
        code = getattr(getattr(impl.function, "__func__", impl.function), "__code__", None)
        if code is not None:
            codes[code] = impl.plugin_name
    name = None
    tb = exc.__traceback__
    while tb is not None:
        name = codes.get(tb.tb_frame.f_code, name)
        tb = tb.tb_next
    return name


class BoundaryError(Exception):
    """A value returned by plugin code broke the contract (turned into a PluginFault)."""


def sensor_geometry(sensor: Any) -> tuple[str, np.ndarray, float]:
    """A sensor's ``angles_deg`` as a (d,) float array and its ``max_range``.

    Raises
    ------
    BoundaryError
        With ``args == (member, why)``: ``angles_deg`` is not a non-empty 1-D
        array of finite real numbers, or ``max_range`` is not a finite number > 0.
    """
    angles, max_range = sensor.angles_deg, sensor.max_range
    a = np.asarray(angles)
    why = (f"has shape {a.shape}" if a.ndim != 1 or a.size == 0 else
           f"has dtype {a.dtype}" if a.dtype.kind not in "iuf" else
           f"holds {a[~np.isfinite(a)][0]}" if not np.isfinite(a).all() else "")
    if why:
        raise BoundaryError("angles_deg", f"angles_deg {why}, expected a non-empty 1-D array "
                            "of finite bearings [deg], one per beam")
    if isinstance(max_range, bool) or not isinstance(max_range, _REAL) \
            or not math.isfinite(max_range) or max_range <= 0:
        raise BoundaryError("max_range", f"max_range is {max_range!r:.60}, expected a finite "
                            "number > 0 [m]")
    return str(sensor.name), a.astype(np.float64), float(max_range)


def sensor_spec_mismatch(reading: Any, d: int, max_range: float = math.inf) -> str | None:
    """Why ``reading`` is not a (d,) float array of ranges in [0, max_range], or ``None``."""
    if not isinstance(reading, np.ndarray):
        return f"returned {type(reading).__name__}, expected a numpy array of shape ({d},)"
    if reading.shape != (d,):
        return f"returned shape {reading.shape}, expected ({d},) (the sensor's angles_deg)"
    if not np.issubdtype(reading.dtype, np.floating) and not np.issubdtype(reading.dtype,
                                                                           np.integer):
        return f"returned dtype {reading.dtype}, expected floats"
    bad = ~np.isfinite(reading)
    if bad.any():
        return f"returned a non-finite value ({reading[bad][0]}) in beam {int(np.argmax(bad))}"
    bad = (reading < 0) | (reading > max_range)
    if bad.any():
        return (f"returned {reading[bad][0]:g} in beam {int(np.argmax(bad))}, expected a range "
                f"in [0, max_range = {max_range:g}]")
    return None


def memberships_mismatch(u: Any, c: int) -> str | None:
    """Why ``u`` is not ``c`` non-negative memberships summing to 1, or ``None``."""
    if not isinstance(u, np.ndarray):
        return f"returned {type(u).__name__}, expected a numpy array of shape ({c},)"
    if u.shape != (c,):
        return f"returned shape {u.shape}, expected ({c},) (one per situation)"
    if not np.all(np.isfinite(u)):
        return "returned a non-finite membership"
    if u.min() < 0:
        return f"returned a negative membership ({u.min():g})"
    if abs(float(u.sum()) - 1.0) > MEMBERSHIP_SUM_TOL:
        return f"returned memberships summing to {float(u.sum()):.6g}, expected 1"
    return None


def check_reading(reading: Any, d: int) -> None:
    """Cheap per-iteration test: a (d,) array (values checked per trial, vectorised).

    The reading is then made read-only: every later component gets it, and it is
    logged, so one that changed it in place would change it for all of them.
    """
    if reading.__class__ is not np.ndarray or reading.shape != (d,):
        raise BoundaryError(sensor_spec_mismatch(reading, d))
    reading.setflags(write=False)


def check_memberships(u: Any, c: int) -> None:
    """Cheap per-iteration test: a (c,) array (values checked per trial, vectorised);
    then made read-only, like the reading."""
    if u.__class__ is not np.ndarray or u.shape != (c,):
        raise BoundaryError(memberships_mismatch(u, c))
    u.setflags(write=False)


def check_proposal(p: Any) -> Proposal:
    """A :class:`Proposal` with a finite heading and a finite or ``None`` speed/activation."""
    if p.__class__ is not Proposal:
        raise BoundaryError(f"returned {type(p).__name__} {p!r:.60}, expected a "
                            "sitframe.Proposal(heading_deg, speed_m_s=None, activation=None)")
    h, s, a = p.heading_deg, p.speed_m_s, p.activation
    if h.__class__ is float and h - h == 0.0 and a is None and (s is None or (
            s.__class__ is float and s - s == 0.0 and s >= 0.0)):
        return p  # (the common case, every iteration: finite floats, no activation)
    if not isinstance(h, _REAL) or isinstance(h, bool) or not math.isfinite(h):
        raise BoundaryError(f"returned a Proposal with heading_deg {h!r}, expected a finite "
                            "number of degrees")
    if s is not None and (not isinstance(s, _REAL) or isinstance(s, bool)
                          or not math.isfinite(s) or s < 0):
        raise BoundaryError(f"returned a Proposal with speed_m_s {s!r}, expected None or a "
                            "finite number >= 0 [m/s]")
    if a is not None and (not isinstance(a, _REAL) or isinstance(a, bool)
                          or not 0.0 <= a <= 1.0):
        raise BoundaryError(f"returned a Proposal with activation {a!r}, expected None or a "
                            "number in [0, 1]")
    return p


def check_reward(r: Any) -> float:
    """A finite real number (not a string, not a bool, not NaN)."""
    if r.__class__ is float or isinstance(r, _REAL) and not isinstance(r, bool | np.bool_):
        v = float(r)
        if math.isfinite(v):
            return v
        raise BoundaryError(f"returned {v}, expected a finite reward")
    raise BoundaryError(f"returned {type(r).__name__} {r!r:.60}, expected a finite real number")


def check_combined(out: Any, k: int, proposals: dict[str, Proposal]) -> tuple[Proposal,
                                                                              np.ndarray]:
    """An arbiter's ``(Proposal, (k,) weights)`` (the weights' values are checked per trial),
    having left the ``k`` ``proposals`` it was given in place (they are logged)."""
    if len(proposals) != k:
        raise BoundaryError(f"changed the proposals it was given: {len(proposals)} left of {k} "
                            "(they are logged; copy the dict to change it)")
    if out.__class__ is not tuple or len(out) != 2:
        raise BoundaryError(f"returned {type(out).__name__}, expected a tuple (Proposal, "
                            f"weights of shape ({k},))")
    prop, w = out
    check_proposal(prop)
    if w.__class__ is not np.ndarray:
        try:
            w = np.asarray(w, dtype=np.float64)
        except (TypeError, ValueError):
            raise BoundaryError(f"returned weights {w!r:.60}, expected ({k},) numbers") from None
    if w.shape != (k,):
        raise BoundaryError(f"returned weights of shape {w.shape}, expected ({k},), one per "
                            "behaviour")
    return prop, w


def check_policy(p: Any, c: int) -> LearnedPolicy | None:
    """A behaviour's ``policy()``: ``None`` or a :class:`LearnedPolicy` with ``c`` rules."""
    if p is None:
        return None
    if not isinstance(p, LearnedPolicy):
        raise BoundaryError(f"returned {type(p).__name__}, expected a sitframe.LearnedPolicy "
                            "or None")
    for out, o in p.outputs.items():
        if o.rules.shape != (c,):
            raise BoundaryError(f"returned a policy whose '{out}' rules have shape "
                                f"{o.rules.shape}, expected ({c},) (one rule per situation)")
        for what, a, hint in (("actions", o.actions, ""),
                              ("q", o.q, " (did rewards far too large overflow it?)")):
            if a is not None and not np.isfinite(a).all():
                raise BoundaryError(f"returned a policy whose '{out}' {what} hold "
                                    f"{np.asarray(a)[~np.isfinite(a)][0]}, expected finite "
                                    f"values{hint}")
    return p


def check_episode_starts(out: Any, n_max: float, world: Any,
                         radius: float) -> tuple[np.ndarray, np.ndarray | None]:
    """A protocol's ``episode_starts``: ``(starts, goals)``, ``n`` (1 to ``n_max``) finite
    start poses (n, 3) where the robot (``radius``) fits in ``world``, and ``None`` or
    ``n`` goals (x, y, radius > 0) in free space."""
    if not isinstance(out, tuple | list) or len(out) != 2:
        raise BoundaryError(f"returned {type(out).__name__}, expected a tuple (starts, goals)")
    try:
        s = np.asarray(out[0], dtype=float)
        g = None if out[1] is None else np.asarray(out[1], dtype=float)
    except (TypeError, ValueError):
        raise BoundaryError("returned starts or goals that are not arrays of numbers") from None
    n = len(s) if s.ndim else 0
    if s.shape != (n, 3) or not 1 <= n <= n_max or (g is not None and g.shape != (n, 3)):
        raise BoundaryError(f"returned starts of shape {s.shape} and goals of shape "
                            f"{None if g is None else g.shape}; expected (n, 3) each (goals may "
                            "be None), n >= 1 (n = 1: episodic is False)")
    for what, a, r in (("start", s, radius), ("goal", g, 0.0)):
        if a is None:
            continue
        ok = np.isfinite(a).all(axis=1)
        ok[ok] = world.is_free(a[ok, :2], r) & ((a[ok, 2] > 0) if what == "goal" else True)
        if not ok.all():
            e = int(np.argmin(ok))
            raise BoundaryError(f"returned {what} {e} = {a[e].tolist()}, expected finite x, y in "
                                f"free space of world '{world.name}'" + (
                                    f" for the robot (radius {r:g} m), heading [rad]"
                                    if what == "start" else ", radius > 0 [m]"))
    return s, g


def check_n_situations(c: Any, unknown_ok: bool = False) -> int | None:
    """An interpreter's ``n_situations``: a positive integer (``None`` too if ``unknown_ok``:
    before ``fit``, e.g. ``c = "auto"``)."""
    if c is None and unknown_ok:
        return None
    if isinstance(c, bool) or not isinstance(c, int | np.integer) or c < 1:
        raise BoundaryError(f"n_situations is {c!r}, expected a positive integer" + (
            "" if unknown_ok else " once the situations are fitted or loaded"))
    return int(c)


def check_flag(v: Any) -> bool:
    """A ``bool`` (or numpy bool) returned by plugin code, e.g. a protocol's ``terminated``."""
    if v.__class__ is bool or isinstance(v, np.bool_):
        return bool(v)
    raise BoundaryError(f"returned {type(v).__name__} {v!r:.60}, expected True or False")


def check_data(d: Any, what: str) -> dict[str, Any]:
    """Per-trial data for the log: a dict of str -> array or scalar."""
    if d is None:
        return {}
    if not isinstance(d, dict) or not all(isinstance(k, str) and k for k in d):
        raise BoundaryError(f"returned {type(d).__name__}, expected a dict of non-empty "
                            f"string keys to arrays or scalars ({what})")
    for k, v in d.items():
        why = ("'/' splits it into an empty group name" if "" in k.split("/")
               else _unloggable(v))
        if why:
            raise BoundaryError(f"returned key '{k}': {why}; expected numbers, bools or strings "
                                f"(scalars or arrays), lists of strings or dicts of these ({what})")
    return d


def check_trial_data(d: Any, iterations: int) -> dict[str, Any]:
    """A behaviour's ``trial_data()``: :func:`check_data`, and the scalars the summary reads,
    ``converged`` a bool and ``convergence_iteration`` an integer in [-1, iterations] (the
    number of iterations it took, -1 if it did not converge)."""
    d = check_data(d, "trial data")
    c = d.get("converged", False)
    if c.__class__ is not bool and not isinstance(c, np.bool_):
        raise BoundaryError(f"returned converged = {c!r:.40}, expected True or False")
    it = d.get("convergence_iteration", -1)
    if isinstance(it, bool) or not isinstance(it, int | np.integer) or not -1 <= it <= iterations:
        raise BoundaryError(f"returned convergence_iteration = {it!r:.40}, expected an integer "
                            f"in [-1, {iterations}] (-1: not converged)")
    return d


#: Scalar types the log stores as attributes.
_SCALAR = (bool, int, float, str, np.integer, np.floating, np.bool_)


def _unloggable(v: Any) -> str | None:
    """Why the log cannot store ``v`` (as :func:`sitframe.logs.writer._write_value` would), or
    None."""
    if v is None or isinstance(v, _SCALAR):
        return None
    if isinstance(v, list | tuple) and v and all(isinstance(s, str) for s in v):
        return None
    if isinstance(v, dict):
        for k, sub in v.items():
            why = "an empty key" if not str(k) else _unloggable(sub)
            if why:
                return f"in '{k}': {why}"
        return None
    try:
        a = np.asarray(v)
    except (TypeError, ValueError):
        return f"{type(v).__name__} that is no rectangular array"
    if a.dtype.kind not in "biufc":
        return f"{type(v).__name__} of dtype {a.dtype}"
    return None
