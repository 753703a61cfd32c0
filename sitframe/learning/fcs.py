"""The situation-based fuzzy control system (thesis 4.5).

One rule per situation: ``IF situation is S_i THEN output is A_k``. The rule's
strength is the membership of the current reading to ``S_i``. Min-Max
inference gives each output label the maximum strength of the rules that
conclude it (with one antecedent per rule the "min" is the membership itself);
the crisp output is the centre of gravity over the singleton positions
(thesis Eq. 4.x, weighted mean of singletons by label strength).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sitframe.sim.kernels import kernels

# The ufuncs' own reductions (``ndarray.sum``/``max`` add a Python layer; the
# controller runs every iteration).
_sum, _max = np.add.reduce, np.maximum.reduce


def label_strengths(strengths: np.ndarray, rule_actions: np.ndarray, n_actions: int) -> np.ndarray:
    """Max-aggregate rule strengths per output label.

    Parameters
    ----------
    strengths
        (c,) rule strengths (memberships of the situations), in [0, 1].
    rule_actions
        (c,) integer action index concluded by each rule.
    n_actions
        Number of output singletons A.

    Returns
    -------
    (A,) strength of each output label: ``max_{i: rule_actions[i] = a} strengths[i]``
    (0 for a label no rule concludes).
    """
    out = np.zeros(n_actions)
    np.maximum.at(out, rule_actions, strengths)
    return out


def centre_of_gravity(label_strength: np.ndarray, singletons: np.ndarray) -> float:
    """Centre of gravity over singletons: ``sum(w_k x_k) / sum(w_k)``.

    Returns the mean of the singletons if every strength is 0 (cannot happen
    with memberships that sum to 1, but keeps the function total).
    """
    total = float(_sum(label_strength))
    if total <= 0.0:
        return float(singletons.mean())
    return float(label_strength @ singletons) / total


@dataclass
class SituationFCS:
    """A fuzzy controller with one rule per situation and singleton outputs.

    Parameters
    ----------
    singletons
        (A,) output positions (e.g. headings in degrees, or speeds in m/s).
    rule_actions
        (c,) index into ``singletons`` concluded by each situation's rule.

    Examples
    --------
    >>> fcs = SituationFCS(np.array([90., 0., -90.]), np.array([0, 1, 2]))
    >>> fcs.output(np.array([0.5, 0.5, 0.0]))
    45.0
    """

    singletons: np.ndarray
    rule_actions: np.ndarray

    def __post_init__(self) -> None:
        self.singletons = np.asarray(self.singletons, dtype=float)
        self.set_rules(self.rule_actions)

    def set_rules(self, rule_actions: np.ndarray) -> None:
        """Replace the rule base (an action index per situation)."""
        given = np.asarray(rule_actions)
        if given.dtype.kind not in "iub" and not (given.dtype.kind == "f" and
                                                 np.array_equal(given, np.floor(given))):
            raise ValueError(f"rule_actions must be whole action indices, got {given.tolist()}")
        actions = given.astype(np.intp)
        if actions.ndim != 1 or actions.size == 0:
            raise ValueError(
                f"rule_actions must be a non-empty 1-D array, got shape {actions.shape}")
        if actions.min() < 0 or actions.max() >= self.singletons.size:
            raise ValueError(
                f"rule_actions must index the {self.singletons.size} singletons, "
                f"got values in [{actions.min()}, {actions.max()}]"
            )
        self.rule_actions = actions
        # (c, A) one-hot: label strengths become one broadcast and a max.
        self._onehot = np.zeros((actions.size, self.singletons.size))
        self._onehot[np.arange(actions.size), actions] = 1.0

    def output(self, memberships: np.ndarray) -> float:
        """Crisp output for the (c,) memberships of one reading."""
        # Max over the rules of each label: label_strengths, as one broadcast.
        kern = kernels()
        if kern is None or self.singletons.size > kern.PAIRWISE_MAX:
            strength = self._onehot * memberships[:, None]
            return centre_of_gravity(_max(strength, axis=0), self.singletons)
        strength = np.empty(self.singletons.size)  # (the same arithmetic, compiled)
        total = kern.label_strengths(self._onehot, memberships, strength)
        if total <= 0.0:
            return float(self.singletons.mean())
        return float(strength @ self.singletons) / total
