"""The scheduler: resolves components from a config and runs the stages.

Stages of an experiment (DESIGN section 3): **collect** sensor data →
**cluster** (fit the situation interpreter) → **learn** (N independent
trials) → **evaluate** (each trial's frozen policy in other worlds). The core
knows no component by name: everything is looked up in the
:class:`~sitframe.pluginmanager.Registry` by the names the config gives.

One control iteration (1.5 s of robot time)::

    reading   = sensor.read(world, pose, rng)
    u         = interpreter.memberships(reading)
    proposals = {label: b.propose(context) for b in behaviours}
    proposal  = arbiter.combine(context, proposals)
    outcome   = step_robot(world, pose, command, robot, rng)
    r         = reward(transition)        # per learning behaviour
    b.learn(transition, r)
    hook.sitframe_step(record)            # only if some plugin implements it

Seeds: the run seed ``S`` gives each stage and each trial its own
:class:`numpy.random.SeedSequence` (``spawn_key`` = stage, trial), so trial
``k`` is the same whatever the number of trials or workers, and all
randomness of a trial flows from one :class:`numpy.random.Generator`.
"""

from __future__ import annotations

import dataclasses
import inspect
import platform
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pluggy

from sitframe import __version__
from sitframe.collect import Collected, collect_trajectories, collect_wander, concat_collected
from sitframe.config import config_hash, to_toml
from sitframe.contract import (
    MEMBERSHIP_SUM_TOL,
    BoundaryError,
    Origin,
    blame,
    call,
    check_combined,
    check_data,
    check_memberships,
    check_policy,
    check_proposal,
    check_protocol,
    check_reading,
    check_reward,
    fault,
    memberships_mismatch,
    sensor_spec_mismatch,
)
from sitframe.errors import InputError, PluginError, PluginFault, TaskCancelled
from sitframe.metrics import collisions_per_1000, coverage, path_length
from sitframe.pluginmanager import Registry, get_plugin_manager
from sitframe.records import (
    Context,
    LearnedPolicy,
    Proposal,
    RunContext,
    RunInfo,
    SensorSpec,
    StepRecord,
    Transition,
    TrialInfo,
    TrialResult,
)
from sitframe.robot import Command, RobotParams, step_robot
from sitframe.world import Goal, World, load_world

#: Seed stages (:func:`stage_seed`); ``STAGE_BATCH``: the episode batches of a run that
#: does not learn (one per world of its evaluation protocol).
STAGE_COLLECT, STAGE_CLUSTER, STAGE_TRIALS, STAGE_EVAL, STAGE_BATCH = 0, 1, 2, 3, 4
#: Summary keys of a frozen-policy evaluation (``evaluate --json`` and ``eval/<world>/...``).
EVAL_KEYS = ("iterations", "collisions", "collisions_per_1000", "distance_m", "mean_speed_m_s",
             "coverage")


def stage_seed(seed: int, stage: int, index: int = 0) -> int:
    """A 64-bit seed for ``(stage, index)`` derived from the run seed."""
    ss = np.random.SeedSequence(entropy=seed, spawn_key=(stage, index))
    return int(ss.generate_state(1, np.uint64)[0])


#: Keys of a ``[behaviours.LABEL]`` (or ``[arbiter]``) table that are not component parameters.
META_KEYS = ("component", "reward", "reward_params", "policy_from")


