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
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pluggy

from sitframe import __version__
from sitframe.collect import Collected, collect_trajectories, collect_wander, concat_collected
from sitframe.config import config_hash, to_toml
from sitframe.episodes import check_goal_config, goal_batch_specs, is_goal_run, run_episode_batch
from sitframe.errors import InputError, PluginError
from sitframe.metrics import collisions_per_1000, coverage, path_length
from sitframe.pluginmanager import Registry, get_plugin_manager
from sitframe.records import Context, Proposal, RunInfo, StepRecord, Transition, TrialResult
from sitframe.robot import Command, RobotParams, step_robot
from sitframe.world import Goal, World, load_world

STAGE_COLLECT, STAGE_CLUSTER, STAGE_TRIALS, STAGE_EVAL = 0, 1, 2, 3
#: Summary keys of a frozen-policy evaluation (``evaluate --json`` and ``eval/<world>/...``).
EVAL_KEYS = ("iterations", "collisions", "collisions_per_1000", "distance_m", "mean_speed_m_s",
             "coverage")


def stage_seed(seed: int, stage: int, index: int = 0) -> int:
    """A 64-bit seed for ``(stage, index)`` derived from the run seed."""
    ss = np.random.SeedSequence(entropy=seed, spawn_key=(stage, index))
    return int(ss.generate_state(1, np.uint64)[0])


@dataclass
class Resolved:
    """A config resolved against a registry: creates fresh components on demand."""

    cfg: dict[str, Any]
    registry: Registry
    file: str | None = None
    robot: RobotParams = field(default_factory=RobotParams)
    _worlds: dict[str, World] = field(default_factory=dict)
    base_dir: str = "."

    @classmethod
    def build(cls, cfg: dict[str, Any], registry: Registry, file: str | None = None,
              base_dir: str = ".") -> Resolved:
        try:
            robot = RobotParams(**cfg["robot"])
        except InputError as exc:
            raise exc.at(file=file, key_prefix="robot") from None
        except (ValueError, TypeError) as exc:
            raise InputError(str(exc), file=file, key="robot") from None
        res = cls(cfg, registry, file, robot, base_dir=base_dir)
        # Create each component once now so bad names/params fail before anything runs.
        res.sensor()
        res.interpreter()
        res.behaviours()
        res.arbiter()
        return res

    def _create(self, kind: str, section: str, table: dict[str, Any]) -> Any:
        params = {k: v for k, v in table.items() if k != "component"}
        return self.registry.create(kind, table["component"], params, file=self.file, key=section)

    def sensor(self) -> Any:
        return self._create("sensor", "sensor", self.cfg["sensor"])

    def interpreter(self) -> Any:
        return self._create("interpreter", "interpreter", self.cfg["interpreter"])

    def arbiter(self) -> Any:
        return self._create("arbiter", "arbiter", self.cfg["arbiter"])

    def behaviours(self) -> dict[str, tuple[Any, Any | None]]:
        """Label -> (behaviour, reward or None), in config order."""
        out = {}
        for label, table in self.cfg["behaviours"].items():
            key = f"behaviours.{label}"
            params = {k: v for k, v in table.items() if k not in
                      ("component", "reward", "reward_params", "policy_from")}
            beh = self.registry.create("behaviour", table["component"], params,
                                       file=self.file, key=key)
            reward = None
            if "reward" in table:
                reward = self.registry.create("reward", table["reward"],
                                              dict(table.get("reward_params", {})),
                                              file=self.file, key=f"{key}.reward")
            out[label] = (beh, reward)
        return out

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
    stop_at_goal
        End the trial as soon as the robot's centre is within the goal radius
        (goal episodes); arrays are then shorter than ``iterations``.
    episodes
        A :class:`sitframe.episodes.EpisodeConfig`: the spec is a *batch* of
        goal episodes in ``world`` (run by :func:`sitframe.episodes.run_episode_batch`),
        returned as one trial.
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
    stop_at_goal: bool = False
    episodes: Any = None


