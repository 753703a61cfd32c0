"""The run driver: an experiment's stages, in order, reported to the observers.

Stages of an experiment (DESIGN section 3): **collect** sensor data →
**cluster** (fit the situation interpreter) → **learn** (N independent
trials, :mod:`sitframe.loop`) → **evaluate** (each trial's frozen policy in
other worlds, or an evaluation protocol's episodes). Components come from
:mod:`sitframe.resolve`; trials go to an executor (this process, a worker
pool or a Dask cluster, :mod:`sitframe.parallel`).
"""

from __future__ import annotations

import dataclasses
import inspect
import platform
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pluggy

from sitframe import __version__
from sitframe.collect import Collected, collect_trajectories, collect_wander, concat_collected
from sitframe.config import config_hash, to_toml
from sitframe.contract import (
    BoundaryError,
    call,
    check_data,
    fault,
    sensor_spec_mismatch,
)
from sitframe.errors import InputError, PluginError, PluginFault, TaskCancelled
from sitframe.loop import (
    STAGE_BATCH,
    STAGE_CLUSTER,
    STAGE_COLLECT,
    STAGE_TRIALS,
    TrialSpec,
    simulate,
    stage_seed,
    step_hook_of,
)
from sitframe.pluginmanager import Registry, get_plugin_manager
from sitframe.records import (
    RunInfo,
    TrialResult,
)
from sitframe.resolve import Resolved, config_worlds


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
        names = config_worlds(cfg)
        #: The run's evaluation protocol (:meth:`Resolved.protocol_name`); None = frozen.
        self.protocol = self.res.protocol_name()
        self.eval_worlds = list(cfg["evaluate"]["worlds"])
        if self.protocol is not None and "evaluate" in e["stages"]:
            self.eval_worlds = self.res.protocol_worlds(self.protocol)
            names += self.eval_worlds
        worlds = {n: self.res.world(n, "experiment.world" if n == e["world"] else "worlds").text
                  for n in dict.fromkeys(names)}
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


__all__ = ["Experiment", "RunResult", "SerialExecutor", "versions"]
