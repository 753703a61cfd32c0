"""A log's tables as pandas DataFrames (:meth:`sitframe.logs.reader.Log.summary_frame`, ...).

Tidy tables: one row per observation, one column per variable.

* :func:`summary_frame` — one row per finished trial (the log's ``/summary``
  table: ``trial`` and every summary scalar, e.g. ``convergence_iteration``,
  ``eval.novel-1.coverage``; then every per-trial scalar a plugin logged,
  namespaced by where the log keeps it: ``plugins.<plugin>.<key>`` for a
  component's ``trial_end`` and an observer's ``sitframe_trial_data``,
  ``behaviours.<label>.<key>`` for a behaviour's ``trial_data``; see
  :meth:`sitframe.logs.reader.Log.plugin_scalars`).
* :func:`iterations_frame` — one row per iteration of every learning trial
  (``trial``, ``iteration``, then the per-iteration arrays, a 2-D array
  spread over named columns: ``x, y, theta`` for the pose the iteration
  started from, ``heading, speed`` for the command, ``contact_x,
  contact_y``, ``reading_<i>``, ``membership_<i>``, ``weight_<label>``,
  ``reward_<label>``, ``proposal_<label>_heading`` / ``_speed``; then every
  per-iteration series a plugin logged, one row per iteration, as
  ``plugins.<plugin>.<key>`` / ``behaviours.<label>.<key>``, a 2-D one as
  ``<name>.<j>``).
* :func:`evaluations_frame` — the same for the frozen-policy evaluations,
  with a ``world`` column (plugin series logged for the evaluation:
  ``plugins.<plugin>.<key>``).

pandas is an optional dependency (``pip install 'sitframe[pandas]'``); a
clear :class:`ImportError` says so when it is missing. ``sitframe export``
(:mod:`sitframe.analysis.export`) writes these tables as CSV or Parquet.

This module imports nothing from sitframe (the reader imports it): it takes the
:class:`~sitframe.logs.reader.Log` it is given rather than a path, and names what it reads
of it in two protocols, :class:`LogTables` and :class:`TrialTables`.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any, Protocol

import numpy as np

__all__ = ["LogTables", "TrialTables", "evaluations_frame", "is_series", "iterations_frame",
           "plugin_series", "summary_frame"]

_NAMED = {"pose": ("x", "y", "theta"), "command": ("heading", "speed"),
          "contact": ("contact_x", "contact_y")}
_SINGULAR = {"reading": "reading", "memberships": "membership", "weights": "weight"}


class TrialTables(Protocol):
    """What the tables read of one trial (a :class:`~sitframe.logs.reader.TrialLog` has it)."""

    index: int
    """The trial's number."""
    world: str
    """The world it learnt in."""
    arrays: dict[str, np.ndarray]
    """Its per-iteration arrays, by name."""
    episodes: dict[str, Any]
    """Its evaluations' arrays, ``eval/<world>/<name>``."""
    plugins: dict[str, dict[str, Any]]
    """Plugin name -> what that plugin logged for the trial."""
    behaviours: dict[str, dict[str, Any]]
    """Behaviour label -> what that behaviour logged for the trial."""


class LogTables(Protocol):
    """What the tables read of a log (a :class:`~sitframe.logs.reader.Log` has it)."""

    def summary(self, *, plugins: bool = False) -> np.ndarray:
        """The summary table, one row per finished trial."""

    def trial_indices(self) -> list[int]:
        """The finished learning trials."""

    def trial(self, index: int) -> TrialTables:
        """Trial ``index``."""

    def weight_labels(self, index: int) -> list[str] | None:
        """The labels of trial ``index``'s weight columns, if the log names them."""


def _pandas() -> Any:
    try:
        import pandas as pd
    except ImportError:
        raise ImportError("pandas is needed for DataFrames and `sitframe export`; install it "
                          "with pip install 'sitframe[pandas]'") from None
    return pd


def summary_frame(log: LogTables) -> Any:
    """One row per finished trial: ``trial``, every summary scalar and every plugin's
    per-trial scalar (NaN = not logged)."""
    pd = _pandas()
    s = log.summary(plugins=True)  # rows of trials whose group is in the log
    frame = pd.DataFrame({n: s[n] for n in s.dtype.names or ()})
    if "converged" in frame:
        frame["converged"] = frame["converged"] > 0.5
    return frame


def _columns(name: str, a: np.ndarray, n: int, labels: list[str] | None) -> dict[str, Any]:
    a = np.asarray(a)[:n]
    if a.ndim == 1:
        return {name.replace("/", "_"): a}
    if a.ndim != 2:
        return {}
    if name in _NAMED and a.shape[1] == len(_NAMED[name]):
        return dict(zip(_NAMED[name], a.T, strict=True))
    head, _, tail = name.partition("/")
    if head == "proposals" and a.shape[1] == 2:
        return {f"proposal_{tail}_heading": a[:, 0], f"proposal_{tail}_speed": a[:, 1]}
    base = _SINGULAR.get(head, head)
    if labels is not None and len(labels) == a.shape[1]:
        return {f"{base}_{lb}": a[:, j] for j, lb in enumerate(labels)}
    return {f"{base}_{j}": a[:, j] for j in range(a.shape[1])}