def simulate(
    res: Resolved,
    spec: TrialSpec,
    *,
    step_hook: Callable[[StepRecord], Any] | None = None,
) -> TrialResult:
    """Run one trial (learning, frozen evaluation or goal episode) and return its arrays."""
    if spec.episodes is not None:
        return run_episode_batch(res, spec, step_hook=step_hook)
    rng = np.random.default_rng(spec.seed)
    world = res.world(spec.world)
    goal = world.goal if spec.goal is None else Goal(np.asarray(spec.goal[:2], float),
                                                     float(spec.goal[2]))
    goal_xy = None if goal is None else goal.position
    goal_r2 = 0.0 if goal is None else goal.radius ** 2
    sensor = res.sensor()
    interp = res.interpreter()
    interp.load_state(spec.interpreter_state)
    c = interp.n_situations
    behaviours = res.behaviours()
    arbiter = res.arbiter()
    L = spec.iterations
    for label, (beh, _r) in behaviours.items():
        if label in spec.policies:
            beh.load_policy(spec.policies[label])
        beh.reset(rng, c, L)
    learners = [(label, beh, rew) for label, (beh, rew) in behaviours.items()
                if rew is not None and spec.learn]
    labels = list(behaviours)
    default_speed = float(res.cfg["experiment"]["default_speed"])
    robot = res.robot

    d = len(sensor.angles_deg)
    pose_a = np.empty((L + 1, 3))
    sonar_a = np.empty((L, d))
    u_a = np.empty((L, c))
    cmd_a = np.empty((L, 2))
    coll_a = np.zeros(L, dtype=bool)
    contact_a = np.full((L, 2), np.nan)
    near_a = np.empty(L)
    weights_a = np.empty((L, len(labels)))
    prop_a = {lb: np.empty((L, 2)) for lb in labels}
    rew_a = {lb: np.empty(L) for lb, _b, _r in learners}

    pose = np.array(world.start if spec.start is None else spec.start, dtype=float)
    reading = sensor.read(world, pose, rng)
    u = interp.memberships(reading)
    ctx = Context(0, pose, reading, u, float(reading.min()), world, goal)
    n_done = L
    for t in range(L):
        proposals = {lb: beh.propose(ctx) for lb, (beh, _r) in behaviours.items()}
        prop, weights = arbiter.combine(ctx, proposals)
        speed = prop.speed_m_s if prop.speed_m_s is not None else default_speed
        cmd = Command(prop.heading_deg, speed)
        out = step_robot(world, pose, cmd, robot, rng)
        pose = out.pose
        reading2 = sensor.read(world, pose, rng)
        u2 = interp.memberships(reading2)
        ctx2 = Context(t + 1, pose, reading2, u2, float(reading2.min()), world, goal)
        tr = Transition(ctx, cmd, out, ctx2)
        rewards = {}
        for lb, beh, rew in learners:
            r = float(rew(tr))
            rewards[lb] = r
            rew_a[lb][t] = r
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
            step_hook(StepRecord(spec.index, tr, proposals, weights, rewards))
        ctx = ctx2
        if spec.stop_at_goal and goal_xy is not None and \
                (pose[0] - goal_xy[0]) ** 2 + (pose[1] - goal_xy[1]) ** 2 <= goal_r2:
            n_done = t + 1
            break
    pose_a[n_done] = pose

    n = n_done
    arrays: dict[str, np.ndarray] = {
        "pose": pose_a[: n + 1], "sonar": sonar_a[:n], "memberships": u_a[:n],
        "command": cmd_a[:n], "collision": coll_a[:n], "contact": contact_a[:n],
        "nearest": near_a[:n], "weights": weights_a[:n],
    }
    for lb in labels:
        arrays[f"proposals/{lb}"] = prop_a[lb][:n]
    for lb in rew_a:
        arrays[f"reward/{lb}"] = rew_a[lb][:n]
    bdata = {lb: beh.trial_data() for lb, (beh, _r) in behaviours.items()}
    summary = trial_summary(world, arrays, bdata, robot)
    result = TrialResult(spec.index, spec.seed, world.name, arrays, bdata, summary)
    for ev_spec in evaluation_specs(spec, bdata):
        attach_evaluation(result, ev_spec.world, simulate(res, ev_spec))
    return result


def evaluation_specs(spec: TrialSpec, bdata: dict[str, dict[str, Any]]) -> list[TrialSpec]:
    """The frozen-policy evaluations of a finished trial (one spec per ``spec.evaluate`` world).

    ``bdata`` is the trial's behaviour data (policies are taken from it).
    Parallel executors run these as separate tasks; :func:`attach_evaluation`
    adds their results to the trial in this order.
    """
    if not spec.evaluate:
        return []
    policies = {lb: extract_policy(data) for lb, data in bdata.items()}
    return [dataclasses.replace(
        spec, seed=stage_seed(spec.seed % (2**63), STAGE_EVAL, k), world=wname,
        iterations=spec.eval_iterations, learn=False, policies=policies, evaluate=())
        for k, wname in enumerate(spec.evaluate)]


#: Per-iteration arrays of a frozen-policy evaluation kept in the log (enough to
#: replay it and to see where and in which situation it collided).
EVAL_ARRAYS = ("pose", "collision", "contact", "command", "nearest", "sonar", "memberships")


def attach_evaluation(result: TrialResult, wname: str, ev: TrialResult) -> None:
    """Add evaluation ``ev`` in world ``wname`` (``eval/<wname>/...``) to its trial's result."""
    for key in EVAL_ARRAYS:
        if key in ev.arrays:
            result.episodes[f"eval/{wname}/{key}"] = ev.arrays[key]
    for key in EVAL_KEYS:
        result.summary[f"eval/{wname}/{key}"] = ev.summary[key]


