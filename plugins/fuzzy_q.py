"""The learned situation-based FCS behaviour (thesis 4.5-4.7).

One rule per situation for each *output* (``heading``, optionally ``speed``);
each rule's consequent is one of the output's singletons. Outputs listed in
``learn`` are learned online by fuzzy Q-learning (:mod:`sitframe.learning`)
from the reward named in the config; the others must come from a learned
policy (``policy_from`` in the config, e.g. the heading rule base of an
earlier obstacle-avoidance log when learning speed, thesis 4.7).

Config (``[behaviours.LABEL]``)::

    component = "fuzzy-q"
    reward = "obstacle-avoidance"
    headings = [90, 60, 30, 0, -30, -60, -90]   # degrees, positive = left
    speeds = []            # m/s singletons; empty = no speed output
    learn = ["heading"]    # outputs learned here
    alpha = 0.3
    gamma = 0.9
    b = 5
    p = 50
    temperature = 0.25
    temperature_mode = "relative"
    temperature_decay = 1.0  # annealing per rule-base change
    temperature_min = 0.0
    update = "thesis"      # or "standard"
    activation = 0.3
    terminal_on_collision = false
    min_updates = 0        # convergence also needs every situation updated this often
    tie_break = "first"    # greedy ties (never-updated situations): "first" or "centre"
    alpha_visits = 0       # learning rate alpha * k / (k + n) after n updates (0: constant)
    replay = 0             # stored transitions learnt from again per iteration (0: none)
    replay_priority = "rare"  # or "uniform": rarely updated situations' transitions first
    q_init = "constant"
    q_init_value = 0.0
    new_row_optimism = 0.5 # evolving situations: a new row's pull towards q_init_value

With an evolving interpreter (``plugins/evolving.py``, the contract in
:mod:`sitframe.situations`) the rows follow the situations:
``situations_changed`` grows a new situation's row from its neighbours'
rows (membership-weighted, pulled towards the optimistic ``q_init_value`` by
``new_row_optimism``) and combines merged rows visit-weighted
(:meth:`sitframe.learning.fuzzy_q.FuzzyQLearner.situations_changed`);
``situation_errors`` reports the last update's absolute TD errors per
situation, from which the interpreter splits situations the task finds hard.
"""

from __future__ import annotations

import dataclasses
import functools
import inspect
from collections.abc import Callable
from typing import Any, TypeVar

import numpy as np

from sitframe import (
    Context,
    FuzzyQLearner,
    LearnedPolicy,
    PolicyOutput,
    Proposal,
    QLearningParams,
    SituationEvent,
    SituationFCS,
    Transition,
    hookimpl,
)
from sitframe import params as P

OUTPUTS = ("heading", "speed")
T = TypeVar("T")


def q_learning_keys(*, leave_out: tuple[str, ...] = ("groups", "min_group_updates"),
                    **defaults: Any) -> Callable[[type[T]], type[T]]:
    """Class decorator: the component's ``__init__`` also takes the fields of
    :class:`~sitframe.QLearningParams` as keyword arguments, one config key each.

    The fields but ``leave_out`` are added, keyword-only, to the signature (so a config's
    keys are checked against them and ``sitframe plugins`` lists them), with the
    dataclass's defaults or the ones given in ``defaults``; the wrapped ``__init__``
    receives their values as one dict, its ``qparams`` argument. One list of the learning
    parameters (the dataclass) then serves every component that learns by fuzzy Q.
    """
    fields = [f for f in dataclasses.fields(QLearningParams) if f.name not in leave_out]
    names = [f.name for f in fields]
    unknown = set(defaults) - set(names)
    if unknown:
        raise TypeError(f"q_learning_keys: no such QLearningParams field: {sorted(unknown)}")

    def decorate(cls: type[T]) -> type[T]:
        init = cls.__init__
        own = [q for q in inspect.signature(init).parameters.values() if q.name != "qparams"]
        sig = inspect.Signature(own + [
            inspect.Parameter(f.name, inspect.Parameter.KEYWORD_ONLY, annotation=f.type,
                              default=defaults.get(f.name, f.default)) for f in fields])

        @functools.wraps(init)
        def __init__(self: T, *args: Any, **kwargs: Any) -> None:
            bound = sig.bind(self, *args, **kwargs)
            bound.apply_defaults()
            given = dict(bound.arguments)
            given.pop("self")
            init(self, **{k: v for k, v in given.items() if k not in names},
                 qparams={k: given[k] for k in names})

        __init__.__signature__ = sig  # type: ignore[attr-defined]
        cls.__init__ = __init__  # type: ignore[method-assign]
        return cls

    return decorate


