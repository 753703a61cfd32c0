"""High-level entry points: prepare a run from a config, evaluate a log, print rule bases.

These glue :mod:`sitframe.config`, :mod:`sitframe.scheduler` and
:mod:`sitframe.logs` together for the CLI and for notebooks::

    from sitframe.config import load_config
    from sitframe.experiment import prepare_experiment
    cfg, source, base = load_config("obstacle-avoidance")
    cfg["experiment"]["trials"] = 2
    exp, kwargs = prepare_experiment(cfg, source=source, out="logs/oa.h5")
    result = exp.run(**kwargs)
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from sitframe.config import validate_config
from sitframe.errors import InputError
from sitframe.logs import open_log
from sitframe.pluginmanager import Registry, get_plugin_manager
from sitframe.scheduler import STAGE_EVAL, Experiment, Resolved, TrialSpec, simulate, stage_seed


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
) -> tuple[Experiment, dict[str, Any]]:
    """Validate ``cfg``, resolve its components and the logs it reuses.

    Everything that can be wrong with the input is checked here, before a
    single byte is written.

    Returns
    -------
    (experiment, run_kwargs)
        Call ``experiment.run(**run_kwargs)``.
    """
    cfg = validate_config(cfg, file=source)
    dirs = tuple(_resolve_path(d, base_dir) for d in cfg["plugins"]["dirs"]) + plugins_dirs
    exp = Experiment(cfg, source=source, out=out, plugins_dirs=dirs)
    exp.info.extra["progress"] = progress
    kwargs: dict[str, Any] = {}
    clusters_from = cfg["experiment"]["clusters_from"]
    if clusters_from:
        path = _resolve_path(clusters_from, base_dir)
        log = open_log(path)
        state = log.interpreter_state()
        interp = exp.res.interpreter()
        try:
            interp.load_state(state)
        except (ValueError, KeyError) as exc:
            raise InputError(f"its situations do not fit this config's interpreter: {exc}",
                             file=path, key="cluster/state") from None
        kwargs["interpreter_state"] = state
    policies: dict[str, dict[str, np.ndarray]] = {}
    for label, table in cfg["behaviours"].items():
        pf = table.get("policy_from")
        if not pf:
            continue
        path = _resolve_path(pf["log"], base_dir)
        log = open_log(path)
        trial = log.trial(int(pf.get("trial", 0)))
        src_label = pf.get("behaviour", label)
        if src_label not in trial.behaviours:
            raise InputError(f"trial {trial.index} has no behaviour '{src_label}' (it has "
                             f"{', '.join(trial.behaviours) or 'none'})", file=path,
                             key=f"behaviours.{label}.policy_from.behaviour")
        policy = trial.policy(src_label)
        if not policy:
            raise InputError(f"behaviour '{src_label}' of trial {trial.index} has no learned "
                             "policy (no policy/... datasets)", file=path, key="trials")
        policies[label] = policy
    if policies:
        kwargs["policies"] = policies
    if out and Path(out).exists() and Path(out).is_dir():
        raise InputError("output path is a folder (expected an .h5 file path)", key="--out")
    return exp, kwargs


def evaluate_log(
    log_path: str,
    *,
    world: str,
    trial: int = 0,
    iterations: int = 1000,
    seed: int = 0,
    plugins_dirs: tuple[str, ...] = (),
) -> dict[str, Any]:
    """Run trial ``trial``'s frozen policies from a log in ``world``.

    Returns the evaluation summary: ``iterations``, ``collisions``,
    ``collisions_per_1000``, ``distance_m``, ``mean_speed_m_s``, ``coverage``.
    """
    log = open_log(log_path)
    cfg = validate_config(log.config, file=log_path)
    state = log.interpreter_state()
    tl = log.trial(trial)
    policies = {label: tl.policy(label) for label in tl.behaviours if tl.policy(label)}
    if not policies:
        raise InputError(f"trial {trial} has no learned policy to evaluate", file=log_path,
                         key="trials")
    pm = get_plugin_manager(plugins_dirs=plugins_dirs)
    res = Resolved.build(cfg, Registry.collect(pm), log_path)
    res.world(world, key="--world")
    spec = TrialSpec(index=trial, seed=stage_seed(seed, STAGE_EVAL, trial), world=world,
                     iterations=iterations, learn=False, interpreter_state=state,
                     policies=policies)
    result = simulate(res, spec)
    s = result.summary
    return {
        "log": log_path, "world": world, "trial": trial,
        "iterations": s["iterations"], "collisions": s["collisions"],
        "collisions_per_1000": s["collisions_per_1000"], "distance_m": s["distance_m"],
        "mean_speed_m_s": s["mean_speed_m_s"], "coverage": s["coverage"],
    }


def rule_base_table(result: Any, trial: int = 0) -> Any:
    """A rich Table of trial ``trial``'s learned rule base with situation descriptions."""
    from rich.table import Table

    from sitframe.clustering import describe_prototype

    tr = result.trials[trial]
    centers = result.interpreter_state.get("centers")
    table = Table(title=f"rule base of trial {tr.index}")
    table.add_column("situation", justify="right")
    table.add_column("description")
    outs = []
    for label, data in tr.behaviours.items():
        for k in data:
            if k.startswith("policy/"):
                outs.append((label, k.split("/", 1)[1]))
                table.add_column(f"{label}.{k.split('/', 1)[1]}", justify="right")
    if not outs:
        return table
    first = tr.behaviours[outs[0][0]][f"policy/{outs[0][1]}"]
    angles = result.sensor_angles_deg
    for i in range(len(first)):
        desc = describe_prototype(centers[i], angles) if centers is not None else ""
        row = [f"S{i}", desc]
        for label, out in outs:
            data = tr.behaviours[label]
            a = int(data[f"policy/{out}"][i])
            val = data[f"singletons/{out}"][a]
            row.append(f"{val:+.0f}°" if out == "heading" else f"{val:.2f} m/s")
        table.add_row(*row)
    return table