def extract_policy(bdata: dict[str, Any]) -> dict[str, np.ndarray]:
    """The ``policy/<output>`` entries of a behaviour's trial data."""
    return {k.split("/", 1)[1]: np.asarray(v) for k, v in bdata.items()
            if k.startswith("policy/")}


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
        hook = experiment.pm.hook
        step_hook = None
        if hook.sitframe_step.get_hookimpls():
            def step_hook(rec: StepRecord) -> None:
                hook.sitframe_step(record=rec)
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
        self.res = Resolved.build(cfg, self.registry, source, base_dir)
        self.out = out
        text = to_toml(cfg)
        e = cfg["experiment"]
        worlds = {}
        names = [e["world"]]
        if "collect" in e["stages"]:
            names += cfg["collect"]["worlds"]
        if "evaluate" in e["stages"]:
            names += cfg["evaluate"]["worlds"]
        self.goal_run = is_goal_run(self.res)
        if self.goal_run and "evaluate" in e["stages"]:
            names += check_goal_config(cfg, self.res, source)
        for name in dict.fromkeys(names):
            key = "experiment.world" if name == e["world"] else "worlds"
            worlds[name] = self.res.world(name, key).text
        plugins = [dataclasses.asdict(info) for info, _c in self.registry.plugins_table()]
        self.info = RunInfo(
            name=e["name"], config=cfg, config_text=text, config_hash=config_hash(text),
            seed=int(e["seed"]), out=out, n_trials=int(e["trials"]),
            iterations=int(e["iterations"]), plugins=plugins, worlds=worlds,
            extra={"versions": versions(), "source": source or ""},
        )

    # -- stages ------------------------------------------------------------
    def collect(self) -> Collected:
        c = self.cfg["collect"]
        rng = np.random.default_rng(stage_seed(self.info.seed, STAGE_COLLECT))
        worlds = [self.res.world(n, "collect.worlds") for n in c["worlds"]]
        sensor = self.res.sensor()
        parts = []
        if c["mode"] in ("trajectory", "both"):
            parts.append(collect_trajectories(worlds, sensor, rng, speed=c["speed"],
                                              rate_hz=c["rate_hz"], params=self.res.robot))
        if c["mode"] in ("wander", "both"):
            parts.append(collect_wander(worlds, sensor, rng, n_samples=c["wander_samples"],
                                        speed=c["speed"], rate_hz=c["rate_hz"],
                                        params=self.res.robot))
        return concat_collected(parts)

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
        if pmap is not None and "pmap" in inspect.signature(interp.fit).parameters:
            fit = interp.fit(samples, rng, pmap=pmap)
        else:
            fit = interp.fit(samples, rng)
        return fit, interp.state()

    def trial_spec(self, k: int, interpreter_state: dict[str, Any],
                   policies: dict[str, dict[str, np.ndarray]] | None = None) -> TrialSpec:
        e = self.cfg["experiment"]
        evaluate = (tuple(self.cfg["evaluate"]["worlds"])
                    if "evaluate" in e["stages"] and not self.goal_run else ())
        return TrialSpec(
            index=k, seed=stage_seed(self.info.seed, STAGE_TRIALS, k), world=e["world"],
            iterations=int(e["iterations"]), learn=True, interpreter_state=interpreter_state,
            policies=policies or {}, evaluate=evaluate,
            eval_iterations=int(self.cfg["evaluate"]["iterations"]))

    # -- phases (``run`` composes them; a sweep interleaves them across runs) --
    def begin(self) -> None:
        """Announce the run to observers (the logger creates, or on resume reopens, the log)."""
        self.info.extra.setdefault("step_hooks", bool(
            getattr(self.executor, "fires_step_hooks", True)))
        self.pm.hook.sitframe_run_start(run=self.info)

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
        self.pm.hook.sitframe_stage_end(run=self.info, stage="collect", data={
            "samples": collected.samples, "poses": collected.poses,
            "source": collected.source, "worlds": list(collected.worlds)})

    def record_clusters(self, fit: dict[str, Any], state: dict[str, Any]) -> None:
        """Hand the cluster stage's output to observers."""
        self.pm.hook.sitframe_stage_end(run=self.info, stage="cluster",
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
        """Specs of the learning trials to run (all, or the indices ``trials``)."""
        stages = self.cfg["experiment"]["stages"]
        specs = []
        if "learn" in stages:
            idx = range(self.info.n_trials) if trials is None else trials
            specs = [self.trial_spec(k, interpreter_state, policies) for k in idx]
        if self.goal_run and "evaluate" in stages:  # goal episodes: one batch per goal world
            first = self.info.n_trials if "learn" in stages else 0
            specs += goal_batch_specs(self, interpreter_state, policies, first)
        return specs

    def trial_done(self, result: TrialResult) -> None:
        """Hand a finished trial to observers (call in trial order)."""
        self.pm.hook.sitframe_trial_end(run=self.info, trial=result)

    def finish(self, status: str) -> None:
        """Tell observers the run ended with ``status`` (complete, aborted, failed)."""
        self.pm.hook.sitframe_run_end(run=self.info, status=status)

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
        self.begin()
        status = "failed"
        results: list[TrialResult] = []
        stream = None
        try:
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
        finally:
            close = getattr(stream, "close", None)
            if close is not None:
                close()  # cancels a parallel executor's pending trials
            self.finish(status)
        return RunResult(self.info, results, time.perf_counter() - t0, status,
                         interpreter_state or {}, np.asarray(self.res.sensor().angles_deg))


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
