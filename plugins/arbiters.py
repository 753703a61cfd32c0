"""Arbiters: fuse behaviour proposals into one command.

``single``
    Passes one behaviour's proposal through (the thesis's learning
    experiments run one behaviour at a time).
``cdb``
    Context-dependent blending (thesis 6.2): a higher-level fuzzy controller
    weights each behaviour by how well the current *context* (the nearest of
    the sensor ranges) fits the behaviour's context sets, and the command is
    the centre of gravity of the behaviours' proposals.
``priority``
    Switching: the first behaviour (in a configured order) whose condition
    holds wins outright, as in subsumption-like arbitration.

The arbiter contract (:class:`sitframe.contract.components.Arbiter`): ``combine(context,
proposals)`` gets the proposals of every behaviour keyed by label, in config
order, and returns ``(fused proposal, weights)`` where ``weights`` is a (k,)
array, one weight per proposal in that order, summing to 1 (logged as the
``weights`` dataset).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from sitframe import Context, InputError, Proposal, RunContext, hookimpl
from sitframe import params as P


class SingleArbiter:
    """Use the proposal of the only behaviour (error if there are several)."""

    name = "single"
    _ONE = np.ones(1)

    def __init__(self) -> None:
        pass

    def combine(self, context: Context, proposals: dict[str, Proposal]) -> tuple[Proposal, Any]:
        if len(proposals) != 1:
            raise ValueError(f"the 'single' arbiter needs exactly one behaviour, got "
                             f"{len(proposals)} ({', '.join(proposals)}); use 'cdb' or 'priority'")
        (prop,) = proposals.values()
        return prop, self._ONE

    def _fused(self) -> dict[str, Any] | None:
        """The compiled trial passes the one proposal on (``sitframe.runs.fused``)."""
        return {} if type(self).combine is SingleArbiter.combine else None


# ---------------------------------------------------------------------------
# helpers
# ---------------------------------------------------------------------------


def trapezoid(x: float, abcd: Sequence[float]) -> float:
    """Membership of ``x`` in the trapezoid ``[a, b, c, d]`` (``a <= b <= c <= d``).

    0 below ``a`` and above ``d``, 1 on ``[b, c]``, linear in between. ``a == b``
    makes a left shoulder (1 for every ``x <= c``), ``c == d`` a right shoulder
    (1 for every ``x >= b``); ``b == c`` is a triangle.
    """
    a, b, c, d = abcd
    if x < b:
        if a == b:
            return 1.0
        return max(0.0, (x - a) / (b - a))
    if x <= c:
        return 1.0
    if c == d:
        return 1.0
    return max(0.0, (d - x) / (d - c))


def _set(name: str, value: Any) -> tuple[float, float, float, float]:
    v = P.number_list(name, value, length=4)
    if not (v[0] <= v[1] <= v[2] <= v[3]):
        raise InputError(f"expected a trapezoid [a, b, c, d] with a <= b <= c <= d [m], got {v}",
                         key=name)
    return v[0], v[1], v[2], v[3]


def _label_index(labels: list[str], label: str, key: str, arbiter: str) -> int:
    # ``key`` is relative to the [arbiter] table: the core prefixes "arbiter." (and the
    # config file) to an InputError raised in ``bind``
    if label not in labels:
        raise InputError(f"the '{arbiter}' arbiter names behaviour '{label}', but the run's "
                         f"behaviours are: {', '.join(labels)}", key=key)
    return labels.index(label)


# ---------------------------------------------------------------------------
# context-dependent blending
# ---------------------------------------------------------------------------


class CDBArbiter:
    """Context-dependent blending over any number of behaviours and context sets.

    Contract. The *context* is ``Context.nearest``, the smallest sensor range
    [m]. Each rule reads "IF context is SET THEN objective is BEHAVIOUR",
    where SET is a trapezoid ``[a, b, c, d]`` on the context (see
    :func:`trapezoid`). A behaviour's weight is the largest membership of the
    context in the sets of its rules (Min-Max inference with one antecedent;
    a behaviour without rules gets 0). The output singletons sit at the
    behaviours' current proposals, so the command is their centre of gravity::

        heading = sum_k w_k * heading_k / sum_k w_k

    and the speed is the same average over the behaviours that propose one
    (``None`` if none does). The returned weights are normalised to sum 1.
    If the context is in no set (a gap between sets), the rule whose core
    ``[b, c]`` is nearest to it fires alone, so the robot is never without a
    command.

    Parameters
    ----------
    sets
        Named context sets ``{name = [a, b, c, d]}`` [m]. Default (thesis Fig.
        6.4, two overlapping shoulders): ``close = [0, 0, 0.2, 0.6]``,
        ``far = [0.2, 0.6, 3, 3]``.
    rules
        Either a table ``{set name = behaviour label}`` (e.g. ``{close = "avoid",
        far = "goal"}``), or a list of tables ``{behaviour = "label", set = NAME
        or [a, b, c, d]}``. Default: the i-th set (in ``sets`` order) drives the
        i-th behaviour (in config order), so the first behaviour is the
        ``close`` one.
    """

    name = "cdb"

    def __init__(
        self,
        *,
        sets: Mapping[str, Sequence[float]] | None = None,
        rules: Mapping[str, str] | Sequence[Mapping[str, Any]] | None = None,
    ) -> None:
        if sets is None:
            sets = {"close": [0.0, 0.0, 0.2, 0.6], "far": [0.2, 0.6, 3.0, 3.0]}
        if not isinstance(sets, Mapping) or not sets:
            raise InputError("expected a table of named trapezoids {name = [a, b, c, d]}",
                             key="sets")
        self.sets = {str(k): _set(f"sets.{k}", v) for k, v in sets.items()}
        # rules as (behaviour label or None = i-th behaviour, trapezoid, key for messages)
        self.rules: list[tuple[str | None, int, tuple[float, float, float, float], str]] = []
        if rules is None:
            for i, (sname, abcd) in enumerate(self.sets.items()):
                self.rules.append((None, i, abcd, f"sets.{sname}"))
        elif isinstance(rules, Mapping):
            for sname, label in rules.items():
                key = f"rules.{sname}"
                if sname not in self.sets:
                    raise InputError(f"unknown context set '{sname}'; sets are: "
                                     f"{', '.join(self.sets)}", key=key)
                self.rules.append((P.string(key, label), -1, self.sets[sname], key))
        elif isinstance(rules, Sequence) and not isinstance(rules, str):
            for i, rule in enumerate(rules):
                key = f"rules[{i}]"
                if not isinstance(rule, Mapping) or set(rule) != {"behaviour", "set"}:
                    raise InputError("expected a table {behaviour = \"label\", set = NAME or "
                                     "[a, b, c, d]}", key=key)
                s = rule["set"]
                if isinstance(s, str):
                    if s not in self.sets:
                        raise InputError(f"unknown context set '{s}'; sets are: "
                                         f"{', '.join(self.sets)}", key=f"{key}.set")
                    abcd = self.sets[s]
                else:
                    abcd = _set(f"{key}.set", s)
                self.rules.append((P.string(f"{key}.behaviour", rule["behaviour"]), -1, abcd,
                                   key))
        else:
            raise InputError("expected a table {set = \"behaviour\"} or a list of "
                             "{behaviour, set} tables", key="rules")
        if not self.rules:
            raise InputError("expected at least one rule", key="rules")
        self._labels: tuple[str, ...] = ()
        self._idx = np.zeros(0, dtype=np.intp)
        self._sets = np.zeros((0, 4))

    def _bind(self, labels: list[str]) -> None:
        idx = []
        for label, i, _abcd, key in self.rules:
            if label is None:
                if i >= len(labels):
                    raise InputError(f"{len(self.sets)} context sets but only {len(labels)} "
                                     f"behaviours ({', '.join(labels)}); give rules = "
                                     "{set = \"behaviour\"}", key="rules")
                idx.append(i)
            else:
                idx.append(_label_index(labels, label, f"{key}", "cdb"))
        self._labels = tuple(labels)
        self._idx = np.asarray(idx, dtype=np.intp)
        self._sets = np.asarray([abcd for _l, _i, abcd, _k in self.rules])

    def bind(self, run: RunContext) -> None:
        """Check the rules against the run's behaviour labels before anything runs."""
        self._bind(list(run.labels))

    def weights(self, nearest: float, labels: list[str]) -> np.ndarray:
        """Normalised (k,) behaviour weights for context ``nearest`` [m]."""
        if tuple(labels) != self._labels:
            self._bind(labels)
        mu = np.array([trapezoid(nearest, s) for s in self._sets])
        w = np.zeros(len(labels))
        np.maximum.at(w, self._idx, mu)
        total = w.sum()
        if total <= 0.0:
            gap = np.maximum(self._sets[:, 1] - nearest, 0) + np.maximum(nearest - self._sets[:, 2],
                                                                         0)
            w[self._idx[int(np.argmin(gap))]] = 1.0
            total = 1.0
        return w / total

    def combine(self, context: Context, proposals: dict[str, Proposal]) -> tuple[Proposal, Any]:
        props = list(proposals.values())
        w = self.weights(context.nearest, list(proposals))
        return Proposal.blend(props, w), w


