"""One trial: the control loop, its arrays and its scoring.

One control iteration (1.5 s of robot time)::

    reading   = sensor.read(world, pose, rng)
    u         = interpreter.memberships(reading)
    proposals = {label: b.propose(context) for b in behaviours}
    proposal  = arbiter.combine(context, proposals)
    outcome   = step_robot(world, pose, command, robot, rng)
    r         = reward(transition)        # per learning behaviour
    b.learn(transition, r)
    hook.sitframe_step(record)            # only if some plugin implements it

Every value crossing from plugin code is checked (:mod:`sitframe.contract`).
A :class:`TrialSpec` is picklable, so worker processes run the same loop.
:func:`simulate` creates the trial's components (:class:`_TrialParts`), runs
the loop (:func:`_run_loop`) and hands every iteration to one
:class:`Recorder`, which owns the per-iteration arrays.

Seeds: the run seed ``S`` gives each stage and each trial its own
:class:`numpy.random.SeedSequence` (``spawn_key`` = stage, trial), so trial
``k`` is the same whatever the number of trials or workers, and all
randomness of a trial flows from one :class:`numpy.random.Generator`.

Why one module of this size: the per-iteration path (sensing to recording) is one chain of
private steps sharing a trial's state; here it reads top to bottom.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
import pluggy

from sitframe import scratch
from sitframe.contract.checks import (
    MEMBERSHIP_SUM_TOL,
    BoundaryError,
    Origin,
    blame,
    call,
    check_combined,
    check_data,
    check_episode_starts,
    check_flag,
    check_memberships,
    check_n_situations,
    check_policy,
    check_proposal,
    check_reading,
    check_reward,
    check_trial_data,
    fault,
    memberships_mismatch,
    sensor_spec_mismatch,
)
from sitframe.contract.config import DEFAULT_SPACE
from sitframe.contract.records import (
    Context,
    LearnedPolicy,
    Proposal,
    StepRecord,
    Transition,
    TrialInfo,
    TrialResult,
    summary_key,
)
from sitframe.contract.tables import protocol_key
from sitframe.errors import PLUGIN_ERRORS, InputError, PluginFault, TaskCancelled
from sitframe.runs import fused
from sitframe.runs.tracker import SituationTracker
from sitframe.sim.metrics import collisions_per_1000, coverage, path_length
from sitframe.sim.robot import Command, RobotParams, StepOutcome, step_robot
from sitframe.sim.world import Goal, World

if TYPE_CHECKING:  # (the run's components, bound: built by the run driver)
    from sitframe.contract.resolve import Resolved

#: Seed stages (:func:`stage_seed`); ``STAGE_BATCH``: the episode batches of a run that
#: does not learn (one per world of its evaluation protocol); ``STAGE_SPACES``: the data and
#: clustering of the situation spaces of their own (index ``2 i``, ``2 i + 1`` for space ``i``).
STAGE_COLLECT, STAGE_CLUSTER, STAGE_TRIALS, STAGE_EVAL, STAGE_BATCH, STAGE_SPACES = range(6)
#: Figures the core measures of every evaluation (``eval/<world>/...``, ``evaluate --json``).
EVAL_KEYS = ("iterations", "collisions", "collisions_per_1000", "distance_m", "mean_speed_m_s",
             "coverage")


def stage_seed(seed: int, stage: int, index: int = 0) -> int:
    """A 64-bit seed for ``(stage, index)`` derived from the run seed."""
    ss = np.random.SeedSequence(entropy=seed, spawn_key=(stage, index))
    return int(ss.generate_state(1, np.uint64)[0])


@dataclass(frozen=True)
class TrialSpec:
    """Everything one trial needs; picklable so workers can run it.

    Attributes
    ----------
    index
        Trial number.
    seed
        64-bit seed of the trial's Generator.
    world
        World name.
    iterations
        Number of control iterations.
    learn
        Whether behaviours with a reward learn (False = evaluation).
    interpreter_state
        Fitted interpreter state (from the cluster stage or a log).
    policies
        Behaviour label -> policy dict to load before the trial.
    evaluate
        World names to evaluate the trial's final policy in afterwards.
    start
        Start pose (x [m], y [m], theta [rad]); ``None`` = the world's start.
    goal
        Goal (x [m], y [m], radius [m]) given to behaviours in the context;
        ``None`` = the world's ``[goal]`` if any.
    protocol
        The evaluation protocol (:class:`sitframe.contract.components.EvaluationProtocol`)
        by name: a spec that does not learn is then a *batch* of its episodes in
        ``world`` (:func:`run_batch`), returned as one trial; a learning spec's
        evaluations are such batches. ``None``: a plain run (one episode).
    observed
        Whether ``sitframe_step`` observers see the trial's iterations (not in
        the evaluations of a learning trial).
    space_states
        Fitted state of each situation space of its own (``[spaces.NAME]``), by
        name; empty in a run with one space.
    """

    index: int
    seed: int
    world: str
    iterations: int
    learn: bool
    interpreter_state: dict[str, Any]
    policies: dict[str, dict[str, np.ndarray]] = field(default_factory=dict)
    evaluate: tuple[str, ...] = ()
    start: tuple[float, float, float] | None = None
    goal: tuple[float, float, float] | None = None
    protocol: str | None = None
    observed: bool = True
    space_states: dict[str, dict[str, Any]] = field(default_factory=dict)


class _Step:
    """Where the loop is, for fault messages: the component's origin and the method."""

    __slots__ = ("origin", "method")

    def __init__(self, origin: Origin | str | None, method: str) -> None:
        self.origin, self.method = origin, method


@contextmanager
def _in_trial(trial: int) -> Iterator[None]:
    """Name ``trial`` in a fault raised while the trial creates and binds its components."""
    try:
        yield
    except PluginFault as exc:
        if exc.trial is not None:
            raise
        raise PluginFault(exc.message, where=exc.where, method=exc.method,
                          trial=trial) from exc


def _observer_fault(exc: BaseException, pm: pluggy.PluginManager, impls: list[Any], name: str,
                    trial: int, iteration: int | None) -> PluginFault:
    """The :class:`PluginFault` of an observer of hook ``name`` that raised ``exc``: it names
    the plugin whose implementation is on the traceback, the trial and the iteration."""
    info = getattr(pm, "sitframe_info", {})
    who = blame(exc, impls)
    where = f"plugin {info[who].describe() if who in info else who}" if who else "an observer"
    return fault(exc, where, name, trial, iteration)


def step_hook_of(pm: pluggy.PluginManager) -> Callable[[StepRecord], Any] | None:
    """A function firing ``sitframe_step`` observers, or ``None`` when no plugin implements it.

    An observer that raises is a :class:`PluginFault` naming its plugin (the
    one whose ``sitframe_step`` is on the traceback), the trial and the iteration.
    """
    hook = pm.hook.sitframe_step
    impls = hook.get_hookimpls()
    if not impls:
        return None

    def step_hook(rec: StepRecord) -> None:
        try:
            hook(record=rec)
        except (KeyboardInterrupt, TaskCancelled, PluginFault):
            raise
        except PLUGIN_ERRORS as exc:  # an observer's fault is reported, not raw
            raise _observer_fault(exc, pm, impls, "sitframe_step", rec.trial,
                                  rec.transition.before.iteration) from exc

    return step_hook


