"""Parameter checks and the declarations of config keys, for components and the config.

Every check raises :class:`sitframe.errors.InputError` whose ``key`` is the
parameter name; the config loader prefixes the table path, so a user sees e.g.
``obstacle.toml: behaviours.avoid.alpha: expected a number in [0, 1], got 1.5``.

Declaring a key once
    A :class:`Key` declares one config key (type, default, unit, range, meaning) and checks
    a value with the functions below; a :class:`Table` declares a config table of keys,
    checks a table (unknown keys with a suggestion, then each key) and fills in its
    defaults. The run config's tables are declared this way
    (:mod:`sitframe.contract.config`), and the same declarations make the config reference
    of the documentation, so the two cannot drift. A plugin component can declare a table
    of its own with the same types.
Reading a component's checks
    A component checks its parameters in ``__init__`` with the functions below (their
    ``unit`` says the unit). :func:`declared_params` reads them back: it creates the
    component with its defaults while :func:`record_checks` records every check, and
    returns one :class:`Key` per parameter (default from the signature, range and unit from
    the check). The component reference of the documentation is made from it.
Environment variables
    The variables sitframe reads (``SITFRAME_NUMBA``, ``SITFRAME_SCRATCH_ROWS``...) are
    :class:`Key` declarations too (:data:`ENVIRONMENT`), read and checked by
    :func:`environment`: a bad value is an :class:`~sitframe.errors.InputError` naming the
    variable, never silently a default.
"""

from __future__ import annotations

import contextlib
import contextvars
import dataclasses
import functools
import inspect
import math
import numbers
import os
from collections.abc import Callable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any, Literal, get_args, get_origin, get_type_hints

from sitframe.errors import InputError, InputTypeError, did_you_mean


def _fmt(value: Any) -> str:
    return repr(value) if isinstance(value, str) else str(value)


#: The checks made while :func:`record_checks` is active (``None``: not recording), and
#: whether a check is running inside another (a list's items are not recorded apart).
_RECORDED: contextvars.ContextVar[list[Key] | None] = contextvars.ContextVar(
    "sitframe_recorded_checks", default=None)
_INSIDE: contextvars.ContextVar[bool] = contextvars.ContextVar("sitframe_inside_check",
                                                               default=False)


@contextlib.contextmanager
def _checking(key: Callable[[], Key]) -> Iterator[None]:
    """Record ``key()`` if checks are being recorded and this check is not nested."""
    recorded = _RECORDED.get()
    if recorded is not None and not _INSIDE.get():
        recorded.append(key())
    token = _INSIDE.set(True)
    try:
        yield
    finally:
        _INSIDE.reset(token)


def number(
    name: str,
    value: Any,
    *,
    lo: float | None = None,
    hi: float | None = None,
    lo_open: bool = False,
    hi_open: bool = False,
    integer: bool = False,
    hint: str = "",
    unit: str = "",
) -> float | int:
    """Check that ``value`` is a finite (integer) number within bounds and return it.

    Parameters
    ----------
    name
        The parameter's name (the error's ``key``).
    value
        A real number (Python or numpy; not a bool).
    lo, hi
        Bounds, closed unless ``lo_open`` / ``hi_open``; ``None``: unbounded.
    integer
        Whether ``value`` must be integral (``3.0`` is accepted as 3).
    hint
        Appended to what is expected, e.g. why a bound is what it is.
    unit
        The value's unit (``"m"``, ``"deg"``, ``"s"``...), for the documentation.

    Returns
    -------
    float or int
        ``value`` as a Python float (an int if ``integer``).

    Raises
    ------
    InputTypeError
        ``value`` is not a real number, or not integral where an integer is expected.
    InputError
        ``value`` is non-finite or out of bounds.
    """
    with _checking(lambda: Key(name, "integer" if integer else "number", unit=unit, lo=lo,
                               hi=hi, lo_open=lo_open, hi_open=hi_open)):
        return _number(name, value, lo, hi, lo_open, hi_open, integer, hint)