@dataclass
class Resolved:
    """A config resolved against a registry: creates fresh, checked, bound components on demand.

    Every component is checked against its protocol when created and bound
    to the run (``bind(run)``, :class:`sitframe.records.RunContext`) before it
    is used; :attr:`origins` names the plugin behind each config key for
    messages.
    """

    cfg: dict[str, Any]
    registry: Registry
    file: str | None = None
    robot: RobotParams = field(default_factory=RobotParams)
    _worlds: dict[str, World] = field(default_factory=dict)
    origins: dict[str, Origin] = field(default_factory=dict)
    run: RunContext | None = None
    base_dir: str = "."

    @classmethod
    def build(cls, cfg: dict[str, Any], registry: Registry, file: str | None = None,
              worlds: tuple[str, ...] = (), base_dir: str = ".") -> Resolved:
        """Resolve ``cfg``: create and bind each component once, so every mistake is found now.

        ``worlds`` names further worlds the caller will use (e.g. ``--world``);
        relative world paths resolve against ``base_dir`` (the config's folder).

        Plugin code that fails here (a property or ``bind`` that raises, a
        first reading that breaks the sensor's spec) fails before anything
        runs or is written: it is a :class:`PluginError` (CLI exit 2), not a
        :class:`PluginFault` of a run (exit 3, a log marked failed).
        """
        try:
            return cls._build(cfg, registry, file, worlds, base_dir)
        except PluginFault as exc:
            raise PluginError(str(exc)) from exc

    @classmethod
    def _build(cls, cfg: dict[str, Any], registry: Registry, file: str | None,
               worlds: tuple[str, ...], base_dir: str) -> Resolved:
        try:
            robot = RobotParams(**cfg["robot"])
        except InputError as exc:
            raise exc.at(file=file, key_prefix="robot") from None
        except (ValueError, TypeError) as exc:
            raise InputError(str(exc), file=file, key="robot") from None
        res = cls(cfg, registry, file, robot, base_dir=base_dir)
        sensor = res._create("sensor", "sensor", cfg["sensor"], bind=False)
        o = res.origins["sensor"]
        spec = call(o, "angles_deg", lambda: SensorSpec(
            str(sensor.name), np.asarray(sensor.angles_deg, dtype=np.float64).reshape(-1),
            float(sensor.max_range), str(getattr(sensor, "unit", "m"))))
        interp = res._create("interpreter", "interpreter", cfg["interpreter"], bind=False)
        c = call(res.origins["interpreter"], "n_situations", lambda: interp.n_situations)
        if c is not None and (isinstance(c, bool) or not isinstance(c, int | np.integer) or c < 1):
            raise PluginFault(f"n_situations is {c!r}, expected a positive integer",
                              where=str(res.origins["interpreter"]), method="n_situations")
        e = cfg["experiment"]
        names = [e["world"], *worlds]
        if "collect" in e["stages"] and not e.get("clusters_from"):
            names += cfg["collect"]["worlds"]
        if "evaluate" in e["stages"]:
            names += cfg["evaluate"]["worlds"]
        loaded = {}
        for n in dict.fromkeys(names):
            loaded[n] = res.world(n, "experiment.world" if n == e["world"] else "worlds")
        res.run = RunContext(robot, spec, tuple(cfg["behaviours"]), None if c is None else int(c),
                             loaded, int(e["seed"]), int(e["iterations"]),
                             float(e["default_speed"]))
        res._bind(sensor, "sensor")
        res._check_sensor(sensor, spec, loaded[e["world"]])
        res._bind(interp, "interpreter")
        res.behaviours()
        res.arbiter()
        return res

    def _check_sensor(self, sensor: Any, spec: SensorSpec, world: World) -> None:
        """Read once at the learning world's start: the reading must match the declared spec."""
        o = self.origins["sensor"]
        reading = call(o, "read", sensor.read, world, world.start.copy(),
                       np.random.default_rng(0))
        why = sensor_spec_mismatch(reading, spec.dim)
        if why is not None:
            raise PluginFault(why, where=str(o), method="read")

    def _create(self, kind: str, key: str, table: dict[str, Any], *, bind: bool = True,
                needs: tuple[str, ...] = ()) -> Any:
        params = {k: v for k, v in table.items() if k not in META_KEYS}
        comp = self.registry.create(kind, table["component"], params, file=self.file, key=key)
        entry = self.registry.get(kind, table["component"])
        origin = Origin(self.registry.describe_plugin(entry.plugin), kind, entry.name, key,
                        entry.plugin)
        self.origins[key] = origin
        check_protocol(comp, origin, needs=needs)
        if bind:
            self._bind(comp, key)
        return comp

    def _bind(self, comp: Any, key: str) -> None:
        fn = getattr(comp, "bind", None)
        if fn is None:
            return
        o = self.origins[key]
        try:
            fn(dataclasses.replace(self.run, component=key))
        except InputError as exc:
            raise exc.at(file=self.file, key_prefix=key) from None
        except (ValueError, TypeError) as exc:  # the component's parameters do not fit the run
            raise InputError(f"{exc} ({o.kind} '{o.name}' of plugin {o.plugin}, at bind)",
                             file=self.file, key=key) from None
        except (KeyboardInterrupt, PluginFault):
            raise
        except Exception as exc:  # noqa: BLE001 - any other fault in plugin code
            raise fault(exc, o, "bind") from exc

    def sensor(self) -> Any:
        return self._create("sensor", "sensor", self.cfg["sensor"])

    def interpreter(self) -> Any:
        return self._create("interpreter", "interpreter", self.cfg["interpreter"])

    def arbiter(self) -> Any:
        table = self.cfg["arbiter"]
        return self._create("arbiter", "arbiter", table,
                            needs=("learn",) if "reward" in table else ())

    def arbiter_reward(self) -> Any | None:
        """The reward the arbiter learns from (``[arbiter] reward = ...``), or ``None``."""
        table = self.cfg["arbiter"]
        if "reward" not in table:
            return None
        return self._create("reward", "arbiter.reward", {
            "component": table["reward"], **dict(table.get("reward_params", {}))})

    def behaviours(self) -> dict[str, tuple[Any, Any | None]]:
        """Label -> (behaviour, reward or None), in config order."""
        out = {}
        for label, table in self.cfg["behaviours"].items():
            key = f"behaviours.{label}"
            needs = (("learn",) if "reward" in table else ()) + \
                (("load_policy",) if "policy_from" in table else ())
            beh = self._create("behaviour", key, table, needs=needs)
            reward = None
            if "reward" in table:
                reward = self._create("reward", f"{key}.reward", {
                    "component": table["reward"], **dict(table.get("reward_params", {}))})
            out[label] = (beh, reward)
        return out

    def protocol_name(self) -> str | None:
        """The evaluation protocol the run's components name (``evaluation_protocol``), or None.

        A component asks for the protocol its behaviour is judged by with a
        class attribute, e.g. ``evaluation_protocol = "goal-episodes"``; two
        components naming different protocols are an input error.
        """
        comps = [b for b, _r in self.behaviours().values()] + [self.arbiter()]
        names = sorted({n for c in comps if (n := getattr(c, "evaluation_protocol", None))})
        if len(names) > 1:
            raise InputError(f"the components ask for different evaluation protocols "
                             f"({', '.join(names)}); expected one", file=self.file,
                             key="behaviours")
        return names[0] if names else None

    def protocol(self, name: str) -> Any:
        """A fresh evaluation protocol ``name``, created from its config table (but ``worlds``)."""
        entry = self.registry.get("protocol", name, file=self.file, key="behaviours")
        table = str(getattr(entry.factory, "table", "evaluate"))
        params = {k: v for k, v in self.cfg.get(table, {}).items() if k != "worlds"}
        return self._create("protocol", table, {**params, "component": name})

    def protocol_worlds(self, name: str) -> list[str]:
        """The worlds of protocol ``name``'s table, loaded and checked (``check_world``)."""
        proto = self.protocol(name)
        table = proto.table
        names = list(self.cfg[table]["worlds"])
        for j, wname in enumerate(names):
            key = f"{table}.worlds[{j}]"
            world = self.world(wname, key=key)
            if hasattr(proto, "check_world"):
                try:
                    call(self.origins[table], "check_world", proto.check_world, world)
                except InputError as exc:
                    raise InputError(exc.message, file=self.file, key=key) from None
        return names

    def world(self, name: str, key: str = "experiment.world") -> World:
        """The world ``name``: a shipped name, or a .toml path relative to :attr:`base_dir`
        (the config file's folder)."""
        if name not in self._worlds:
            path: str | Path = name  # a shipped name
            if name.endswith(".toml") or "/" in name:
                path = Path(name)
                if not path.is_absolute() and self.base_dir not in ("", "."):
                    path = Path(self.base_dir) / path
            try:
                self._worlds[name] = load_world(path)
            except InputError as exc:
                if exc.file is None or (isinstance(path, Path) and not path.is_file()):
                    # the path itself is wrong: the config's key is where to fix it
                    where = f" ({exc.file})" if exc.file else ""
                    raise InputError(f"{exc.message}{where}", file=self.file, key=key) from None
                raise
            w = self._worlds[name]
            clear = float(w.clearance(w.start[None, :2])[0])
            # (collection rooms are driven along their trajectories, not from the start pose)
            if not key.startswith("collect") and clear < self.robot.radius:
                raise InputError(f"the robot disc (radius {self.robot.radius:g} m) does not fit at "
                                 f"the start pose of world '{name}' (clearance {clear:.3g} m); "
                                 f"expected robot.radius <= {clear:.3g} or another world",
                                 file=self.file, key="robot.radius")
        return self._worlds[name]


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
    eval_iterations
        Iterations per evaluation.
    start
        Start pose (x [m], y [m], theta [rad]); ``None`` = the world's start.
    goal
        Goal (x [m], y [m], radius [m]) given to behaviours in the context;
        ``None`` = the world's ``[goal]`` if any.
    protocol
        The evaluation protocol (:class:`sitframe.components.EvaluationProtocol`)
        by name: a spec that does not learn is then a *batch* of its episodes in
        ``world`` (:func:`run_batch`), returned as one trial; a learning spec's
        evaluations are such batches. ``None``: frozen-policy evaluations.
    observed
        Whether ``sitframe_step`` observers see the trial's iterations (not in
        the evaluations of a learning trial).
    """

    index: int
    seed: int
    world: str
    iterations: int
    learn: bool
    interpreter_state: dict[str, Any]
    policies: dict[str, dict[str, np.ndarray]] = field(default_factory=dict)
    evaluate: tuple[str, ...] = ()
    eval_iterations: int = 1000
    start: tuple[float, float, float] | None = None
    goal: tuple[float, float, float] | None = None
    protocol: str | None = None
    observed: bool = True


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


def step_hook_of(pm: pluggy.PluginManager) -> Callable[[StepRecord], Any] | None:
    """A function firing ``sitframe_step`` observers, or ``None`` when no plugin implements it.

    An observer that raises is a :class:`PluginFault` naming its plugin (the
    one whose ``sitframe_step`` is on the traceback), the trial and the iteration.
    """
    hook = pm.hook
    impls = hook.sitframe_step.get_hookimpls()
    if not impls:
        return None
    info = getattr(pm, "sitframe_info", {})

    def step_hook(rec: StepRecord) -> None:
        try:
            hook.sitframe_step(record=rec)
        except (KeyboardInterrupt, TaskCancelled, PluginFault):
            raise
        except Exception as exc:  # noqa: BLE001 - an observer's fault is reported, not raw
            name = blame(exc, impls)
            where = (f"plugin {info[name].describe() if name in info else name}"
                     if name else "an observer")
            raise fault(exc, where, "sitframe_step", rec.trial,
                        rec.transition.before.iteration) from exc

    return step_hook


def simulate(
    res: Resolved,
    spec: TrialSpec,
    *,
    step_hook: Callable[[StepRecord], Any] | None = None,
    protocol: Any = None,
) -> TrialResult:
    """Run one trial (learning, frozen evaluation or episode) and return its arrays.

    An evaluation ``protocol``'s ``terminated(context)``, called after every
    iteration, ends the trial early; ``iterations`` is then only its limit. A
    spec with a protocol that does not learn is a batch of episodes
    (:func:`run_batch`). ``step_hook`` fires for learning trials and episode
    batches of their own, never for the evaluations of a learning trial
    (``observed=False``), whichever executor runs them: the serial one runs
    them here, a pool as separate tasks, and the logs must not differ.

    Raises
    ------
    PluginFault
        Plugin code raised, or returned a value that breaks the contract
        (:mod:`sitframe.contract`); names the plugin, component, method,
        trial and iteration.
    """
    if not spec.observed:
        step_hook = None  # an evaluation of a learning trial (sitframe_step: "not called")
    if spec.protocol is not None and not spec.learn:
        return run_batch(res, spec, step_hook=step_hook)
    rng = np.random.default_rng(spec.seed)
    world = res.world(spec.world)
    goal = world.goal if spec.goal is None else Goal(np.asarray(spec.goal[:2], float),
                                                     float(spec.goal[2]))
    k = spec.index
    with _in_trial(k):  # each trial creates and binds its own components
        sensor = res.sensor()
        interp = res.interpreter()
    og = res.origins  # the component origins, for messages
    call(og["interpreter"], "load_state", interp.load_state, spec.interpreter_state, trial=k)
    c = call(og["interpreter"], "n_situations", lambda: int(interp.n_situations), trial=k)
    with _in_trial(k):
        behaviours = res.behaviours()
        arbiter = res.arbiter()
        arb_reward = res.arbiter_reward() if spec.learn else None
    L = spec.iterations
    for label, (beh, _r) in behaviours.items():
        o = og[f"behaviours.{label}"]
        if label in spec.policies:
            call(o, "load_policy", beh.load_policy, spec.policies[label], trial=k)
        call(o, "reset", beh.reset, rng, c, L, trial=k)
    if "arbiter" in spec.policies and hasattr(arbiter, "load_policy"):
        call(og["arbiter"], "load_policy", arbiter.load_policy, spec.policies["arbiter"], trial=k)
    if hasattr(arbiter, "reset"):
        call(og["arbiter"], "reset", arbiter.reset, rng, c, L, trial=k)
    learners = [(label, beh, rew, og[f"behaviours.{label}"], og[f"behaviours.{label}.reward"])
                for label, (beh, rew) in behaviours.items() if rew is not None and spec.learn]
    if arb_reward is not None:
        learners.append(("arbiter", arbiter, arb_reward, og["arbiter"], og["arbiter.reward"]))
    labels = list(behaviours)
    components = [("sensor", sensor), ("interpreter", interp),
                  *[(f"behaviours.{lb}", b) for lb, (b, _r) in behaviours.items()],
                  *[(f"behaviours.{lb}.reward", r) for lb, (_b, r) in behaviours.items()
                    if r is not None and spec.learn],  # (a frozen run uses no reward)
                  ("arbiter", arbiter), ("arbiter.reward", arb_reward)]
    components = [(key, comp) for key, comp in components if comp is not None]
    tinfo = TrialInfo(k, "learn" if spec.learn else "evaluate", world, L, rng)
    for key, comp in components:
        if hasattr(comp, "trial_start"):
            call(og[key], "trial_start", comp.trial_start, tinfo, trial=k)
    default_speed = float(res.cfg["experiment"]["default_speed"])
    robot = res.robot

    d = res.run.sensor.dim
    pose_a = np.empty((L + 1, 3))
    sonar_a = np.empty((L, d))
    u_a = np.empty((L, c))
    cmd_a = np.empty((L, 2))
    coll_a = np.zeros(L, dtype=bool)
    contact_a = np.full((L, 2), np.nan)
    near_a = np.empty(L)
    weights_a = np.empty((L, len(labels)))
    prop_a = {lb: np.empty((L, 2)) for lb in labels}
    rew_a = {lb: np.empty(L) for lb, *_ in learners}

    at_read, at_u = _Step(og["sensor"], "read"), _Step(og["interpreter"], "memberships")
    at_combine, at_core = _Step(og["arbiter"], "combine"), _Step(None, "step")
    at_propose = [(lb, beh, _Step(og[f"behaviours.{lb}"], "propose"))
                  for lb, (beh, _r) in behaviours.items()]
    at_learn = [(lb, beh, rew, _Step(ob, "learn"), _Step(orw, "__call__"))
                for lb, beh, rew, ob, orw in learners]
    at_end = None if protocol is None else _Step(
        og.get(protocol.table) or f"protocol '{protocol.name}'", "terminated")
    step_at = at_read
    t = 0
    pose = np.array(world.start if spec.start is None else spec.start, dtype=float)
    n_done = L
    try:
        reading = sensor.read(world, pose, rng)
        check_reading(reading, d)
        near = _nearest(reading)
        step_at = at_u
        u = interp.memberships(reading)
        check_memberships(u, c)
        ctx = Context(0, pose, reading, u, near, world, goal)
        for t in range(L):
            proposals = {}
            for lb, beh, step_at in at_propose:  # noqa: B007 - step_at names the caller on a fault
                proposals[lb] = check_proposal(beh.propose(ctx))
            step_at = at_combine
            prop, weights = check_combined(arbiter.combine(ctx, proposals), len(labels))
            step_at = at_core
            speed = prop.speed_m_s if prop.speed_m_s is not None else default_speed
            cmd = Command(prop.heading_deg, speed)
            out = step_robot(world, pose, cmd, robot, rng)
            pose = out.pose
            step_at = at_read
            reading2 = sensor.read(world, pose, rng)
            check_reading(reading2, d)
            near = _nearest(reading2)
            step_at = at_u
            u2 = interp.memberships(reading2)
            check_memberships(u2, c)
            ctx2 = Context(t + 1, pose, reading2, u2, near, world, goal)
            tr = Transition(ctx, cmd, out, ctx2)
            rewards = {}
            for lb, beh, rew, at_l, step_at in at_learn:
                r = check_reward(rew(tr))
                rewards[lb] = r
                rew_a[lb][t] = r
                step_at = at_l
                beh.learn(tr, r)
            pose_a[t] = ctx.pose
            sonar_a[t] = ctx.reading
            u_a[t] = ctx.memberships
            cmd_a[t] = (cmd.heading_change_deg, cmd.speed_m_s)
            if out.collided:
                coll_a[t] = True
                contact_a[t] = out.contact_xy
            near_a[t] = ctx.nearest
            weights_a[t] = weights
            for lb in labels:
                p = proposals[lb]
                prop_a[lb][t] = (p.heading_deg, np.nan if p.speed_m_s is None else p.speed_m_s)
            if step_hook is not None:
                step_at = _Step(None, "sitframe_step")
                step_hook(StepRecord(spec.index, tr, proposals, weights, rewards))
            ctx = ctx2
            if at_end is not None and (step_at := at_end) and protocol.terminated(ctx):
                n_done = t + 1
                break
    except (KeyboardInterrupt, TaskCancelled, PluginFault, InputError):
        raise  # (a plugin's InputError names the input it found wrong)
    except Exception as exc:
        if step_at.origin is None and step_at.method == "step":
            raise  # the core's own arithmetic: a bug here, not the plugin's
        raise _loop_fault(exc, step_at, k, t, res, locals()) from exc
    pose_a[n_done] = pose
    n = n_done
    _check_trial_values(sonar_a[:n], u_a[:n], weights_a[:n], og, k)
    arrays: dict[str, np.ndarray] = {
        "pose": pose_a[: n + 1], READING: sonar_a[:n], "memberships": u_a[:n],
        "command": cmd_a[:n], "collision": coll_a[:n], "contact": contact_a[:n],
        "nearest": near_a[:n], "weights": weights_a[:n],
    }
    for lb in labels:
        arrays[f"proposals/{lb}"] = prop_a[lb][:n]
    for lb in rew_a:
        arrays[f"reward/{lb}"] = rew_a[lb][:n]
    bdata, policies = {}, {}
    learned = [(lb, b, og[f"behaviours.{lb}"]) for lb, (b, _r) in behaviours.items()]
    if hasattr(arbiter, "policy"):
        learned.append(("arbiter", arbiter, og["arbiter"]))
    for lb, b, o in learned:
        if hasattr(b, "trial_data"):
            bdata[lb] = _checked(o, "trial_data", check_data, b.trial_data, k, "trial data")
        if hasattr(b, "policy"):
            pol = _checked(o, "policy", lambda p: check_policy(p, c), b.policy, k)
            if pol is not None:
                policies[lb] = pol
    summary = trial_summary(world, arrays, bdata, robot)
    result = TrialResult(spec.index, spec.seed, world.name, arrays, bdata, summary,
                         policies=policies)
    _collect_plugin_data(result, components, tinfo, og, res)
    for ev_spec in evaluation_specs(spec, result.policies):
        attach_evaluation(result, ev_spec.world, simulate(res, ev_spec))
    return result


def run_batch(res: Resolved, spec: TrialSpec, *,
              step_hook: Callable[[StepRecord], Any] | None = None) -> TrialResult:
    """Run a batch of ``spec.protocol``'s episodes in ``spec.world``; return it as one trial.

    Start poses (and goals) come from the protocol, given a Generator seeded
    by ``spec.seed``; episode ``e`` runs with its own seed spawned from it, so
    a batch is reproducible and episode ``e`` does not depend on the others.
    Each episode is :func:`simulate` from its start, with its goal, until the
    protocol's ``terminated`` or its ``iterations``. The trial holds the
    episodes' arrays concatenated (``pose`` has one extra row per episode;
    ``episodes["first_iteration"]`` gives each one's first row), the
    per-episode figures (one array per key, and one ``NNNN`` group per
    episode) and the summary (:func:`trial_summary` over all episodes) with
    the protocol's aggregates as ``eval/<world>/<key>``.
    """
    k = spec.index
    with _in_trial(k):
        proto = res.protocol(str(spec.protocol))
    o = res.origins[proto.table]
    world = res.world(spec.world, key=f"{proto.table}.worlds")
    ss = np.random.SeedSequence(spec.seed % 2**64)
    rng = np.random.default_rng(ss.spawn(1)[0])
    starts, goals = call(o, "episode_starts", proto.episode_starts, world, rng, res.robot,
                         trial=k)
    starts = np.asarray(starts, dtype=float)
    n = len(starts)
    if starts.shape != (n, 3) or n < 1 or (goals is not None and np.shape(goals) != (n, 3)):
        raise PluginFault(f"returned starts of shape {starts.shape} and goals of shape "
                          f"{None if goals is None else np.shape(goals)}; expected (n, 3) "
                          "each (goals may be None), n >= 1", where=str(o),
                          method="episode_starts", trial=k)
    seeds = np.random.SeedSequence(spec.seed % 2**64, spawn_key=(1,)).generate_state(n, np.uint64)
    parts: list[TrialResult] = []
    figures: list[dict[str, Any]] = []
    for e in range(n):
        goal = None if goals is None else tuple(float(v) for v in goals[e])
        ep = dataclasses.replace(spec, seed=int(seeds[e]), iterations=int(proto.iterations),
                                 evaluate=(), start=tuple(float(v) for v in starts[e]),
                                 goal=goal, protocol=None)
        r = simulate(res, ep, step_hook=step_hook, protocol=proto)
        parts.append(r)
        figures.append(_checked(o, "score_episode", check_data, lambda r=r, e=e: (
            proto.score_episode(r.arrays, starts[e], None if goals is None else goals[e],
                                res.robot)), k, "per-episode figures"))
    per_ep = {key: np.asarray([f[key] for f in figures]) for key in figures[0]}
    scores = _checked(o, "aggregate", check_data, lambda: proto.aggregate(per_ep), k,
                      "the batch's scores")
    arrays = {key: np.concatenate([p.arrays[key] for p in parts]) for key in parts[0].arrays}
    first = np.cumsum([0] + [int(p.arrays["collision"].size) for p in parts[:-1]])
    episodes: dict[str, Any] = {**per_ep, "start": starts}
    if goals is not None:
        episodes["goal"] = goals
    episodes["first_iteration"] = first.astype(np.int64)
    for e, f in enumerate(figures):
        episodes[f"{e:04d}"] = row = {**f, "start": starts[e]}
        if goals is not None:
            row["goal"] = goals[e]
    summary = trial_summary(world, arrays, {}, res.robot)  # (nothing converges here)
    summary["distance_m"] = float(np.asarray(  # (not across the jumps between episodes)
        [path_length(p.arrays["pose"][:, :2]) for p in parts]).sum())
    for key, v in scores.items():
        summary[summary_key("eval", world.name, key)] = v
    return TrialResult(k, spec.seed, world.name, arrays, parts[0].behaviours, summary,
                       episodes, policies=parts[0].policies)


def batch_scores(result: TrialResult) -> dict[str, Any]:
    """The protocol's aggregates of a batch returned by :func:`run_batch`."""
    prefix = summary_key("eval", result.world, "")
    return {k[len(prefix):]: v for k, v in result.summary.items() if k.startswith(prefix)}


