"""Learning: the situation-based fuzzy control system and fuzzy Q-learning of its rule base.

What it holds
    :mod:`~sitframe.learning.fcs` (one rule per situation, Min-Max inference, centre of
    gravity: thesis 4.5), :mod:`~sitframe.learning.fuzzy_q` (fuzzy Q-learning of the rule
    base, soft-max exploration, convergence: thesis 4.6).

What it may import
    :mod:`sitframe.situations`, :mod:`sitframe.sim` (kernels) and the ground floor; never
    the plugin contract, runs, logs or analysis.

Entry points
    :class:`~sitframe.learning.fuzzy_q.FuzzyQLearner`,
    :class:`~sitframe.learning.fuzzy_q.QLearningParams`,
    :class:`~sitframe.learning.fcs.SituationFCS`. The names of the former module
    ``sitframe.learning`` are served from here.
"""

from __future__ import annotations

import importlib
from typing import Any

_FUZZY_Q = ("FuzzyQLearner", "QLearningParams", "greedy_actions", "softmax_choice")


def __getattr__(name: str) -> Any:
    if name in _FUZZY_Q:
        fuzzy_q = importlib.import_module("sitframe.learning.fuzzy_q")

        return getattr(fuzzy_q, name)
    raise AttributeError(f"module 'sitframe.learning' has no attribute {name!r}")
