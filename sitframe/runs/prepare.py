"""Prepare a run: from a config (its components, and what it reuses from other logs), or
from the log of an interrupted run, to finish it (:func:`prepare_resume`).

``prepare_experiment`` checks everything that can be wrong with the input before a
byte is written, opens the logs a config builds on (``clusters_from``,
``policy_from``; intact logs only) and fingerprints what it reads from them;
which trial of such a log (:mod:`sitframe.logs.policies`) is reused::

    from sitframe.contract.config import load_config
    from sitframe.runs.prepare import prepare_experiment
    cfg, source, base = load_config("obstacle-avoidance")
    cfg["experiment"]["trials"] = 2
    exp, kwargs = prepare_experiment(cfg, source=source, out="logs/oa.h5")
    result = exp.run(**kwargs)

Resuming (``sitframe run --resume LOG``). A log left by a killed (``status = "running"``),
interrupted (``aborted``) or failed run holds everything needed to finish it: the resolved config,
the run seed, the fitted situations (``/cluster/state``) and every trial that
finished. Resuming rebuilds the experiment from that config, runs only the
missing trial indices with the same per-trial seeds (spawned from the run
seed and the index, see :func:`sitframe.runs.loop.stage_seed`), appends them
and marks the log ``complete``. Every dataset is then bit-for-bit what an
uninterrupted run with the same seed writes.

Reproducibility needs the same code: if this sitframe resolves the logged
config differently (its defaults changed, so the config hash differs), the
resume is refused rather than mixing trials from two configurations. If the
source of sitframe or of a plugin changed since the run started (root
attribute ``code_hash``, see :func:`code_fingerprint`), the resume goes on
but ``experiment.info.extra["code_changed"]`` is set and the CLI warns that
the new trials may not match the logged ones. Another numpy version or other
numpy SIMD targets than the log records (``versions``; another CPU, see
:mod:`sitframe.runs.parallel`) is refused: the trials would differ in the last bits,
then everywhere.
"""

from __future__ import annotations

import dataclasses
import hashlib
import math
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from sitframe.contract.config import config_hash, load_config, to_toml, validate_config
from sitframe.contract.records import LearnedPolicy
from sitframe.errors import InputError, note
from sitframe.logs.policies import (
    best_trial,
    check_logged_policy,
    check_state,
    logged_policy,
    plugins_of,
)
from sitframe.logs.reader import Log, open_log
from sitframe.logs.writer import code_fingerprint, lock_log, unlock_log
from sitframe.runs.arithmetic import arithmetic, arithmetic_hint
from sitframe.runs.collect import trajectory_poses
from sitframe.runs.evaluation import select_trial, selection_rule
from sitframe.runs.experiment import Experiment


def _resolve_path(path: str, base_dir: str) -> str:
    p = Path(path)
    return str(p if p.is_absolute() or base_dir in ("", ".") else Path(base_dir) / p)


