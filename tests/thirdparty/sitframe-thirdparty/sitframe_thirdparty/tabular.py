"""A tabular Q-learner over the dominant situation, and a wanderer (behaviours)."""

from typing import Any

import numpy as np

from sitframe import Context, LearnedPolicy, PolicyOutput, Proposal, Transition, hookimpl


class TabularQ:
    """Q-learning over the dominant situation; judged by the ``sprints`` protocol."""

    name = "tabular-q"
    evaluation_protocol = "sprints"

    def __init__(self, *, headings: list[float] = (45, 15, 0, -15, -45), alpha: float = 0.3,
                 gamma: float = 0.8, epsilon: float = 0.2) -> None:
        self.actions = np.asarray(headings, dtype=float)
        self.alpha, self.gamma, self.epsilon = float(alpha), float(gamma), float(epsilon)
        self.fixed: np.ndarray | None = None

    def reset(self, rng: np.random.Generator, n_situations: int, iterations: int) -> None:
        self.rng = rng
        self.q = np.zeros((n_situations, self.actions.size))
        self.tried = np.zeros_like(self.q, dtype=bool)
        self.td: list[float] = []
        self.a = 0

    def propose(self, context: Context) -> Proposal:
        s = int(context.memberships.argmax())
        if self.fixed is not None:
            self.a = int(self.fixed[s])
        elif self.rng.random() < self.epsilon:
            self.a = int(self.rng.integers(self.actions.size))
        else:
            self.a = int(self.q[s].argmax())
        return Proposal(float(self.actions[self.a]), activation=float(
            np.clip(1.0 - context.nearest / 0.8, 0.0, 1.0)))

    def learn(self, transition: Transition, reward: float) -> None:
        s = int(transition.before.memberships.argmax())
        s2 = int(transition.after.memberships.argmax())
        td = reward + self.gamma * self.q[s2].max() - self.q[s, self.a]
        self.q[s, self.a] += self.alpha * td
        self.tried[s, self.a] = True
        self.td.append(abs(td))

    def trial_data(self) -> dict[str, Any]:
        return {"explored": float(self.tried.mean()),         # a per-trial scalar
                "td_error": np.asarray(self.td, dtype=float)}  # a per-iteration series

    def policy(self) -> LearnedPolicy:
        rules = self.q.argmax(axis=1) if self.fixed is None else self.fixed
        return LearnedPolicy({"heading": PolicyOutput(self.actions, rules, "deg", self.q.copy())})

    def load_policy(self, policy: LearnedPolicy) -> None:
        self.fixed = np.asarray(policy.outputs["heading"].rules)


class Wanderer:
    """Drifts left or right, a new drift drawn from the trial's generator every 20 iterations."""

    name = "wanderer"

    def __init__(self, *, drift_deg: float = 10.0, speed: float = 0.2) -> None:
        self.drift, self.speed = float(drift_deg), float(speed)

    def reset(self, rng: np.random.Generator, n_situations: int, iterations: int) -> None:
        self.rng, self.heading = rng, 0.0

    def propose(self, context: Context) -> Proposal:
        if context.iteration % 20 == 0:
            self.heading = float(self.rng.uniform(-self.drift, self.drift))
        return Proposal(self.heading, self.speed)


@hookimpl
def sitframe_behaviours() -> list[type]:
    return [TabularQ, Wanderer]