UNITS = {"heading": "deg", "speed": "m/s"}


@q_learning_keys()
class FuzzyQBehaviour:
    """A situation FCS whose rule base is learned by fuzzy Q-learning."""

    name = "fuzzy-q"

    def __init__(
        self,
        *,
        headings: list[float] = (90, 60, 30, 0, -30, -60, -90),  # type: ignore[assignment]
        speeds: list[float] = (),  # type: ignore[assignment]
        learn: list[str] = ("heading",),  # type: ignore[assignment]
        new_row_optimism: float = 0.5,
        qparams: dict[str, Any],
    ) -> None:
        self.singletons: dict[str, np.ndarray] = {
            "heading": np.asarray(P.number_list("headings", list(headings), lo=-90, hi=90,
                                                unit="deg"))
        }
        if len(speeds):
            self.singletons["speed"] = np.asarray(P.number_list("speeds", list(speeds), lo=0.0,
                                                                unit="m/s"))
        if isinstance(learn, str):
            learn = [learn]
        self.learn_outputs = [P.choice(f"learn[{i}]", o, OUTPUTS) for i, o in enumerate(learn)]
        for o in self.learn_outputs:
            if o not in self.singletons:
                raise ValueError(f"learn names '{o}' but no '{o}s' singletons are configured")
        self.qparams = QLearningParams(**qparams)
        self.new_row_optimism = float(P.number("new_row_optimism", new_row_optimism,
                                               lo=0.0, hi=1.0))
        self.learners: dict[str, FuzzyQLearner] = {}
        self.fcs: dict[str, SituationFCS] = {}
        self.fixed: dict[str, np.ndarray] = {}
        self._iterations = 0

    # -- lifecycle -------------------------------------------------------
    def reset(self, rng: np.random.Generator, n_situations: int, iterations: int) -> None:
        self._iterations = iterations
        self.learners = {}
        self.fcs = {}
        for out, singles in self.singletons.items():
            if out in self.fixed:
                rules = self.fixed[out]
                if rules.size != n_situations:
                    raise ValueError(f"the fixed {out} rule base has {rules.size} rules but the "
                                     f"interpreter has {n_situations} situations")
                self.fcs[out] = SituationFCS(singles, rules)
            elif out in self.learn_outputs:
                lr = FuzzyQLearner(n_situations, singles.size, self.qparams, rng, iterations)
                self.learners[out] = lr
                self.fcs[out] = SituationFCS(singles, lr.rule_base)
            else:
                raise ValueError(f"output '{out}' is neither learned (learn = [...]) nor given "
                                 "by a learned policy (policy_from)")

    def load_policy(self, policy: LearnedPolicy) -> None:
        """Fix outputs to a learned policy's rule bases (outputs this behaviour lacks are ignored).

        Raises ``ValueError`` when the policy's actions for an output differ
        from this behaviour's singletons: its rule indices would then name
        other actions than the ones learned.
        """
        for out, o in policy.outputs.items():
            if out not in self.singletons:
                continue
            mine = self.singletons[out]
            if o.actions.shape != mine.shape or not np.array_equal(o.actions, mine):
                raise ValueError(f"the policy's {out} actions {o.actions.tolist()} differ from "
                                 f"this behaviour's {out}s {mine.tolist()}; configure the same "
                                 "singletons as the run that learned it")
            rules = np.asarray(o.rules, dtype=np.intp)
            self.fixed[out] = rules
            self.learners.pop(out, None)
            if out in self.fcs:
                self.fcs[out].set_rules(rules)

    # -- loop ------------------------------------------------------------
    def propose(self, context: Context) -> Proposal:
        u = context.memberships
        for lr in self.learners.values():
            lr.record_rules(context.iteration)
        heading = self.fcs["heading"].output(u)
        speed = self.fcs["speed"].output(u) if "speed" in self.fcs else None
        return Proposal(heading, speed)

    def learn(self, transition: Transition, reward: float) -> None:
        u0 = transition.before.memberships
        u1 = transition.after.memberships
        collided = transition.outcome.collided
        it = transition.before.iteration
        for out, lr in self.learners.items():
            if lr.update(u0, reward, u1, collided, it):
                self.fcs[out].set_rules(lr.rule_base)

    def _fused(self) -> dict[str, Any] | None:
        """The compiled trial's controllers and learner (``sitframe.runs.fused``): a heading
        output and optionally a speed output, each fixed or learned, at most one of them by
        a plain :class:`~sitframe.FuzzyQLearner` (its TD errors and rows of evolving
        situations too); ``None`` with two learned outputs, replay, per-group convergence
        or a subclass's own ``propose``, ``learn``, ``situation_errors`` or
        ``learning_converged``."""
        cls, me = type(self), FuzzyQBehaviour
        if cls.propose is not me.propose or cls.learn is not me.learn or \
                cls.situation_errors is not me.situation_errors or \
                cls.learning_converged is not me.learning_converged or \
                "heading" not in self.fcs or len(self.learners) > 1:
            return None
        (out, lr), = self.learners.items() if self.learners else [(None, None)]
        if lr is not None and (type(lr) is not FuzzyQLearner or lr.params.groups > 1
                               or lr.params.replay):
            return None
        return {"heading": self.fcs["heading"], "speed": self.fcs.get("speed"),
                "learner": lr, "learned": out}

    # -- evolving situations (sitframe.situations) ------------------------------
    def situations_changed(self, event: SituationEvent) -> None:
        """Grow or combine the learned rows when the interpreter's situations change."""
        for out, lr in self.learners.items():
            lr.situations_changed(event, self.new_row_optimism)
            self.fcs[out].set_rules(lr.rule_base)

    def learning_converged(self) -> bool:
        """Whether every learned output's rule base has converged (frozen for the trial;
        ``True`` when this behaviour learns nothing)."""
        return all(lr.converged_at is not None for lr in self.learners.values())

    def situation_errors(self) -> np.ndarray | None:
        """(c,) absolute TD errors of the last ``learn``, summed over the learned outputs."""
        if not self.learners:
            return None
        for lr in self.learners.values():
            lr.track_td = True  # (kept from now on: only an evolving interpreter asks)
        errs = [lr.td_abs for lr in self.learners.values()]
        return errs[0] if len(errs) == 1 else np.sum(errs, axis=0)

    # -- results ---------------------------------------------------------
    def trial_data(self) -> dict[str, Any]:
        data: dict[str, Any] = {}
        conv_its = []
        for out, lr in self.learners.items():
            d = lr.data(self._iterations)
            for k, v in d.items():
                data[f"{out}/{k}"] = v
            conv_its.append(d["convergence_iteration"])
        if conv_its:
            data["converged"] = all(c >= 0 for c in conv_its)
            data["convergence_iteration"] = max(conv_its) if data["converged"] else -1
        return data

    def policy(self) -> LearnedPolicy:
        """Each output's rule base: the greedy (or converged) one if learned, else the fixed one."""
        outs = {}
        for out, fcs in self.fcs.items():
            lr = self.learners.get(out)
            rules = lr.final_rule_base() if lr is not None else fcs.rule_actions
            outs[out] = PolicyOutput(self.singletons[out], np.asarray(rules).astype(np.int16),
                                     UNITS[out], None if lr is None else lr.q.copy())
        return LearnedPolicy(outs)