#: Name of the per-iteration sensor readings in a trial's arrays and the log
#: (sensor-neutral; logs before contract v2 call it ``sonar``, read back as both).
READING = "reading"


def _nearest(reading: np.ndarray) -> float:
    """The smallest range of a reading; NaN here is the sensor's fault, found at once."""
    v = float(reading.min())
    if v != v:  # NaN
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
            if isinstance(r, np.ndarray) and (why := sensor_spec_mismatch(r, res.run.sensor.dim)):
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


def _check_trial_values(readings: np.ndarray, u: np.ndarray, weights: np.ndarray,
                        origins: dict[str, Origin], trial: int) -> None:
    """Vectorised checks of every reading, membership vector and weight of a finished trial."""
    bad = ~np.isfinite(readings).all(axis=1)
    if bad.any():
        t = int(np.argmax(bad))
        raise PluginFault(sensor_spec_mismatch(readings[t], readings.shape[1]) or "non-finite",
                          where=str(origins["sensor"]), method="read", trial=trial, iteration=t)
    bad = ~np.isfinite(u).all(axis=1) | (u < 0).any(axis=1) | \
        (np.abs(u.sum(axis=1) - 1.0) > MEMBERSHIP_SUM_TOL)
    if bad.any():
        t = int(np.argmax(bad))
        raise PluginFault(memberships_mismatch(u[t], u.shape[1]) or "invalid",
                          where=str(origins["interpreter"]), method="memberships", trial=trial,
                          iteration=t)
    bad = ~np.isfinite(weights).all(axis=1)
    if bad.any():
        t = int(np.argmax(bad))
        raise PluginFault(f"returned non-finite weights {weights[t].tolist()}",
                          where=str(origins["arbiter"]), method="combine", trial=trial,
                          iteration=t)


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
        except Exception as exc:  # noqa: BLE001 - an observer's fault is reported, not raw
            raise fault(exc, where, "sitframe_trial_data", k) from exc
        if data:
            add(impl.plugin_name, where, data)