def progress_hook_of(pm: pluggy.PluginManager) -> Callable[[int, int], None] | None:
    """A function ``(trial, iterations)`` firing ``sitframe_progress``, or ``None`` when no
    plugin implements it (a fault as :func:`step_hook_of`'s)."""
    hook = pm.hook.sitframe_progress
    impls = hook.get_hookimpls()
    if not impls:
        return None

    def progress(trial: int, iterations: int) -> None:
        try:
            hook(trial=trial, iterations=iterations)
        except (KeyboardInterrupt, TaskCancelled, PluginFault):
            raise
        except PLUGIN_ERRORS as exc:
            raise _observer_fault(exc, pm, impls, "sitframe_progress", trial, None) from exc

    return progress


def simulate(
    res: Resolved,
    spec: TrialSpec,
    *,
    step_hook: Callable[[StepRecord], Any] | None = None,
    progress: Callable[[int, int], None] | None = None,
    protocol: Any = None,
) -> TrialResult:
    """Run one trial (learning, a batch of evaluation episodes, or one episode); return it.

    An evaluation ``protocol``'s ``terminated(context)``, called after every
    iteration, ends the trial early; ``iterations`` is then only its limit. A
    spec with a protocol that does not learn is a batch of episodes
    (:func:`run_batch`). ``step_hook`` fires for learning trials and episode
    batches of their own, never for the evaluations of a learning trial
    (``observed=False``), whichever executor runs them: the serial one runs
    them here, a pool as separate tasks, and the logs must not differ.
    ``progress(trial, iterations)`` (``sitframe_progress``) fires where ``step_hook`` does,
    every :data:`~sitframe.runs.fused.EVERY` iterations.

    A trial whose loop has nothing to do but its step runs compiled when its components
    have a compiled form (:mod:`sitframe.runs.fused`), with the same results.

    Raises
    ------
    PluginFault
        Plugin code raised, or returned a value that breaks the contract
        (:mod:`sitframe.contract`); names the plugin, component, method,
        trial and iteration.
    """
    if not spec.observed:
        step_hook = progress = None  # an evaluation of a learning trial ("not called")
    if spec.protocol is not None and not spec.learn:
        return run_batch(res, spec, step_hook=step_hook, progress=progress)
    rng = np.random.default_rng(spec.seed)
    world = res.world(spec.world)
    goal = world.goal if spec.goal is None else Goal(np.asarray(spec.goal[:2], float),
                                                     float(spec.goal[2]))
    parts = _TrialParts.create(res, spec, rng, world)
    rec = Recorder(spec.iterations, res.run.sensor.dim, parts.c, list(parts.behaviours),
                   [lb for lb, *_ in parts.learners],
                   {sp.name: sp.c for sp in parts.spaces})
    start = np.array(world.start if spec.start is None else spec.start, dtype=float)
    env = _Env(world, goal, rng, start)
    # None unless the trial learns over rooms or its protocol trains in episodes
    env.chain = _room_episodes(res, spec) or _training_episodes(res, spec, world)
    if env.chain is not None:
        env.start, env.goal, env.world = next(env.chain.pairs)
    env.cands = _candidates(res, spec)  # None unless the trial learns several rule bases
    env.track = SituationTracker.start(parts.interp, spec.learn, parts.components, res.origins,
                                       spec.index)  # None unless the situations evolve
    if env.cands is not None and env.track is not None:
        raise InputError("expected an interpreter whose situations do not evolve: the "
                         "candidates are judged with the situations the trial started from",
                         key="experiment.candidates")
    fz = "observed, ended by a protocol, candidates, spaces or protocol episodes" \
        if step_hook is not None or not _runs_out(protocol) or env.cands is not None or \
        parts.spaces or isinstance(env.chain, _TrainingEpisodes) \
        else fused.prepare(res, spec, parts, env.track)
    n = _run_loop(res, spec, parts, rec, env, step_hook, progress, protocol) \
        if isinstance(fz, str) else fused.run(fz, res, spec, rec, env, env.chain, progress)
    if progress is not None and n % fused.EVERY:
        progress(spec.index, n % fused.EVERY)  # (the rest; every EVERY iterations: the loop)
    arrays = rec.arrays(n, res.origins, spec.index, res.run.sensor.max_range)
    result = _trial_result(res, spec, world, parts, arrays, env)
    for ev_spec in evaluation_specs(spec, result.policies, result.situations.get("state")):
        attach_evaluation(result, ev_spec.world, simulate(res, ev_spec))
    return result


def _runs_out(protocol: Any) -> bool:
    """Whether nothing but the iteration limit ends a run of ``protocol`` (none, or a built-in
    whose ``terminated`` is never true: its ``_fused()`` says so), so that the compiled
    trial, which does not call ``terminated``, may run it."""
    f = getattr(protocol, "_fused", None)
    return protocol is None or (callable(f) and (f() or {}).get("terminates") is False)


@dataclass(frozen=True)
class _Space:
    """A situation space of its own in a trial: its interpreter (loaded), the readings it
    sees (``view``, ``None``: all) and its number of situations ``c``."""

    name: str
    interp: Any
    view: np.ndarray | None
    c: int
    at_u: _Step


@dataclass
class _TrialParts:
    """One trial's components, created, loaded and reset (:meth:`create`).

    ``learners`` are ``(label, component, reward, its origin, the reward's origin)``
    of every behaviour (and the arbiter) that learns in this trial; ``components``
    ``(config key, component)`` of all of them, for the lifecycle calls. ``spaces``
    are the situation spaces of their own (none in a run with one space) and
    ``where`` gives each behaviour label (and ``"arbiter"``) the index of the
    space it reads: 0 the default, ``i`` ``spaces[i - 1]``.
    """

    sensor: Any
    interp: Any
    c: int
    behaviours: dict[str, tuple[Any, Any]]
    arbiter: Any
    learners: list[tuple[str, Any, Any, Origin, Origin]]
    components: list[tuple[str, Any]]
    tinfo: TrialInfo
    spaces: list[_Space] = field(default_factory=list)
    where: dict[str, int] = field(default_factory=dict)

    def c_of(self, label: str) -> int:
        """The number of situations of the space ``label`` (a behaviour or ``"arbiter"``)
        reads."""
        i = self.where.get(label, 0)
        return self.c if i == 0 else self.spaces[i - 1].c

    @classmethod
    def create(cls, res: Resolved, spec: TrialSpec, rng: np.random.Generator,
               world: World) -> _TrialParts:
        """Create the trial's components and call their ``load_*``, ``reset``, ``trial_start``."""
        k, og = spec.index, res.origins
        with _in_trial(k):  # each trial creates and binds its own components
            sensor = res.sensor()
            interp = res.interpreter()
        call(og["interpreter"], "load_state", interp.load_state, spec.interpreter_state, trial=k)
        c = call(og["interpreter"], "n_situations",
                 lambda: check_n_situations(interp.n_situations), trial=k)
        spaces = [_space_load(res, name, spec) for name in res.config.spaces]
        where = _space_index(res)
        with _in_trial(k):
            behaviours = res.behaviours()
            arbiter = res.arbiter()
            arb_reward = res.arbiter_reward() if spec.learn else None
        L = spec.iterations
        own = {lb: spaces[where[lb] - 1].c if lb in where else c
               for lb in [*behaviours, "arbiter"]}
        for label, (beh, _r) in behaviours.items():
            o = og[f"behaviours.{label}"]
            if label in spec.policies:
                call(o, "load_policy", beh.load_policy, spec.policies[label], trial=k)
            call(o, "reset", beh.reset, rng, own[label], L, trial=k)
        if "arbiter" in spec.policies:  # (an arbiter with policy() has load_policy)
            call(og["arbiter"], "load_policy", arbiter.load_policy, spec.policies["arbiter"],
                 trial=k)
        if hasattr(arbiter, "reset"):
            call(og["arbiter"], "reset", arbiter.reset, rng, own["arbiter"], L, trial=k)
        learners = [(lb, beh, rew, og[f"behaviours.{lb}"], og[f"behaviours.{lb}.reward"])
                    for lb, (beh, rew) in behaviours.items() if rew is not None and spec.learn]
        if arb_reward is not None:
            learners.append(("arbiter", arbiter, arb_reward, og["arbiter"], og["arbiter.reward"]))
        components = [("sensor", sensor), ("interpreter", interp),
                      *[(f"spaces.{sp.name}", sp.interp) for sp in spaces],
                      *[(f"behaviours.{lb}", b) for lb, (b, _r) in behaviours.items()],
                      *[(f"behaviours.{lb}.reward", r) for lb, (_b, r) in behaviours.items()
                        if r is not None and spec.learn],  # (a frozen run uses no reward)
                      ("arbiter", arbiter), ("arbiter.reward", arb_reward)]
        components = [(key, comp) for key, comp in components if comp is not None]
        tinfo = TrialInfo(k, "learn" if spec.learn else "evaluate", world, L, rng)
        for key, comp in components:
            if hasattr(comp, "trial_start"):
                call(og[key], "trial_start", comp.trial_start, tinfo, trial=k)
        return cls(sensor, interp, c, behaviours, arbiter, learners, components, tinfo, spaces,
                   where)