# ---------------------------------------------------------------------------
# priority switching
# ---------------------------------------------------------------------------


class PriorityArbiter:
    """Switching: the first behaviour whose condition holds wins outright.

    Parameters
    ----------
    rules
        Ordered list of tables ``{behaviour = "label", nearest_below = x}``,
        ``{behaviour = "label", nearest_above = x}`` (``x`` in metres, compared
        with ``Context.nearest``), ``{behaviour = "label", activation_above =
        a}`` (holds when the behaviour's proposal carries an activation >=
        ``a``, see :class:`sitframe.Proposal`) or ``{behaviour = "label"}``
        (always holds). If no condition holds, the last rule's behaviour wins.
        Default: every behaviour but the last (in config order) holds when its
        proposal's activation is at least ``activation`` -- or, for a behaviour
        that gives no activation, when ``nearest < threshold``; the last
        always holds -- e.g. ``avoid`` when something is within ``threshold``
        (or the avoider says it is needed), else ``goal``.
    threshold
        The distance [m] of the default rules.
    activation
        The activation in [0, 1] at which a default rule holds.

    The weights are 1 for the winner and 0 for the others.
    """

    name = "priority"
    _CONDS = ("nearest_below", "nearest_above", "activation_above")

    def __init__(self, *, rules: Sequence[Mapping[str, Any]] | None = None,
                 threshold: float = 0.5, activation: float = 0.5) -> None:
        self.threshold = P.number("threshold", threshold, lo=0.0)
        self.activation = P.number("activation", activation, lo=0.0, hi=1.0)
        self.rules: list[tuple[str, str | None, float]] | None = None
        if rules is not None:
            if isinstance(rules, str) or not isinstance(rules, Sequence) or not rules:
                raise InputError("expected a non-empty list of {behaviour = \"label\", "
                                 "nearest_below = x} tables", key="rules")
            self.rules = []
            for i, rule in enumerate(rules):
                key = f"rules[{i}]"
                if not isinstance(rule, Mapping) or "behaviour" not in rule:
                    raise InputError("expected a table {behaviour = \"label\"[, nearest_below = "
                                     "x | nearest_above = x]}", key=key)
                conds = [k for k in rule if k != "behaviour"]
                if len(conds) > 1 or (conds and conds[0] not in self._CONDS):
                    raise InputError(f"expected at most one condition of "
                                     f"{', '.join(self._CONDS)}, got {', '.join(conds)}", key=key)
                label = P.string(f"{key}.behaviour", rule["behaviour"])
                if conds:
                    hi = 1.0 if conds[0] == "activation_above" else None
                    self.rules.append((label, conds[0], P.number(
                        f"{key}.{conds[0]}", rule[conds[0]], lo=0.0, hi=hi)))
                else:
                    self.rules.append((label, None, 0.0))
        self._labels: tuple[str, ...] = ()
        self._bound: list[tuple[int, str | None, float]] = []

    def _bind(self, labels: list[str]) -> None:
        if self.rules is None:
            self._bound = [(i, "default", self.threshold) for i in range(len(labels) - 1)]
            self._bound.append((len(labels) - 1, None, 0.0))
        else:
            self._bound = [(_label_index(labels, lb, f"rules[{i}].behaviour", "priority"), c, x)
                           for i, (lb, c, x) in enumerate(self.rules)]
        self._labels = tuple(labels)

    def bind(self, run: RunContext) -> None:
        """Check the rules against the run's behaviour labels before anything runs."""
        self._bind(list(run.labels))

    def winner(self, nearest: float, labels: list[str],
               activations: Sequence[float | None] | None = None) -> int:
        """Index (in ``labels``) of the behaviour that wins at context ``nearest`` [m].

        ``activations`` are the proposals' activations in label order (``None``
        where a behaviour gives none).
        """
        if tuple(labels) != self._labels:
            self._bind(labels)
        for i, cond, x in self._bound:
            act = activations[i] if activations is not None else None
            if cond is None or (cond == "nearest_below" and nearest < x) or \
                    (cond == "nearest_above" and nearest > x) or \
                    (cond == "activation_above" and act is not None and act >= x) or \
                    (cond == "default" and (nearest < x if act is None
                                            else act >= self.activation)):
                return i
        return self._bound[-1][0]

    def combine(self, context: Context, proposals: dict[str, Proposal]) -> tuple[Proposal, Any]:
        labels = list(proposals)
        k = self.winner(context.nearest, labels, [p.activation for p in proposals.values()])
        w = np.zeros(len(labels))
        w[k] = 1.0
        return proposals[labels[k]], w


@hookimpl
def sitframe_arbiters() -> list[Any]:
    return [SingleArbiter, CDBArbiter, PriorityArbiter]
