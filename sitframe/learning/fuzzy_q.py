"""Fuzzy Q-learning of a situation rule base (thesis 4.6).

The learner keeps a lookup table ``Q`` of shape (c situations, A actions) and
a *current rule base*: one action per situation, executed by the fuzzy
controller. Every iteration it updates the Q-values of the current rules that
were activated, and from time to time it replaces the rule base using a
soft-max (Boltzmann) behaviour policy over each situation's Q row.

Choices where the thesis is ambiguous (all configurable):

* **Update rule** (``update``). ``"thesis"`` is Eq. 4.14,
  ``Q_i += alpha * (w_i r + gamma w_i V(s') - Q_i)``, which pulls weakly
  activated rules toward 0. ``"standard"`` is the usual fuzzy Q-learning form
  ``Q_i += alpha * w_i * (r + gamma V(s') - Q_i)``. In both,
  ``V(s') = sum_j u_j(s') max_a Q(j, a)`` (Eq. 4.15) and ``w_i`` is the rule
  strength, i.e. the membership of the reading to situation ``i``.
* **Which rules are updated** (``activation``). The thesis updates "all the
  rules which were activated". Read literally as *every* rule, Eq. 4.14 pulls
  the current action of each inactive situation toward 0 every iteration (with
  m = 1.2 most memberships are ~0), the greedy choice keeps flipping and
  learning never converges. We update only rules whose strength is at least
  ``activation`` (default 0.3); ``activation = 0`` gives the literal reading.
* **Soft-max temperature** (``temperature``, ``temperature_mode``). The Q scale
  differs between the two update rules and with the reward, so the default is
  scale-free (``"relative"``): each row's logits are
  ``(Q - max Q) / (temperature * (max Q - min Q))`` so the worst action of a
  situation is ``exp(-1/temperature)`` times as likely as the best one,
  whatever the scale. ``"absolute"`` uses ``Q / temperature`` as in the
  textbook.
* **When the rule base changes**: after a collision, or after ``b``
  collision-free iterations since the last change (thesis 4.6.3).
* **Convergence**: the greedy rule base (argmax of each row) is unchanged for
  ``p`` consecutive rule-base changes (thesis 4.6.4). After that the greedy
  rule base is frozen, learning stops and the trial goes on so that
  post-convergence collisions can be counted.
"""

from __future__ import annotations

from dataclasses import KW_ONLY, dataclass
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

from sitframe import params as P
from sitframe import scratch
from sitframe.sim.kernels import kernels

if TYPE_CHECKING:
    from sitframe.situations.events import SituationEvent