def prepare_experiment(
    cfg: dict[str, Any],
    *,
    source: str | None = None,
    base_dir: str = ".",
    out: str | None = None,
    plugins_dirs: tuple[str, ...] = (),
    progress: bool = False,
    config_plugins: bool = True,
) -> tuple[Experiment, dict[str, Any]]:
    """Validate ``cfg``, resolve its components and the logs it reuses.

    Everything that can be wrong with the input is checked here, before a
    single byte is written. Relative paths in the config (worlds, logs,
    plugin folders) resolve against ``base_dir``, the config file's folder.
    What the run reads from other logs is fingerprinted in
    ``experiment.info.extra["inputs"]`` (written to the log; ``run --resume``
    compares it).

    Parameters
    ----------
    config_plugins
        Load the config's ``[plugins] dirs`` (False when the config comes
        from a log: a log alone never decides which code runs).

    Returns
    -------
    (experiment, run_kwargs)
        Call ``experiment.run(**run_kwargs)``.
    """
    cfg = validate_config(cfg, file=source, pending=True)  # (all checked as it resolves)
    dirs = tuple(_resolve_path(d, base_dir) for d in cfg["plugins"]["dirs"]) \
        if config_plugins else ()
    dirs += plugins_dirs
    exp = Experiment(cfg, source=source, out=out, plugins_dirs=dirs, base_dir=base_dir)
    exp.info.extra["progress"] = progress
    config = exp.config
    kwargs: dict[str, Any] = {}
    _check_collect(exp, source)
    checked: dict[str, Log] = {}
    inputs: dict[str, str] = {}

    checked_keys: dict[str, str] = {}

    def source_log(path: str, key: str) -> Log:
        """Open a log this run builds on, read whole once (checksums): intact logs only."""
        if path not in checked:
            checked_keys[path] = key
            checked[path] = open_log(path)
            checked[path].check()
        return checked[path]

    def reused(clusters_from: str, key: str, space: str) -> dict[str, Any]:
        """The situations a space reuses from another log (fingerprinted as an input)."""
        path = _resolve_path(clusters_from, base_dir)
        log = source_log(path, key)
        state = log.interpreter_state()
        logged_sensor = validate_config(log.config, file=path, pending=True)["sensor"]
        if logged_sensor != cfg["sensor"]:
            raise InputError(
                f"its situations were fitted on readings of sensor {logged_sensor}, but this "
                f"config reads {cfg['sensor']}; use the same [sensor] table",
                file=path, key="sensor")
        check_state(exp.res, state, path, log.sensor, space=space)
        inputs["clusters_from" if space == "default" else f"spaces/{space}"] = \
            fingerprint(state)
        return state

    if config.experiment.clusters_from:
        kwargs["interpreter_state"] = reused(config.experiment.clusters_from,
                                             "experiment.clusters_from", "default")
    space_states = {name: reused(section.clusters_from, f"spaces.{name}.clusters_from", name)
                    for name, section in config.spaces.items() if section.clusters_from}
    if space_states:
        kwargs["space_states"] = space_states
    policies: dict[str, LearnedPolicy] = {}
    for label, table in config.behaviours.items():
        pf = table.policy_from
        if not pf:
            continue
        path = _resolve_path(pf["log"], base_dir)
        log = source_log(path, f"behaviours.{label}.policy_from")
        which = pf.get("trial", 0)
        if isinstance(which, dict):
            k = select_trial(path, which, plugins_dirs=dirs)
            note(f"behaviours.{label}.policy_from: trial {k} of {pf['log']} "
                 f"({selection_rule(which)})")
            trial = log.trial(k)
        else:
            trial = log.trial(best_trial(log) if which == "best" else int(which))
        src_label = pf.get("behaviour", label)
        if src_label not in trial.behaviours:
            raise InputError(f"trial {trial.index} has no behaviour '{src_label}' (it has "
                             f"{', '.join(trial.behaviours) or 'none'})", file=path,
                             key=f"behaviours.{label}.policy_from.behaviour")
        policy = logged_policy(trial, src_label, path)
        if policy is None:
            raise InputError(f"behaviour '{src_label}' of trial {trial.index} has no learned "
                             "policy (no policy/... datasets)", file=path, key="trials")
        check_logged_policy(exp.res, label, policy, path)
        policies[label] = policy
        inputs[f"policy_from/{label}"] = fingerprint(
            {f"{kind}/{out}": getattr(o, kind) for out, o in policy.outputs.items()
             for kind in ("rules", "actions")})
    exp.info.extra["inputs"] = inputs
    if policies:
        kwargs["policies"] = policies
    if out:
        inputs = {path: f"the log it reads ({what})" for path, what in checked_keys.items()}
        inputs[source or ""] = "the run's config"
        for name, w in exp.res._worlds.items():
            inputs[w.source or ""] = f"world '{name}'"
        check_out(out, inputs)
    return exp, kwargs