def _number(name: str, value: Any, lo: float | None, hi: float | None, lo_open: bool,
            hi_open: bool, integer: bool, hint: str) -> float | int:
    kind = "an integer" if integer else "a number"
    bounds = ""
    if lo is not None or hi is not None:
        left = "(-inf" if lo is None else ("(" if lo_open else "[") + str(lo)
        right = "inf)" if hi is None else str(hi) + (")" if hi_open else "]")
        bounds = f" in {left}, {right}"
    expected = f"expected {kind}{bounds}{hint}"
    if isinstance(value, bool) or not isinstance(value, numbers.Real):  # (numpy's too)
        raise InputTypeError(f"{expected}, got {type(value).__name__} {_fmt(value)}", key=name)
    if integer and not (isinstance(value, int) or float(value).is_integer()):
        raise InputTypeError(f"{expected}, got {_fmt(value)}", key=name)
    if not math.isfinite(value):
        raise InputError(f"{expected}, got non-finite {value}", key=name)
    if lo is not None and (value < lo or (lo_open and value == lo)):
        raise InputError(f"{expected}, got {_fmt(value)}", key=name)
    if hi is not None and (value > hi or (hi_open and value == hi)):
        raise InputError(f"{expected}, got {_fmt(value)}", key=name)
    return int(value) if integer else float(value)


def number_list(
    name: str,
    value: Any,
    *,
    min_len: int = 1,
    lo: float | None = None,
    hi: float | None = None,
    length: int | None = None,
    unit: str = "",
) -> list[float]:
    """Check a list of finite numbers (each optionally within bounds)."""
    with _checking(lambda: Key(name, "numbers", unit=unit, lo=lo, hi=hi)):
        return _number_list(name, value, min_len, lo, hi, length)


def _number_list(name: str, value: Any, min_len: int, lo: float | None, hi: float | None,
                 length: int | None) -> list[float]:
    if isinstance(value, str) or not isinstance(value, Sequence):
        raise InputError(f"expected a list of numbers, got {type(value).__name__} "
                         f"{_fmt(value)}", key=name)
    if length is not None and len(value) != length:
        raise InputError(f"expected a list of {length} numbers, got {len(value)}", key=name)
    if len(value) < min_len:
        raise InputError(f"expected at least {min_len} numbers, got {len(value)}", key=name)
    return [float(number(f"{name}[{i}]", v, lo=lo, hi=hi)) for i, v in enumerate(value)]


def choice(name: str, value: Any, choices: Sequence[str]) -> str:
    """Check that ``value`` is one of ``choices``."""
    with _checking(lambda: Key(name, "choice", choices=tuple(choices))):
        return _choice(name, value, choices)


def choice_field(obj: Any, name: str) -> str:
    """Check a dataclass field annotated ``Literal[...]`` against the choices its type names.

    The annotation is the one place the choices are written; the check, its error
    message and the documentation's reference read them from there.
    """
    return choice(name, getattr(obj, name), literal_choices(type(obj))[name])


@functools.cache
def literal_choices(cls: type) -> dict[str, tuple[str, ...]]:
    """The choices of each field of ``cls`` annotated ``Literal[...]``, by field name."""
    return {n: get_args(t) for n, t in get_type_hints(cls).items() if get_origin(t) is Literal}


def _choice(name: str, value: Any, choices: Sequence[str]) -> str:
    if not isinstance(value, str) or value not in choices:
        hint = did_you_mean(str(value), choices) if isinstance(value, str) else ""
        raise InputError(
            f"expected one of {', '.join(repr(c) for c in choices)}, got {_fmt(value)}{hint}",
            key=name,
        )
    return value


def boolean(name: str, value: Any) -> bool:
    """Check that ``value`` is a bool (a TOML ``true``/``false``; 0 and 1 are refused).

    Raises
    ------
    InputError
        ``<name>: expected true or false, got <value>``.
    """
    with _checking(lambda: Key(name, "true/false")):
        if not isinstance(value, bool):
            raise InputError(f"expected true or false, got {_fmt(value)}", key=name)
        return value


def string(name: str, value: Any) -> str:
    """Check that ``value`` is a non-empty string (a name, a path).

    Raises
    ------
    InputError
        ``<name>: expected a non-empty string, got <value>``.
    """
    with _checking(lambda: Key(name, "string")):
        if not isinstance(value, str) or not value:
            raise InputError(f"expected a non-empty string, got {_fmt(value)}", key=name)
        return value