@dataclass(frozen=True)
class QLearningParams:
    """Parameters of fuzzy Q-learning; defaults are thesis Table A.1.

    Attributes
    ----------
    alpha
        Learning rate in (0, 1].
    gamma
        Discount factor in [0, 1).
    b
        Collision-free iterations between rule-base changes.
    p
        Consecutive rule-base changes with an unchanged greedy rule base that
        count as convergence.
    temperature
        Soft-max temperature (see ``temperature_mode``).
    temperature_mode
        ``"relative"`` (scale-free, default) or ``"absolute"``.
    temperature_decay, temperature_min
        Annealing: after the k-th rule-base change the temperature is
        ``max(temperature_min, temperature * temperature_decay**k)``
        (default 1.0: constant, as in the thesis).
    q_init
        ``"constant"`` (every entry ``q_init_value``) or ``"random"`` (uniform in
        ``q_init_value ± q_init_spread``).
    q_init_value, q_init_spread
        See ``q_init``.
    update
        ``"thesis"`` (Eq. 4.14, default) or ``"standard"``.
    activation
        Minimum rule strength for a rule to be updated (0 = every rule).
    terminal_on_collision
        Treat a collision as the end of an episode: its update target is the
        reward alone, without ``gamma * V(s')``. The thesis always bootstraps;
        then a collision's target (-30 + 0.9 V) differs from a safe action's
        (~+27 + 0.9 V) by less than the noise in V, and the learned rule base
        tolerates collisions.
    alpha_visits
        Learning-rate schedule per rule and action: ``alpha * k / (k + n)``
        after ``n`` updates of that rule's action, ``k = alpha_visits``
        (0 = constant ``alpha``, the thesis). A decaying rate lets Q settle
        (stochastic approximation) where a noisy reward would otherwise keep
        flipping near-equal greedy actions, so the thesis's convergence
        criterion can be met; ``k`` is roughly the number of updates after
        which the rate has halved.
    min_updates
        Convergence also requires every situation's rules to have been updated
        at least this many times (0 = the thesis's criterion alone). A greedy
        rule base can stay unchanged for ``p`` changes simply because a rare
        situation was never experienced; this guards against freezing it.
        A situation the training world never produces then prevents
        convergence, so keep it small.
    tie_break
        Which of several actions with equal greatest Q the greedy rule base
        takes: ``"first"`` (the first in the action list, numpy's argmax; the
        default) or ``"centre"`` (the one nearest the middle of the list, e.g.
        0 deg in a symmetric heading set). Exact ties arise in situations
        whose rules were never updated (all still at ``q_init_value``); with
        ``"first"`` such a situation gets the first heading (+90 deg).
    replay
        Stored transitions learnt from again after each learning iteration
        (0 = none, the thesis). Every learning iteration's active rules (their
        strengths and executed actions), reward, next memberships and collision
        flag are kept for the trial; after the iteration's own update ``replay``
        of them are drawn by the trial's generator and each is learnt from with
        the current Q (target ``r + gamma V(s')``; off-policy as any Q-learning
        update: each rule learns about the action it executed then). No
        environment step is added; rows an evolving interpreter removed are
        skipped. Replayed updates count in ``updates`` (and so in
        ``min_updates``); the log's ``replayed`` says how many there were.
    replay_priority
        How replayed transitions are drawn: ``"uniform"``, or ``"rare"`` (the
        default): with probability proportional to ``1 / (1 + n)``, ``n`` the
        updates so far of the transition's strongest rule, so that situations met
        a few times (a dead end, a tight corner) are learnt from about as often as
        common ones instead of staying near their initial Q.
    """

    alpha: float = 0.3
    gamma: float = 0.9
    b: int = 5
    p: int = 50
    _: KW_ONLY  # alpha, gamma, b, p (the thesis' symbols) may come in order; the rest by name
    temperature: float = 0.25
    temperature_mode: Literal["relative", "absolute"] = "relative"
    temperature_decay: float = 1.0
    temperature_min: float = 0.0
    q_init: Literal["constant", "random"] = "constant"
    q_init_value: float = 0.0
    q_init_spread: float = 0.0
    update: Literal["thesis", "standard"] = "thesis"
    activation: float = 0.3
    terminal_on_collision: bool = False
    min_updates: int = 0
    tie_break: Literal["first", "centre"] = "first"
    alpha_visits: float = 0.0
    groups: int = 1
    min_group_updates: int = 0
    replay: int = 0
    replay_priority: Literal["rare", "uniform"] = "rare"

    def __post_init__(self) -> None:
        P.number("alpha", self.alpha, lo=0.0, hi=1.0, lo_open=True)
        P.number("gamma", self.gamma, lo=0.0, hi=1.0, hi_open=True)
        P.number("b", self.b, lo=1, integer=True)
        P.number("p", self.p, lo=1, integer=True)
        P.number("temperature", self.temperature, lo=0.0, lo_open=True)
        P.choice_field(self, "temperature_mode")
        P.number("temperature_decay", self.temperature_decay, lo=0.0, hi=1.0, lo_open=True)
        P.number("temperature_min", self.temperature_min, lo=0.0)
        P.choice_field(self, "q_init")
        P.number("q_init_value", self.q_init_value)
        P.number("q_init_spread", self.q_init_spread, lo=0.0)
        P.choice_field(self, "update")
        P.number("activation", self.activation, lo=0.0, hi=1.0)
        P.boolean("terminal_on_collision", self.terminal_on_collision)
        P.number("min_updates", self.min_updates, lo=0, integer=True)
        P.choice_field(self, "tie_break")
        P.number("alpha_visits", self.alpha_visits, lo=0.0)
        P.number("groups", self.groups, lo=1, integer=True)
        P.number("min_group_updates", self.min_group_updates, lo=0, integer=True)
        P.number("replay", self.replay, lo=0, integer=True)
        P.choice_field(self, "replay_priority")


