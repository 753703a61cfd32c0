"""Learned policies in logs: which trial a config reuses, and reading its policy back.

``policy_from.trial = "best"`` picks :func:`best_trial`; a number picks that
trial; a selection table picks by a short episode run
(:func:`sitframe.runs.evaluation.select_trial`). :func:`logged_policy` reads a
trial's learned policy and :func:`check_state` checks that logged situations
fit a config's interpreter.
"""

from __future__ import annotations

import importlib.metadata
import os
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from sitframe.contract.checks import Origin, fault, memberships_mismatch
from sitframe.contract.records import LearnedPolicy, SensorSpec, summary_key
from sitframe.errors import PLUGIN_ERRORS, InputError, PluginError
from sitframe.logs.reader import Log
from sitframe.situations.clustering import average_ranks

if TYPE_CHECKING:
    from sitframe.contract.resolve import Resolved


def check_state(res: Resolved, state: dict[str, Any], path: str,
                sensor: SensorSpec | None = None, space: str = "default") -> None:
    """Load a logged interpreter state into a fresh interpreter (InputError if it does not fit).

    ``sensor``: the geometry of the sensor whose readings the state was fitted on (a
    log's :attr:`Log.sensor`), which the run's sensor must still have. ``space``: the
    situation space whose interpreter takes it (a state fitted on all the readings must
    fit a space's ``view``: its memberships of a reading seen through the view are checked).
    """
    now = res.run.sensor
    if sensor is not None and ((now.name, now.dim, now.max_range) != (
            sensor.name, sensor.dim, sensor.max_range)
            or not np.array_equal(now.angles_deg, sensor.angles_deg)):
        raise InputError(f"its situations were fitted on readings of sensor '{sensor.name}' "
                         f"({sensor.dim} beams at {sensor.angles_deg.tolist()} deg, max range "
                         f"{sensor.max_range:g}), but the sensor '{now.name}' now has {now.dim} "
                         f"at {now.angles_deg.tolist()} deg, max range {now.max_range:g} (did "
                         "its plugin change?)", file=path, key="sensor")
    if space == "default":
        _fits(res.interpreter(), res.origins["interpreter"], "load_state", state,
              "its situations do not fit this config's interpreter", path, "cluster/state")
        return
    interp, key = res.space_interpreter(space), f"spaces.{space}"
    _fits(interp, res.origins[key], "load_state", state,
          f"its situations do not fit the interpreter of space '{space}'", path,
          f"{key}.clusters_from")
    view = res.run.spaces[space].view
    probe = np.full(len(view), res.run.sensor.max_range / 2)
    try:
        u = interp.memberships(probe)
        why = memberships_mismatch(u, int(interp.n_situations))
    except (ValueError, IndexError, TypeError) as exc:
        why = str(exc)
    if why is not None:
        raise InputError(f"its situations do not fit the {len(view)} readings of space "
                         f"'{space}' (view {list(view)}): {why}", file=path,
                         key=f"{key}.view")


def check_logged_policy(res: Resolved, label: str, policy: LearnedPolicy, path: str,
                 key: str = "") -> None:
    """Load a logged policy into a fresh behaviour ``label`` (InputError at ``key``, default
    its ``policy_from``, if it does not fit), so that a mismatch is found before the run
    starts, not in its first trial."""
    _fits(res.behaviours()[label][0], res.origins[f"behaviours.{label}"], "load_policy", policy,
          f"its policy does not fit behaviour '{label}'", path,
          key or f"behaviours.{label}.policy_from")


def _fits(comp: Any, origin: Origin, method: str, value: Any, what: str, path: str,
          key: str) -> None:
    try:
        getattr(comp, method)(value)
    except (ValueError, KeyError, TypeError) as exc:
        why = f"missing {exc}" if isinstance(exc, KeyError) else exc
        raise InputError(f"{what}: {why}", file=path, key=key) from None
    except PLUGIN_ERRORS as exc:  # any other fault is the plugin's
        raise PluginError(str(fault(exc, origin, method))) from exc


@contextmanager
def plugins_of(log: Log, path: str, plugins_dirs: Iterable[str | os.PathLike[str]] = ()
               ) -> Iterator[None]:
    """Add to an "unknown <kind>" error raised inside the block which of the plugins that
    wrote ``log`` are not loaded now (neither an entry point nor a file of ``plugins_dirs``;
    a log of a run with ``--plugins-dir`` names its files)."""
    try:
        yield
    except InputError as exc:
        if not exc.message.startswith("unknown "):
            raise
        loaded = {ep.name for ep in importlib.metadata.entry_points(group="sitframe")} | {
            f.stem for d in plugins_dirs for f in Path(d).glob("*.py")}
        gone = [f"{q['name']} ({q.get('file') or q.get('distribution')})" for q in log.plugins
                if q.get("name") not in loaded and q.get("origin") != "registered"]
        if not gone:
            raise
        raise InputError(f"{exc.message}; the log was written with plugins not loaded now: "
                         f"{', '.join(gone)} (pass --plugins-dir DIR, or install them)",
                         file=exc.file or path, key=exc.key) from None


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
