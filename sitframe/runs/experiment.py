"""The run driver: an experiment's stages, in order, reported to the observers.

Stages of an experiment (DESIGN section 3): **collect** sensor data →
**cluster** (fit the situation interpreter) → **learn** (N independent
trials, :mod:`sitframe.runs.loop`) → **evaluate** (each trial's frozen policy in
other worlds, or an evaluation protocol's episodes). Components come from
:mod:`sitframe.contract.resolve`; trials go to an executor (this process, a worker
pool or a Dask cluster, :mod:`sitframe.runs.parallel`).
"""

from __future__ import annotations

import dataclasses
import inspect
import os
import platform
import threading
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pluggy

from sitframe import __version__
from sitframe.contract.checks import BoundaryError, call, check_data, fault, sensor_spec_mismatch
from sitframe.contract.config import DEFAULT_SPACE, config_hash, to_toml
from sitframe.contract.pluginmanager import Registry, get_plugin_manager
from sitframe.contract.records import RunInfo, TrialResult
from sitframe.contract.resolve import Resolved
from sitframe.errors import (
    PLUGIN_ERRORS,
    InputError,
    PluginError,
    PluginFault,
    TaskCancelled,
    located,
    located_in,
    warn,
)
from sitframe.params import check_environment
from sitframe.runs.arithmetic import arithmetic_versions
from sitframe.runs.collect import (
    Collected,
    collect_trajectories,
    collect_wander,
    concat_collected,
)
from sitframe.runs.loop import (
    STAGE_BATCH,
    STAGE_CLUSTER,
    STAGE_COLLECT,
    STAGE_SPACES,
    STAGE_TRIALS,
    TRIAL_WORK,
    TrialSpec,
    progress_hook_of,
    simulate,
    stage_seed,
    step_hook_of,
)
from sitframe.runs.parallel import InOrder, SerialExecutor, TrialPipeline
from sitframe.situations.labels import describe_prototypes


@dataclass
class RunResult:
    """What :func:`run_experiment` returns (also the basis of ``run --json``)."""

    info: RunInfo
    trials: list[TrialResult]
    wall_seconds: float
    status: str
    interpreter_state: dict[str, Any] = field(default_factory=dict)
    sensor_angles_deg: np.ndarray | None = None
    space_states: dict[str, dict[str, Any]] = field(default_factory=dict)