def make_prerequisites(cfg: dict[str, Any], base_dir: str = ".", *,
                       executor_for: Callable[[int], Any] | None = None,
                       plugins_dirs: tuple[str, ...] = (), progress: bool = False,
                       say: Callable[[str], None] = print,
                       _stack: tuple[str, ...] = ()) -> list[str]:
    """Make the logs a config builds on, before the run is prepared.

    A config's ``[prerequisites]`` table maps a log path it reads (in
    ``clusters_from`` or a ``policy_from``) to the experiment that makes
    that log (a preset name, or a .toml path relative to the config's folder)::

        [prerequisites]
        "logs/obstacle-avoidance-12.h5" = "obstacle-avoidance-12"

    For each entry: a log that does not exist is made now, by running that
    experiment unchanged (its own prerequisites first) with the log as its
    output; a log that exists is reused if it is complete and was made by the
    same config (same config hash); anything else is refused, so a run never
    builds on a log other than the one its prerequisite names. Every choice is
    said in one line through ``say``.

    Parameters
    ----------
    executor_for
        ``executor_for(n_trials)`` gives the executor a prerequisite run uses
        (default: in this process).
    plugins_dirs, progress
        As for :func:`prepare_experiment`.

    Returns
    -------
    list of str
        The paths of the logs made now (in the order made).
    """
    made: list[str] = []
    for log, experiment in cfg.get("prerequisites", {}).items():
        key = f"prerequisites.{log}"
        path = _resolve_path(log, base_dir)
        name = _resolve_path(experiment, base_dir) if experiment.endswith(".toml") \
            else experiment
        if name in _stack:
            raise InputError(f"prerequisites form a cycle: {' -> '.join((*_stack, name))}",
                             key=key)
        pcfg, psource, pbase = load_config(name)
        if Path(path).exists():
            same_code, arith = _check_reusable(path, pcfg, experiment, key)
            say(f"reusing {path}: a complete log of '{experiment}' (same config" + (
                "" if same_code else "; made by other code than this: remove it to remake "
                "it with this code") + (f"; made with {arith}, not this process's "
                                        f"{arithmetic()}" if arith else "") + ")")
            continue
        made += make_prerequisites(pcfg, pbase, executor_for=executor_for,
                                   plugins_dirs=plugins_dirs, progress=progress, say=say,
                                   _stack=(*_stack, name))
        say(f"{path} not found: running '{experiment}' first to make it")
        exp, kwargs = prepare_experiment(pcfg, source=psource, base_dir=pbase, out=path,
                                         plugins_dirs=plugins_dirs, progress=progress)
        if executor_for is not None:
            exp.executor = executor_for(exp.info.n_trials)
        lock_log(path)
        failed = True
        try:
            exp.run(**kwargs)
            failed = False
        finally:
            exp.executor.shutdown(cancel=failed)
            unlock_log(path)
        made.append(path)
    return made


def _check_reusable(path: str, cfg: dict[str, Any], experiment: str,
                    key: str) -> tuple[bool, str]:
    """An existing prerequisite log: complete, and made by the prerequisite's own config.

    Returns whether this code made it (the log's ``code_hash`` against the
    sources now, with the plugins the log names), and the numpy arithmetic it
    was made with when that differs from this process's (else ``""``: a log
    made on another CPU is a valid input, but this process would remake
    another one; :func:`sitframe.runs.arithmetic.arithmetic`)."""
    log = open_log(path)
    if not log.complete:
        raise InputError(f"the prerequisite log is not complete (status {log.status}); finish "
                         f"it with `sitframe run --resume {path}`, or remove it to remake it",
                         file=path, key=key)
    if str(log.attrs.get("config_hash", "")) != config_hash(to_toml(cfg)):
        raise InputError(f"exists but was not made by '{experiment}' as it is now (another "
                         "config); remove it to remake it, or name the config that made it",
                         file=path, key=key)
    arith = arithmetic(log.versions)
    return (str(log.attrs.get("code_hash", "")) == code_fingerprint(log.plugins),
            "" if arith in ("", arithmetic(like=log.versions)) else arith)


def check_out(out: str, inputs: dict[str, str]) -> None:
    """Refuse an output path that is a folder, one of the run's ``inputs`` (path -> what it
    is), or an existing file that is not an HDF5 log: the run would destroy it."""
    p = Path(out)
    if not p.exists():
        return
    if p.is_dir():
        raise InputError("output path is a folder (expected an .h5 file path)", key="--out")
    for path, what in inputs.items():
        try:
            same = bool(path) and os.path.samefile(p, path)
        except OSError:
            same = False
        if same:
            raise InputError(f"is {what}; the run would overwrite its own input: choose "
                             "another --out", file=out, key="--out")
    if not h5py.is_hdf5(p):
        raise InputError("exists and is not an HDF5 log; refusing to replace it: choose another "
                         "--out or remove the file", file=out, key="--out")