def known_keys(table: Any, known: Sequence[str], *, prefix: str = "",
               file: str | None = None) -> None:
    """Reject a key of the mapping ``table`` that is not in ``known``, suggesting the closest.

    The error's key is ``prefix.key`` (``key`` without a prefix); ``known`` is
    listed in the order given.
    """
    for key in table:
        if key not in known:
            raise InputError(f"unknown key{did_you_mean(str(key), known)}; expected one of "
                             f"{', '.join(known)}", file=file,
                             key=f"{prefix}.{key}" if prefix else str(key))


_ACCEPTED: dict[Any, tuple[frozenset[str], bool, frozenset[str]]] = {}


def _params_of(factory: Any) -> tuple[frozenset[str], bool, frozenset[str]]:
    """Keyword names, ``**kwargs``, positional-only names of ``factory`` (read once per
    factory: a run creates its components once per episode)."""
    try:
        return _ACCEPTED[factory]
    except (KeyError, TypeError):
        pass
    names, var_kw = _accepted(factory)
    try:
        positional = frozenset(q.name for q in inspect.signature(factory).parameters.values()
                               if q.kind is q.POSITIONAL_ONLY)
    except (TypeError, ValueError):
        positional = frozenset()
    out = (frozenset(names), var_kw, positional)
    try:
        _ACCEPTED[factory] = out
    except TypeError:  # (an unhashable factory: read every time)
        pass
    return out


def accepted_params(factory: Any) -> tuple[set[str], bool]:
    """Keyword parameter names ``factory`` accepts, and whether it takes ``**kwargs``."""
    names, var_kw, _pos = _params_of(factory)
    return set(names), var_kw


def _accepted(factory: Any) -> tuple[set[str], bool]:
    try:
        sig = inspect.signature(factory)
    except (TypeError, ValueError):
        return set(), True
    names = set()
    var_kw = False
    for p in sig.parameters.values():
        if p.kind is inspect.Parameter.VAR_KEYWORD:
            var_kw = True
        elif p.kind in (inspect.Parameter.KEYWORD_ONLY, inspect.Parameter.POSITIONAL_OR_KEYWORD):
            names.add(p.name)
    return names, var_kw


def check_params(
    factory: Any, params: dict[str, Any], *, file: str | None = None, key: str | None = None
) -> None:
    """Reject parameters ``factory`` does not accept, suggesting the closest name."""
    names, var_kw, positional = _params_of(factory)
    if var_kw:
        return
    for pname in params:
        if pname not in names:
            where = f"{key}.{pname}" if key else pname
            if pname in positional:
                raise InputError(f"'{pname}' is a positional-only parameter of "
                                 f"'{getattr(factory, 'name', factory)}', which sitframe cannot "
                                 "pass: it passes a table's keys by keyword", file=file, key=where)
            raise InputError(
                f"unknown parameter '{pname}'{did_you_mean(pname, names)} for "
                f"'{getattr(factory, 'name', factory)}'; accepted: {', '.join(sorted(names))}",
                file=file,
                key=where,
            )


# -- declarations ------------------------------------------------------------------------

class _Marker:
    def __init__(self, name: str) -> None:
        self.name = name

    def __repr__(self) -> str:
        return self.name


#: :attr:`Key.default` of a key a table must give.
REQUIRED = _Marker("REQUIRED")
#: :attr:`Key.default` of a key that stays out of a config that does not give it.
ABSENT = _Marker("ABSENT")


#: What a :class:`Key` of each kind holds, as the documentation says it (``"any"``: checked
#: by the component itself).
KINDS = {"integer": "integer", "number": "number", "numbers": "list of numbers",
         "choice": "string", "true/false": "true/false", "string": "string",
         "text": "string", "path": "string (a path)", "names": "list of names",
         "choices": "list of strings", "table": "table",
         "trial": "integer, \"best\" or table", "any": "any"}