class Experiment:
    """A configured experiment ready to run its stages.

    Parameters
    ----------
    cfg
        Validated config (:func:`sitframe.contract.config.load_config`).
    source
        Where the config came from (for messages).
    pm
        Plugin manager; a fresh one from :func:`get_plugin_manager` by default.
    out
        HDF5 log path (written by the logger plugin), or ``None``.
    plugins_dirs
        Folders of loose plugin modules (also loaded by worker processes).
    executor
        Runs the trials (:mod:`sitframe.runs.parallel`); default
        :class:`~sitframe.runs.parallel.SerialExecutor` (in this process, with ``sitframe_step``).
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
        #: The typed config (what the run reads); :attr:`cfg` is its serial form.
        self.config = self.res.config
        self.out = out
        #: Fitted state of each situation space of its own, by name (:meth:`prepare_spaces`).
        self.space_states: dict[str, dict[str, Any]] = {}
        text = to_toml(cfg)
        e = self.config.experiment
        names = self.res.stage_worlds()
        #: The run's evaluation protocol (:meth:`Resolved.protocol_name`) and its worlds.
        self.protocol = self.res.protocol_name()
        self.eval_worlds = self.res.protocol_worlds(self.protocol) \
            if "evaluate" in e.stages else []
        names += self.eval_worlds
        worlds = {n: self.res.world(n, self.config.world_key(n)).text
                  for n in dict.fromkeys(names)}
        plugins = [dataclasses.asdict(info) for info, _c in self.registry.plugins_table()]
        self.info = RunInfo(
            name=e.name, config=cfg, config_text=text, config_hash=config_hash(text),
            seed=e.seed, out=out, n_trials=e.trials, iterations=e.iterations, plugins=plugins,
            worlds=worlds,
            extra={"versions": versions(), "source": source or "",
                   "sensor": self.res.run.sensor.as_dict(),
                   "evaluation": {"protocol": self.protocol, "worlds": self.eval_worlds}},
        )

    # -- stages ------------------------------------------------------------
    def collect(self, c: Any = None, rng: np.random.Generator | None = None,
                key: str = "collect") -> Collected:
        """The collect stage: ``c`` (default ``[collect]``) with ``rng`` (default the stage's)."""
        c = self.config.collect if c is None else c
        rng = np.random.default_rng(stage_seed(self.info.seed, STAGE_COLLECT)) \
            if rng is None else rng
        worlds = [self.res.world(n, f"{key}.worlds") for n in c.worlds]
        sensor = self.res.sensor()
        o = self.res.origins["sensor"]
        parts = []
        # "both" follows the trajectories of the rooms that have them (a generated room has
        # none: it is only wandered in); "trajectory" needs them in every room
        paths = [w for w in worlds if w.trajectories]
        if c.mode == "trajectory" and len(paths) < len(worlds):
            j = next(j for j, w in enumerate(worlds) if not w.trajectories)
            raise InputError(f"world '{c.worlds[j]}' has no [[trajectories]] to collect along; "
                             "expected a room with trajectories, or collect.mode = \"wander\" "
                             "or \"both\"", file=self.source, key=f"{key}.worlds[{j}]")
        if c.mode in ("trajectory", "both") and paths:
            along = call(o, "read", collect_trajectories, paths, sensor, rng,
                         speed=c.speed, rate_hz=c.rate_hz, params=self.res.robot)
            at = np.asarray([j for j, w in enumerate(worlds) if w.trajectories], dtype=np.int16)
            parts.append(dataclasses.replace(along, source=at[along.source],
                                             worlds=tuple(w.name for w in worlds)))
        if c.mode in ("wander", "both"):
            parts.append(call(o, "read", collect_wander, worlds, sensor, rng,
                              n_samples=c.wander_samples, speed=c.speed,
                              rate_hz=c.rate_hz, params=self.res.robot))
        collected = concat_collected(parts)
        spec, X = self.res.run.sensor, collected.samples
        why = sensor_spec_mismatch(X[0], spec.dim, spec.max_range) if len(X) else None
        bad = ~np.isfinite(X).all(axis=1) | (X < 0).any(axis=1) | (X > spec.max_range).any(axis=1)
        if why is None and bad.any():
            why = sensor_spec_mismatch(X[int(np.argmax(bad))], spec.dim, spec.max_range)
        if why is not None:
            raise PluginFault(f"{why} (collect stage)", where=str(o), method="read")
        return collected

    def cluster(self, samples: np.ndarray, pmap: Any = None, *,
                rng: np.random.Generator | None = None,
                space: str = DEFAULT_SPACE) -> tuple[dict[str, Any], dict[str, Any]]:
        """Fit the interpreter of ``space`` (default the ``[interpreter]``) on ``samples``;
        ``pmap`` is passed on if its ``fit`` takes one."""
        if rng is None:
            rng = np.random.default_rng(stage_seed(self.info.seed, STAGE_CLUSTER))
        interp = self.res.space_interpreter(space)
        key = self.res.space_key(space)
        c = getattr(interp, "n_situations", None)
        if isinstance(c, int) and len(samples) < c:
            raise InputError(f"the collect stage recorded {len(samples)} samples, fewer than the "
                             f"{c} situations to fit; expected at least {c}: collect more "
                             "(collect.worlds, collect.rate_hz, collect.mode) or lower c",
                             file=self.source, key=f"{key}.c")
        o = self.res.origins[key]
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
        e = self.config.experiment
        evaluate = tuple(self.eval_worlds) if "evaluate" in e.stages else ()
        return TrialSpec(
            index=k, seed=stage_seed(self.info.seed, STAGE_TRIALS, k), world=e.world,
            iterations=e.iterations, learn=True, interpreter_state=interpreter_state,
            policies=policies or {}, evaluate=evaluate, protocol=self.protocol,
            space_states=dict(self.space_states))

    def prepare_spaces(self, given: dict[str, dict[str, Any]] | None = None,
                       collected: Collected | None = None) -> dict[str, dict[str, Any]]:
        """The fitted state of every situation space of its own (``[spaces.NAME]``).

        A state in ``given`` (its ``clusters_from`` log's, or the log being
        resumed) is taken as it is; any other space is fitted on the run's
        collected readings (``collected``) seen through its ``view``, or, when
        the run collects nothing or the space has ``collect`` settings of its
        own, on readings collected for it (seeds of stage :data:`STAGE_SPACES`,
        one per space, so the default space's data and every preset's log stay
        what they were). All spaces are recorded as the stage ``spaces``
        (not again when resuming: the log has them).
        """
        given = dict(given or {})
        record: dict[str, Any] = {}
        for i, (name, section) in enumerate(self.config.spaces.items()):
            view = list(self.res.run.spaces[name].view)
            entry: dict[str, Any] = {"view": np.asarray(view, dtype=np.int64),
                                     "readers": list(self.config.readers(name)),
                                     "component": section.interpreter.name}
            if name in given:
                state = given[name]
                entry["source"] = f"clusters_from: {section.clusters_from}" \
                    if section.clusters_from else "given"
            else:
                if collected is None or section.collect:
                    table = dataclasses.replace(self.config.collect, **{
                        k: (tuple(v) if k == "worlds" else v) for k, v in section.collect.items()})
                    rng = np.random.default_rng(stage_seed(self.info.seed, STAGE_SPACES, 2 * i))
                    data = self.collect(table, rng, key=f"spaces.{name}.collect")
                    entry["samples"] = data.samples[:, view]
                    samples = data.samples
                else:
                    samples = collected.samples
                rng = np.random.default_rng(stage_seed(self.info.seed, STAGE_SPACES, 2 * i + 1))
                fit, state = self.cluster(samples[:, view], rng=rng, space=name)
                entry["fit"] = fit
                entry["source"] = "fitted"
            entry["state"] = state
            entry["labels"] = self._labels(state, view)
            given[name] = state
            record[name] = entry
        if record and not self.info.extra.get("resume"):
            self._notify("sitframe_stage_end", run=self.info, stage="spaces", data=record)
        self.space_states = {name: given[name] for name in self.config.spaces}
        return self.space_states

    def _labels(self, state: dict[str, Any], view: list[int]) -> list[str]:
        """``S1: wall on left``, ... for a state with range ``centers`` over ``view`` (no two
        alike: :func:`~sitframe.situations.labels.describe_prototypes`)."""
        centers = np.asarray(state.get("centers", np.zeros((0, 0))), dtype=float)
        angles = self.res.run.sensor.angles_deg[view]
        if centers.ndim != 2 or centers.shape[1] != len(view):
            return [f"S{i + 1}" for i in range(len(centers))]
        return [f"S{i}: {w}" for i, w in enumerate(describe_prototypes(centers, angles), 1)]

    # -- phases (``run`` composes them; a sweep interleaves them across runs) --
    def begin(self) -> None:
        """Announce the run to observers (the logger creates, or on resume reopens, the log)."""
        self.info.extra.setdefault("step_hooks", bool(self.executor.in_process))
        if self.out and "code_hash" not in self.info.extra:
            from sitframe.logs.writer import code_fingerprint  # h5py: imported only when a run logs

            self.info.extra["code_hash"] = code_fingerprint(self.info.plugins)
        self._notify("sitframe_run_start", run=self.info)

    def needs_clusters(self, interpreter_state: dict[str, Any] | None,
                       collected: Collected | None = None) -> bool:
        """Whether :meth:`prepare` would collect/cluster (raises if the stages cannot)."""
        if interpreter_state is not None or (collected is None and self.starts_online()):
            return False
        if collected is None and "collect" not in self.config.experiment.stages:
            raise InputError("the run needs clusters: include 'collect' and 'cluster' "
                             "in experiment.stages or reuse clusters from a log",
                             file=self.source, key="experiment.stages")
        return True

    def starts_online(self) -> bool:
        """Whether the situations start from nothing: an evolving interpreter
        (:mod:`sitframe.situations`) in a run without a cluster stage."""
        return ("cluster" not in self.config.experiment.stages
                and not self.config.experiment.clusters_from
                and bool(getattr(self.res.interpreter(), "evolving", False)))

    def record_collected(self, collected: Collected) -> None:
        """Hand the collect stage's output to observers."""
        self._notify("sitframe_stage_end", run=self.info, stage="collect", data={
            "samples": collected.samples, "poses": collected.poses,
            "source": collected.source, "worlds": list(collected.worlds)})

    def record_clusters(self, fit: dict[str, Any], state: dict[str, Any]) -> None:
        """Hand the cluster stage's output to observers (and say, naming the config and
        key, when no clustering trial filled every situation)."""
        if "[fallback" in str(fit.get("rule", "")):
            c = len(np.asarray(state.get("centers", ())))
            warn(f"{self.source}: interpreter.c: every clustering trial left one of the {c} "
                 "situations empty (more situations than the collected samples fill); the "
                 "best-ranked trial is used anyway: lower c, or collect more samples")
        self._notify("sitframe_stage_end", run=self.info, stage="cluster",
                                        data={**fit, "state": state})

    def prepare(self, interpreter_state: dict[str, Any] | None = None,
                collected: Collected | None = None,
                space_states: dict[str, dict[str, Any]] | None = None) -> dict[str, Any]:
        """Collect and cluster (unless ``interpreter_state`` is given); return the state.

        Situations given from elsewhere (``clusters_from``) are still recorded as
        the cluster stage, so the run's own log is self-contained for
        ``evaluate`` and ``analyse`` (not again when resuming: the log has them).
        The situation spaces of their own are fitted (or taken from
        ``space_states``) after it (:meth:`prepare_spaces`).
        """
        collected_here: list[Collected] = []
        state = self._prepare_default(interpreter_state, collected, collected_here)
        if self.config.spaces:
            self.prepare_spaces(space_states, collected or next(iter(collected_here), None))
        return state

    def _prepare_default(self, interpreter_state: dict[str, Any] | None,
                         collected: Collected | None,
                         collected_here: list[Collected]) -> dict[str, Any]:
        """:meth:`prepare` for the default space (``collected_here`` gets what it collected)."""
        if interpreter_state is None and collected is None and self.starts_online():
            interp = self.res.interpreter()
            interpreter_state = call(self.res.origins["interpreter"], "state", interp.state)
            if not self.info.extra.get("resume"):
                self.record_clusters({"fitted": "on-line, from no situations"}, interpreter_state)
            return interpreter_state
        if not self.needs_clusters(interpreter_state, collected):
            if not self.info.extra.get("resume"):
                source = self.config.experiment.clusters_from or "given by the caller"
                self.record_clusters({"reused_from": source}, interpreter_state)
            return interpreter_state  # type: ignore[return-value]
        if collected is None:
            collected = self.collect()
            self.record_collected(collected)
            collected_here.append(collected)
        fit, state = self.cluster(collected.samples, getattr(self.executor, "task_map", None))
        self.record_clusters(fit, state)
        return state

    def trial_specs(self, interpreter_state: dict[str, Any],
                    policies: dict[str, dict[str, np.ndarray]] | None = None,
                    trials: list[int] | None = None) -> list[TrialSpec]:
        """Specs of the trials to run: the learning trials (all, or the indices ``trials``),
        or, in a run that does not learn, one batch of its evaluation protocol's
        episodes per world (trial ``j``: world ``j``, seed of stage :data:`STAGE_BATCH`).

        A learning trial evaluates its own learned policies (:func:`evaluation_specs`).
        """
        stages = self.config.experiment.stages
        if "learn" in stages:
            idx = range(self.info.n_trials) if trials is None else trials
            return [self.trial_spec(k, interpreter_state, policies) for k in idx]
        if "evaluate" not in stages:
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
            trial = kwargs.get("trial") if hook_name == "sitframe_trial_end" else None
            before = dict(trial.plugin_data) if trial is not None else {}
            try:
                impl.function(*[kwargs[a] for a in impl.argnames])
                if trial is not None:
                    _check_plugin_data(trial.plugin_data, before, impl.plugin_name)
            except (KeyboardInterrupt, TaskCancelled):
                raise
            except PLUGIN_ERRORS as exc:  # reported below, naming the plugin
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
            skip: set[int] | frozenset[int] = frozenset(),
            space_states: dict[str, dict[str, Any]] | None = None) -> RunResult:
        """Run the configured stages; observers see every stage and trial.

        ``interpreter_state`` (e.g. read from an earlier log) skips collect
        and cluster. ``trials`` restricts which learning-trial indices run;
        ``skip`` drops any spec (learning trial or episode batch) whose index
        is in it (resume: the ones already in the log). See :func:`drive`.
        """
        return drive([(self, RunPlan(interpreter_state, collected, policies, trials,
                                     frozenset(skip), space_states))], self.executor)[0]


