"""Property-based fuzzing of the input loaders and the FCM API (issue 8, item 5).

Every generated input must either load or raise the *documented* error:

* ``sitframe.sim.world.parse_world`` and ``sitframe.contract.config.parse_config``:
  :class:`~sitframe.errors.InputError` (a ``ValueError``), one line, naming
  the file;
* ``sitframe.situations.fcm.fcm`` / ``memberships`` / ``validity``: ``ValueError`` or
  ``TypeError``; and what loads is a valid fuzzy partition (finite, rows sum
  to 1).

Nothing else may escape: no ``KeyError``, ``IndexError``, ``AttributeError``,
``ZeroDivisionError``, ``OverflowError``, numpy warnings (run as errors) ...

Each target is a ``classify_*`` function that returns ``"loaded"`` or
``"documented"`` and lets anything else propagate, and a hypothesis strategy
of inputs. The tests run them with a moderate number of examples;
``benchmarks/scale/fuzz_loaders.py`` imports this module and runs the same
strategies with 10,000 examples each, tallying the outcomes.
"""

from __future__ import annotations

import json
import math
import warnings
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from sitframe.contract.config import parse_config
from sitframe.errors import InputError
from sitframe.sim.world import parse_world
from sitframe.situations.fcm import FCMResult, fcm, memberships, validity

FILE = "fuzz.toml"

# ----------------------------------------------------------------------------- TOML rendering


def _toml_str(s: str) -> str:
    # JSON string escapes are TOML basic-string escapes, except that TOML also
    # forbids a raw DEL.
    return json.dumps(s, ensure_ascii=False).replace("\x7f", "\\u007f")


def _toml_key(k: str) -> str:
    if k and all(ch.isascii() and (ch.isalnum() or ch in "_-") for ch in k):
        return k
    return _toml_str(k)