@dataclasses.dataclass(frozen=True)
class Key:
    """One config key, declared once: what validation checks and the reference shows.

    Attributes
    ----------
    name
        The key, as written in the TOML table.
    kind
        One of :data:`KINDS`: ``"integer"`` and ``"number"`` (within ``lo``/``hi``),
        ``"numbers"`` (a list of them), ``"choice"`` (one of ``choices``), ``"choices"``
        (a non-empty list of them), ``"true/false"``, ``"string"`` (non-empty), ``"text"``
        (any string), ``"path"`` (a string, empty for none), ``"names"`` (a list of
        non-empty strings; non-empty unless ``lo = 0``), ``"table"`` (any table), ``"any"``
        (not checked here: the component checks it).
    default
        The value a config that leaves the key out gets (:data:`REQUIRED`: none, the key
        must be given; :data:`ABSENT`, the default: none, the key stays out of the config
        and the component's own default applies).
    doc
        What the key means, in one sentence.
    unit
        Its unit, if it has one (``"m"``, ``"deg"``, ``"s"``, ``"m/s"``, ``"Hz"``).
    lo, hi, lo_open, hi_open
        Its range (numbers; for ``"names"`` ``lo = 0`` allows an empty list).
    choices
        The allowed strings of a ``"choice"`` or ``"choices"`` key.
    check
        A further check ``check(value, name) -> value`` after the kind's (raising an
        :class:`InputError` keyed ``name``), e.g. a name that must be a relative path.
    """

    name: str
    kind: str
    default: Any = ABSENT
    doc: str = ""
    unit: str = ""
    lo: float | None = None
    hi: float | None = None
    lo_open: bool = False
    hi_open: bool = False
    choices: tuple[str, ...] = ()
    check: Callable[[Any, str], Any] | None = dataclasses.field(default=None, compare=False)

    def validate(self, value: Any) -> Any:
        """``value`` checked (an :class:`InputError` keyed :attr:`name`); its checked form."""
        name, kind = self.name, self.kind
        if kind in ("integer", "number"):
            integer = kind == "integer"
            if integer and self.hi is not None:  # the upper bound apart: the usual message
                v = int(number(name, value, lo=self.lo, lo_open=self.lo_open, integer=True))
                if v > self.hi or (self.hi_open and v == self.hi):
                    raise InputError(f"expected an integer {'<' if self.hi_open else '<='} "
                                     f"{_num(self.hi)}, got {v}", key=name)
                value = v
            else:
                checked = number(name, value, lo=self.lo, hi=self.hi, lo_open=self.lo_open,
                                 hi_open=self.hi_open, integer=integer)
                value = checked if integer else value  # a number keeps its TOML type
        elif kind == "numbers":
            value = number_list(name, value, lo=self.lo, hi=self.hi)
        elif kind == "choice":
            value = choice(name, value, self.choices)
        elif kind == "choices":
            if not isinstance(value, list) or not value:
                raise InputError(f"expected a non-empty list of {name} from {list(self.choices)}",
                                 key=name)
            for i, v in enumerate(value):
                choice(f"{name}[{i}]", v, self.choices)
        elif kind == "true/false":
            value = boolean(name, value)
        elif kind == "string":
            value = string(name, value)
        elif kind in ("text", "path"):
            if not isinstance(value, str):
                raise InputError("expected a path to a log (string)" if kind == "path"
                                 else "expected a string", key=name)
        elif kind == "names":
            _names(name, value, allow_empty=self.lo == 0)
        elif kind == "table" and not isinstance(value, dict):
            raise InputError("expected a table", key=name)
        return self.check(value, name) if self.check else value

    @property
    def type_text(self) -> str:
        """The key's type in words (``"integer"``, ``"list of names"``, ...)."""
        return KINDS.get(self.kind, self.kind)

    @property
    def range_text(self) -> str:
        """The key's range or choices in words (empty when it has none)."""
        if self.choices:
            return ", ".join(repr(c).replace("'", '"') for c in self.choices)
        if self.kind in ("integer", "number", "numbers") and \
                (self.lo is not None or self.hi is not None):
            left = "(-inf" if self.lo is None else ("(" if self.lo_open else "[") + _num(self.lo)
            right = "inf)" if self.hi is None else _num(self.hi) + (")" if self.hi_open else "]")
            return f"{left}, {right}"
        if self.kind == "names":
            return "may be empty" if self.lo == 0 else "at least one"
        return ""


def _num(x: float) -> str:
    return str(int(x)) if float(x).is_integer() else f"{x:g}"