@dataclass(frozen=True)
class RunPlan:
    """What one run of :func:`drive` starts from (all optional).

    Attributes
    ----------
    interpreter_state
        Situations fitted elsewhere (skips collect and cluster).
    collected
        Collected samples to cluster (skips collect).
    policies
        Frozen learned policies per behaviour label (``policy_from``).
    trials
        Learning-trial indices to run (default all).
    skip
        Indices of specs not to run (resume: those already in the log).
    space_states
        Fitted states of situation spaces of their own, by name (``clusters_from``
        of a ``[spaces.NAME]``, or resume); the others are fitted.
    """

    interpreter_state: dict[str, Any] | None = None
    collected: Collected | None = None
    policies: dict[str, Any] | None = None
    trials: list[int] | None = None
    skip: frozenset[int] = frozenset()
    space_states: dict[str, dict[str, Any]] | None = None

    @classmethod
    def of(cls, kwargs: dict[str, Any]) -> RunPlan:
        """From ``prepare_experiment``'s run keyword arguments."""
        return cls(**{k: (frozenset(v) if k == "skip" else v) for k, v in kwargs.items()})


class _Runs:
    """The runs of one :func:`drive` call: their specs, release order, results and status."""

    def __init__(self, runs: list[tuple[Experiment, RunPlan]], pipe: TrialPipeline,
                 handles: list[Any]) -> None:
        self.runs, self.pipe, self.handles = runs, pipe, handles
        self.status = ["pending"] * len(runs)
        self.states: list[dict[str, Any]] = [{} for _ in runs]
        self.release: list[InOrder] = [InOrder(()) for _ in runs]
        self.results: list[list[TrialResult]] = [[] for _ in runs]

    def add_trials(self, i: int, state: dict[str, Any]) -> None:
        exp, plan = self.runs[i]
        self.states[i] = state
        specs = [s for s in exp.trial_specs(state, plan.policies, plan.trials)
                 if s.index not in plan.skip]
        self.release[i] = InOrder(s.index for s in specs)
        self.pipe.add_trials(((i, s.index), self.handles[i], s) for s in specs)
        if not specs:
            self.finish(i, "complete")

    def trial(self, i: int, k: int, result: TrialResult) -> None:
        for r in self.release[i].add(k, result):
            self.results[i].append(r)
            self.runs[i][0].trial_done(r)
        if self.release[i].complete:
            self.finish(i, "complete")

    def finish(self, i: int, status: str) -> None:
        self.status[i] = status
        self.runs[i][0].finish(status)

    def stop(self, exc: BaseException) -> None:
        """Mark every run still running ``aborted`` (Ctrl-C) or ``failed``.

        Each run is told, whatever the others do: an observer that cannot record the end
        (a full disk fails the failed run's log as it failed the trial) does not keep the
        later runs from being told, nor hide ``exc``, the reason the runs stop."""
        status = "aborted" if isinstance(exc, KeyboardInterrupt) else "failed"
        for i, st in enumerate(self.status):
            if st != "running":
                continue
            if isinstance(exc, PluginFault):
                self.runs[i][0].info.extra["failure"] = str(exc)
            try:
                self.finish(i, status)
            except (InputError, PluginError):
                if not isinstance(exc, InputError | PluginError):
                    raise


