"""An experiment plugin: a frozen fuzzy-q behaviour reading the sonar through its own situations.

Loaded with ``--plugins-dir benchmarks/plugins``; registers the behaviour
``fuzzy-q-own``. It is the wall-following preset's rule base (16 situations
in proximity space, band 0.88 in its room) put into a run whose shared
interpreter has other situations (``goal-finding-learned``'s 12 in log-range
space), to measure what a better wall follower is worth to the learned
arbitration (README, "Learned arbitration", session 15).

Parameters: ``situations_from``, a complete log (path relative to the folder
``sitframe`` runs in) whose FCM situations (config and fitted state) this
behaviour reads the readings through and whose best trial's ``follow`` rule
base it drives with, frozen; and the ``fuzzy-q`` behaviour's parameters
(its ``headings`` must be the log's).

Limits, why this is not a core feature yet: the core checks every logged
policy against the *shared* interpreter's number of situations, so this
behaviour logs no policy (``policy`` is absent) and takes its rule base from
``situations_from`` itself, in learning and in every evaluation; only the FCM
interpreter is supported; the situations log is read, not fingerprinted into
the run's inputs.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from sitframe import Context, Proposal, hookimpl
from sitframe.logs.policies import best_trial, logged_policy
from sitframe.logs.reader import open_log
from sitframe.plugins.fcm_interpreter import FCMInterpreter
from sitframe.plugins.fuzzy_q import FuzzyQBehaviour


class OwnSituationsBehaviour(FuzzyQBehaviour):
    """A frozen ``fuzzy-q`` behaviour over the situations of another log (module docstring)."""

    name = "fuzzy-q-own"

    def __init__(self, *, situations_from: str, behaviour: str = "follow", **kw: Any) -> None:
        super().__init__(**kw)
        log = open_log(situations_from)
        table = dict(log.config["interpreter"])
        if table.pop("component") != "fcm":
            raise ValueError(f"{situations_from}: only fcm situations are supported")
        self.interpreter = FCMInterpreter(**table)
        self.interpreter.load_state(log.interpreter_state())
        self.load_policy(logged_policy(log.trial(best_trial(log)), behaviour, situations_from))

    @property
    def policy(self) -> Any:  # type: ignore[override]
        """Absent (AttributeError): the core would check it against the shared c."""
        raise AttributeError("policy")

    def reset(self, rng: np.random.Generator, n_situations: int, iterations: int) -> None:
        super().reset(rng, self.interpreter.n_situations, iterations)

    def propose(self, context: Context) -> Proposal:
        u = self.interpreter.memberships(context.reading)
        return super().propose(dataclasses.replace(context, memberships=u))


@hookimpl
def sitframe_behaviours() -> list[Any]:
    return [OwnSituationsBehaviour]
