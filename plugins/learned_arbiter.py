"""Learned arbitration (thesis 7, third future-work item): *how* to blend, by fuzzy Q-learning.

``fuzzy-q-arbiter``
    An arbiter whose rule base maps a *state* to a *behaviour weighting*
    and is learned online by fuzzy Q-learning (:class:`sitframe.FuzzyQLearner`)
    from a goal-reaching reward while the behaviours themselves stay frozen
    (``policy_from`` their own logs): the hierarchy the thesis proposes,
    first the low-level behaviours, then their arbitration.
``goal-progress``
    The goal-reaching reward it learns from.

**State.** The run's fuzzy situations (memberships ``u``, (c,)) times a crisp
*goal context*: the sector of the goal's bearing relative to the robot
(``sectors`` equal sectors, the first centred straight ahead, then
counter-clockwise: with 4, ``ahead``, ``left``, ``behind``, ``right``) and,
with ``stall_iterations > 0``, whether the robot is *stalled*: it has not
come closer to the goal than ever before in this episode (by ``stall_margin``)
for ``stall_iterations`` iterations; it stays stalled until it does. The
stall flag is the arbiter's only memory (a purely reactive arbiter cannot
tell "walking into a U-trap" from "walking around it"; the flag is Bug2's
leave condition). The fuzzy state has ``c x n_contexts`` rules: rule
``(context, i)`` fires with strength ``u_i`` in the current context, 0 in
the others.

**Actions** (``actions``). A discrete set of weightings: tables ``{label =
weight}`` over the behaviour labels, normalised to sum 1. Default: each
behaviour alone and each pair at 1/2 each (for avoid, goal, follow: 6
actions). The fused command is that of CDB, with weights ``w = sum_i u_i
W[a_i]`` where ``a_i`` is the action of situation ``i``'s rule in the current
context: ``heading = sum_k w_k heading_k``, speed the same average over the
behaviours that propose one.

**Safety hand-over** (``safety = [near, far]`` [m], ``safety_behaviour``,
default the first behaviour; off by default). Close to an obstacle one
behaviour takes over as in CDB: with ``h`` = 1 below ``near``, 0 beyond
``far``, linear between (on the nearest range), the weights are ``h e_s +
(1 - h) w`` (``e_s`` the safety behaviour alone, ``w`` the learned
weighting), and each rule learns with its strength scaled by ``1 - h``: the
arbiter is credited only for what it decided. The arbitration learned is
then *where the robot is free to choose*: which behaviour leads, when to
follow a wall.

**Learning.** :class:`sitframe.QLearningParams` (same keys and meaning as
``fuzzy-q``; defaults here: ``update = "standard"``, ``terminal_on_collision
= true``, relative temperature 0.25, ``b = 5``, ``p = 50``). Convergence is the
learner's: the greedy rule base unchanged for ``p`` rule-base changes
(``convergence = "rule base"``, the default). With ``convergence = "every
context"`` learning goes on until *every context* converged: each goal
context's rules unchanged for ``p`` rule-base changes and, once the context
was visited at all, updated ``min_context_updates`` times in all (a context
the training never produced does not hold learning back). A context visited
rarely (being stalled with the goal behind, say) then keeps the trial
learning until it has been trained, instead of being frozen untried when the
common contexts settle (the stall of the one-space arbitration, README).

**Per-context counts** (trial data, every trial): ``arbitration/contexts``
(names), ``arbitration/context_visits`` (learning iterations spent in each
context), ``arbitration/context_updates`` (rule updates in each) and
``arbitration/context_converged_at`` (the iteration each context converged,
-1 never; judged per context whatever ``convergence`` is), read by the report.

**Situations.** The arbiter reads the situations of its own space when its
table names one (``space = "NAME"``, a ``[spaces.NAME]`` table: e.g. a
handful of situations fitted on readings of its own learning room), else the
run's ``[interpreter]``; ``c`` below is that space's number.

**Policy.** Logged as one output per goal context (``ahead``, ``left``, ...,
``ahead_stalled``, ...), each (c,) rules over the action indices with their
Q (c, A); the weightings themselves are in the trial data
(``action_weights``, (A, k)). ``load_policy`` freezes the arbitration.

**Reward** (``goal-progress``), on each transition, with ``d`` the distance
[m] from the robot's centre to the goal and ``d_best`` the smallest ``d`` so
far in the episode:

1. collision: ``collision`` (-50);
2. the goal reached (``d <= radius``): ``goal`` (+50);
3. otherwise ``progress * max(0, d_best - d) + time``: +``progress``
   (100) per metre of *new* approach to the goal, and ``time`` (-1) each
   iteration. Moving away costs only time, so a detour around a trap is
   not punished beyond its length, and dithering earns nothing. With
   ``signed = true`` the progress term is ``progress * (d_before - d)``
   instead (potential-based shaping: every step says whether it went
   towards the goal or away, at the price of punishing the first half of a
   detour);
4. minus ``near_cost * max(0, near - nearest range)`` (both 0 by default):
   a cost of passing close to obstacles.

A new episode (the goal moved) starts a new ``d_best``.

``distance`` says what ``d`` is. ``"straight"`` (default): the straight
line, which a wall between the robot and the goal does not lengthen, so at
the floor of a U pocket with the goal behind it the robot is as close as it
can get, and every step out of the pocket is charged as a step away.
``"path"``: the length of the shortest path the robot's disc could drive to
the goal (:class:`sitframe.PathDistance`, around walls and through doors; the
reward PointNav agents are trained with, Savva et al. 2019, *Habitat*), so
leaving a pocket or heading for a door is progress. The reward is the
simulator's, used only while learning: the map never reaches the arbiter,
whose state (and stall flag) still measures the straight line, as a robot
with odometry and a goal position can. Where the path is undefined (the
disc touching a wall) the last defined distance stands in; a goal no path
of the disc reaches (e.g. a world's ``[goal]`` too close to a wall) is an
error, not a reward that never pays.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from itertools import combinations
from typing import Any

import numpy as np

from sitframe import (
    Context,
    FuzzyQLearner,
    InputError,
    LearnedPolicy,
    PathDistance,
    PolicyOutput,
    Proposal,
    QLearningParams,
    RobotParams,
    RunContext,
    Transition,
    hookimpl,
)
from sitframe import params as P

from .arbiters import _label_index
from .fuzzy_q import q_learning_keys

#: What the reward's ``d`` measures (module docstring).
DISTANCES = ("straight", "path")
#: When learning stops (module docstring, "Learning").
CONVERGENCE = ("rule base", "every context")
#: Names of the goal-bearing sectors for 4 and 8 sectors (others: ``s0``, ``s1``, ...).
SECTOR_NAMES = {1: ("any",), 2: ("ahead", "behind"), 4: ("ahead", "left", "behind", "right"),
                8: ("ahead", "ahead_left", "left", "behind_left", "behind", "behind_right",
                    "right", "ahead_right")}


def _goal_distance(ctx: Context) -> float:
    if ctx.goal is None:
        raise InputError(f"learned arbitration needs a goal, but world '{ctx.world.name}' has "
                         "no [goal] and the run gives none (use goal episodes)",
                         file=ctx.world.source, key="goal")
    g = ctx.goal.position
    return math.hypot(g[0] - ctx.pose[0], g[1] - ctx.pose[1])


def goal_sector(ctx: Context, sectors: int) -> int:
    """Index of the goal bearing's sector: 0 centred straight ahead, counter-clockwise."""
    assert ctx.goal is not None
    g = ctx.goal.position
    bearing = math.atan2(g[1] - ctx.pose[1], g[0] - ctx.pose[0]) - ctx.pose[2]
    width = 2 * math.pi / sectors
    return int(((bearing + width / 2) % (2 * math.pi)) // width) % sectors


class _Progress:
    """The episode's best distance to the goal and when it last improved."""

    def __init__(self, margin: float,
                 distance: Callable[[Context], float] = _goal_distance) -> None:
        self.margin, self.distance = margin, distance
        self.goal: tuple[float, float] | None = None
        self.best = math.inf
        self.since = 0

    def observe(self, ctx: Context) -> float:
        """Update with ``ctx``; return the best distance *before* it."""
        assert ctx.goal is not None
        key = (float(ctx.goal.position[0]), float(ctx.goal.position[1]))
        d = self.distance(ctx)
        if key != self.goal or ctx.iteration == 0:
            self.goal, self.best, self.since = key, d, 0
            return d
        best = self.best
        if d < best - self.margin:
            self.best, self.since = d, 0
        else:
            self.since += 1
        return best


class GoalProgressReward:
    """Goal-reaching reward: new approach to the goal, a cost per iteration, collision, goal.

    See the module docstring. Parameters in ``[arbiter] reward_params``.
    """

    name = "goal-progress"

    def __init__(self, *, progress: float = 100.0, time: float = -1.0,
                 collision: float = -50.0, goal: float = 50.0, near: float = 0.0,
                 near_cost: float = 0.0, signed: bool = False,
                 distance: str = "straight") -> None:
        self.progress = P.number("progress", progress, lo=0.0)
        self.signed = P.boolean("signed", signed)
        self.near = P.number("near", near, lo=0.0)
        self.near_cost = P.number("near_cost", near_cost, lo=0.0)
        self.time = P.number("time", time)
        self.collision = P.number("collision", collision)
        self.goal = P.number("goal", goal)
        self.distance = P.choice("distance", distance, DISTANCES)
        self._radius = RobotParams().radius  # (bind gives the run's)
        self._field: PathDistance | None = None
        self._key: tuple[float, ...] = ()  # goal and pose of the last path distance
        self._last = math.inf
        self._track = self._new_track()

    def _new_track(self) -> _Progress:
        return _Progress(0.0, _goal_distance if self.distance == "straight" else self._path)

    def bind(self, run: RunContext) -> None:
        self._radius = float(run.robot.radius)

    def trial_start(self, trial: Any) -> None:
        self._field, self._key, self._last = None, (), math.inf
        self._track = self._new_track()

    def _path(self, ctx: Context) -> float:
        """Shortest-path distance [m] to the goal (the last defined one where it is not)."""
        assert ctx.goal is not None
        goal = (float(ctx.goal.position[0]), float(ctx.goal.position[1]))
        key = (*goal, float(ctx.pose[0]), float(ctx.pose[1]))
        if key == self._key:
            return self._last
        f = self._field
        if f is None or f.world is not ctx.world or tuple(f.goal) != goal:
            f = self._field = PathDistance(ctx.world, np.asarray(goal), self._radius)
            self._last = math.inf
        d = f(ctx.pose[:2])
        if not math.isfinite(d):
            if not np.isfinite(f.to_goal).any():  # no progress could ever be measured
                raise InputError(
                    f"reward_params.distance = \"path\": no free path of the robot's disc "
                    f"(radius {self._radius:g} m) leads to the goal at ({goal[0]:g}, {goal[1]:g}) "
                    f"in world '{ctx.world.name}'; expected a goal the robot can reach, or "
                    "distance = \"straight\"", file=ctx.world.source, key="goal")
            d = self._last if math.isfinite(self._last) else _goal_distance(ctx)
        self._key, self._last = key, d
        return d

    def __call__(self, tr: Transition) -> float:
        d0 = self._track.distance(tr.before)  # (first: _path keeps the last pose's answer)
        if self._track.goal is None or tr.before.iteration == 0:
            self._track.observe(tr.before)
        if tr.outcome.collided:
            self._track.observe(tr.after)
            return self.collision
        best = self._track.observe(tr.after)
        assert tr.after.goal is not None
        if _goal_distance(tr.after) <= tr.after.goal.radius:
            return self.goal
        close = self.near_cost * max(0.0, self.near - tr.after.nearest)
        d = self._track.distance(tr.after)
        gain = d0 - d if self.signed else max(0.0, best - d)
        return self.progress * gain + self.time - close


def _near_far(name: str, value: Sequence[float], off: str) -> tuple[float, ...]:
    """A ``[near, far]`` range [m] with near < far, or ``()`` for ``[]`` (``off``)."""
    v = P.number_list(name, list(value), lo=0.0) if len(value) else []
    if v and (len(v) != 2 or v[0] >= v[1]):
        raise InputError(f"expected [near, far] with near < far [m], or [] ({off}), got {v}",
                         key=name)
    return tuple(v)


def _closeness(nearest: float, near_far: tuple[float, ...]) -> float:
    """1 below ``near_far[0]``, 0 beyond ``near_far[1]``, linear between (nearest range [m])."""
    a, b = near_far
    return min(1.0, max(0.0, (b - nearest) / (b - a)))


def default_actions(labels: Sequence[str]) -> list[dict[str, float]]:
    """Each behaviour alone, then each pair at 1/2 each."""
    acts = [{lb: 1.0} for lb in labels]
    acts += [{a: 0.5, b: 0.5} for a, b in combinations(labels, 2)]
    return acts


@q_learning_keys(leave_out=("q_init", "q_init_spread", "tie_break", "groups",
                            "min_group_updates", "replay", "replay_priority"),
                 update="standard", terminal_on_collision=True)
class FuzzyQArbiter:
    """Learned arbitration: fuzzy Q-learning of a behaviour weighting per situation x context.

    Parameters
    ----------
    actions
        List of weightings ``{label = weight}`` (weights >= 0, not all 0);
        default :func:`default_actions`.
    sectors
        Number of goal-bearing sectors (1, 2, 4 or 8).
    stall_iterations
        Iterations without a new closest approach to the goal after which the
        robot counts as stalled (0: no stall context).
    stall_margin
        How much closer [m] than the best so far counts as a new approach.
    proximity
        ``[near, far]`` [m]: split every goal context into ``close`` and
        ``far`` by the nearest range (doubles the rules); ``[]`` off.
    safety, safety_behaviour
        The safety hand-over (module docstring); ``[]`` off.
    convergence, min_context_updates
        ``"rule base"`` or ``"every context"`` (module docstring).
    alpha, gamma, b, p, temperature, alpha_visits, ...
        :class:`sitframe.QLearningParams`.
    """

    name = "fuzzy-q-arbiter"

    def __init__(
        self,
        *,
        actions: Sequence[Mapping[str, float]] | None = None,
        sectors: int = 4,
        stall_iterations: int = 20,
        stall_margin: float = 0.1,
        proximity: Sequence[float] = (),
        safety: Sequence[float] = (),
        safety_behaviour: str | None = None,
        convergence: str = "rule base",
        min_context_updates: int = 0,
        qparams: dict[str, Any],
    ) -> None:
        self.sectors = int(P.number("sectors", sectors, lo=1, integer=True))
        if self.sectors not in SECTOR_NAMES:
            raise InputError(f"expected 1, 2, 4 or 8 goal-bearing sectors, got {self.sectors}",
                             key="sectors")
        self.stall_iterations = int(P.number("stall_iterations", stall_iterations, lo=0,
                                             integer=True))
        self.stall_margin = P.number("stall_margin", stall_margin, lo=0.0, unit="m")
        self.proximity = _near_far("proximity", proximity, "no proximity context")
        self.safety = _near_far("safety", safety, "no safety hand-over")
        self.safety_behaviour = None if safety_behaviour is None else \
            P.string("safety_behaviour", safety_behaviour)
        self._safe_k = 0
        self._close = 0.0
        self._actions_cfg = None if actions is None else self._check_actions(actions)
        names = list(SECTOR_NAMES[self.sectors])
        if self.stall_iterations:
            names += [f"{n}_stalled" for n in names]
        if self.proximity:
            names = [f"{n}_{p}" for n in names for p in ("close", "far")]
        self.contexts = names
        self.convergence = P.choice("convergence", convergence, CONVERGENCE)
        every = self.convergence == "every context"
        self.qparams = QLearningParams(
            **qparams, groups=len(names) if every else 1,
            min_group_updates=int(P.number("min_context_updates", min_context_updates, lo=0,
                                           integer=True)))
        self.visits = np.zeros(len(names), dtype=np.int64)
        self._stable = np.zeros(len(names), dtype=np.int64)
        self._converged_at = np.full(len(names), -1, dtype=np.int64)
        self._greedy: np.ndarray | None = None
        self._changes = 0
        self.W = np.zeros((0, 0))
        self._labels: tuple[str, ...] = ()
        self.c = 0
        self.learner: FuzzyQLearner | None = None
        self.fixed: np.ndarray | None = None
        self.rules = np.zeros(0, dtype=np.intp)
        self._track = _Progress(self.stall_margin)
        self._iterations = 0

    @staticmethod
    def _check_actions(actions: Any) -> list[dict[str, float]]:
        if isinstance(actions, (str, Mapping)) or not isinstance(actions, Sequence) or \
                not actions:
            raise InputError("expected a non-empty list of weightings {label = weight}",
                             key="actions")
        out = []
        for i, a in enumerate(actions):
            if not isinstance(a, Mapping) or not a:
                raise InputError("expected a table {label = weight}", key=f"actions[{i}]")
            w = {str(k): P.number(f"actions[{i}].{k}", v, lo=0.0) for k, v in a.items()}
            if sum(w.values()) <= 0:
                raise InputError("expected at least one weight > 0", key=f"actions[{i}]")
            out.append(w)
        return out

    # -- binding ---------------------------------------------------------
    def _bind(self, labels: Sequence[str]) -> None:
        acts = self._actions_cfg if self._actions_cfg is not None else default_actions(labels)
        W = np.zeros((len(acts), len(labels)))
        for i, a in enumerate(acts):
            for lb, w in a.items():
                W[i, _label_index(list(labels), lb, f"actions[{i}].{lb}", self.name)] = w
        self.W = W / W.sum(axis=1, keepdims=True)
        self._labels = tuple(labels)
        if self.safety_behaviour is not None:
            self._safe_k = _label_index(list(labels), self.safety_behaviour,
                                        "safety_behaviour", self.name)

    def bind(self, run: RunContext) -> None:
        """Build the (A, k) weighting matrix over the run's behaviour labels."""
        self._bind(list(run.labels))

    # -- lifecycle ---------------------------------------------------------
    def reset(self, rng: np.random.Generator, n_situations: int, iterations: int) -> None:
        self.c = n_situations
        self._iterations = iterations
        self._track = _Progress(self.stall_margin)
        self.visits = np.zeros(len(self.contexts), dtype=np.int64)
        self._stable = np.zeros(len(self.contexts), dtype=np.int64)
        self._converged_at = np.full(len(self.contexts), -1, dtype=np.int64)
        self._greedy, self._changes = None, 0
        n = n_situations * len(self.contexts)
        if self.fixed is not None:
            if self.fixed.size != n:
                per = self.fixed.size // len(self.contexts)
                raise ValueError(f"the loaded arbitration has {per} rules per context but the "
                                 f"interpreter has {n_situations} situations")
            self.learner, self.rules = None, self.fixed.copy()
        else:
            self.learner = FuzzyQLearner(n, self.W.shape[0], self.qparams, rng, iterations)
            self.rules = self.learner.rule_base

    def load_policy(self, policy: LearnedPolicy) -> None:
        """Freeze the arbitration to a logged one (same contexts and number of actions)."""
        if set(policy.outputs) != set(self.contexts):
            raise ValueError(f"the policy's goal contexts {list(policy.outputs)} differ from this "
                             f"arbiter's {self.contexts}; configure the same sectors and "
                             "stall_iterations as the run that learned it")
        a = {o.actions.size for o in policy.outputs.values()}
        if a != {self.W.shape[0]} and self.W.size:
            raise ValueError(f"the policy chooses among {a.pop()} weightings, this arbiter has "
                             f"{self.W.shape[0]}; configure the same actions")
        self.fixed = np.concatenate([np.asarray(policy.outputs[name].rules, dtype=np.intp)
                                     for name in self.contexts])  # (a log sorts the outputs)

    # -- loop --------------------------------------------------------------
    def _context(self, ctx: Context, stalled: bool) -> int:
        k = goal_sector(ctx, self.sectors)
        return k + (self.sectors if stalled else 0)

    def _state(self, ctx: Context, stalled: bool) -> np.ndarray:
        """(c * n_contexts,) rule strengths: the memberships in the current context's block(s).

        With a proximity context the blocks ``close`` and ``far`` of the goal
        context share the memberships by how near the nearest range is
        (``close`` 1 below ``proximity[0]``, 0 beyond ``proximity[1]``, linear
        between; ``far`` = 1 - ``close``).
        """
        u = np.zeros(self.c * len(self.contexts))
        j = self._context(ctx, stalled)
        if not self.proximity:
            u[j * self.c:(j + 1) * self.c] = ctx.memberships
            return u
        close = _closeness(ctx.nearest, self.proximity)
        u[2 * j * self.c:(2 * j + 1) * self.c] = close * ctx.memberships
        u[(2 * j + 1) * self.c:(2 * j + 2) * self.c] = (1.0 - close) * ctx.memberships
        return u

    def _block(self, ctx: Context, stalled: bool) -> int:
        """Index (in :attr:`contexts`) of the context of ``ctx`` (the nearer of its proximity
        halves when there is a proximity context)."""
        j = self._context(ctx, stalled)
        if not self.proximity:
            return j
        return 2 * j + (0 if _closeness(ctx.nearest, self.proximity) >= 0.5 else 1)

    def _stalled(self) -> bool:
        return bool(self.stall_iterations) and self._track.since >= self.stall_iterations

    def combine(self, context: Context, proposals: dict[str, Proposal]) -> tuple[Proposal, Any]:
        labels = list(proposals)
        if tuple(labels) != self._labels:
            self._bind(labels)
        if self.learner is not None:
            self.learner.record_rules(context.iteration)
            self.rules = self.learner.rule_base
        self._track.observe(context)
        stalled = self._stalled()
        self._u = self._state(context, stalled)
        if self.learner is not None:
            self.visits[self._block(context, stalled)] += 1
        w = self._u @ self.W[self.rules]
        if self.safety:
            self._close = close = _closeness(context.nearest, self.safety)
            w = (1.0 - close) * w
            w[self._safe_k] += close
        props = list(proposals.values())
        return Proposal.blend(props, w), w / w.sum()

    def learn(self, transition: Transition, reward: float) -> None:
        if self.learner is None:
            return
        after = transition.after
        # the stall flag the next combine will see (unless a new episode starts there)
        stalled = bool(self.stall_iterations) and self._track.since + 1 >= \
            self.stall_iterations and _goal_distance(after) >= self._track.best - self.stall_margin
        u1 = self._state(after, stalled)
        u0 = self._u * (1.0 - self._close) if self.safety else self._u
        changed = self.learner.update(u0, reward, u1, transition.outcome.collided,
                                      transition.before.iteration)
        self.rules = self.learner.rule_base
        if changed:
            self._context_convergence(transition.before.iteration)

    def _context_convergence(self, iteration: int) -> None:
        """After a rule-base change: each context's greedy rules stable for ``p`` changes
        (with ``min_context_updates`` updates) counts as that context converged."""
        assert self.learner is not None
        g = len(self.contexts)
        greedy = self.learner.greedy.reshape(g, -1)
        if self._greedy is not None:
            same = (greedy == self._greedy).all(axis=1)
            self._stable = np.where(same, self._stable + 1, 0)
        self._greedy = greedy.copy()
        upd = self.learner.updates.reshape(g, -1).sum(axis=1)
        ok = (self._stable >= self.qparams.p) & (upd >= self.qparams.min_group_updates) & \
            (upd > 0)
        self._converged_at = np.where(ok, np.where(self._converged_at < 0, iteration + 1,
                                                   self._converged_at), -1)

    # -- results -------------------------------------------------------------
    def trial_data(self) -> dict[str, Any]:
        data: dict[str, Any] = {"action_weights": self.W.copy()}
        if self.learner is not None:
            d = self.learner.data(self._iterations)
            data.update({f"arbitration/{k}": v for k, v in d.items()})
            g = len(self.contexts)
            data["arbitration/contexts"] = list(self.contexts)
            data["arbitration/context_visits"] = self.visits.copy()
            data["arbitration/context_updates"] = self.learner.updates.reshape(g, -1).sum(axis=1)
            data["arbitration/context_converged_at"] = self._converged_at.copy()
            data["converged"] = bool(d["converged"])
            data["convergence_iteration"] = int(d["convergence_iteration"])
        return data

    def policy(self) -> LearnedPolicy:
        """One output per goal context: (c,) weighting indices and their Q (c, A)."""
        rules = self.learner.final_rule_base() if self.learner is not None else self.rules
        q = None if self.learner is None else self.learner.q
        a = self.W.shape[0]
        outs = {}
        for j, name in enumerate(self.contexts):
            sl = slice(j * self.c, (j + 1) * self.c)
            outs[name] = PolicyOutput(np.arange(a, dtype=float), np.asarray(rules[sl]).astype(
                np.int16), "", None if q is None else q[sl].copy())
        return LearnedPolicy(outs)


@hookimpl
def sitframe_arbiters() -> list[Any]:
    return [FuzzyQArbiter]


@hookimpl
def sitframe_rewards() -> list[Any]:
    return [GoalProgressReward]