def _check_plugin_data(data: dict[str, Any], before: dict[str, Any], plugin: str) -> None:
    """What an observer's ``sitframe_trial_end`` did to ``trial.plugin_data``: only its own
    entry, loggable (:func:`check_data`); else the entries are put back (the logger, which
    runs last, writes the trial as it was) and a :class:`BoundaryError` says why."""
    try:
        for key in set(data) | set(before):
            if data.get(key) is before.get(key):
                continue
            if key != plugin:
                raise BoundaryError(f"changed trial.plugin_data['{key}'], which is not its own "
                                    f"(its own is trial.plugin_data['{plugin}'])")
            check_data(data.get(key), f"trial.plugin_data['{plugin}']")
    except BoundaryError:
        data.clear()
        data.update(before)
        raise


def drive(runs: list[tuple[Experiment, RunPlan]], executor: Any) -> list[RunResult]:
    """The run lifecycle, shared by ``run``, ``run --resume`` and ``sweep``.

    Each run is announced to its observers (:meth:`Experiment.begin`), gets
    its situations (given, or collected and clustered), and its trials go to
    ``executor`` through one :class:`~sitframe.runs.parallel.TrialPipeline`; each
    run's finished trials reach its observers (the HDF5 logger) in this
    process, in trial order, as soon as each trial and all before it have
    finished (:class:`~sitframe.runs.parallel.InOrder`), and the run ends
    ``complete``. With several runs on a pool (a sweep), every run's collect
    and cluster stages are tasks too, so all runs' work shares the workers.

    Ctrl-C (KeyboardInterrupt) or a failure cancels the pending tasks, leaves
    the trials already handed to observers in the logs, marks every run
    still running ``aborted`` (Ctrl-C) or ``failed`` and re-raises.
    """
    check_environment()  # (a bad environment variable: before anything starts)
    t0 = time.perf_counter()
    for exp, _plan in runs:
        exp.executor = executor
    handles = [exp if executor.in_process else Setup.of(exp) for exp, _plan in runs]
    pipe = TrialPipeline(executor, run_trial, TRIAL_WORK)
    book = _Runs(runs, pipe, handles)
    try:
        with pipe:
            for i, (exp, plan) in enumerate(runs):
                book.status[i] = "running"  # (observers hear the end even if begin fails)
                with located_in(exp.res.file):  # (a setting found wrong as the run set up)
                    exp.begin()
                    if exp.needs_clusters(plan.interpreter_state, plan.collected) and \
                            len(runs) > 1 and not executor.in_process:
                        pipe.add_call(i, run_clusters, handles[i])
                        continue
                    if len(runs) == 1 and "learn" in exp.config.experiment.stages:
                        if isinstance(handles[i], Setup):  # forked workers inherit it
                            _cache.setdefault(handles[i].key, exp)
                        executor.warm(warm_up, handles[i])  # workers start while we cluster
                    book.add_trials(i, exp.prepare(plan.interpreter_state, plan.collected,
                                                   plan.space_states))
            for kind, tag, value in pipe:
                if kind == "call":
                    collected, fit, state = value
                    runs[tag][0].record_collected(collected)
                    runs[tag][0].record_clusters(fit, state)
                    if runs[tag][0].config.spaces:
                        runs[tag][0].prepare_spaces(runs[tag][1].space_states, collected)
                    book.add_trials(tag, state)
                else:
                    book.trial(*tag, value)
    except BaseException as exc:
        book.stop(exc)
        task = getattr(exc, "task", None)  # (a trial's or a run's: found wrong as it ran)
        if isinstance(exc, InputError) and task is not None:
            i = task[0] if isinstance(task, tuple) else task
            raise located(exc, runs[i][0].res.file) from None
        raise
    wall = time.perf_counter() - t0
    return [RunResult(exp.info, book.results[i], wall, book.status[i], book.states[i],
                      exp.res.run.sensor.angles_deg, dict(exp.space_states))
            for i, (exp, _plan) in enumerate(runs)]