def evaluation_specs(spec: TrialSpec, policies: dict[str, LearnedPolicy]) -> list[TrialSpec]:
    """The evaluations of a finished trial (one spec per ``spec.evaluate`` world).

    ``policies`` are the trial's learned policies (``TrialResult.policies``).
    With a ``spec.protocol`` each evaluation is a batch of its episodes
    (:func:`run_batch`) with these policies, else one frozen-policy run of
    ``eval_iterations`` from the world's start.
    Parallel executors run these as separate tasks; :func:`attach_evaluation`
    adds their results to the trial in this order.
    """
    if not spec.evaluate:
        return []
    return [dataclasses.replace(
        spec, seed=stage_seed(spec.seed % (2**63), STAGE_EVAL, k), world=wname,
        iterations=spec.eval_iterations, learn=False, policies=dict(policies), evaluate=(),
        observed=False) for k, wname in enumerate(spec.evaluate)]


#: Per-iteration arrays of a frozen-policy evaluation kept in the log (enough to
#: replay it and to see where and in which situation it collided).
EVAL_ARRAYS = ("pose", "collision", "contact", "command", "nearest", READING, "memberships")


def attach_evaluation(result: TrialResult, wname: str, ev: TrialResult) -> None:
    """Add evaluation ``ev`` in world ``wname`` (``eval/<wname>/...``) to its trial's result.

    A batch of episodes (:func:`run_batch`) also brings its per-episode
    figures (``episodes/eval/<wname>/...``) and its protocol's aggregates.
    """
    for key in EVAL_ARRAYS:
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