class CrispQBehaviour(FuzzyQBehaviour):
    """Crisp tabular Q-learning over the *dominant* situation: the baseline without fuzziness.

    The same learner, parameters, exploration (soft-max rule-base changes every
    ``b`` iterations) and convergence test as ``fuzzy-q``, but the memberships
    are replaced by a one-hot vector of the dominant situation (the largest
    membership, first on ties) everywhere: the robot executes the dominant
    situation's action alone (no blending of rules), and only that situation's
    rule is updated, with strength 1, towards ``r + gamma max_a Q(s', a)``
    where ``s'`` is the next dominant situation -- ordinary Q-learning on a
    discretised state. Comparing it with ``fuzzy-q`` under the same config
    answers "is the fuzzy part needed?" (docs/results/fuzzy-vs-crisp.md).
    """

    name = "crisp-q"

    def reset(self, rng: np.random.Generator, n_situations: int, iterations: int) -> None:
        super().reset(rng, n_situations, iterations)
        self._eye = np.eye(n_situations)

    def propose(self, context: Context) -> Proposal:
        return super().propose(_dominant(context, self._eye))

    def learn(self, transition: Transition, reward: float) -> None:
        before, after = _dominant(transition.before, self._eye), \
            _dominant(transition.after, self._eye)
        super().learn(Transition(before, transition.command, transition.outcome, after), reward)


def _dominant(context: Context, eye: np.ndarray) -> Context:
    """``context`` with its memberships replaced by the dominant situation's one-hot row."""
    return Context(context.iteration, context.pose, context.reading,
                   eye[int(context.memberships.argmax())], context.nearest, context.world,
                   context.goal)


@hookimpl
def sitframe_behaviours() -> list[Any]:
    return [FuzzyQBehaviour, CrispQBehaviour]