def _names(name: str, value: Any, allow_empty: bool) -> None:
    if not isinstance(value, list) or (not value and not allow_empty):
        raise InputError(f"expected a {'' if allow_empty else 'non-empty '}list of names, "
                         f"got {value!r}", key=name)
    for i, v in enumerate(value):
        if not isinstance(v, str) or not v:
            raise InputError(f"expected a name (string), got {v!r}", key=f"{name}[{i}]")


@dataclasses.dataclass(frozen=True)
class Table:
    """A config table, declared once: its keys, checked and documented from one place.

    The core's tables are declared so (:mod:`sitframe.contract.config`), and so is a
    plugin's (its class attribute ``config_table``, :mod:`sitframe.contract.tables`).

    Attributes
    ----------
    name
        The table's name in the config (``[name]``).
    keys
        Its keys (:class:`Key`), in the order a config lists them.
    doc
        What the table configures, in a sentence or two.
    free
        The table takes keys beyond the declared ones (a component table: the component's
        parameters, which the component checks).
    always
        (A plugin's table) fill it into every config, used or not (for tables every config
        held before plugins declared them: the built-in ``[evaluate]`` and ``[goal]``);
        default: only into configs that give it or whose components use it.
    """

    name: str
    keys: tuple[Key, ...]
    doc: str = ""
    free: bool = False
    always: bool = False

    def key(self, name: str) -> Key:
        return next(k for k in self.keys if k.name == name)

    def defaults(self) -> dict[str, Any]:
        """The values a config that leaves keys out gets (a fresh dict, declaration order)."""
        return {k.name: _copy(k.default) for k in self.keys
                if k.default is not REQUIRED and k.default is not ABSENT}

    def validate(self, table: Mapping[str, Any], *, file: str | None = None
                 ) -> dict[str, Any]:
        """``table`` with its defaults filled in, every key checked: an unknown key (with a
        did-you-mean; unless :attr:`free`), a missing required one, a wrong value is an
        :class:`InputError` naming ``file`` and ``<table>.<key>``."""
        if not self.free:
            known_keys(dict(table), [k.name for k in self.keys], prefix=self.name, file=file)
        out = {**self.defaults(), **table}
        for k in self.keys:
            if k.default is REQUIRED and k.name not in out:
                raise InputError(f"missing '{k.name}'" + (f" ({k.doc})" if k.doc else ""),
                                 file=file, key=f"{self.name}.{k.name}")
            if k.name in out:
                try:
                    out[k.name] = k.validate(out[k.name])
                except InputError as exc:
                    raise exc.at(file=file, key_prefix=self.name) from None
        return out


def _copy(value: Any) -> Any:
    return list(value) if isinstance(value, list | tuple) else dict(value) \
        if isinstance(value, dict) else value


# -- reading a component's checks --------------------------------------------------------


@contextlib.contextmanager
def record_checks() -> Iterator[list[Key]]:
    """Record every check made inside the block (one :class:`Key` each)."""
    recorded: list[Key] = []
    token = _RECORDED.set(recorded)
    try:
        yield recorded
    finally:
        _RECORDED.reset(token)


def declared_params(factory: Any) -> list[Key]:
    """One :class:`Key` per keyword parameter of ``factory`` (a component class, or any
    callable that checks its parameters with this module's functions).

    The default is the signature's; the kind, range, choices and unit are those of the
    check ``factory`` makes of the parameter when it is created with its defaults
    (:func:`record_checks`); a parameter it does not check that way gets the kind of its
    annotation. A factory that cannot be created with its defaults gives signature and
    annotations only.
    """
    try:
        sig = inspect.signature(factory)
    except (TypeError, ValueError):
        return []
    params = [p for p in sig.parameters.values()
              if p.kind in (p.KEYWORD_ONLY, p.POSITIONAL_OR_KEYWORD) and p.name != "self"]
    with record_checks() as recorded:
        try:
            factory()
        except Exception:  # noqa: BLE001 - a factory that needs more than its defaults
            pass
    checks = {}
    for k in recorded:
        checks.setdefault(k.name, k)
    out = []
    for p in params:
        default = REQUIRED if p.default is p.empty else p.default
        if isinstance(default, tuple):
            default = list(default)
        k = checks.get(p.name) or Key(p.name, _kind_of(p.annotation, default))
        out.append(dataclasses.replace(k, default=default))
    return out


