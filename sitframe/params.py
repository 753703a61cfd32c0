"""Parameter validation helpers for component authors and the config loader.

Every check raises :class:`sitframe.errors.InputError` whose ``key`` is the
parameter name; the config loader prefixes the table path, so a user sees e.g.
``obstacle.toml: behaviours.avoid.alpha: expected a number in [0, 1], got 1.5``.
"""

from __future__ import annotations

import inspect
import math
import numbers
from collections.abc import Sequence
from typing import Any

from sitframe.errors import InputError, InputTypeError, did_you_mean


def _fmt(value: Any) -> str:
    return repr(value) if isinstance(value, str) else str(value)


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
) -> list[float]:
    """Check a list of finite numbers (each optionally within bounds)."""
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