# ---------------------------------------------------------------------------
# What a worker receives and runs
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class Setup:
    """What a worker needs to rebuild an experiment's components (picklable).

    Attributes
    ----------
    key
        Cache key: hash of the resolved config and the plugin folders.
    cfg
        The validated config.
    source
        Where the config came from (for messages).
    plugins_dirs
        Folders of loose plugin modules to load.
    base_dir
        Absolute folder the config's world paths are relative to.
    """

    key: str
    cfg: dict[str, Any]
    source: str | None
    plugins_dirs: tuple[str, ...]
    base_dir: str = "."

    @classmethod
    def of(cls, experiment: Experiment) -> Setup:
        dirs = tuple(os.path.abspath(d) for d in experiment.plugins_dirs)
        base = os.path.abspath(experiment.base_dir)
        key = config_hash(to_toml(experiment.cfg) + "\0" + "\0".join((*dirs, base)))
        return cls(key, experiment.cfg, experiment.source, dirs, base)


_cache: dict[str, Experiment] = {}
_cache_lock = threading.Lock()


def _experiment(handle: Experiment | Setup) -> Experiment:
    """The experiment of a task: the caller's own (in-process executors) or, in a worker,
    one rebuilt from its :class:`Setup` (built once per worker; thread-safe)."""
    if isinstance(handle, Experiment):
        return handle
    with _cache_lock:
        exp = _cache.get(handle.key)
        if exp is None:
            exp = Experiment(handle.cfg, source=handle.source, plugins_dirs=handle.plugins_dirs,
                             base_dir=handle.base_dir)
            if len(_cache) > 16:  # a long-lived Dask worker serving many sweeps
                _cache.clear()
            _cache[handle.key] = exp
        return exp


