"""Prepare a run from a config: its components, and what it reuses from other logs.

``prepare_experiment`` checks everything that can be wrong with the input before a
byte is written, opens the logs a config builds on (``clusters_from``,
``policy_from``; intact logs only) and fingerprints what it reads from them;
``best_trial`` is the rule ``policy_from.trial = "best"`` applies::

    from sitframe.config import load_config
    from sitframe.prepare import prepare_experiment
    cfg, source, base = load_config("obstacle-avoidance")
    cfg["experiment"]["trials"] = 2
    exp, kwargs = prepare_experiment(cfg, source=source, out="logs/oa.h5")
    result = exp.run(**kwargs)
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

from sitframe.clustering import average_ranks
from sitframe.collect import trajectory_poses
from sitframe.config import (
    SELECTION_DEFAULTS,
    config_hash,
    load_config,
    to_toml,
    validate_config,
)
from sitframe.errors import InputError, note
from sitframe.experiment import Experiment
from sitframe.logs import Log, lock_log, open_log, unlock_log
from sitframe.records import LearnedPolicy, summary_key
from sitframe.resolve import Resolved


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
    cfg = validate_config(cfg, file=source)
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

    clusters_from = config.experiment.clusters_from
    if clusters_from:
        path = _resolve_path(clusters_from, base_dir)
        log = source_log(path, "experiment.clusters_from")
        state = log.interpreter_state()
        logged_sensor = validate_config(log.config, file=path)["sensor"]
        if logged_sensor != cfg["sensor"]:
            raise InputError(
                f"its situations were fitted on readings of sensor {logged_sensor}, but this "
                f"config reads {cfg['sensor']}; use the same [sensor] table",
                file=path, key="sensor")
        check_state(exp.res, state, path)
        kwargs["interpreter_state"] = state
        inputs["clusters_from"] = fingerprint(state)
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
            _check_reusable(path, pcfg, experiment, key)
            say(f"reusing {path}: a complete log of '{experiment}' (same config)")
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


def _check_reusable(path: str, cfg: dict[str, Any], experiment: str, key: str) -> None:
    """An existing prerequisite log: complete, and made by the prerequisite's own config."""
    log = open_log(path)
    if not log.complete:
        raise InputError(f"the prerequisite log is not complete (status {log.status}); finish "
                         f"it with `sitframe run --resume {path}`, or remove it to remake it",
                         file=path, key=key)
    if str(log.attrs.get("config_hash", "")) != config_hash(to_toml(cfg)):
        raise InputError(f"exists but was not made by '{experiment}' as it is now (another "
                         "config); remove it to remake it, or name the config that made it",
                         file=path, key=key)


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
        except InputError as exc:
            raise InputError(f"wander mode holds each command 1/rate_hz s: {exc.message}",
                             file=source, key="collect.rate_hz") from None
        except (ValueError, TypeError) as exc:
            raise InputError(f"wander mode holds each command 1/rate_hz s: {exc}",
                             file=source, key="collect.rate_hz") from None
        n += c.wander_samples * len(c.worlds)
    if c.mode in ("trajectory", "both"):
        turn_step = math.radians(exp.res.robot.max_turn_rate_deg_s) / rate
        worlds = []
        estimate = 0.0  # upper bound: samples along the paths + turning on the spot
        for i, name in enumerate(c.worlds):
            world = exp.res.world(name, "collect.worlds")
            if not world.trajectories:
                raise InputError(f"world '{name}' has no [[trajectories]] to collect along; "
                                 "expected a data-collection room (e.g. collect-1) or "
                                 "collect.mode = \"wander\"", file=source,
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


def check_state(res: Resolved, state: dict[str, Any], path: str) -> None:
    """Load a logged interpreter state into a fresh interpreter (InputError if it does not fit)."""
    try:
        res.interpreter().load_state(state)
    except (ValueError, KeyError, TypeError) as exc:
        why = f"missing {exc}" if isinstance(exc, KeyError) else exc
        raise InputError(f"its situations do not fit this config's interpreter: {why}",
                         file=path, key="cluster/state") from None


def best_trial(log: Log) -> int:
    """The trial whose frozen rule base did best in the log's learning world.

    Quality is judged, as the project judges it everywhere, by collisions
    *and* coverage: each trial is ranked by ``eval/<learning world>/
    collisions_per_1000`` (fewest first) and by ``eval/<learning
    world>/coverage`` (most first), ties sharing their average rank, and the
    trial with the smallest sum of the two ranks is chosen; ties go to fewer
    collisions per 1000 iterations after convergence, then to the lowest
    index. Collisions alone would favour a rule base that loops in one corner
    of the room (few collisions because it hardly goes anywhere). Only the
    learning world is used, never the other evaluation rooms, so choosing a
    trial this way does not peek at rooms the robot is later tested in.

    Raises
    ------
    InputError
        The log has no trials, or no evaluation in its learning world.
    """
    table = log.summary()
    world = log.config.get("experiment", {}).get("world", "training")
    column = summary_key("eval", world, "collisions_per_1000", sep=".")
    names = table.dtype.names or ()
    if table.size == 0 or column not in names:
        raise InputError(f"cannot pick the best trial: the log has no evaluation in its learning "
                         f"world '{world}' (include 'evaluate' and '{world}' in the run)",
                         file=log.path, key="summary")
    after = table["collisions_per_1000_after_convergence"] if \
        "collisions_per_1000_after_convergence" in names else np.zeros(table.size)
    cov_key = summary_key("eval", world, "coverage", sep=".")
    coverage = table[cov_key] if cov_key in names \
        else np.zeros(table.size)
    return best_of(table["trial"], table[column], coverage, after)


def selection_rule(selection: dict[str, Any]) -> str:
    """:func:`select_trial`'s rule for ``selection``, in words."""
    sel = {**SELECTION_DEFAULTS, **selection}
    return (f"highest {sel['score']} in {sel['episodes']} episodes in '{sel['world']}', "
            f"seed {sel['seed']}")


def select_trial(path: str, selection: dict[str, Any], *,
                 plugins_dirs: tuple[str, ...] = ()) -> int:
    """The trial of log ``path`` whose frozen policies score highest in a short episode run.

    ``policy_from.trial = {world, episodes, score, seed}``. Every trial runs
    the same ``episodes`` episodes (same start/goal pairs: ``seed``) of the
    evaluation protocol in ``world``, exactly as ``sitframe evaluate PATH
    --world W --trial K --goal-episodes N --seed S`` does (a log of a run
    without a protocol, e.g. obstacle avoidance, is fused with goal seeking
    by the ``goal-finding`` preset's CDB); the trial with the highest
    ``score`` (a key of that command's output, default
    ``collision_free_rate``) wins, ties to the lowest index. Choose ``world``
    among the rooms the robot *learns* in, never a test room: a short
    goal-episode run in ``goal-training`` predicts the collision-free rate in
    unseen rooms far better than :func:`best_trial`'s rank sum (README,
    "Choosing the avoidance rule base").

    Raises
    ------
    InputError
        ``score`` is not a key the protocol reports, or is NaN for a trial.
    """
    from sitframe.evaluation import evaluate_log

    sel = {**SELECTION_DEFAULTS, **selection}
    best, best_score = -1, -math.inf
    for k in open_log(path).trial_indices():
        out = evaluate_log(path, world=str(sel["world"]), trial=k, seed=int(sel["seed"]),
                           goal_episodes=int(sel["episodes"]), plugins_dirs=plugins_dirs)
        v = out.get(str(sel["score"]))
        if not isinstance(v, (int, float)) or math.isnan(v):
            raise InputError(f"cannot select a trial by '{sel['score']}': the episodes report "
                             f"{'NaN' if isinstance(v, float) else 'no such score'} for trial "
                             f"{k}; expected one of "
                             f"{', '.join(x for x, y in out.items() if isinstance(y, float))}",
                             file=path, key="policy_from.trial.score")
        if v > best_score:
            best, best_score = int(k), float(v)
    return best


#: How :func:`best_trial` chooses, in one line (shown by ``sitframe run``).
BEST_TRIAL_RULE = "smallest rank sum of (fewest collisions, most coverage)"


def best_of(index: Any, eval_collisions: Any, coverage: Any, after_collisions: Any) -> int:
    """The rule of :func:`best_trial` on parallel sequences (NaN ranks worst)."""
    coll = np.nan_to_num(np.asarray(eval_collisions, float), nan=np.inf)
    cov = np.nan_to_num(np.asarray(coverage, float), nan=-np.inf)
    score = average_ranks(coll) + average_ranks(-cov)
    order = np.lexsort((np.asarray(index),
                        np.nan_to_num(np.asarray(after_collisions, float), nan=np.inf), score))
    return int(np.asarray(index)[order[0]])


def logged_policy(trial: Any, label: str, path: str) -> LearnedPolicy | None:
    """A trial's learned policy of ``label``, located at the log on error."""
    try:
        return trial.learned_policy(label)
    except InputError as exc:
        raise exc.at(file=path) from None