def greedy_actions(q: np.ndarray, tie_break: str = "first") -> np.ndarray:
    """(c,) index of the greatest Q in each row of ``q`` (c, A), ties broken by ``tie_break``.

    ``"first"``: the lowest index (``q.argmax(axis=1)``). ``"centre"``: among
    the tied actions the one nearest ``(A - 1) / 2``, then the lower index.
    """
    if tie_break == "first":
        return q.argmax(axis=1)
    a = q.shape[1]
    closeness = -np.abs(np.arange(a) - (a - 1) / 2.0)
    score = np.where(q == q.max(axis=1, keepdims=True), closeness, -np.inf)
    return score.argmax(axis=1)


def softmax_choice(
    q: np.ndarray,
    params: QLearningParams,
    rng: np.random.Generator,
    temperature: float | None = None,
) -> np.ndarray:
    """Draw one action per row of ``q`` (c, A) with the soft-max policy.

    ``temperature`` overrides ``params.temperature`` (annealing). Returns (c,)
    action indices. Uses one uniform draw per row (inverse CDF), so the random
    stream consumed is always ``c`` numbers.
    """
    tau = params.temperature if temperature is None else temperature
    # A tiny temperature makes the logits of all but the best actions overflow to -inf
    # (exp: 0, the greedy limit, exactly); an infinite Q (a reward that overflowed it)
    # makes NaN, which the contract reports at the trial's end ('expected finite values').
    # Neither is a Python warning on the user's terminal.
    with np.errstate(over="ignore", divide="ignore", invalid="ignore", under="ignore"):
        if params.temperature_mode == "relative":
            top = q.max(axis=1, keepdims=True)
            spread = top - q.min(axis=1, keepdims=True)
            logits = (q - top) / (tau * np.where(spread > 0, spread, 1.0))
        else:
            logits = (q - q.max(axis=1, keepdims=True)) / tau
        w = np.exp(logits)
    cdf = np.cumsum(w, axis=1)
    draws = rng.random(q.shape[0]) * cdf[:, -1]
    return np.minimum((cdf < draws[:, None]).sum(axis=1), q.shape[1] - 1)