def _space_index(res: Resolved) -> dict[str, int]:
    """Behaviour label (or ``"arbiter"``) -> ``1 + i`` for those that read the ``i``-th
    situation space of its own (the others read the default space)."""
    names = list(res.config.spaces)
    out = {}
    for lb in [*res.config.behaviours, "arbiter"]:
        space = res.config.space_of("arbiter" if lb == "arbiter" else f"behaviours.{lb}")
        if space in names:
            out[lb] = 1 + names.index(space)
    return out


def _space_load(res: Resolved, name: str, spec: TrialSpec) -> _Space:
    """Create space ``name``'s interpreter for a trial and load its fitted state."""
    key, k = f"spaces.{name}", spec.index
    if name not in spec.space_states:
        raise InputError(f"no fitted situations for space '{name}' (expected them from its "
                         "clusters_from log, the collect and cluster stages, or the log)",
                         key=key)
    with _in_trial(k):
        interp = res.space_interpreter(name)
    o = res.origins[key]
    call(o, "load_state", interp.load_state, spec.space_states[name], trial=k)
    c = call(o, "n_situations", lambda: check_n_situations(interp.n_situations), trial=k)
    return _Space(name, interp, res.space_view(name), int(c), _Step(o, "memberships"))



class Recorder:
    """The per-iteration arrays of one trial: allocated, filled and trimmed in one place.

    A trial longer than :func:`sitframe.scratch.limit` iterations keeps them in scratch
    files, whose pages the loop releases as it goes (:mod:`sitframe.scratch`).

    Parameters
    ----------
    iterations
        The trial's limit ``L`` (an episode may stop earlier).
    dim
        Length ``d`` of a sensor reading.
    c
        Number of situations.
    labels
        The behaviours' labels, in config order.
    rewarded
        The labels whose rewards are recorded (the learners').
    spaces
        Name -> number of situations of each situation space of its own (its
        memberships are recorded as ``spaces/<name>/memberships``).
    """

    def __init__(self, iterations: int, dim: int, c: int, labels: list[str],
                 rewarded: list[str], spaces: dict[str, int] | None = None) -> None:
        L, long = iterations, scratch.wanted(iterations)

        def new(shape: Any, dtype: Any = np.float64, fill: Any = None) -> np.ndarray:
            return scratch.empty(shape, dtype, fill=fill, file=long)

        self.labels = labels
        self.pose = new((L + 1, 3))
        self.reading = new((L, dim))
        self.memberships = new((L, c))
        self.spaces = {name: new((L, cs)) for name, cs in (spaces or {}).items()}
        self.weights = new((L, len(labels)))
        self.command = new((L, 2))
        self.nearest = new(L)
        self.collision = new(L, bool, False)
        self.contact = new((L, 2), np.float64, np.nan)
        self.proposals = new((L, 2 * len(labels)))
        self.rewards = new((L, len(rewarded)))
        self.rewarded = rewarded

    def record(self, t: int, ctx: Context, cmd: Command, out: StepOutcome, weights: np.ndarray,
               proposals: dict[str, Proposal], rewards: dict[str, float]) -> None:
        """Record iteration ``t``: its context, command, outcome, weights, proposals, rewards."""
        self.pose[t] = ctx.pose
        self.reading[t] = ctx.reading
        self.memberships[t] = ctx.memberships
        self.weights[t] = weights
        self.command[t] = cmd.heading_change_deg, cmd.speed_m_s
        self.nearest[t] = ctx.nearest
        if out.collided:
            self.collision[t] = True
            self.contact[t] = out.contact_xy
        row = self.proposals[t]
        for i, p in enumerate(proposals.values()):
            row[2 * i] = p.heading_deg
            row[2 * i + 1] = np.nan if p.speed_m_s is None else p.speed_m_s
        if rewards:
            self.rewards[t] = tuple(rewards.values())

    def record_spaces(self, t: int, ctxs: list[Context]) -> None:
        """Record iteration ``t``'s memberships of each space of its own (``ctxs[1:]``)."""
        for u, ctx in zip(self.spaces.values(), ctxs[1:], strict=True):
            u[t] = ctx.memberships

    def arrays(self, n: int, origins: dict[str, Origin], trial: int,
               max_range: float = np.inf) -> dict[str, np.ndarray]:
        """The first ``n`` iterations' arrays (the final pose is the last of ``pose``).

        Checks every reading (against the sensor's ``max_range``), membership
        vector and weight first (vectorised, :func:`_check_trial_values`).
        """
        for i in range(0, n, fused.RELEASE):  # (in blocks: a long trial's arrays are never all in)
            j = min(n, i + fused.RELEASE)
            _check_trial_values(self.reading[i:j], self.memberships[i:j], self.weights[i:j],
                                origins, trial, max_range, first=i)
            for name, u in self.spaces.items():
                _check_memberships_rows(u[i:j], origins[f"spaces.{name}"], trial, first=i)
            scratch.release_all()
        out = {"pose": self.pose[: n + 1], READING: self.reading[:n],
               "memberships": self.memberships[:n], "command": self.command[:n],
               "collision": self.collision[:n], "contact": self.contact[:n],
               "nearest": self.nearest[:n], "weights": self.weights[:n]}
        for i, lb in enumerate(self.labels):
            out[f"proposals/{lb}"] = scratch.copy(self.proposals[:n, 2 * i: 2 * i + 2])
        for name, u in self.spaces.items():
            out[f"spaces/{name}/memberships"] = u[:n]
        for i, lb in enumerate(self.rewarded):
            out[f"reward/{lb}"] = scratch.copy(self.rewards[:n, i])
        return out


class _Env:
    """Where a trial runs: world, goal, Generator and start pose; the chain of training
    episodes (:class:`_TrainingEpisodes`) and the tracker of evolving situations, if any."""

    __slots__ = ("world", "goal", "rng", "start", "chain", "track", "cands")

    def __init__(self, world: World, goal: Goal | None, rng: np.random.Generator,
                 start: np.ndarray) -> None:
        self.world, self.goal, self.rng, self.start = world, goal, rng, start
        self.chain: _TrainingEpisodes | RoomEpisodes | None = None
        self.track: SituationTracker | None = None
        self.cands: Candidates | None = None