def _frame(arrays: dict[str, np.ndarray], columns: dict[str, Any], weights: list[str] | None,
           series: dict[str, Any] | None = None) -> Any:
    pd = _pandas()
    if "collision" not in arrays:
        return pd.DataFrame()
    n = int(np.asarray(arrays["collision"]).shape[0])
    cols: dict[str, Any] = {**{k: np.full(n, v) for k, v in columns.items()},
                            "iteration": np.arange(n)}
    first = ("pose", "reading", "memberships", "command", "collision", "contact", "nearest")
    names = [k for k in first if k in arrays] + [k for k in arrays if k not in first]
    for name in names:
        a = arrays[name]
        if name == "sonar" and "reading" in arrays:  # the pre-v2 alias of reading
            continue
        if np.ndim(a) >= 1 and np.shape(a)[0] in (n, n + 1):  # pose has L + 1 rows
            cols.update(_columns(name, a, n, weights if name == "weights" else None))
    for name, a in (series or {}).items():  # plugins' per-iteration series
        if is_series(a, n):
            a = np.asarray(a)[:n]
            cols.update({name: a} if a.ndim == 1 else
                        {f"{name}.{j}": a[:, j] for j in range(a.shape[1])})
    return pd.DataFrame(cols)


#: What a behaviour's group holds besides its ``trial_data``: the learned policy the core
#: logs (not a plugin's series).
POLICY_KEYS = ("policy/", "actions/", "units/", "q/")


def is_series(a: Any, n: int) -> bool:
    """Whether ``a`` is a per-iteration series of a trial of ``n`` iterations: a numeric
    1-D or 2-D array of ``n`` (or ``n + 1``, as the pose) rows."""
    a = np.asarray(a)
    return a.ndim in (1, 2) and n > 0 and a.shape[0] in (n, n + 1) and a.dtype.kind in "biuf"


def plugin_series(tr: TrialTables, world: str | None = None) -> dict[str, np.ndarray]:
    """The arrays the plugins logged for a trial (``world``: for its evaluation there), by
    namespaced name (``plugins.<plugin>.<key>``, ``behaviours.<label>.<key>``); whether
    each is per iteration is for the caller to check (:func:`is_series`)."""
    out: dict[str, np.ndarray] = {}
    scope = f"eval/{world}/" if world is not None else None
    for plugin, data in tr.plugins.items():
        for key, v in data.items():
            if not isinstance(v, np.ndarray):
                continue
            if scope is None and not key.startswith("eval/"):
                out[f"plugins.{plugin}.{key.replace('/', '.')}"] = v
            elif scope is not None and key.startswith(scope):
                out[f"plugins.{plugin}.{key[len(scope):].replace('/', '.')}"] = v
    if scope is None:
        for label, data in tr.behaviours.items():
            for key, v in data.items():
                if isinstance(v, np.ndarray) and not key.startswith(POLICY_KEYS):
                    out[f"behaviours.{label}.{key.replace('/', '.')}"] = v
    return out


def _trials(log: LogTables, trials: Iterable[int] | None) -> list[TrialTables]:
    return [log.trial(k) for k in (log.trial_indices() if trials is None else trials)]


def iterations_frame(log: LogTables, trials: Iterable[int] | None = None) -> Any:
    """One row per iteration of the learning trials (default all), with a ``trial`` column."""
    pd = _pandas()
    parts = [_frame(tr.arrays, {"trial": tr.index, "world": tr.world},
                    log.weight_labels(tr.index), plugin_series(tr))
             for tr in _trials(log, trials)]
    return pd.concat(parts, ignore_index=True) if parts else pd.DataFrame()


def _evaluations(tr: TrialTables) -> dict[str, dict[str, np.ndarray]]:
    """World -> arrays of each frozen-policy evaluation (``episodes/eval/<world>/<name>``)."""
    out: dict[str, dict[str, np.ndarray]] = {}
    for key, val in tr.episodes.items():
        parts = key.split("/")
        if len(parts) == 3 and parts[0] == "eval":
            out.setdefault(parts[1], {})[parts[2]] = np.asarray(val)
    return out


def evaluations_frame(log: LogTables, trials: Iterable[int] | None = None) -> Any:
    """One row per iteration of every frozen-policy evaluation (``trial``, ``world``, ...)."""
    pd = _pandas()
    parts = [_frame(arrays, {"trial": tr.index, "world": w}, None, plugin_series(tr, w))
             for tr in _trials(log, trials) for w, arrays in _evaluations(tr).items()]
    return pd.concat(parts, ignore_index=True) if parts else pd.DataFrame()