def run_trial(handle: Experiment | Setup, spec: TrialSpec) -> TrialResult:
    """Task: run one trial and return its data (``sitframe_step`` fires where it runs)."""
    exp = _experiment(handle)
    return simulate(exp.res, spec, step_hook=step_hook_of(exp.pm),
                    progress=progress_hook_of(exp.pm))


def run_clusters(handle: Experiment | Setup
                 ) -> tuple[Collected, dict[str, Any], dict[str, Any]]:
    """Task: the collect and cluster stages (``collected, fit, state``)."""
    exp = _experiment(handle)
    collected = exp.collect()
    fit, state = exp.cluster(collected.samples)
    return collected, fit, state


def warm_up(handle: Experiment | Setup) -> int:
    """Task: build the components now; returns the worker's pid."""
    _experiment(handle)
    return os.getpid()


def versions() -> dict[str, str]:
    """Versions of sitframe, Python and the numerical/IO stack, numpy's SIMD targets and its
    BLAS (:func:`sitframe.runs.arithmetic.arithmetic_versions`: with the numpy version, what
    decides the last bits of sin, cos, exp, log and dot products, so of every trajectory)."""
    import h5py
    import scipy

    return {
        "sitframe": __version__, "python": platform.python_version(),
        **arithmetic_versions(),
        "scipy": scipy.__version__, "h5py": h5py.__version__, "hdf5": h5py.version.hdf5_version,
        "pluggy": pluggy.__version__ if hasattr(pluggy, "__version__") else "",
    }


__all__ = ["Experiment", "RunPlan", "RunResult", "Setup", "drive", "run_clusters",
           "run_trial", "versions"]