def fingerprint(arrays: dict[str, Any]) -> str:
    """SHA-256 over named arrays (name, dtype, shape and bytes, in name order)."""
    h = hashlib.sha256()
    for k in sorted(arrays):
        a = np.ascontiguousarray(arrays[k])
        h.update(f"{k}\0{a.dtype.str}\0{a.shape}\0".encode())
        h.update(a.tobytes())
    return h.hexdigest()


#: Most samples the collect stage may record (beyond this the arrays do not fit in memory).
MAX_COLLECT_SAMPLES = 10_000_000


def _check_collect(exp: Experiment, source: str | None) -> None:
    """Data collection that cannot work, found before anything is written: a world without
    trajectories, far too many samples, a wander rate the robot cannot hold, or fewer
    samples than situations to fit."""
    e, c = exp.config.experiment, exp.config.collect
    if e.clusters_from or "collect" not in e.stages:
        return
    rate, speed = c.rate_hz, c.speed
    n = 0
    if c.mode in ("wander", "both"):  # wandering holds each command 1/rate_hz seconds
        try:
            dataclasses.replace(exp.res.robot, control_period_s=1.0 / rate)
        except (ValueError, TypeError) as exc:  # (an InputError's message without its key)
            raise InputError(f"wander mode holds each command 1/rate_hz s: "
                             f"{getattr(exc, 'message', exc)}", file=source,
                             key="collect.rate_hz") from None
        n += c.wander_samples * len(c.worlds)
    if c.mode in ("trajectory", "both"):
        turn_step = math.radians(exp.res.robot.max_turn_rate_deg_s) / rate
        worlds = []
        estimate = 0.0  # upper bound: samples along the paths + turning on the spot
        for i, name in enumerate(c.worlds):
            world = exp.res.world(name, "collect.worlds")
            if not world.trajectories and c.mode == "both":
                continue  # (only wandered in: a generated room has no trajectories)
            if not world.trajectories:
                raise InputError(f"world '{name}' has no [[trajectories]] to collect along; "
                                 "expected a data-collection room (e.g. collect-1) or "
                                 "collect.mode = \"wander\" or \"both\" (which only wanders "
                                 "in a room without trajectories)", file=source,
                                 key=f"collect.worlds[{i}]")
            for t in world.trajectories:
                estimate += float(np.hypot(*np.diff(t, axis=0).T).sum()) * rate / speed
                estimate += len(t) * (math.pi / turn_step if turn_step > 0 else 0.0) + 1
            worlds.append(world)
        if estimate > MAX_COLLECT_SAMPLES:
            raise InputError(f"the trajectories would give about {estimate:.3g} samples "
                             f"(length x rate_hz / speed, plus turns); expected at most "
                             f"{MAX_COLLECT_SAMPLES}: lower rate_hz or raise speed",
                             file=source, key="collect.rate_hz")
        n += sum(len(trajectory_poses(t, speed / rate, turn_step_rad=turn_step))
                 for w in worlds for t in w.trajectories)
    k = getattr(exp.res.interpreter(), "n_situations", None)
    if isinstance(k, int) and n < k:
        raise InputError(f"the collect stage would record {n} samples, fewer than the {k} "
                         f"situations to fit; expected at least {k}: collect more "
                         "(collect.worlds, collect.rate_hz, collect.mode) or lower c",
                         file=source, key="interpreter.c")