def _run_loop(res: Resolved, spec: TrialSpec, parts: _TrialParts, rec: Recorder, env: _Env,
              step_hook: Callable[[StepRecord], Any] | None,
              progress: Callable[[int, int], None] | None, protocol: Any) -> int:
    """The control loop (module docstring); returns the number of iterations run.

    Every plugin call is preceded by setting ``step_at`` to where it is, so a
    raise is reported at the right plugin and method (:func:`_loop_fault`).
    With situation spaces of their own, each component gets the context of the
    space it reads (``ctxs[i]``, :func:`_in_spaces`); with one space
    ``ctxs == [ctx]``.
    """
    og, k = res.origins, spec.index
    sensor, interp, arbiter = parts.sensor, parts.interp, parts.arbiter
    world, goal, rng = env.world, env.goal, env.rng
    d, c, n_labels = res.run.sensor.dim, parts.c, len(parts.behaviours)
    default_speed = res.config.experiment.default_speed
    robot = res.robot
    track, chain, spaces, where = env.track, env.chain, parts.spaces, parts.where
    cands = env.cands
    at_read, at_u = _Step(og["sensor"], "read"), _Step(og["interpreter"], "memberships")
    at_combine, at_core = _Step(og["arbiter"], "combine"), _Step(None, "step")
    at_step = _Step(None, "sitframe_step")
    at_propose = [(lb, beh, where.get(lb, 0), _Step(og[f"behaviours.{lb}"], "propose"))
                  for lb, (beh, _r) in parts.behaviours.items()]
    at_learn = [(lb, beh, rew, where.get(lb, 0), _Step(ob, "learn"), _Step(orw, "__call__"))
                for lb, beh, rew, ob, orw in parts.learners]
    at_arb = where.get("arbiter", 0)
    at_end = None if protocol is None else _Step(
        og.get(protocol_key(protocol)) or f"protocol '{protocol.name}'", "terminated")
    step_at = at_read
    t = 0
    pose = env.start
    n_done = spec.iterations
    ctx = None
    ctxs: list[Context] = []
    try:
        for t in range(spec.iterations):
            if ctx is None:  # the trial's (or a training episode's) first reading
                step_at = at_read
                pose.setflags(write=False)
                reading = sensor.read(world, pose, rng)
                check_reading(reading, d)
                step_at = at_u
                u = interp.memberships(reading)
                check_memberships(u, c)
                ctx = Context(t, pose, reading, u, _nearest(reading), world, goal)
                ctxs = _in_spaces(ctx, spaces, k) if spaces else [ctx]
                ctx = ctxs[0]
            proposals = {}
            for lb, beh, i, step_at in at_propose:  # noqa: B007 - step_at names the caller
                proposals[lb] = check_proposal(beh.propose(ctxs[i]))
            step_at = at_combine
            prop, weights = check_combined(arbiter.combine(ctxs[at_arb], proposals), n_labels,
                                           proposals)
            step_at = at_core
            cmd = Command(prop.heading_deg,
                          default_speed if prop.speed_m_s is None else prop.speed_m_s)
            out = step_robot(world, pose, cmd, robot, rng)
            pose = out.pose
            pose.setflags(write=False)  # the robot's own: the sensor must not move it
            step_at = at_read
            reading2 = sensor.read(world, pose, rng)
            check_reading(reading2, d)
            step_at = at_u
            u2 = interp.memberships(reading2)
            check_memberships(u2, c)
            ctx2 = Context(t + 1, pose, reading2, u2, _nearest(reading2), world, goal)
            ctxs2 = _in_spaces(ctx2, spaces, k) if spaces else [ctx2]
            trs = [Transition(a, cmd, out, b) for a, b in zip(ctxs, ctxs2, strict=True)]
            rewards = {}
            for lb, beh, rew, i, at_l, step_at in at_learn:
                rewards[lb] = r = check_reward(rew(trs[i]))
                step_at = at_l
                beh.learn(trs[i], r)
            if track is not None:
                track.step(t)
            rec.record(t, ctx, cmd, out, weights, proposals, rewards)
            if spaces:
                rec.record_spaces(t, ctxs)
            if step_hook is not None:
                step_at = at_step
                step_hook(StepRecord(k, trs[0], proposals, weights, rewards))
            if (t + 1) % fused.EVERY == 0:
                _block_done(k, t + 1, progress)
            ctx, ctxs = ctxs2[0], ctxs2
            if at_end is not None and (step_at := at_end) and \
                    check_flag(protocol.terminated(ctx)):
                n_done = t + 1
                break
            if cands is not None and cands.over(t + 1):
                step_at = at_core
                cands.next_round(res, spec, parts, rng)
            if chain is not None and chain.over(ctx, t + 1, spec.iterations):
                pose, goal, world = next(chain.pairs)  # the next training episode starts here
                ctx = None
    except (KeyboardInterrupt, TaskCancelled, PluginFault, InputError):
        raise  # (a plugin's InputError names the input it found wrong)
    except PLUGIN_ERRORS as exc:
        if step_at.origin is None and step_at.method == "step":
            raise  # the core's own arithmetic: a bug here, not the plugin's
        raise _loop_fault(exc, step_at, k, t, res, locals()) from exc
    rec.pose[n_done] = pose
    return n_done


def _block_done(trial: int, t: int, progress: Callable[[int, int], None] | None) -> None:
    """After iteration ``t - 1``, a multiple of :data:`~sitframe.runs.fused.EVERY`: tell
    ``progress``, and every :data:`~sitframe.runs.fused.RELEASE` iterations drop the pages
    of the rows recorded in scratch files (:func:`sitframe.scratch.release_all`)."""
    if t % fused.RELEASE == 0:
        scratch.release_all()
    if progress is not None:
        progress(trial, fused.EVERY)


def _in_spaces(ctx: Context, spaces: list[_Space], trial: int) -> list[Context]:
    """The context of each situation space: ``[default, *spaces]``, each with its own
    memberships and all of them in ``Context.spaces`` (a fault in a space's interpreter
    names it)."""
    us = {DEFAULT_SPACE: ctx.memberships}
    reading = ctx.reading
    for sp in spaces:
        try:
            u = sp.interp.memberships(reading if sp.view is None else reading[sp.view])
            check_memberships(u, sp.c)
        except (KeyboardInterrupt, TaskCancelled, PluginFault, InputError):
            raise
        except BoundaryError as exc:
            raise PluginFault(str(exc), where=str(sp.at_u.origin), method="memberships",
                              trial=trial, iteration=ctx.iteration) from None
        except PLUGIN_ERRORS as exc:
            raise fault(exc, sp.at_u.origin, "memberships", trial, ctx.iteration) from exc
        us[sp.name] = u
    it, pose, nearest, world, goal = ctx.iteration, ctx.pose, ctx.nearest, ctx.world, ctx.goal
    return [Context(it, pose, reading, us[name], nearest, world, goal, us)
            for name in (DEFAULT_SPACE, *(sp.name for sp in spaces))]


def _trial_result(res: Resolved, spec: TrialSpec, world: World, parts: _TrialParts,
                  arrays: dict[str, np.ndarray], env: _Env) -> TrialResult:
    """The finished trial: behaviours' data and policies, summary, plugins' data."""
    k, og = spec.index, res.origins
    bdata, policies = _learned_state(res, spec, parts)
    chosen: dict[str, Any] = {}
    if env.cands is not None:  # the candidate that scored best in the validation rooms
        bdata, policies, chosen = env.cands.choose(res, spec, bdata, policies)
    summary = trial_summary(world, arrays, bdata, res.robot)
    episodes = {} if env.chain is None else env.chain.record(arrays, summary, res.robot)
    if env.cands is not None:
        episodes.update(env.cands.record(chosen, summary))
    result = TrialResult(spec.index, spec.seed, world.name, arrays, bdata, summary, episodes,
                         policies=policies)
    if env.track is not None:
        result.situations = call(og["interpreter"], "state", env.track.finish, arrays["pose"],
                                 res.run.sensor.dim, trial=k)
        summary["situations"] = result.situations["count"]
    _collect_plugin_data(result, parts.components, parts.tinfo, og, res)
    return result