def toml_value(v: Any) -> str:
    """Render a value as an inline TOML value (nan and inf included)."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return _toml_str(v)
    if isinstance(v, list | tuple):
        return "[" + ", ".join(toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{_toml_key(k)} = {toml_value(x)}" for k, x in v.items()) + "}"
    raise TypeError(type(v).__name__)


def to_toml(doc: dict[str, Any]) -> str:
    """Render a dict as a TOML document (tables as [headers], arrays of tables as [[...]])."""
    lines = []
    tables = {}
    for k, v in doc.items():
        if isinstance(v, dict) or (isinstance(v, list) and v and all(isinstance(x, dict)
                                                                    for x in v)):
            tables[k] = v
        else:
            lines.append(f"{_toml_key(k)} = {toml_value(v)}")
    for k, v in tables.items():
        if isinstance(v, dict):
            lines.append(f"\n[{_toml_key(k)}]")
            for kk, vv in v.items():
                lines.append(f"{_toml_key(kk)} = {toml_value(vv)}")
        else:
            for item in v:
                lines.append(f"\n[[{_toml_key(k)}]]")
                for kk, vv in item.items():
                    lines.append(f"{_toml_key(kk)} = {toml_value(vv)}")
    return "\n".join(lines) + "\n"


# ----------------------------------------------------------------------------- value strategies

#: Scalars a TOML file can hold, weighted towards the troublesome ones.
SCALARS = st.one_of(
    st.integers(-3, 12),
    st.integers(),
    st.floats(-20, 20),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([0, -0.0, 1e308, -1e308, 5e-324, 2**63, -(2**63) - 1, 10**30]),
    st.booleans(),
    st.text(max_size=4),
)
VALUES = st.recursive(SCALARS, lambda inner: st.one_of(
    st.lists(inner, max_size=4), st.dictionaries(st.text(max_size=4), inner, max_size=3)),
    max_leaves=8)

#: Plausible coordinates: mostly room-sized numbers, sometimes anything.
COORD = st.one_of(st.integers(-1, 14), st.floats(-1, 14), SCALARS)
POINT = st.one_of(st.lists(COORD, min_size=2, max_size=2), st.lists(COORD, max_size=4), SCALARS)
POINTS = st.one_of(st.lists(POINT, max_size=8), VALUES)
ROOM = [[0, 0], [13, 0], [13, 8], [0, 8], [0, 0]]
BOX = [[3, 3], [4, 3], [4, 4], [3, 4]]


@st.composite
def world_docs(draw: st.DrawFn) -> dict[str, Any]:
    """A valid world (room, random box obstacles, start, goal), then 0-3 edits: random
    geometry (self-intersecting or degenerate polygons, start or goal anywhere), bad
    values (NaN/inf, wrong types), misspelled or missing keys."""
    boxes = []
    for _ in range(draw(st.integers(0, 3))):
        x, y = draw(st.floats(0.5, 11.5)), draw(st.floats(0.5, 6.5))
        w, h = draw(st.floats(0.01, 2.0)), draw(st.floats(0.01, 2.0))
        boxes.append({"points": [[x, y], [x + w, y], [x + w, y + h], [x, y + h]]})
    doc: dict[str, Any] = {
        "name": "room", "description": "fuzz",
        "robot": {"start": [draw(st.floats(-1, 14)), draw(st.floats(-1, 9)),
                            draw(st.floats(-720, 720))]},
        "walls": [{"points": ROOM}],
    }
    if boxes:
        doc["obstacles"] = boxes
    if draw(st.booleans()):
        doc["trajectories"] = [{"points": draw(st.lists(
            st.lists(st.floats(0, 13), min_size=2, max_size=2), min_size=2, max_size=5))}]
    if draw(st.booleans()):
        doc["goal"] = {"position": [draw(st.floats(-1, 14)), draw(st.floats(-1, 9))],
                       "radius": draw(st.floats(0.01, 1.0))}
    edits = {
        "name": SCALARS, "description": SCALARS, "robot": VALUES,
        "robot.start": st.one_of(st.lists(COORD, max_size=4), VALUES),
        "robot.radius": st.one_of(st.floats(0, 5), SCALARS),
        "robot.strat": VALUES,
        "walls": st.one_of(st.lists(st.fixed_dictionaries(
            {"points": POINTS}, optional={"name": SCALARS, "pionts": VALUES}), max_size=3),
            VALUES),
        "walls.extra": st.lists(st.lists(st.floats(-1, 14), min_size=2, max_size=2),
                                min_size=0, max_size=6),
        "obstacles": st.one_of(st.lists(st.fixed_dictionaries({"points": POINTS}),
                                        max_size=3), VALUES),
        "obstacles.random": st.lists(st.lists(st.floats(-1, 14), min_size=2, max_size=2),
                                     min_size=0, max_size=6),
        "trajectories": st.one_of(st.lists(st.fixed_dictionaries({"points": POINTS}),
                                           max_size=2), VALUES),
        "goal": VALUES,
        "goal.position": st.one_of(st.lists(COORD, max_size=3), VALUES),
        "goal.radius": SCALARS,
        "meta": VALUES,
        "nmae": VALUES,
    }
    for key in draw(st.lists(st.sampled_from(sorted(edits)), max_size=3, unique=True)):
        value = draw(edits[key])
        head, _, tail = key.partition(".")
        if tail in ("extra", "random"):
            old = doc.get(head, [])
            doc[head] = [*(old if isinstance(old, list) else []), {"points": value}]
        elif tail:
            if not isinstance(doc.get(head), dict):
                doc[head] = {}
            doc[head][tail] = value
        else:
            doc[head] = value
    for k in draw(st.lists(st.sampled_from(sorted(doc)), max_size=1)):
        if draw(st.integers(0, 3)) == 0:
            doc.pop(k, None)
    return doc


BASE_CONFIG = {
    "experiment": {"name": "x", "trials": 1, "iterations": 100, "seed": 3},
    "collect": {"worlds": ["collect-1", "collect-2"]},
    "interpreter": {"component": "fcm", "c": 6, "trials": 4},
    "behaviours": {"avoid": {"component": "fuzzy-q", "reward": "obstacle-avoidance", "p": 5}},
    "evaluate": {"worlds": ["novel-1"], "iterations": 100},
}
CONFIG_KEYS = {
    "experiment": ["name", "description", "seed", "trials", "iterations", "stages", "world",
                   "default_speed", "clusters_from", "trails"],
    "robot": ["radius", "max_speed", "min_speed", "substep_s", "control_period_s",
              "max_turn_rate_deg_s", "recovery", "radus"],
    "sensor": ["component", "max_range", "beam_width_deg"],
    "collect": ["mode", "worlds", "speed", "rate_hz", "wander_samples", "wrlds"],
    "interpreter": ["component", "c", "m", "trials"],
    "arbiter": ["component"],
    "evaluate": ["worlds", "iterations"],
    "goal": ["episodes", "timeout", "min_distance", "worlds", "pairs", "radius", "margin"],
    "plugins": ["dirs"],
    "experimnt": ["name"],
}


@st.composite
def config_docs(draw: st.DrawFn) -> dict[str, Any]:
    """The small test config with a few keys replaced by arbitrary values or removed."""
    doc = json.loads(json.dumps(BASE_CONFIG))
    for _ in range(draw(st.integers(1, 4))):
        section = draw(st.sampled_from(sorted(CONFIG_KEYS)))
        key = draw(st.sampled_from(CONFIG_KEYS[section]))
        table = doc.setdefault(section, {})
        if not isinstance(table, dict):
            continue
        table[key] = draw(VALUES)
    if draw(st.integers(0, 9)) == 0:  # a whole section of the wrong shape
        doc[draw(st.sampled_from(sorted(CONFIG_KEYS)))] = draw(SCALARS)
    if draw(st.integers(0, 4)) == 0:
        doc["behaviours"] = draw(st.one_of(
            st.dictionaries(st.text(max_size=3), VALUES, max_size=2),
            st.just({"avoid": {"component": "fuzzy-q", "policy_from": draw(VALUES)}})))
    for k in draw(st.lists(st.sampled_from(sorted(doc)), max_size=1)):
        doc.pop(k, None)
    return doc


def _mutate(text: str) -> st.SearchStrategy[str]:
    """``text`` with a few characters deleted, replaced or inserted (TOML-ish near misses)."""
    @st.composite
    def mutated(draw: st.DrawFn) -> str:
        s = text
        for _ in range(draw(st.integers(1, 4))):
            i = draw(st.integers(0, len(s)))
            op = draw(st.sampled_from(["del", "rep", "ins", "cut"]))
            ch = draw(st.one_of(st.sampled_from(list("[]{}=,.\"'#\n 0-+e_xnaif")),
                                st.characters()))
            if op == "del":
                s = s[:i] + s[i + 1:]
            elif op == "rep":
                s = s[:i] + ch + s[i + 1:]
            elif op == "ins":
                s = s[:i] + ch + s[i:]
            else:
                s = s[:i]
        return s
    return mutated()


GOOD_WORLD = to_toml({
    "name": "room", "description": "fuzz room", "robot": {"start": [1.0, 1.0, 0.0]},
    "walls": [{"points": ROOM}], "obstacles": [{"points": BOX}],
    "trajectories": [{"points": [[0.5, 0.5], [2.5, 0.5]]}],
    "goal": {"position": [12.0, 7.0], "radius": 0.3},
})
GOOD_CONFIG = to_toml(BASE_CONFIG)

#: Hypothesis strategies of TOML text for each loader.
WORLD_TEXT = st.one_of(st.text(max_size=300), _mutate(GOOD_WORLD),
                       world_docs().map(to_toml))
CONFIG_TEXT = st.one_of(st.text(max_size=300), _mutate(GOOD_CONFIG),
                        config_docs().map(to_toml))


def _check_input_error(exc: InputError) -> None:
    msg = str(exc)
    assert exc.file == FILE, msg
    assert "\n" not in msg and msg.startswith(FILE), msg


def classify_world(text: str) -> str:
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with np.errstate(all="raise", under="ignore"):  # (underflow to 0 is harmless)
            try:
                world = parse_world(text, file=FILE)
            except InputError as exc:
                _check_input_error(exc)
                return "documented"
    assert world.segments.shape[1] == 4 and np.all(np.isfinite(world.segments))
    assert np.all(np.isfinite(world.start))
    return "loaded"


def classify_config(text: str) -> str:
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        try:
            cfg = parse_config(text, file=FILE)
        except InputError as exc:
            _check_input_error(exc)
            return "documented"
    assert cfg["behaviours"]
    return "loaded"


# ----------------------------------------------------------------------------- FCM strategies

_DTYPES = st.sampled_from([np.float64, np.float32, np.float16, np.int64, np.int8, np.uint8,
                           np.bool_, np.complex128, np.dtype("U3"), np.dtype("O"),
                           np.dtype("M8[s]")])
_FLOATS = st.one_of(st.floats(0, 3), st.floats(allow_nan=True, allow_infinity=True),
                    st.sampled_from([1e150, 1e200, -1e-300, 0.0]))


@st.composite
def arrays(draw: st.DrawFn, dims: tuple[int, ...] = (0, 1, 2, 2, 2, 3)) -> Any:
    """Arrays of random shape and dtype (mostly small 2-D float), or non-array things."""
    kind = draw(st.integers(0, 9))
    if kind == 0:
        return draw(st.one_of(st.none(), SCALARS, st.lists(st.lists(SCALARS, max_size=3),
                                                             max_size=3)))
    ndim = draw(st.sampled_from(dims))
    shape = tuple(draw(st.integers(0 if kind == 1 else 1, 6)) for _ in range(ndim))
    if kind in (1, 2):
        dtype = draw(_DTYPES)
        if dtype == np.dtype("O"):
            return np.array([draw(SCALARS) for _ in range(int(np.prod(shape)))],
                            dtype=object).reshape(shape)
        return draw(hnp.arrays(dtype, shape))
    elements = _FLOATS if kind == 3 else st.floats(0, 3)
    return draw(hnp.arrays(np.float64, shape, elements=elements))


NUMBERS = st.one_of(SCALARS, st.none(), st.sampled_from([np.float64(1.2), np.int64(3),
                                                         np.float32("nan"), 1 + 2j, "1.2"]))


@st.composite
def fcm_args(draw: st.DrawFn) -> dict[str, Any]:
    """Valid ``fcm`` arguments (small data, extreme values included), then 0-2 of them
    replaced by bad ones (any shape, dtype, NaN/inf, wrong types)."""
    n, d = draw(st.integers(1, 12)), draw(st.integers(1, 4))
    X = draw(hnp.arrays(np.float64, (n, d), elements=st.one_of(
        st.floats(0, 3), st.sampled_from([0.0, 3.0, 1e-300, 1e100, -1e100]))))
    c = draw(st.integers(2, max(2, n)))
    args: dict[str, Any] = {"X": X, "c": c, "m": draw(st.one_of(
        st.floats(1.01, 4.0), st.sampled_from([1.2, 2.0, 1 + 1e-9, 1e6])))}
    if draw(st.booleans()):
        args["tol"] = draw(st.floats(1e-12, 1.0))
    args["max_iter"] = draw(st.integers(1, 20))
    if draw(st.booleans()):
        args["init_centers"] = draw(hnp.arrays(np.float64, (c, d), elements=st.floats(0, 3)))
    if draw(st.booleans()):
        args["seed"] = draw(st.one_of(st.integers(0, 2**64 - 1),
                                      st.builds(np.random.default_rng, st.integers(0, 9))))
    bad = {"X": arrays(), "c": NUMBERS, "m": NUMBERS, "tol": NUMBERS, "max_iter": NUMBERS,
           "init_centers": arrays(), "seed": st.one_of(st.integers(-2**70, 2**70), NUMBERS)}
    for key in draw(st.lists(st.sampled_from(sorted(bad)), max_size=2, unique=True)):
        args[key] = draw(bad[key])
    return args


@st.composite
def membership_args(draw: st.DrawFn) -> dict[str, Any]:
    """Valid ``memberships`` arguments (a (d,) reading or (n, d) samples), 0-2 replaced."""
    c, d = draw(st.integers(1, 6)), draw(st.integers(1, 4))
    centers = draw(hnp.arrays(np.float64, (c, d), elements=st.floats(0, 3)))
    shape = (d,) if draw(st.booleans()) else (draw(st.integers(1, 8)), d)
    X = draw(hnp.arrays(np.float64, shape, elements=st.one_of(
        st.floats(0, 3), st.sampled_from([0.0, 1e-300, 1e100]))))
    if draw(st.booleans()) and shape == (d,):
        X = centers[draw(st.integers(0, c - 1))].copy()  # on a centre
    args = {"X": X, "centers": centers,
            "m": draw(st.one_of(st.floats(1.01, 4.0), st.sampled_from([1.2, 1 + 1e-9, 1e6])))}
    bad = {"X": arrays(dims=(0, 1, 2, 3)), "centers": arrays(), "m": NUMBERS}
    for key in draw(st.lists(st.sampled_from(sorted(bad)), max_size=2, unique=True)):
        args[key] = draw(bad[key])
    return args


FCM_ARGS = fcm_args()
MEMBERSHIP_ARGS = membership_args()


class _Result:
    """A duck-typed FCM result (``validity`` accepts any object with u, centers, m)."""

    def __init__(self, u: Any, centers: Any, m: Any) -> None:
        self.u, self.centers, self.m = u, centers, m


@st.composite
def validity_args(draw: st.DrawFn) -> tuple[Any, Any]:
    kind = draw(st.integers(0, 3))
    if kind == 0:  # a real result, possibly for other data
        X = draw(hnp.arrays(np.float64, (draw(st.integers(2, 8)), draw(st.integers(1, 3))),
                            elements=st.floats(0, 3)))
        c = draw(st.integers(2, X.shape[0]))
        res = fcm(X, c, draw(st.floats(1.05, 3.0)), max_iter=5, seed=draw(st.integers(0, 9)))
        if draw(st.booleans()):
            X = draw(arrays())
        return X, res
    if kind == 1:
        return draw(arrays()), draw(st.one_of(st.none(), SCALARS, st.just(object())))
    u = draw(arrays())
    if kind == 2 and isinstance(u, np.ndarray) and u.ndim == 2 and u.dtype.kind == "f":
        with np.errstate(all="ignore"):
            u = np.abs(u) / np.abs(u).sum(axis=1, keepdims=True)  # often a valid partition
    res_cls = draw(st.sampled_from([_Result, FCMResult]))
    centers, m = draw(arrays()), draw(st.one_of(st.floats(1.0, 4.0), NUMBERS))
    if res_cls is FCMResult:
        return draw(arrays()), FCMResult(centers=centers, u=u, objective=0.0, n_iter=1,
                                         converged=True, m=m)
    return draw(arrays()), _Result(u, centers, m)


def _partition_ok(u: np.ndarray, n: int | None = None) -> None:
    assert u.ndim == 2 and (n is None or u.shape[0] == n)
    assert np.all(np.isfinite(u)) and u.min() >= 0 and u.max() <= 1 + 1e-9
    np.testing.assert_allclose(u.sum(axis=1), 1.0, atol=1e-6)


def _fcm_call(fn: Any, *args: Any, **kw: Any) -> tuple[str, Any]:
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with np.errstate(all="raise", under="ignore"):
            try:
                return "loaded", fn(*args, **kw)
            except (ValueError, TypeError) as exc:
                assert "\n" not in str(exc)
                return "documented", None


def classify_fcm(args: dict[str, Any]) -> str:
    kw = dict(args)
    X, c, m = kw.pop("X"), kw.pop("c"), kw.pop("m")
    out, res = _fcm_call(fcm, X, c, m, **kw)
    if out == "loaded":
        _partition_ok(res.u, np.shape(X)[0])
        assert res.centers.shape == (res.u.shape[1], np.shape(X)[1])
        assert np.all(np.isfinite(res.centers)) and math.isfinite(res.objective)
    return out


def classify_memberships(args: dict[str, Any]) -> str:
    out, u = _fcm_call(memberships, args["X"], args["centers"], args["m"])
    if out == "loaded":
        _partition_ok(np.atleast_2d(u))
    return out


def classify_validity(args: tuple[Any, Any]) -> str:
    out, v = _fcm_call(validity, *args)
    if out == "loaded":
        assert set(v) == {"pc", "pe", "nfi", "min_ht", "mean_ht", "min_card", "rf", "objective"}
        assert all(isinstance(x, float) and not math.isnan(x) for x in v.values()), v
    return out


@st.composite
def component_docs(draw: st.DrawFn) -> dict[str, Any]:
    """The small config with 1-3 component parameters (sensor, interpreter, behaviour,
    reward, arbiter, robot) set to arbitrary values: the components validate them."""
    doc = json.loads(json.dumps(BASE_CONFIG))
    reg = _registry()
    arbiter = draw(st.sampled_from(sorted(reg.entries["arbiter"])))
    doc["arbiter"] = {"component": arbiter}
    reward = draw(st.sampled_from(sorted(reg.entries["reward"])))
    doc["behaviours"]["avoid"]["reward"] = reward
    doc["behaviours"]["avoid"]["reward_params"] = {}
    from sitframe.params import accepted_params
    from sitframe.sim.robot import RobotParams

    tables = {
        "sensor": (doc.setdefault("sensor", {}), reg.entries["sensor"]["pioneer-sonar"]),
        "interpreter": (doc["interpreter"], reg.entries["interpreter"]["fcm"]),
        "behaviour": (doc["behaviours"]["avoid"], reg.entries["behaviour"]["fuzzy-q"]),
        "reward": (doc["behaviours"]["avoid"]["reward_params"], reg.entries["reward"][reward]),
        "arbiter": (doc["arbiter"], reg.entries["arbiter"][arbiter]),
        "robot": (doc.setdefault("robot", {}), RobotParams),
    }
    for _ in range(draw(st.integers(1, 3))):
        table, entry = tables[draw(st.sampled_from(sorted(tables)))]
        names = sorted(accepted_params(getattr(entry, "factory", entry))[0])
        if names:
            table[draw(st.sampled_from(names))] = draw(st.one_of(VALUES, st.lists(
                st.one_of(st.floats(-100, 100), st.integers(-5, 200)), max_size=10)))
    return doc


_REGISTRY: list[Any] = []


def _registry() -> Any:
    if not _REGISTRY:
        from sitframe.contract.pluginmanager import Registry, get_plugin_manager

        _REGISTRY.append(Registry.collect(get_plugin_manager()))
    return _REGISTRY[0]


def classify_components(doc: dict[str, Any]) -> str:
    """``parse_config`` then resolve every component (what ``sitframe run`` does first)."""
    from sitframe.contract.resolve import Resolved

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        try:
            cfg = parse_config(to_toml(doc), file=FILE)
            Resolved.build(cfg, _registry(), FILE)
        except InputError as exc:
            _check_input_error(exc)
            return "documented"
    return "loaded"


#: name -> (strategy, classifier); the benchmark iterates over this.
TARGETS: dict[str, tuple[st.SearchStrategy, Any]] = {
    "parse_world": (WORLD_TEXT, classify_world),
    "parse_config": (CONFIG_TEXT, classify_config),
    "config+components": (component_docs(), classify_components),
    "fcm.fcm": (FCM_ARGS, classify_fcm),
    "fcm.memberships": (MEMBERSHIP_ARGS, classify_memberships),
    "fcm.validity": (validity_args(), classify_validity),
}

# ----------------------------------------------------------------------------- tests

FUZZ = settings(max_examples=250, deadline=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much,
                                       HealthCheck.data_too_large])


@pytest.mark.parametrize("name", sorted(TARGETS))
def test_fuzz_target(name: str) -> None:
    strategy, classify = TARGETS[name]

    @FUZZ
    @given(strategy)
    def run(value: Any) -> None:
        assert classify(value) in ("loaded", "documented")

    run()


def test_renderer_round_trips() -> None:
    import tomllib

    assert tomllib.loads(GOOD_CONFIG) == BASE_CONFIG
    assert parse_world(GOOD_WORLD, file=FILE).name == "room"
    assert classify_config(GOOD_CONFIG) == "loaded"


# ----------------------------------------------------------------------------- regressions
# Inputs the fuzzers found escaping as the wrong error type (fixed in sitframe.situations.fcm).


@pytest.mark.parametrize("bad", [
    np.array([[1 + 1j, 0], [0, 1]]),            # was a ComplexWarning; imaginary part dropped
    np.array([["1", "2"], ["3", "4"]]),           # was silently parsed as numbers
    np.array([["2020-01-01"] * 2] * 2, dtype="M8[D]"),
])
def test_fcm_rejects_non_real_arrays(bad: np.ndarray) -> None:
    X = np.array([[0.0, 0.0], [1.0, 1.0], [2.0, 2.0]])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(TypeError, match="real numeric array"):
            fcm(bad, 2)
        with pytest.raises(TypeError, match="real numeric array"):
            memberships(X, bad, 1.2)
        res = fcm(X, 2, seed=0)
        with pytest.raises(TypeError, match="real numeric array"):
            validity(X, _Result(bad, res.centers, 1.2))


@pytest.mark.parametrize("result", [None, 0.0, "fcm", object()])
def test_validity_rejects_non_results(result: Any) -> None:  # was an AttributeError
    with pytest.raises(TypeError, match="FCMResult"):
        validity(np.zeros((3, 2)), result)


def test_error_with_newline_in_key_stays_one_line() -> None:
    # found by the world fuzzer: a quoted TOML key holding a newline broke the one-line error
    text = GOOD_WORLD.replace("[robot]", '[robot]\n"a\\nb" = 1')
    with pytest.raises(InputError) as info:
        parse_world(text, file=FILE)
    assert str(info.value) == f"{FILE}: robot.a\\nb: unknown key; expected one of start, radius"
