"""A cheaper ``__init__`` for the frozen, slotted dataclasses built on every loop iteration.

A frozen dataclass's generated ``__init__`` sets each field with ``object.__setattr__``
(its own ``__setattr__`` refuses); the records of one control iteration (a
:class:`~sitframe.sim.robot.Command`, a :class:`~sitframe.sim.robot.StepOutcome`, the
:mod:`sitframe.contract.records`) are built some 5000 times per trial, where that costs
about a third of their construction. :func:`slot_init` gives such a class an ``__init__``
that fills the slots through their descriptors instead: the same signature, defaults and
``__post_init__`` call, the same instance (still frozen: assigning a field afterwards
raises :class:`dataclasses.FrozenInstanceError`); equality, hashing, ``repr``, pickling
and ``dataclasses.replace`` are the dataclass's own. :func:`record` makes such a class in one
decorator.
"""

from __future__ import annotations

import dataclasses
from typing import TypeVar, dataclass_transform

__all__ = ["record", "slot_init"]

T = TypeVar("T", bound=type)


def slot_init(cls: T) -> T:
    """Replace the generated ``__init__`` of the frozen, slotted dataclass ``cls``.

    Parameters
    ----------
    cls
        A ``@dataclass(frozen=True, slots=True)`` class whose fields are all ``init`` fields
        with plain defaults (no ``default_factory``, no ``InitVar``).

    Returns
    -------
    type
        ``cls``, with the new ``__init__`` (so it can decorate the class).

    Raises
    ------
    TypeError
        ``cls`` is not such a dataclass.
    """
    params = getattr(cls, "__dataclass_params__", None)
    fields = dataclasses.fields(cls) if params is not None else ()
    if params is None or not params.frozen or "__slots__" not in cls.__dict__ or any(
            not f.init or f.default_factory is not dataclasses.MISSING for f in fields):
        raise TypeError(f"slot_init: {cls.__name__} is not a frozen, slotted dataclass with "
                        "plain fields")
    ns: dict[str, object] = {}
    args, body = [], []
    for f in fields:
        ns[f"_set_{f.name}"] = cls.__dict__[f.name].__set__
        if f.default is dataclasses.MISSING:
            args.append(f.name)
        else:
            ns[f"_default_{f.name}"] = f.default
            args.append(f"{f.name}=_default_{f.name}")
        body.append(f"    _set_{f.name}(self, {f.name})")
    if hasattr(cls, "__post_init__"):
        body.append("    self.__post_init__()")
    exec(f"def __init__(self, {', '.join(args)}):\n" + "\n".join(body), ns)  # noqa: S102
    init = ns["__init__"]
    init.__qualname__ = f"{cls.__qualname__}.__init__"  # type: ignore[attr-defined]
    init.__module__ = cls.__module__
    init.__annotations__ = {**cls.__init__.__annotations__}  # type: ignore[misc]
    init.__doc__ = cls.__init__.__doc__  # type: ignore[misc]
    cls.__init__ = init  # type: ignore[misc]
    return cls


@dataclass_transform(frozen_default=True)
def record(cls: T) -> T:
    """``@dataclass(frozen=True, slots=True)`` with :func:`slot_init`'s cheaper ``__init__``."""
    return slot_init(dataclasses.dataclass(frozen=True, slots=True)(cls))