def _learned_state(res: Resolved, spec: TrialSpec, parts: _TrialParts
                   ) -> tuple[dict[str, dict[str, Any]], dict[str, LearnedPolicy]]:
    """The behaviours' (and a learning arbiter's) trial data and policies, now."""
    k, og = spec.index, res.origins
    bdata, policies = {}, {}
    learned = [(lb, b, og[f"behaviours.{lb}"]) for lb, (b, _r) in parts.behaviours.items()]
    if hasattr(parts.arbiter, "policy"):
        learned.append(("arbiter", parts.arbiter, og["arbiter"]))
    for lb, b, o in learned:
        if hasattr(b, "trial_data"):
            bdata[lb] = _checked(o, "trial_data", check_trial_data, b.trial_data, k,
                                 spec.iterations)
        if hasattr(b, "policy"):
            pol = _checked(o, "policy", lambda p, lb=lb: check_policy(p, parts.c_of(lb)),
                           b.policy, k)
            if pol is not None:
                policies[lb] = pol
    if parts.spaces:  # (which situation space each behaviour read, logged with its data)
        for lb, _b, _o in learned:
            bdata.setdefault(lb, {})["space"] = res.config.space_of(
                "arbiter" if lb == "arbiter" else f"behaviours.{lb}")
    return bdata, policies