def summary_key(*parts: str) -> str:
    """The one spelling of a summary key: ``eval/<world>/<metric>`` (``.`` in the log's table)."""
    return "/".join(parts)


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


class SerialExecutor:
    """Runs trials one after another in this process (fires ``sitframe_step``).

    The executor protocol is ``map(experiment, specs)`` yielding one
    :class:`TrialResult` per spec, in the order of ``specs``, as soon as each
    is available (so observers can log trial ``k`` before ``k + 1`` ends).
    Parallel executors (:mod:`sitframe.parallel`) follow the same protocol
    but run in other processes, where ``sitframe_step`` observers do not fire.
    """

    #: ``sitframe_step`` observers see every iteration with this executor.
    fires_step_hooks = True

    def map(self, experiment: Experiment, specs: list[TrialSpec]) -> Iterator[TrialResult]:
        step_hook = step_hook_of(experiment.pm)
        for spec in specs:
            yield simulate(experiment.res, spec, step_hook=step_hook)


@dataclass
class RunResult:
    """What :func:`run_experiment` returns (also the basis of ``run --json``)."""

    info: RunInfo
    trials: list[TrialResult]
    wall_seconds: float
    status: str
    interpreter_state: dict[str, Any] = field(default_factory=dict)
    sensor_angles_deg: np.ndarray | None = None