class RowStack:
    """Equal-shaped rows kept one after the other in one buffer: what ``numpy.stack`` of a list
    of them gives, without the list or the stacking copy.

    A learner's snapshots (one per rule-base change, a Q table each) are the largest part of
    a long trial's data; a list of them stacked at the end held them twice. The buffer grows
    by reallocation, which for a large buffer moves pages rather than copies them, and
    :meth:`array` hands out the rows written as a view of it. After that a row appended
    grows a new buffer instead (the view stays valid).

    Parameters
    ----------
    first
        The first row; its shape is every row's.
    dtype
        The rows' type (default ``first``'s); a row is cast to it as ``astype`` casts.
    file
        Keep the buffer in a scratch file once it outgrows :data:`sitframe.scratch.BLOCK`
        bytes (a long trial's, :mod:`sitframe.scratch`).
    """

    def __init__(self, first: np.ndarray, dtype: Any = None, *, file: bool = False) -> None:
        first = np.asarray(first)
        self._file = file
        self._buf = np.empty((16, *first.shape), dtype=dtype or first.dtype)
        self._n = 0
        self._shared = False  # (a view of the buffer is out: never resize it in place)
        self.append(first)

    def __len__(self) -> int:
        return self._n

    def append(self, row: np.ndarray) -> None:
        """Add one row (copied)."""
        self._room(1)
        self._buf[self._n] = row
        self._n += 1

    def extend(self, rows: np.ndarray) -> None:
        """Add the rows of ``rows`` (k, *shape) (copied)."""
        k = len(rows)
        self._room(k)
        self._buf[self._n:self._n + k] = rows
        self._n += k

    def array(self) -> np.ndarray:
        """The rows so far, (n, *shape): a view of the buffer, not a copy."""
        self._shared = True
        return self._buf[:self._n]

    def _room(self, k: int) -> None:
        cap = len(self._buf)
        if self._n + k <= cap:
            return
        shape = (max(2 * cap, self._n + k), *self._buf.shape[1:])
        big = self._file and shape[0] * self._buf[:1].nbytes >= scratch.BLOCK  # (or memory)
        if not (self._shared or big or scratch.in_file(self._buf)):
            self._buf.resize(shape, refcheck=False)
            return
        grown = scratch.empty(shape, self._buf.dtype, file=big)
        scratch.copy_rows(grown, self._buf[:self._n])
        self._buf, self._shared = grown, False