def prepare_resume(
    path: str | os.PathLike[str],
    *,
    plugins_dirs: tuple[str, ...] = (),
    progress: bool = False,
) -> tuple[Any, dict[str, Any], list[int]]:
    """Rebuild the experiment of an unfinished log.

    Parameters
    ----------
    path
        The log to resume; it is also the output.
    plugins_dirs
        Extra plugin folders (as ``--plugins-dir``); the config's own
        ``plugins.dirs`` are resolved relative to the original config file.
    progress
        Show the progress bar.

    Returns
    -------
    (experiment, run_kwargs, missing)
        Call ``experiment.run(**run_kwargs)`` (``run_kwargs["skip"]`` holds the
        indices already logged, so only the rest run); ``missing`` lists the
        learning-trial indices not yet in the log.

    Raises
    ------
    InputError
        The log cannot be read, or this sitframe no longer resolves its config
        to the same config.
    """

    p = str(path)
    log = open_log(p)
    log.check()  # never append to a damaged log (checksums catch damaged data too)
    raw = log.config
    try:
        cfg = validate_config(raw, file=p, pending=True)  # (all checked as it resolves)
    except InputError as exc:
        raise InputError(f"the log's config is no longer valid: {exc.message}", file=p,
                         key=f"config.{exc.key}" if exc.key else "config") from None
    source = str(log.attrs.get("source", "")) or None
    base_dir = "."
    if source and not source.startswith("preset:"):
        base_dir = str(Path(source).parent)
    if cfg["plugins"]["dirs"] and not plugins_dirs:
        raise InputError(f"the logged config loads plugin code from {cfg['plugins']['dirs']}; "
                         "resuming never runs code that only a log names: pass --plugins-dir "
                         "DIR for each folder you trust", file=p, key="config.plugins.dirs")
    with plugins_of(log, p, plugins_dirs):
        exp, kwargs = prepare_experiment(cfg, source=source, base_dir=base_dir, out=p,
                                         plugins_dirs=plugins_dirs, progress=progress,
                                         config_plugins=False)
    logged_hash = str(log.attrs.get("config_hash", ""))
    if exp.info.config_hash != logged_hash:
        raise InputError("this sitframe resolves the logged config differently (config hash "
                         f"{exp.info.config_hash[:12]} != logged {logged_hash[:12]}: defaults "
                         "changed since the run); resuming would mix two configurations",
                         file=p, key="config_hash")
    _check_inputs(log, exp)
    _check_arithmetic(log)
    exp.info.extra["resume"] = True
    logged_code = str(log.attrs.get("code_hash", ""))
    exp.info.extra["code_changed"] = bool(logged_code) and \
        logged_code != code_fingerprint(exp.info.plugins)
    if log.has("cluster/state"):
        kwargs["interpreter_state"] = log.interpreter_state()
        check_state(exp.res, kwargs["interpreter_state"], p, log.sensor)
    if log.has("spaces"):
        kwargs["space_states"] = log.space_states()
        for name, state in kwargs["space_states"].items():
            check_state(exp.res, state, p, space=name)
    have = set(log.trial_indices())
    kwargs["skip"] = frozenset(have)
    missing = [k for k in range(exp.info.n_trials) if k not in have] \
        if "learn" in exp.config.experiment.stages else []
    return exp, kwargs, missing


def _check_arithmetic(log: Any) -> None:
    """Refuse to resume with another numpy version, other numpy SIMD targets or another BLAS
    kernel than the run started with (on what the log recorded; logs that record none of
    them are resumed as before)."""
    then, now = arithmetic(log.versions), arithmetic(like=log.versions)
    if then and then != now:
        raise InputError(f"the run started with {then}, this process has {now}: the new trials "
                         "would not be bit-identical to what the run would have written; "
                         f"expected the same ({arithmetic_hint(now, then)})", file=log.path,
                         key="versions")


def _check_inputs(log: Any, exp: Any) -> None:
    """Refuse to resume when what the logged trials depended on changed since: a world's
    file, a plugin's version, or what was read from another log (``inputs``)."""
    p = log.path
    now = exp.info.worlds
    for name, text in log.worlds.items():
        if name in now and now[name] != text:
            raise InputError(f"world '{name}' changed since the run started (its file differs "
                             "from the copy in the log); resuming would run trials in two "
                             "different rooms", file=p, key="worlds")
    current = {d.get("name"): (d.get("distribution"), d.get("version"))
               for d in exp.info.plugins}
    for d in log.plugins:
        name, was = d.get("name"), (d.get("distribution"), d.get("version"))
        if name in current and current[name] != was:
            raise InputError(f"plugin '{name}' is {current[name][1]} now, {was[1]} when the run "
                             "started; resuming would mix results of two versions", file=p,
                             key="plugins")
        if name not in current and d.get("origin") != "plugins-dir":
            raise InputError(f"plugin '{name}' ({was[0] or d.get('origin')}) that the run used "
                             "is not installed now", file=p, key="plugins")
    logged = log._json_attr("inputs", "{}", dict)
    for key, digest in logged.items():
        if exp.info.extra.get("inputs", {}).get(key) != digest:
            raise InputError(f"what the run read for {key} changed since it started (another "
                             "log was rewritten); resuming would mix two inputs", file=p,
                             key=f"inputs.{key}")


__all__ = ["prepare_resume"]