class Experiment:
    """A configured experiment ready to run its stages.

    Parameters
    ----------
    cfg
        Validated config (:func:`sitframe.config.load_config`).
    source
        Where the config came from (for messages).
    pm
        Plugin manager; a fresh one from :func:`get_plugin_manager` by default.
    out
        HDF5 log path (written by the logger plugin), or ``None``.
    plugins_dirs
        Folders of loose plugin modules (also loaded by worker processes).
    executor
        Runs the trials: anything with ``map(experiment, specs)`` yielding
        :class:`TrialResult` in the order of ``specs``. Default
        :class:`SerialExecutor` (in this process, with ``sitframe_step``).
    base_dir
        Folder that world paths in the config are relative to (the config
        file's folder).
    """

    def __init__(self, cfg: dict[str, Any], *, source: str | None = None,
                 pm: pluggy.PluginManager | None = None, out: str | None = None,
                 plugins_dirs: tuple[str, ...] = (), executor: Any = None,
                 base_dir: str = ".") -> None:
        self.cfg = cfg
        self.source = source
        self.base_dir = base_dir
        self.plugins_dirs = tuple(plugins_dirs)
        self.executor = executor or SerialExecutor()
        self.pm = pm or get_plugin_manager(plugins_dirs=plugins_dirs)
        self.registry = Registry.collect(self.pm)
        self.res = Resolved.build(cfg, self.registry, source, base_dir=base_dir)
        self.out = out
        text = to_toml(cfg)
        e = cfg["experiment"]
        worlds = {}
        names = [e["world"]]
        if "collect" in e["stages"]:
            names += cfg["collect"]["worlds"]
        if "evaluate" in e["stages"]:
            names += cfg["evaluate"]["worlds"]
        #: The run's evaluation protocol (:meth:`Resolved.protocol_name`); None = frozen.
        self.protocol = self.res.protocol_name()
        self.eval_worlds = list(cfg["evaluate"]["worlds"])
        if self.protocol is not None and "evaluate" in e["stages"]:
            self.eval_worlds = self.res.protocol_worlds(self.protocol)
            names += self.eval_worlds
        for name in dict.fromkeys(names):
            key = "experiment.world" if name == e["world"] else "worlds"
            worlds[name] = self.res.world(name, key).text
        plugins = [dataclasses.asdict(info) for info, _c in self.registry.plugins_table()]
        self.info = RunInfo(
            name=e["name"], config=cfg, config_text=text, config_hash=config_hash(text),
            seed=int(e["seed"]), out=out, n_trials=int(e["trials"]),
            iterations=int(e["iterations"]), plugins=plugins, worlds=worlds,
            extra={"versions": versions(), "source": source or "",
                   "sensor": self.res.run.sensor.as_dict()},
        )

    # -- stages ------------------------------------------------------------
    def collect(self) -> Collected:
        c = self.cfg["collect"]
        rng = np.random.default_rng(stage_seed(self.info.seed, STAGE_COLLECT))
        worlds = [self.res.world(n, "collect.worlds") for n in c["worlds"]]
        sensor = self.res.sensor()
        o = self.res.origins["sensor"]
        parts = []
        if c["mode"] in ("trajectory", "both"):
            parts.append(call(o, "read", collect_trajectories, worlds, sensor, rng,
                              speed=c["speed"], rate_hz=c["rate_hz"], params=self.res.robot))
        if c["mode"] in ("wander", "both"):
            parts.append(call(o, "read", collect_wander, worlds, sensor, rng,
                              n_samples=c["wander_samples"], speed=c["speed"],
                              rate_hz=c["rate_hz"], params=self.res.robot))
        collected = concat_collected(parts)
        why = sensor_spec_mismatch(collected.samples[0], self.res.run.sensor.dim) \
            if len(collected.samples) else None
        bad = ~np.isfinite(collected.samples).all(axis=1)
        if why is None and bad.any():
            why = sensor_spec_mismatch(collected.samples[int(np.argmax(bad))],
                                       self.res.run.sensor.dim)
        if why is not None:
            raise PluginFault(f"{why} (collect stage)", where=str(o), method="read")
        return collected

    def cluster(self, samples: np.ndarray,
                pmap: Any = None) -> tuple[dict[str, Any], dict[str, Any]]:
        """Fit the interpreter on ``samples``; ``pmap`` is passed on if its ``fit`` takes one."""
        rng = np.random.default_rng(stage_seed(self.info.seed, STAGE_CLUSTER))
        interp = self.res.interpreter()
        c = getattr(interp, "n_situations", None)
        if isinstance(c, int) and len(samples) < c:
            raise InputError(f"the collect stage recorded {len(samples)} samples, fewer than the "
                             f"{c} situations to fit; expected at least {c}: collect more "
                             "(collect.worlds, collect.rate_hz, collect.mode) or lower c",
                             file=self.source, key="interpreter.c")
        o = self.res.origins["interpreter"]
        if pmap is not None and "pmap" in inspect.signature(interp.fit).parameters:
            fit = call(o, "fit", interp.fit, samples, rng, pmap=pmap)
        else:
            fit = call(o, "fit", interp.fit, samples, rng)
        state = call(o, "state", interp.state)
        for what, d in (("fit", fit), ("state", state)):
            try:
                check_data(d, "the fitted interpreter, to log")
            except BoundaryError as exc:
                raise PluginFault(str(exc), where=str(o), method=what) from None
        return fit or {}, state

    def trial_spec(self, k: int, interpreter_state: dict[str, Any],
                   policies: dict[str, dict[str, np.ndarray]] | None = None) -> TrialSpec:
        e = self.cfg["experiment"]
        evaluate = tuple(self.eval_worlds) if "evaluate" in e["stages"] else ()
        return TrialSpec(
            index=k, seed=stage_seed(self.info.seed, STAGE_TRIALS, k), world=e["world"],
            iterations=int(e["iterations"]), learn=True, interpreter_state=interpreter_state,
            policies=policies or {}, evaluate=evaluate,
            eval_iterations=int(self.cfg["evaluate"]["iterations"]), protocol=self.protocol)

    # -- phases (``run`` composes them; a sweep interleaves them across runs) --
    def begin(self) -> None:
        """Announce the run to observers (the logger creates, or on resume reopens, the log)."""
        self.info.extra.setdefault("step_hooks", bool(
            getattr(self.executor, "fires_step_hooks", True)))
        if self.out and "code_hash" not in self.info.extra:
            from sitframe.logs import code_fingerprint  # h5py: imported only when a run logs

            self.info.extra["code_hash"] = code_fingerprint(self.info.plugins)
        self._notify("sitframe_run_start", run=self.info)

    def needs_clusters(self, interpreter_state: dict[str, Any] | None,
                       collected: Collected | None = None) -> bool:
        """Whether :meth:`prepare` would collect/cluster (raises if the stages cannot)."""
        if interpreter_state is not None:
            return False
        if collected is None and "collect" not in self.cfg["experiment"]["stages"]:
            raise InputError("the run needs clusters: include 'collect' and 'cluster' "
                             "in experiment.stages or reuse clusters from a log",
                             file=self.source, key="experiment.stages")
        return True

    def record_collected(self, collected: Collected) -> None:
        """Hand the collect stage's output to observers."""
        self._notify("sitframe_stage_end", run=self.info, stage="collect", data={
            "samples": collected.samples, "poses": collected.poses,
            "source": collected.source, "worlds": list(collected.worlds)})

    def record_clusters(self, fit: dict[str, Any], state: dict[str, Any]) -> None:
        """Hand the cluster stage's output to observers."""
        self._notify("sitframe_stage_end", run=self.info, stage="cluster",
                                        data={**fit, "state": state})

    def prepare(self, interpreter_state: dict[str, Any] | None = None,
                collected: Collected | None = None) -> dict[str, Any]:
        """Collect and cluster (unless ``interpreter_state`` is given); return the state.

        Situations given from elsewhere (``clusters_from``) are still recorded as
        the cluster stage, so the run's own log is self-contained for
        ``evaluate`` and ``analyse`` (not again when resuming: the log has them).
        """
        if not self.needs_clusters(interpreter_state, collected):
            if not self.info.extra.get("resume"):
                source = self.cfg["experiment"]["clusters_from"] or "given by the caller"
                self.record_clusters({"reused_from": source}, interpreter_state)
            return interpreter_state  # type: ignore[return-value]
        if collected is None:
            collected = self.collect()
            self.record_collected(collected)
        fit, state = self.cluster(collected.samples, getattr(self.executor, "task_map", None))
        self.record_clusters(fit, state)
        return state

    def trial_specs(self, interpreter_state: dict[str, Any],
                    policies: dict[str, dict[str, np.ndarray]] | None = None,
                    trials: list[int] | None = None) -> list[TrialSpec]:
        """Specs of the trials to run: the learning trials (all, or the indices ``trials``),
        or, in a run with an evaluation protocol that does not learn, one batch of its
        episodes per world (trial ``j``: world ``j``, seed of stage :data:`STAGE_BATCH`).

        A learning trial evaluates its own learned policies (:func:`evaluation_specs`).
        """
        stages = self.cfg["experiment"]["stages"]
        if "learn" in stages:
            idx = range(self.info.n_trials) if trials is None else trials
            return [self.trial_spec(k, interpreter_state, policies) for k in idx]
        if self.protocol is None or "evaluate" not in stages:
            return []
        return [TrialSpec(index=j, seed=stage_seed(self.info.seed, STAGE_BATCH, j), world=name,
                          iterations=int(self.res.protocol(self.protocol).iterations),
                          learn=False, interpreter_state=interpreter_state,
                          policies=policies or {}, protocol=self.protocol)
                for j, name in enumerate(self.eval_worlds)]

    def trial_done(self, result: TrialResult) -> None:
        """Hand a finished trial to observers (call in trial order)."""
        self._notify("sitframe_trial_end", run=self.info, trial=result)

    def _notify(self, hook_name: str, **kwargs: Any) -> None:
        """Call an observer hook's implementations, in pluggy's order, each one once.

        An implementation that raises does not stop the others (the logger,
        which runs last, still writes the finished trial); the first failure
        is then raised as one :class:`PluginFault` naming its plugin.
        """
        hook = getattr(self.pm.hook, hook_name)
        impls = hook.get_hookimpls()
        if any(getattr(i, "hookwrapper", False) or getattr(i, "wrapper", False) for i in impls):
            hook(**kwargs)  # wrappers need pluggy's own call loop
            return
        first: BaseException | None = None
        for impl in reversed(impls):  # pluggy calls the last registered first
            if first is not None and hook_name == "sitframe_run_end":
                # an observer that fails at the end fails the run: the later ones
                # (the logger runs last) record it
                kwargs["status"] = "failed"
                self.info.extra.setdefault("failure", str(first))
            try:
                impl.function(*[kwargs[a] for a in impl.argnames])
            except (KeyboardInterrupt, TaskCancelled):
                raise
            except Exception as exc:  # noqa: BLE001 - reported below, naming the plugin
                if first is None:
                    where = f"plugin {self.registry.describe_plugin(impl.plugin_name)}"
                    first = exc if isinstance(exc, InputError | PluginError) else fault(
                        exc, where, hook_name, getattr(kwargs.get("trial"), "index", None))
                    if first is not exc:
                        first.__cause__ = exc
        if first is not None:
            raise first

    def finish(self, status: str) -> None:
        """Tell observers the run ended with ``status`` (complete, aborted, failed)."""
        self._notify("sitframe_run_end", run=self.info, status=status)

    def run(self, *, interpreter_state: dict[str, Any] | None = None,
            collected: Collected | None = None,
            policies: dict[str, dict[str, np.ndarray]] | None = None,
            trials: list[int] | None = None,
            skip: set[int] | frozenset[int] = frozenset()) -> RunResult:
        """Run the configured stages; observers see every stage and trial.

        ``interpreter_state`` (e.g. read from an earlier log) skips collect
        and cluster. ``trials`` restricts which learning-trial indices run;
        ``skip`` drops any spec (learning trial or episode batch) whose index
        is in it (resume: the ones already in the log).

        Trials go to ``self.executor``; their results reach the observers
        (the HDF5 logger) in this process, in trial order, as soon as each
        trial and all before it have finished. Ctrl-C (KeyboardInterrupt)
        stops the executor (pending trials are cancelled), leaves the trials
        already handed to observers in the log, marks the run ``aborted`` and
        re-raises.
        """
        t0 = time.perf_counter()
        status = "failed"
        results: list[TrialResult] = []
        stream = None
        try:
            self.begin()
            start = getattr(self.executor, "start", None)
            if start is not None and "learn" in self.cfg["experiment"]["stages"]:
                start(self)  # e.g. warm up worker processes while we collect and cluster
            interpreter_state = self.prepare(interpreter_state, collected)
            specs = [s for s in self.trial_specs(interpreter_state, policies, trials)
                     if s.index not in skip]
            if specs:
                stream = self.executor.map(self, specs)
                for result in stream:
                    results.append(result)
                    self.trial_done(result)
            status = "complete"
        except KeyboardInterrupt:
            status = "aborted"
            raise
        except PluginFault as exc:
            self.info.extra["failure"] = str(exc)
            raise
        finally:
            close = getattr(stream, "close", None)
            if close is not None:
                close()  # cancels a parallel executor's pending trials
            self.finish(status)
        return RunResult(self.info, results, time.perf_counter() - t0, status,
                         interpreter_state or {}, self.res.run.sensor.angles_deg)


def versions() -> dict[str, str]:
    """Versions of sitframe, Python and the numerical/IO stack."""
    import h5py
    import scipy

    return {
        "sitframe": __version__, "python": platform.python_version(), "numpy": np.__version__,
        "scipy": scipy.__version__, "h5py": h5py.__version__, "hdf5": h5py.version.hdf5_version,
        "pluggy": pluggy.__version__ if hasattr(pluggy, "__version__") else "",
    }


__all__ = ["Experiment", "Resolved", "RunResult", "TrialSpec", "simulate", "stage_seed",
           "PluginError", "Proposal"]
