"""Resume an interrupted run from its log (``sitframe run --resume LOG``).

A log left by a killed (``status = "running"``), interrupted (``aborted``)
or failed run holds everything needed to finish it: the resolved config,
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

import os
from pathlib import Path
from typing import Any

from sitframe.contract.config import validate_config
from sitframe.errors import InputError
from sitframe.logs._log import code_fingerprint, open_log
from sitframe.logs.policies import plugins_of
from sitframe.runs.parallel import arithmetic, arithmetic_hint
from sitframe.runs.prepare import check_state, prepare_experiment


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
        cfg = validate_config(raw, file=p)
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
