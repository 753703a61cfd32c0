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
    q_init = "constant"
    q_init_value = 0.0
"""

from __future__ import annotations

from typing import Any

import numpy as np

from sitframe import hookimpl
from sitframe import params as P
from sitframe.fuzzy import SituationFCS
from sitframe.learning import FuzzyQLearner, QLearningParams
from sitframe.records import Context, Proposal, Transition

OUTPUTS = ("heading", "speed")


class FuzzyQBehaviour:
    """A situation FCS whose rule base is learned by fuzzy Q-learning."""

    name = "fuzzy-q"

    def __init__(
        self,
        *,
        headings: list[float] = (90, 60, 30, 0, -30, -60, -90),  # type: ignore[assignment]
        speeds: list[float] = (),  # type: ignore[assignment]
        learn: list[str] = ("heading",),  # type: ignore[assignment]
        alpha: float = 0.3,
        gamma: float = 0.9,
        b: int = 5,
        p: int = 50,
        temperature: float = 0.25,
        temperature_mode: str = "relative",
        temperature_decay: float = 1.0,
        temperature_min: float = 0.0,
        q_init: str = "constant",
        q_init_value: float = 0.0,
        q_init_spread: float = 0.0,
        update: str = "thesis",
        activation: float = 0.3,
        terminal_on_collision: bool = False,
        min_updates: int = 0,
        tie_break: str = "first",
    ) -> None:
        self.singletons: dict[str, np.ndarray] = {
            "heading": np.asarray(P.number_list("headings", list(headings), lo=-90, hi=90))
        }
        if len(speeds):
            self.singletons["speed"] = np.asarray(P.number_list("speeds", list(speeds), lo=0.0))
        if isinstance(learn, str):
            learn = [learn]
        self.learn_outputs = [P.choice(f"learn[{i}]", o, OUTPUTS) for i, o in enumerate(learn)]
        for o in self.learn_outputs:
            if o not in self.singletons:
                raise ValueError(f"learn names '{o}' but no '{o}s' singletons are configured")
        self.qparams = QLearningParams(
            alpha=alpha, gamma=gamma, b=b, p=p, temperature=temperature,
            temperature_mode=temperature_mode, temperature_decay=temperature_decay,
            temperature_min=temperature_min, q_init=q_init, q_init_value=q_init_value,
            q_init_spread=q_init_spread, update=update, activation=activation,
            terminal_on_collision=terminal_on_collision, min_updates=min_updates,
            tie_break=tie_break,
        )
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

    def load_policy(self, policy: dict[str, np.ndarray]) -> None:
        """Fix outputs to learned rule bases: ``policy['heading']`` etc. (c,) action indices."""
        for out, rules in policy.items():
            if out not in self.singletons:
                continue
            rules = np.asarray(rules, dtype=np.intp)
            if rules.min() < 0 or rules.max() >= self.singletons[out].size:
                raise ValueError(f"policy for '{out}' indexes {rules.max() + 1} actions, "
                                 f"but {self.singletons[out].size} are configured")
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

    # -- results ---------------------------------------------------------
    def trial_data(self) -> dict[str, Any]:
        data: dict[str, Any] = {}
        conv_its = []
        for out, lr in self.learners.items():
            d = lr.data(self._iterations)
            for k, v in d.items():
                data[f"{out}/{k}"] = v
            conv_its.append(d["convergence_iteration"])
        for out, fcs in self.fcs.items():
            data[f"policy/{out}"] = (self.learners[out].final_rule_base()
                                     if out in self.learners else fcs.rule_actions).astype(np.int16)
            data[f"singletons/{out}"] = self.singletons[out]
        if conv_its:
            data["converged"] = all(c >= 0 for c in conv_its)
            data["convergence_iteration"] = max(conv_its) if data["converged"] else -1
        return data


@hookimpl
def sitframe_behaviours() -> list[Any]:
    return [FuzzyQBehaviour]