def _kind_of(annotation: Any, default: Any) -> str:
    text = str(annotation).replace("typing.", "").replace(" | None", "").replace("None | ", "")
    if isinstance(default, bool) or text == "bool":
        return "true/false"
    if isinstance(default, int) or text == "int":
        return "integer"
    if isinstance(default, float) or text == "float":
        return "number"
    if isinstance(default, str) or text == "str":
        return "string"
    if isinstance(default, list) or text.startswith(("list", "Sequence", "tuple")):
        return "numbers" if "float" in text or "int" in text else "names"
    if isinstance(default, dict) or text.startswith("dict"):
        return "table"
    return text.replace("'", "") if annotation is not inspect.Parameter.empty else ""


# -- environment variables ---------------------------------------------------------------

#: The environment variables sitframe reads, declared once: :func:`environment` reads and
#: checks them, the CLI checks them all before a command runs (:func:`check_environment`), and
#: the CLI reference lists them from here. A ``"text"`` variable is on when set to anything.
ENVIRONMENT: dict[str, Key] = {k.name: k for k in (
    Key("SITFRAME_TRACEBACK", "text", "", "Set to anything: an error shows its Python "
        "traceback instead of one line."),
    Key("SITFRAME_DISABLE_PLUGIN_AUTOLOAD", "text", "", "Set to anything: no entry-point "
        "plugin is loaded, not even the built-ins."),
    Key("SITFRAME_NUMBA", "choice", "1", "`0`: the numpy path instead of the compiled "
        "kernels (the same results, slower).", choices=("0", "1")),
    Key("SITFRAME_FUSED", "choice", "1", "`0`: every trial runs the Python loop, none "
        "compiled whole; `wait`: when the compiled trial's kernel is not cached yet, it is "
        "compiled in the run's own process before its first compiled trial, instead of in "
        "the background while trials run the Python loop.", choices=("0", "1", "wait")),
    Key("SITFRAME_START_METHOD", "choice", "", "The multiprocessing start method of a run's "
        "worker pool (default: `forkserver` where the platform has it, else `spawn`).",
        choices=("fork", "forkserver", "spawn")),
    Key("SITFRAME_CACHE_DIR", "path", "", "Where the compiled kernels are cached, and the "
        "scratch files' default folder (default: the user's cache folder, by platformdirs; "
        "numba's own `NUMBA_CACHE_DIR` wins for the kernels)."),
    Key("SITFRAME_SCRATCH_ROWS", "integer", 20_000, "A trial longer than this many "
        "iterations keeps its per-iteration rows in scratch files instead of memory "
        "(`0`: every trial).", lo=0),
    Key("SITFRAME_SCRATCH_DIR", "path", "", "The scratch files' folder (default: "
        "`scratch` in the cache folder). Where no file can be made there, the rows stay in "
        "memory."),
)}


def environment(name: str) -> Any:
    """The value of the environment variable ``name`` (a key of :data:`ENVIRONMENT`),
    checked: its declared default when unset or blank.

    A choice is compared in lower case, an integer may be written as a float (``2e4``).

    Raises
    ------
    InputError
        Keyed ``name``: the value is not what the variable takes (e.g.
        ``SITFRAME_FUSED: expected one of '0', '1', 'wait', got 'maybe'``).
    """
    key = ENVIRONMENT[name]
    raw = os.environ.get(name, "").strip()
    if not raw:
        return key.default
    value: Any = raw.lower() if key.kind == "choice" else raw
    if key.kind == "integer":
        try:
            value = float(raw)
        except ValueError:
            raise InputError(f"expected an integer in {key.range_text}, got {raw!r}",
                             key=name) from None
        value = int(value) if value.is_integer() else value
    return key.validate(value)


def check_environment() -> None:
    """Check every variable of :data:`ENVIRONMENT` that is set (the first bad one raises
    :func:`environment`'s :class:`~sitframe.errors.InputError`)."""
    for name in ENVIRONMENT:
        environment(name)


def cache_folder() -> Path:
    """sitframe's cache folder: ``SITFRAME_CACHE_DIR``, else the user's cache folder
    (:func:`platformdirs.user_cache_dir`). Not created."""
    own = environment("SITFRAME_CACHE_DIR")
    if own:
        return Path(own).expanduser()
    import platformdirs

    return Path(platformdirs.user_cache_dir("sitframe", appauthor=False))