class FuzzyQLearner:
    """Learns one consequent (e.g. heading) of a situation rule base.

    Parameters
    ----------
    n_situations, n_actions
        Shape of the lookup table.
    params
        :class:`QLearningParams`.
    rng
        The trial's generator: Q initialisation and every soft-max draw.
    max_iterations
        Upper bound on iterations (sizes the per-iteration records).

    Attributes
    ----------
    q : (c, A) lookup table.
    rule_base : (c,) action index per situation, currently executed.
    converged_at : iteration at which convergence was declared, or None.
    """

    def __init__(
        self,
        n_situations: int,
        n_actions: int,
        params: QLearningParams,
        rng: np.random.Generator,
        max_iterations: int,
    ) -> None:
        self.params = params
        self.rng = rng
        c, a = n_situations, n_actions
        if params.q_init == "random":
            self.q = params.q_init_value + rng.uniform(-1.0, 1.0, (c, a)) * params.q_init_spread
        else:
            self.q = np.full((c, a), float(params.q_init_value))
        self.rule_base = rng.integers(0, a, size=c)  # thesis Alg. 3 step 5: random rules
        self.greedy = greedy_actions(self.q, params.tie_break)
        self.converged_at: int | None = None
        self.stable_changes = 0
        self.since_change = 0
        self.n_changes = 0
        self.updates = np.zeros(c, dtype=np.int64)
        self._visits: dict[tuple[int, int], int] = {}  # (rule, action) -> updates (alpha_visits)
        #: (c,) absolute TD error of each rule updated by the last :meth:`update` (0 elsewhere),
        #: kept only once ``track_td`` is set (an evolving interpreter asks for them).
        self.td_abs = np.zeros(c)
        self.track_td = False
        self._vmax: np.ndarray | None = None
        #: Rows merged away or pruned by :meth:`situations_changed` (left out of ``min_updates``).
        self.removed = np.zeros(c, dtype=bool)
        # Records: one row per rule-base change (snapshots) and per iteration.
        self._snap_iter: list[int] = [0]
        long = scratch.wanted(max_iterations)
        self._snap_rules = RowStack(self.rule_base, np.int16, file=long)
        self._snap_greedy = RowStack(self.greedy, np.int16, file=long)
        self._snap_q = RowStack(self.q, file=long)
        self.rules_per_iteration = scratch.empty((max_iterations, c), np.int8, fill=0)
        g = int(params.groups)
        if g > 1 and c % g:
            raise ValueError(f"{c} rules do not fall into {g} equal groups")
        #: per group: consecutive stable rule-base changes, and the iteration it converged
        #: (-1: not yet); only with ``groups > 1``
        self.group_stable = np.zeros(g, dtype=np.int64)
        self.group_converged_at = np.full(g, -1, dtype=np.int64)
        #: stored transitions for ``replay``: (active rules, strengths, actions, reward,
        #: next memberships, collided), and each one's strongest rule
        self._buffer: list[tuple[list[int], list[float], list[int], float, np.ndarray,
                                 bool]] = []
        self._buffer_key = np.zeros(0, dtype=np.int64)  # (grown by doubling; first len(_buffer))
        #: replayed updates so far (the log's ``replayed``)
        self.replayed = 0

    @property
    def temperature(self) -> float:
        """The soft-max temperature for the next rule-base change (after annealing)."""
        prm = self.params
        if prm.temperature_decay == 1.0:
            return prm.temperature
        return max(prm.temperature_min, prm.temperature * prm.temperature_decay ** self.n_changes)

    def record_rules(self, iteration: int) -> None:
        """Remember the rule base executed at ``iteration``."""
        self.rules_per_iteration[iteration] = self.rule_base

    def update(
        self,
        u_before: np.ndarray,
        reward: float,
        u_after: np.ndarray,
        collided: bool,
        iteration: int,
    ) -> bool:
        """Learn from one iteration, then change the rule base if it is time.

        Parameters
        ----------
        u_before
            (c,) memberships of the reading the rule base acted on (rule strengths).
        reward
            The reward for the iteration.
        u_after
            (c,) memberships of the next reading (for V(s'), Eq. 4.15).
        collided
            Whether the iteration ended in a collision (triggers a change).
        iteration
            0-based iteration (for the records).

        Returns
        -------
        bool
            Whether the rule base was changed (so a controller must reload it).
        """
        if self.converged_at is not None:
            if self.track_td:
                self._monitor(u_before, reward, u_after, collided)
            return False
        self._vmax = None  # (q changes below)
        prm = self.params
        # Scalar Python: usually one or two rules are active, and a handful of numpy
        # calls on such tiny arrays would cost more than the arithmetic. The operations
        # (and their order) are those of the array expressions they replaced.
        u0 = u_before.tolist()
        act = prm.activation
        active = [i for i, w in enumerate(u0) if w >= act] if act > 0 else range(len(u0))
        if self.track_td:
            self.td_abs[:] = 0.0
        if active:
            rules = self.rule_base.tolist()
            weights, actions = [u0[i] for i in active], [rules[i] for i in active]
            self._learn_one(list(active), weights, actions, reward, u_after, collided,
                            self.track_td)
            if prm.replay:
                self._buffer.append((list(active), weights, actions, reward, u_after.copy(),
                                     collided))
                n = len(self._buffer)
                if n > self._buffer_key.size:
                    self._buffer_key = np.resize(self._buffer_key, 2 * n)
                self._buffer_key[n - 1] = active[int(np.argmax(weights))]
                self._replay()
        self.since_change += 1
        if collided or self.since_change >= prm.b:
            self._change(iteration)
            return True
        return False

    def _learn_one(self, active: list[int], weights: list[float], actions: list[int],
                   reward: float, u_after: np.ndarray, collided: bool, track: bool) -> None:
        """One fuzzy-Q update of rules ``active`` (strengths ``weights``, executed
        ``actions``) from a transition with ``reward`` and next memberships ``u_after``."""
        prm, q = self.params, self.q
        v_next = 0.0 if (collided and prm.terminal_on_collision) else \
            float(u_after @ np.maximum.reduce(q, axis=1))
        alpha, gamma, thesis = prm.alpha, prm.gamma, prm.update == "thesis"
        target = reward + gamma * v_next
        kappa = prm.alpha_visits
        for i, w, a in zip(active, weights, actions, strict=True):
            cur = q.item(i, a)
            if kappa:
                n = self._visits.get((i, a), 0)
                self._visits[i, a] = n + 1
                alpha = prm.alpha * kappa / (kappa + n)
            delta = (w * reward + gamma * w * v_next - cur) if thesis else target - cur
            q[i, a] = cur + alpha * delta if thesis else cur + alpha * w * delta
            self.updates[i] += 1
            if track:
                self.td_abs[i] = abs(delta)

    def _replay(self) -> None:
        """Learn again from ``params.replay`` stored transitions (see :class:`QLearningParams`)."""
        keys = self._buffer_key[:len(self._buffer)]
        if self.params.replay_priority == "rare":
            w = 1.0 / (1.0 + self.updates[keys])
        else:
            w = np.ones(keys.size)
        cdf = np.cumsum(w)
        picks = np.searchsorted(cdf, self.rng.random(self.params.replay) * cdf[-1], side="right")
        for t in np.minimum(picks, keys.size - 1).tolist():
            active, weights, actions, reward, u_after, collided = self._buffer[t]
            if self.removed[active].any():
                continue  # (a row an evolving interpreter merged away or pruned)
            self._learn_one(active, weights, actions, reward, u_after, collided, False)
            self.replayed += 1

    def _monitor(self, u_before: np.ndarray, reward: float, u_after: np.ndarray,
                 collided: bool) -> None:
        """After convergence: the TD errors the frozen rules would get (``td_abs``), no update.

        Learning has stopped, but an evolving interpreter still needs to know
        where the frozen rule base fits the task badly (it may split there).
        """
        prm = self.params
        if self._vmax is None:  # (the frozen rules' max Q per row; reset when rows change)
            self._vmax = np.maximum.reduce(self.q, axis=1)
        v_next = 0.0 if (collided and prm.terminal_on_collision) else float(u_after @ self._vmax)
        act = prm.activation if prm.activation > 0 else -np.inf  # (0: every rule)
        thesis, td = prm.update == "thesis", self.td_abs
        kern = kernels()
        if kern is not None:  # (same arithmetic, compiled)
            kern.frozen_td(u_before, act, thesis, float(reward), prm.gamma, v_next, self.q,
                           self.rule_base, td)
            return
        td.fill(0.0)
        q, rules, gamma = self.q, self.rule_base, prm.gamma
        for i in (u_before >= act).nonzero()[0].tolist():
            w = u_before.item(i) if thesis else 1.0
            td[i] = abs(w * reward + gamma * w * v_next - q.item(i, rules.item(i)))

    def _groups_converged(self, greedy: np.ndarray, iteration: int) -> bool:
        """Per-group convergence (``groups > 1``): update each group's stability and its
        convergence iteration; whether every group that counts has converged."""
        prm = self.params
        g = prm.groups
        same = (greedy == self.greedy).reshape(g, -1).all(axis=1)
        self.group_stable = np.where(same, self.group_stable + 1, 0)
        upd = self.updates.reshape(g, -1).sum(axis=1)
        ok = (self.group_stable >= prm.p) & (upd >= prm.min_group_updates)
        self.group_converged_at = np.where(ok & (self.group_converged_at < 0), iteration + 1,
                                           np.where(ok, self.group_converged_at, -1))
        return bool((ok | (upd == 0)).all())

    def group_data(self) -> dict[str, np.ndarray]:
        """Per group: its updates and the iteration it converged (-1: not), for the log."""
        g = self.params.groups
        return {"group_updates": self.updates.reshape(g, -1).sum(axis=1),
                "group_converged_at": self.group_converged_at.copy()}

    def _change(self, iteration: int) -> None:
        self.since_change = 0
        greedy = greedy_actions(self.q, self.params.tie_break)
        grouped = self.params.groups > 1 and self._groups_converged(greedy, iteration)
        if np.array_equal(greedy, self.greedy):
            self.stable_changes += 1
        else:
            self.stable_changes = 0
            self.greedy = greedy
        self.n_changes += 1
        if (grouped if self.params.groups > 1 else self.stable_changes >= self.params.p) and (
                self.params.min_updates == 0 or self._min_updates() >= self.params.min_updates):
            self.converged_at = iteration + 1
            self.rule_base = greedy.copy()
        else:
            self.rule_base = softmax_choice(self.q, self.params, self.rng, self.temperature)
        self._snap_iter.append(iteration + 1)
        self._snap_rules.append(self.rule_base)
        self._snap_greedy.append(greedy)
        self._snap_q.append(self.q)

    def _min_updates(self) -> int:
        """Fewest updates of a situation that counts (with evolving situations: rows that were
        updated at least once and not removed; ids not yet created are not situations)."""
        if not self.removed.any() and not self._evolving:
            return int(self.updates.min())
        live = self.updates[~self.removed & (self.updates > 0)]
        return int(live.min()) if live.size else 0

    _evolving = False

    def situations_changed(self, event: SituationEvent, optimism: float = 0.5) -> None:
        """Follow an evolving interpreter's change of situations (:mod:`sitframe.situations`).

        * ``create``/``split``: the new row is its parents' rows weighted by the
          event's weights (their FCM memberships at the new prototype: what the
          blended controller did there), pulled towards the optimistic initial
          value, ``(1 - optimism) * sum_j w_j Q_j + optimism * q_init_value``,
          so the neighbours' ranking of actions is kept but the gaps shrink and
          the soft-max tries the others. Its greedy action is learned anew:
          convergence is re-opened (the rule base of a new situation was never
          learned). Without parents the row is ``q_init_value``.
        * ``merge``: the survivor's row is the visit-weighted mean (``updates``)
          of the merged rows; the absorbed rows are reset and marked removed.
        * ``prune``: the row is reset and marked removed.
        """
        self._evolving = True
        self._vmax = None
        q0 = float(self.params.q_init_value)
        i = int(event.id)
        touched = {i, *(int(j) for j in event.parents)}  # (their learning rates start anew)
        self._visits = {k: n for k, n in self._visits.items() if k[0] not in touched}
        if event.kind in ("create", "split"):
            if event.parents:
                prior = np.asarray(event.weights) @ self.q[list(event.parents)]
                self.q[i] = (1.0 - optimism) * prior + optimism * q0
            else:
                self.q[i] = q0
            self.updates[i] = 0
            self.removed[i] = False
            if self.converged_at is not None:
                self.converged_at = None
                self.stable_changes = 0
            return
        if event.kind == "merge":
            rows = [int(j) for j in event.parents]
            visits = self.updates[rows].astype(float) + 1.0
            self.q[i] = (visits / visits.sum()) @ self.q[rows]
            self.updates[i] = int(self.updates[rows].sum())
        for j in event.removed:
            self.q[j] = q0
            self.updates[j] = 0
            self.removed[j] = True
        self.greedy = greedy_actions(self.q, self.params.tie_break)
        if self.converged_at is not None:
            self.rule_base = self.greedy.copy()

    def final_rule_base(self) -> np.ndarray:
        """The greedy rule base (the converged one if learning converged)."""
        return (greedy_actions(self.q, self.params.tie_break) if self.converged_at is None
                else self.rule_base.copy())

    def data(self, iterations: int) -> dict[str, np.ndarray | int | bool]:
        """Arrays to log: snapshots at each rule-base change and per-iteration rules."""
        return {
            "q": self.q.copy(),
            "q_snapshots": self._snap_q.array(),
            "snapshot_iteration": np.asarray(self._snap_iter, dtype=np.int64),
            "snapshot_rule_base": self._snap_rules.array(),
            "snapshot_greedy": self._snap_greedy.array(),
            "rule_base": scratch.copy(self.rules_per_iteration[:iterations]),
            "final_rule_base": self.final_rule_base().astype(np.int16),
            "updates": self.updates.copy(),
            **({"replayed": self.replayed} if self.params.replay else {}),
            "converged": self.converged_at is not None,
            "convergence_iteration": -1 if self.converged_at is None else int(self.converged_at),
        }