class Candidates:
    """Several rule bases learnt one after another in a trial; the best in validation kept.

    ``experiment.candidates = K`` splits a learning trial into ``K`` rounds of
    ``iterations / K`` iterations (the last takes the remainder). At the end of a
    round every learner's data and policy are kept and the learners are reset
    (``reset`` again, with the trial's Generator: a fresh rule base, Q from its
    initial values); the robot drives on where it is (or in the next room of a
    trial over rooms). After the last round each candidate's frozen policies run
    ``validation_iterations`` iterations from the start of every validation
    room (the same seeds for every candidate, so they meet the same noise), and
    the candidate with the lowest score

        collisions per 1000 (pooled over the rooms) - :attr:`COVERAGE_WEIGHT` x
        mean coverage

    (the earliest of equal ones) is the trial's: its policies are evaluated and
    logged, its data is the behaviours' trial data (its convergence iteration
    counts from the trial's start). The validation runs are steps the learner
    spends: the summary's ``validation_iterations`` counts them; ``candidate`` is
    the one kept, ``select/...`` in the episodes records every candidate's first
    iteration, figures and score.
    """

    #: Coverage's weight in the score: 0.1 more coverage is worth 2 collisions per 1000.
    COVERAGE_WEIGHT = 20.0

    def __init__(self, k: int, iterations: int, rooms: list[str], run_iterations: int) -> None:
        self.ends = [iterations * (j + 1) // k for j in range(k)]
        self.rooms, self.run_iterations = rooms, run_iterations
        self.saved: list[tuple[dict[str, dict[str, Any]], dict[str, LearnedPolicy]]] = []

    def over(self, t: int) -> bool:
        """Whether a round (not the last) ends after iteration ``t``."""
        return len(self.saved) < len(self.ends) - 1 and t == self.ends[len(self.saved)]

    def next_round(self, res: Resolved, spec: TrialSpec, parts: _TrialParts,
                   rng: np.random.Generator) -> None:
        """Keep the round's data and policies; reset every learner for the next round."""
        self.saved.append(_learned_state(res, spec, parts))
        for lb, beh, _rew, o, _orw in parts.learners:
            call(o, "reset", beh.reset, rng, parts.c_of(lb), spec.iterations, trial=spec.index)

    def choose(self, res: Resolved, spec: TrialSpec, bdata: dict[str, dict[str, Any]],
               policies: dict[str, LearnedPolicy]
               ) -> tuple[dict[str, dict[str, Any]], dict[str, LearnedPolicy], dict[str, Any]]:
        """Judge every candidate (the last one's ``bdata``, ``policies`` given) in the
        validation rooms; the chosen one's data and policies, and every candidate's figures."""
        self.saved.append((bdata, policies))
        seeds = np.random.SeedSequence(spec.seed % 2**64, spawn_key=(4,)).generate_state(
            len(self.rooms), np.uint64)
        coll = np.zeros(len(self.saved))
        cov = np.zeros(len(self.saved))
        for j, (_b, pol) in enumerate(self.saved):
            runs = [simulate(res, dataclasses.replace(
                spec, seed=int(seeds[r]), world=room, iterations=self.run_iterations,
                learn=False, policies=dict(pol), evaluate=(), start=None, goal=None,
                protocol=None, observed=False)).summary for r, room in enumerate(self.rooms)]
            coll[j] = 1000.0 * sum(s["collisions"] for s in runs) / \
                (self.run_iterations * len(runs))
            cov[j] = float(np.mean([s["coverage"] for s in runs]))
        score = coll - self.COVERAGE_WEIGHT * cov
        best = int(np.argmin(score))
        return (*self.saved[best], {"candidate": best, "collisions_per_1000": coll,
                                    "coverage": cov, "score": score})

    def record(self, chosen: dict[str, Any], summary: dict[str, Any]) -> dict[str, Any]:
        """Add the chosen candidate and the validation steps to ``summary``; return the
        candidates' records (``select/...``)."""
        summary["candidate"] = int(chosen["candidate"])
        summary["validation_iterations"] = len(self.saved) * len(self.rooms) * \
            self.run_iterations
        return {"select/first_iteration": np.asarray([0, *self.ends[:-1]], dtype=np.int64),
                "select/collisions_per_1000": chosen["collisions_per_1000"],
                "select/coverage": chosen["coverage"], "select/score": chosen["score"]}


def _candidates(res: Resolved, spec: TrialSpec) -> Candidates | None:
    """The rounds of a learning trial that learns several candidates, else None."""
    e = res.config.experiment
    if not spec.learn or e.candidates <= 1:
        return None
    for j, room in enumerate(e.validation_rooms):
        res.world(room, key=f"experiment.validation_rooms[{j}]")
    return Candidates(e.candidates, spec.iterations, list(e.validation_rooms),
                      e.validation_iterations)


class _TrainingEpisodes:
    """A learning trial as a chain of an evaluation protocol's episodes.

    A protocol with a true ``train_in_episodes`` attribute (e.g. ``goal-episodes``
    with ``[goal] train = "episodes"``) makes every learning trial of its run
    a sequence of its episodes: the robot starts at the first start pose with
    its goal, and when the protocol's ``terminated`` holds or the episode has
    lasted the protocol's ``iterations``, it is put at the next start with the
    next goal; learning carries on across episodes. The pairs come from
    ``episode_starts`` (or the protocol's optional ``training_starts``, same
    arguments and result, when it draws training pairs otherwise, e.g. a
    curriculum) with a Generator of their own (seeded by the trial's seed),
    drawn again whenever a batch is used up.
    """

    def __init__(self, proto: Any, world: World, seed: int, robot: RobotParams,
                 origin: Origin, trial: int) -> None:
        self.proto, self.world, self.robot = proto, world, robot
        self.origin, self.trial = origin, trial
        self.rng = np.random.default_rng(np.random.SeedSequence(seed % 2**64, spawn_key=(2,)))
        self.first: list[int] = [0]
        self.goals: list[tuple[float, float, float]] = []
        self.reached: list[bool] = []
        self.pairs = self._pairs()

    def _pairs(self) -> Iterator[tuple[np.ndarray, Goal | None, World]]:
        method = "training_starts" if callable(getattr(self.proto, "training_starts", None)) \
            else "episode_starts"
        draw = getattr(self.proto, method)
        while True:
            starts, goals = _checked(self.origin, method, check_episode_starts,
                                     lambda: draw(self.world, self.rng, self.robot),
                                     self.trial, np.inf, self.world, self.robot.radius)
            for e, start in enumerate(starts):
                g = None if goals is None else goals[e]
                self.goals.append((np.nan, np.nan, np.nan) if g is None else tuple(g))
                yield start.copy(), None if g is None else Goal(g[:2], float(g[2])), self.world

    def over(self, ctx: Context, t: int, limit: int) -> bool:
        """Whether the episode ends at ``ctx`` (iteration ``t`` of a trial of ``limit``):
        terminated or timed out (never at the trial's own end)."""
        if t >= limit:
            return False
        done = _checked(self.origin, "terminated", check_flag, lambda: self.proto.terminated(ctx),
                        self.trial)
        if done or t - self.first[-1] >= int(self.proto.iterations):
            self.reached.append(done)
            self.first.append(t)
            return True
        return False

    def record(self, arrays: dict[str, np.ndarray], summary: dict[str, Any],
               robot: RobotParams) -> dict[str, Any]:
        """The episodes' first rows and goals (``learn/...``); the distance without the jumps."""
        pose = arrays["pose"]
        first = np.asarray(self.first, dtype=np.int64)
        summary["distance_m"] = float(sum(path_length(seg[:, :2])
                                          for seg in np.split(pose, first[1:])))
        n = len(first)
        return {"learn/first_iteration": first, "learn/goal": np.asarray(self.goals[:n]),
                "learn/success": np.asarray(self.reached + [False] * (n - len(self.reached)))[:n]}


class RoomEpisodes:
    """A learning trial over a family of rooms (``experiment.rooms``), episode by episode.

    The trial is a chain of episodes of ``episode_iterations`` iterations (the
    last one ends with the trial). Each episode runs in one of the rooms, from a
    start pose drawn uniformly among the room's free poses (the robot disc and a
    margin of :attr:`MARGIN` clear of every wall), heading uniform (with ``tight`` > 0 that
    share of the episodes starts at the free pose nearest a wall among
    :attr:`TIGHT_DRAWS`: a curriculum for situations rarely met); the rooms
    come in rounds, each round every room once in an order shuffled anew. Rooms,
    orders and poses come from a Generator of their own seeded by the trial's
    seed (``spawn_key = (3,)``), so the trial's other draws are those of a trial
    in one world and a seed gives the same chain whatever the rooms' count of
    workers. Learning carries on across episodes (nothing is reset between them).

    The log records, besides the trial's usual arrays, ``room`` (per iteration,
    the index into ``learn/rooms`` of the room it ran in) and per episode
    ``learn/first_iteration`` and ``learn/room``; the summary's ``coverage`` is
    the mean over the rooms the trial visited of the share of each room's free
    cells visited in its episodes there (:func:`sitframe.sim.metrics.coverage`),
    ``rooms_visited`` their number, ``distance_m`` the path without the jumps
    between episodes.

    Parameters
    ----------
    worlds
        The rooms, in config order.
    episode
        Iterations of one episode.
    seed
        The trial's seed.
    robot
        The robot (its radius decides which poses are free).
    tight
        The share of episodes, in [0, 1], that start in a tight place.
    """

    #: Clearance [m] beyond the robot's radius of an episode's start position.
    MARGIN = 0.1

    #: Free poses drawn for a tight start; the one nearest a wall or edge is taken.
    TIGHT_DRAWS = 20

    def __init__(self, worlds: list[World], episode: int, seed: int,
                 robot: RobotParams, tight: float = 0.0) -> None:
        self.worlds, self.episode, self.robot, self.tight = worlds, int(episode), robot, tight
        self.rng = np.random.default_rng(np.random.SeedSequence(seed % 2**64, spawn_key=(3,)))
        self.first: list[int] = [0]
        self.rooms: list[int] = []
        self.pairs = self._pairs()

    def _pairs(self) -> Iterator[tuple[np.ndarray, Goal | None, World]]:
        while True:
            for i in self.rng.permutation(len(self.worlds)):
                world = self.worlds[int(i)]
                self.rooms.append(int(i))
                yield self._start(world), world.goal, world

    def _start(self, world: World) -> np.ndarray:
        """An episode's start pose: uniform among the free poses, or (a share ``tight`` of
        the episodes, decided by a draw made only when ``tight`` > 0) the one nearest a wall
        of :attr:`TIGHT_DRAWS` such poses."""
        draws = 1 if not self.tight or self.rng.random() >= self.tight else self.TIGHT_DRAWS
        poses = [world.random_free_pose(self.rng, self.robot.radius, margin=self.MARGIN)
                 for _ in range(draws)]
        if draws == 1:
            return poses[0]
        return poses[int(np.argmin(world.clearance(np.asarray(poses)[:, :2])))]

    def over(self, ctx: Context, t: int, limit: int) -> bool:
        """Whether the episode ends after iteration ``t`` of a trial of ``limit`` (never at
        the trial's own end)."""
        if t < limit and t - self.first[-1] >= self.episode:
            self.first.append(t)
            return True
        return False

    def record(self, arrays: dict[str, np.ndarray], summary: dict[str, Any],
               robot: RobotParams) -> dict[str, Any]:
        """Add ``room`` to the trial's ``arrays``, the coverage over rooms and the distance
        without the jumps to its ``summary``; return the episodes' records (``learn/...``)."""
        pose, n = arrays["pose"], int(arrays["collision"].size)
        first = np.asarray(self.first, dtype=np.int64)
        rooms = np.asarray(self.rooms[: first.size], dtype=np.int16)
        arrays["room"] = np.repeat(rooms, np.diff(np.append(first, n)))
        summary["distance_m"] = float(sum(path_length(seg[:, :2])
                                          for seg in np.split(pose, first[1:])))
        visited = np.unique(rooms)
        summary["coverage"] = float(np.mean([coverage(
            self.worlds[i], pose[:-1][arrays["room"] == i, :2], radius=robot.radius)
            for i in visited]))
        summary["rooms_visited"] = int(visited.size)
        return {"learn/first_iteration": first, "learn/room": rooms,
                "learn/rooms": [w.name for w in self.worlds]}


def _room_episodes(res: Resolved, spec: TrialSpec) -> RoomEpisodes | None:
    """The episode chain of a learning trial over ``experiment.rooms``, else None."""
    e = res.config.experiment
    if not spec.learn or not e.rooms:
        return None
    worlds = [res.world(name, key=f"experiment.rooms[{j}]") for j, name in enumerate(e.rooms)]
    return RoomEpisodes(worlds, e.episode_iterations, spec.seed, res.robot, e.tight_starts)


def _training_episodes(res: Resolved, spec: TrialSpec, world: World) -> _TrainingEpisodes | None:
    """The episode chain of a learning trial whose protocol trains in episodes, else None."""
    if not spec.learn or spec.protocol is None:
        return None
    proto = res.protocol(str(spec.protocol))
    if not getattr(proto, "train_in_episodes", False):
        return None
    return _TrainingEpisodes(proto, world, spec.seed, res.robot, res.origins[protocol_key(proto)],
                             spec.index)


def run_batch(res: Resolved, spec: TrialSpec, *,
              step_hook: Callable[[StepRecord], Any] | None = None,
              progress: Callable[[int, int], None] | None = None) -> TrialResult:
    """Run a batch of ``spec.protocol``'s episodes in ``spec.world``; return it as one trial.

    Start poses (and goals) come from the protocol, given a Generator seeded
    by ``spec.seed``; episode ``e`` runs with its own seed spawned from it, so
    a batch is reproducible and episode ``e`` does not depend on the others
    (a continuing protocol, ``episodic = False``: one run on ``spec.seed``).
    Each episode is :func:`simulate` from its start, with its goal, until the
    protocol's ``terminated`` or its ``iterations``. The trial holds the
    episodes' arrays concatenated (``pose`` has one extra row per episode),
    the summary (:func:`trial_summary`) with the protocol's aggregates as
    ``eval/<world>/<key>`` and, if episodic, ``episodes``: starts, goals,
    ``first_iteration`` (each one's first row) and the per-episode figures
    (one array per key, one ``NNNN`` group per episode); else the run's plugin data.
    """
    k = spec.index
    with _in_trial(k):
        proto = res.protocol(str(spec.protocol))
    o = res.origins[protocol_key(proto)]
    world = res.world(spec.world, key=f"{protocol_key(proto)}.worlds")
    episodic = bool(getattr(proto, "episodic", True))
    ss = np.random.SeedSequence(spec.seed % 2**64)
    rng = np.random.default_rng(ss.spawn(1)[0])
    starts, goals = _checked(o, "episode_starts", check_episode_starts,
                             lambda: proto.episode_starts(world, rng, res.robot), k,
                             np.inf if episodic else 1, world, res.robot.radius)
    n = len(starts)
    seeds = np.random.SeedSequence(spec.seed % 2**64, spawn_key=(1,)).generate_state(
        n, np.uint64) if episodic else [spec.seed]
    score = getattr(proto, "score_episode", None)
    parts: list[TrialResult] = []
    figures: list[dict[str, Any]] = []
    for e in range(n):
        goal = None if goals is None else tuple(float(v) for v in goals[e])
        ep = dataclasses.replace(spec, seed=int(seeds[e]), iterations=int(proto.iterations),
                                 evaluate=(), start=tuple(float(v) for v in starts[e]),
                                 goal=goal, protocol=None)
        parts.append(r := simulate(res, ep, step_hook=step_hook, progress=progress,
                                   protocol=proto))
        figures.append({} if score is None else _checked(
            o, "score_episode", check_data, lambda r=r, e=e: score(
                r.arrays, starts[e], None if goals is None else goals[e], res.robot), k,
            "per-episode figures"))
    for e, f in enumerate(figures):
        if f.keys() != figures[0].keys():
            raise PluginFault(f"returned {sorted(f)} for episode {e} but {sorted(figures[0])} "
                              "for episode 0; expected the same keys for every episode",
                              where=str(o), method="score_episode", trial=k)
    per_ep = {key: np.asarray([f[key] for f in figures]) for key in figures[0]}
    scores = _checked(o, "aggregate", check_data, lambda: proto.aggregate(per_ep), k,
                      "the batch's scores") if hasattr(proto, "aggregate") else {}
    if clash := sorted(set(scores) & set(EVAL_KEYS)):
        raise PluginFault(f"returned {clash}, which the core measures itself (one of "
                          f"{', '.join(EVAL_KEYS)}); expected other names", where=str(o),
                          method="aggregate", trial=k)
    arrays = {key: np.concatenate([p.arrays[key] for p in parts]) for key in parts[0].arrays}
    episodes: dict[str, Any] = {}
    if episodic:
        first = np.cumsum([0] + [int(p.arrays["collision"].size) for p in parts[:-1]])
        episodes = {**per_ep, "start": starts, **({} if goals is None else {"goal": goals}),
                    "first_iteration": first.astype(np.int64)}
        for e, f in enumerate(figures):
            episodes[f"{e:04d}"] = {**f, "start": starts[e],
                                    **({} if goals is None else {"goal": goals[e]})}
    summary = trial_summary(world, arrays, {}, res.robot)  # (nothing converges here)
    summary["distance_m"] = float(np.asarray(  # (not across the jumps between episodes)
        [path_length(p.arrays["pose"][:, :2]) for p in parts]).sum())
    for key, v in scores.items():
        summary[summary_key("eval", world.name, key)] = v
    return TrialResult(k, spec.seed, world.name, arrays, parts[0].behaviours, summary,
                       episodes, policies=parts[0].policies,
                       plugin_data={} if episodic else parts[0].plugin_data)


def batch_scores(result: TrialResult) -> dict[str, Any]:
    """The protocol's aggregates of a batch returned by :func:`run_batch`."""
    prefix = summary_key("eval", result.world, "")
    return {k[len(prefix):]: v for k, v in result.summary.items() if k.startswith(prefix)}


_min = np.minimum.reduce  # (``ndarray.min`` without its Python wrapper)

#: Name of the per-iteration sensor readings in a trial's arrays and the log
#: (sensor-neutral; logs before contract v2 call it ``sonar``, read back as both).
READING = "reading"


def _nearest(reading: np.ndarray) -> float:
    """The smallest range of a reading; NaN here is the sensor's fault, found at once."""
    v = float(_min(reading))
    if not v >= 0.0:  # NaN, or a negative range
        raise BoundaryError(sensor_spec_mismatch(reading, reading.size) or "returned NaN")
    return v


def _loop_fault(exc: Exception, step_at: _Step, trial: int, t: int, res: Resolved,
                scope: dict[str, Any]) -> PluginFault:
    """The fault for ``exc`` raised at ``step_at``; blame a bad upstream value where there is one.

    The loop checks readings and memberships cheaply (type and shape); when a
    later component fails, the full checks run on this iteration's inputs
    first, so a NaN reading is blamed on the sensor, not on the behaviour
    that choked on it.
    """
    if step_at.origin is not None and step_at.method != "read":
        c = res.run.n_situations
        for name in ("reading2", "reading"):
            r = scope.get(name)
            if isinstance(r, np.ndarray) and (why := sensor_spec_mismatch(
                    r, res.run.sensor.dim, res.run.sensor.max_range)):
                return PluginFault(why, where=str(res.origins["sensor"]), method="read",
                                   trial=trial, iteration=t)
        for name in ("u2", "u"):
            u = scope.get(name)
            if isinstance(u, np.ndarray) and c is not None and (why := memberships_mismatch(u, c)):
                return PluginFault(why, where=str(res.origins["interpreter"]),
                                   method="memberships", trial=trial, iteration=t)
    if isinstance(exc, BoundaryError):
        return PluginFault(str(exc), where=str(step_at.origin or "an observer"),
                           method=step_at.method, trial=trial, iteration=t)
    return fault(exc, step_at.origin or "an observer (sitframe_step)", step_at.method, trial, t)


def _check_memberships_rows(u: np.ndarray, origin: Origin, trial: int, first: int = 0) -> None:
    """Vectorised check of a space's memberships over a finished trial (the rows from
    iteration ``first`` on)."""
    bad = ~np.isfinite(u).all(axis=1) | (u < 0).any(axis=1) | \
        (np.abs(u.sum(axis=1) - 1.0) > MEMBERSHIP_SUM_TOL)
    if bad.any():
        t = int(np.argmax(bad))
        raise PluginFault(memberships_mismatch(u[t], u.shape[1]) or "invalid", where=str(origin),
                          method="memberships", trial=trial, iteration=first + t)


def _check_trial_values(readings: np.ndarray, u: np.ndarray, weights: np.ndarray,
                        origins: dict[str, Origin], trial: int, max_range: float,
                        first: int = 0) -> None:
    """Vectorised checks of every reading, membership vector and weight of a finished trial
    (the rows from iteration ``first`` on)."""
    def nonfinite(x: np.ndarray) -> np.ndarray:
        return ~np.isfinite(x).all(axis=1)

    for values, bad, key, method, why in (
            (readings, nonfinite(readings) | (readings > max_range).any(axis=1), "sensor", "read",
             lambda r: sensor_spec_mismatch(r, readings.shape[1], max_range) or "non-finite"),
            (u, nonfinite(u) | (u < 0).any(axis=1)
             | (np.abs(u.sum(axis=1) - 1.0) > MEMBERSHIP_SUM_TOL), "interpreter", "memberships",
             lambda m: memberships_mismatch(m, u.shape[1]) or "invalid"),
            (weights, nonfinite(weights) | (weights < 0).any(axis=1), "arbiter", "combine",
             lambda w: f"returned {'non-finite' if not np.isfinite(w).all() else 'negative'} "
                       f"weights {w.tolist()}, expected the share each proposal got (>= 0)")):
        if bad.any():
            t = int(np.argmax(bad))
            raise PluginFault(why(values[t]), where=str(origins[key]), method=method,
                              trial=trial, iteration=first + t)


def _checked(origin: Origin, method: str, check: Callable[[Any], Any], fn: Callable[[], Any],
             trial: int, *what: str) -> Any:
    value = call(origin, method, fn, trial=trial)
    try:
        return check(value, *what)
    except BoundaryError as exc:
        raise PluginFault(str(exc), where=str(origin), method=method, trial=trial) from None


def _collect_plugin_data(result: TrialResult, components: list[tuple[str, Any]],
                         tinfo: TrialInfo, origins: dict[str, Origin], res: Resolved) -> None:
    """Components' ``trial_end`` and observers' ``sitframe_trial_data`` into ``plugin_data``."""
    k = result.index

    def add(plugin: str, where: str, data: dict[str, Any]) -> None:
        box = result.plugin_data.setdefault(plugin, {})
        for key, v in data.items():
            if key in box:
                raise PluginFault(f"hands '{key}' for the log, which another component of the "
                                  f"same plugin already handed", where=where,
                                  method="trial_end", trial=k)
            box[key] = v

    for key, comp in components:
        if hasattr(comp, "trial_end"):
            o = origins[key]
            data = _checked(o, "trial_end", check_data, lambda c=comp: c.trial_end(tinfo), k,
                            "per-trial data")
            if data:
                add(o.plugin_name, str(o), data)
    for impl in res.registry.pm.hook.sitframe_trial_data.get_hookimpls():
        where = f"plugin {res.registry.describe_plugin(impl.plugin_name)}"
        try:
            data = check_data(impl.function(trial=result), "sitframe_trial_data")
        except BoundaryError as exc:
            raise PluginFault(str(exc), where=where, method="sitframe_trial_data",
                              trial=k) from None
        except (KeyboardInterrupt, TaskCancelled, PluginFault):
            raise
        except PLUGIN_ERRORS as exc:  # an observer's fault is reported, not raw
            raise fault(exc, where, "sitframe_trial_data", k) from exc
        if data:
            add(impl.plugin_name, where, data)


def evaluation_specs(spec: TrialSpec, policies: dict[str, LearnedPolicy],
                     situations: dict[str, Any] | None = None) -> list[TrialSpec]:
    """The evaluations of a finished trial (one spec per ``spec.evaluate`` world).

    ``policies`` are the trial's learned policies (``TrialResult.policies``);
    ``situations`` the trial's final interpreter state when its situations
    evolved (``TrialResult.situations["state"]``), else the spec's is used.
    Each evaluation is a batch of ``spec.protocol``'s episodes (:func:`run_batch`)
    with these policies (by default one run from the world's start, the
    ``frozen`` protocol).
    Parallel executors run these as separate tasks; :func:`attach_evaluation`
    adds their results to the trial in this order.
    """
    if not spec.evaluate:
        return []
    return [dataclasses.replace(
        spec, seed=stage_seed(spec.seed % (2**63), STAGE_EVAL, k), world=wname,
        learn=False, policies=dict(policies), evaluate=(),
        observed=False, interpreter_state=situations or spec.interpreter_state)
        for k, wname in enumerate(spec.evaluate)]


#: Per-iteration arrays of an evaluation kept in the log (enough to replay it and
#: to see where and in which situation it collided).
EVAL_ARRAYS = ("pose", "collision", "contact", "command", "nearest", READING, "memberships")


def attach_evaluation(result: TrialResult, wname: str, ev: TrialResult) -> None:
    """Add evaluation ``ev`` in world ``wname`` (``eval/<wname>/...``) to its trial's result.

    Its arrays (:data:`EVAL_ARRAYS`), per-episode records (``episodes/eval/<wname>/...``),
    the figures of :data:`EVAL_KEYS`, its protocol's aggregates and its plugin data.
    """
    for key in (*EVAL_ARRAYS, *(k for k in ev.arrays if k.startswith("spaces/"))):
        if key in ev.arrays:
            result.episodes[f"eval/{wname}/{key}"] = ev.arrays[key]
    for key, v in ev.episodes.items():
        result.episodes[f"eval/{wname}/{key}"] = v
    scores = {key: ev.summary[key] for key in EVAL_KEYS} | batch_scores(ev)
    for key, v in scores.items():
        result.summary[summary_key("eval", wname, key)] = v
    for plugin, data in ev.plugin_data.items():
        box = result.plugin_data.setdefault(plugin, {})
        box.update({f"eval/{wname}/{k}": v for k, v in data.items()})


def trial_summary(world: World, arrays: dict[str, np.ndarray], bdata: dict[str, dict[str, Any]],
                  robot: RobotParams) -> dict[str, Any]:
    """Scalars of a trial: convergence, collision rates, distance, coverage."""
    coll = arrays["collision"]
    L = coll.size
    if L == 0:
        raise ValueError("a trial needs at least one iteration")
    conv = [d.get("convergence_iteration", -1) for d in bdata.values() if "converged" in d]
    converged = bool(conv) and all(c >= 0 for c in conv)
    conv_it = max(conv) if converged else -1
    xy = arrays["pose"][:, :2]
    out = {
        "iterations": L,
        "converged": converged,
        "convergence_iteration": int(conv_it),
        "collisions": int(coll.sum()),
        "collisions_per_1000": collisions_per_1000(coll),
        "collisions_before_convergence": int(coll[: conv_it if converged else L].sum()),
        "collisions_per_1000_after_convergence":
            collisions_per_1000(coll, conv_it) if converged and conv_it < L else float("nan"),
        "distance_m": path_length(xy),
        "mean_speed_m_s": float(arrays["command"][:, 1].mean()),
        "coverage": coverage(world, xy, radius=robot.radius),
    }
    for key, val in arrays.items():
        if key.startswith("reward/"):
            out[f"mean_{key.replace('/', '_')}"] = float(val.mean())
    return out


@dataclass(frozen=True)
class TrialWork:
    """How a trial splits into tasks for a pool (:class:`~sitframe.runs.parallel.TrialPipeline`)
    and is put back together: the learning part, then one task per evaluation world."""

    learning: Callable[[TrialSpec], TrialSpec]
    evaluations: Callable[[TrialSpec, TrialResult], list[TrialSpec]]
    attach: Callable[[TrialResult, str, TrialResult], None]


#: The control loop's :class:`TrialWork`: the same pieces :func:`simulate` runs in sequence.
TRIAL_WORK = TrialWork(
    learning=lambda spec: dataclasses.replace(spec, evaluate=()) if spec.evaluate else spec,
    evaluations=lambda spec, result: evaluation_specs(spec, result.policies,
                                                      result.situations.get("state")),
    attach=attach_evaluation)
